"""Issue 31 goal 2, issue 33 goal 2: the advice search behind a refusal is bounded by the work
ESTIMATES of its candidates (reference seconds, taken from the compute limit before each is
tried), not by the wall time they took, so the same request gets the same advice on a quiet
machine and a loaded one (the users run of seed 31 gave another message on 18 of 96 refusals
between two runs of the same code: benchmarks/README.md, branch certspeed). Wall time stays a
safety stop at the limit."""

from __future__ import annotations

import copy
import json
import time
from pathlib import Path

import pytest

from planner import PlannerError, estimate_work, plan
from planner.orchestrator.plan import AdviceBudget
from planner.orchestrator.work import MORE_TIME

ROOT = Path(__file__).resolve().parents[1]
TABLE1 = json.loads((ROOT / "app" / "static" / "examples" / "table1.json").read_text())
#: Table I in 0.05 s: 2.65x too little for leg 2's speed limit; 32x the time plans. The 20 s
#: settling tail the estimate counts in full (0.19 s, each candidate its factor of it) makes
#: the budget bind at limits of seconds while the search takes ~0.2 s of wall time: the wall
#: time's safety stop at the limit stays far even at 3x on a loaded machine
TOO_FAST = {**copy.deepcopy(TABLE1), "settings": {"total_time_s": 0.05, "tail_max_s": 20.0}}


def _refusal(req: dict, limit_s: float | None) -> str:
    with pytest.raises(PlannerError) as info:
        plan(req, work_limit_s=limit_s)
    assert info.value.code == "infeasible"
    return info.value.message


def _fast_clock(monkeypatch: pytest.MonkeyPatch, speed: float) -> None:
    """``time.perf_counter`` running ``speed`` times as fast as it does (a loaded machine, as
    the wall clock sees the planner's work)."""
    real = time.perf_counter
    base = real()
    monkeypatch.setattr(time, "perf_counter", lambda: base + speed * (real() - base))


@pytest.mark.parametrize("limit_s", [3.0, 8.0, 12.0])
def test_the_advice_is_the_same_when_the_wall_clock_runs_3x_fast(monkeypatch, limit_s):
    """At each compute limit the refusal's message is the same with the wall clock at 3x
    (the plan and its candidates seem to take 3x as long) as at 1x. With the wall time
    counted (main before this change), Table I in 0.05 s at a 1.2 s limit tried 32x and advised
    it at 1x, and stopped before it and advised fastest at 3x.
    (A first plan of the process loads the kernels: planned once before, so that the wall
    time's safety stop at the limit is far.) The figure of the violation is not compared
    (:func:`_where_and_advice`)."""
    plan(TABLE1)
    quiet = _refusal(TOO_FAST, limit_s)
    _fast_clock(monkeypatch, 3.0)
    loaded = _refusal(TOO_FAST, limit_s)
    assert _where_and_advice(loaded) == _where_and_advice(quiet)


def _where_and_advice(message: str) -> tuple[str, str]:
    """A refusal's place (``at t = ... s (segment n)``) and everything after its verdict (the
    advice). Not the figure of the violation between them: the refused step's slack problem is
    bounded by the CPU time the plan used (``planner.constraints.WorkBound``, issue 33 goal 2),
    so on a loaded machine, or on a process's first plan, the message may say the figure was not
    computed within the bound where a quiet run gives it (seen in ``make test``'s parallel run:
    "by how much the corridor would be left was not computed" against "left by 93 mm"); the
    verdict, its place and the advice do not change."""
    where = message.split(")", 1)[0]
    assert where.startswith("at t = "), message
    verdict, advice = message.split("; set require_settled to false", 1)
    return where, advice


def test_the_candidates_are_the_ones_whose_estimates_fit_the_limit():
    """The time factors tried are exactly those whose estimates (the request's times the
    factor), summed in order with the refused plan's own, fit the limit: the first factor
    that does not fit is named as not tried within the work limit, and with no limit the
    search goes on to the factor that plans (32x)."""
    est = estimate_work(TOO_FAST).seconds
    free = _refusal(TOO_FAST, None)
    assert "32x the time plans" in free
    limit_s = 8.0  # (main before this change: the candidates' wall time counted, 32x tried and advised)
    left, fit = limit_s - est, []
    for f in MORE_TIME[1:]:  # 2x gives less time than leg 2's speed limit needs: not planned
        if est * f > left:
            break
        left -= est * f
        fit.append(f)
    assert fit and fit[-1] < 32
    bounded = _refusal(TOO_FAST, limit_s)
    assert ", ".join(f"{f}x" for f in fit) + " the time do not help either" in bounded, bounded
    assert "more was not tried within the work limit" in bounded


def test_a_budget_takes_estimates_and_stops_at_its_wall_deadline(monkeypatch):
    """:class:`AdviceBudget`: a cost that fits is taken from what is left, one that does not
    is refused and nothing is taken; past the deadline nothing fits whatever its cost; without
    a bound every cost fits (or the bound given for it)."""
    b = AdviceBudget(1.0, time.perf_counter() + 100.0)
    assert b.take(0.6) and b.seconds == pytest.approx(0.4)
    assert not b.take(0.5) and b.seconds == pytest.approx(0.4)
    assert b.take(0.4) and b.seconds == pytest.approx(0.0)
    late = AdviceBudget(10.0, time.perf_counter() - 1.0)
    assert not late.take(0.001) and late.seconds == 10.0
    free = AdviceBudget()
    assert free.take(1e9) and not free.take(61.0, 60.0) and free.take(59.0, 60.0)
