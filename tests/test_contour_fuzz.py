"""Contouring must not fail needlessly (issue 22 follow-up): generated CAM programs
(tests/contour_fuzz.py) planned with both feeds; a pass one feed plans is planned by the
other, and every plan is checked independently against rs274's path (deviation of samples and
chords, the reported deviation, the programmed feed, the drive limits). An ``infeasible``
verdict's advice is checked before it is given. The full fuzz is benchmarks/fuzz_contour.py."""

from __future__ import annotations

import numpy as np
import pytest

from planner.contour import estimate_contour, plan_contour
from planner.errors import PlannerError
from tests.contour_fuzz import FEEDS, check, program
from tests.test_contour import ORIGIN, SMALL


def _both(prog: str) -> dict[str, dict]:
    return {feed: check(prog, feed) for feed in FEEDS}


@pytest.mark.slow
@pytest.mark.parametrize("seed", [5, 8])
def test_fuzz_seeds_that_failed_plan_in_both_feeds(seed):
    """Seeds where one feed answered infeasible and the other planned (the taper of a thin
    first cell over many samples; cells too long for a slowed program feed)."""
    runs = _both(program(np.random.default_rng(seed)))
    for feed, r in runs.items():
        assert r["code"] == "ok", (feed, r["message"])
        assert not r["problems"], (feed, r["problems"])


@pytest.mark.parametrize("seed", range(1000, 1005))
def test_generated_small_programs_agree_between_feeds(seed):
    """A fixed slice of small generated programs (one pass of up to four moves): both feeds
    plan within the tolerance, the feed and the limits, or both refuse with the same code;
    never ``infeasible`` in one feed only."""
    runs = _both(program(np.random.default_rng(seed), max_passes=1, max_moves=4))
    codes = {feed: r["code"] for feed, r in runs.items()}
    assert codes["program"] == codes["fastest"], {f: r["message"] for f, r in runs.items()}
    for feed, r in runs.items():
        assert not r["problems"], (feed, r["problems"])


@pytest.mark.slow
def test_infeasible_advice_is_checked():
    """At a sample time of 1 s no timing holds 0.01 mm on SMALL; the error names where the
    plans stop and what the check found: an advice that plans is named as checked (and does
    plan), else the advice tried is said not to help (checked) or not checked within the bound."""
    req = {"program": SMALL, "origin": ORIGIN, "tolerance_m": 1e-5, "settings": {"Ts": 1.0}}
    with pytest.raises(PlannerError) as err:
        plan_contour(req)
    msg = err.value.message
    assert err.value.code == "infeasible" and "the plans stop at line" in msg, msg
    assert "checked" in msg, msg
    if "plans, checked" in msg:  # the advice named plans: so it does
        if err.value.field == "settings.Ts":
            req["settings"] = {"Ts": float(msg.split("settings.Ts ")[-1].split(" s plans")[0])}
        else:
            assert err.value.field == "tolerance_m"
            req["tolerance_m"] = float(msg.split("tolerance_m ")[-1].split(" ")[0])
        res = plan_contour(req)
        assert res.contour is not None and res.contour.max_deviation_m <= res.contour.tolerance_m


def test_estimate_names_the_advice_check_apart():
    """estimate_contour is the work of a program that plans (issue 33: the 4 s floor of the
    advice check made it 2-16x the work of small programs); the bound on checking an
    infeasible pass's advice (at least ADVICE_MIN_S) is named in the detail, not added."""
    import re

    from planner.contour.estimate import ADVICE_MIN_S, ADVICE_WORK

    seconds, detail = estimate_contour({"program": SMALL, "origin": ORIGIN})
    m = re.search(r"checked within ([0-9.]+) s more", detail)
    assert m is not None, detail
    # the bound: ADVICE_WORK times the (one) piece's share, at least ADVICE_MIN_S; not in seconds
    bound = float(m.group(1))
    assert bound >= ADVICE_MIN_S * 0.99 and seconds < bound, (seconds, detail)
    assert bound == pytest.approx(max(ADVICE_MIN_S, ADVICE_WORK * seconds), rel=0.1), (seconds, detail)


@pytest.mark.slow
def test_work_limit_stops_the_advice_check():
    """With a work limit already spent when the pass is found infeasible, its advice is not
    checked: the error says so (no candidate planned past the limit)."""
    req = {"program": SMALL, "origin": ORIGIN, "tolerance_m": 1e-5, "settings": {"Ts": 1.0}}
    with pytest.raises(PlannerError) as err:
        plan_contour(req, work_limit_s=1e-6)
    msg = err.value.message
    assert err.value.code == "infeasible" and "not checked within the work bound" in msg, msg
    assert "plans, checked" not in msg and "do not plan either" not in msg, msg
