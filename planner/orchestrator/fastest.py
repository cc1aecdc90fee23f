"""``settings.fastest``: the shortest timing whose constrained plan is feasible, found by
planning candidate timings (:func:`search`).

Feasible (:func:`planner.orchestrator.timing.feasible`): no step needed slack, the actual
trajectory is contained, forces, strokes and leg speeds within their limits, settled.

A timing is one sample count per segment (``settings.segment_samples``), so the search is
not limited to one integer for the whole corridor (on Table I one sample more per segment is
0.1 s):

1. **uniform**: the smallest feasible ``S`` for every segment, by an exponential search from
   ``S = N / 2`` and bisection (assumes more time never hurts; verified both ways: ``S`` is
   feasible and ``S - 1`` was planned and is not);
2. **ends**: the start point's wait and the end point's hold cut to one sample each (the
   robot is at rest at the start, and arrives at rest: the arrival rows of the constrained
   mode);
3. **per segment**, front to back: the smallest count that keeps the plan feasible (and
   shortens it), by bisection between 1 and the current count (so ``count - 1`` was planned
   and is not feasible, given the other segments' counts at that time). ``MAX_PASSES - 1``
   further passes try one sample fewer in every segment again; none by default: on Table I
   with the rate limit such a pass found nothing and cost 9 candidates (~50 ms), without it
   it shortened the plan from 0.50 to 0.45 s. Infeasible candidates are abandoned at their
   first infeasible step, so trying low counts is cheap.

Work is reused: a candidate that changes segment ``i`` differs from the best plan so far only
from the first step whose horizon reaches segment ``i``
(``start_i - N``), so it is planned from the best plan's state there
(:class:`~planner.orchestrator.simulate.Resume`) rather than from the start; a candidate is
abandoned at its first infeasible step (the controller raises ``infeasible`` there).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import PlannerError
from ..schema import MAX_SAMPLES_PER_SEGMENT, MAX_TOTAL_STEPS, PlanResult, Segment, Settings
from .simulate import Resume, Simulation
from .timing import feasible

__all__ = ["MAX_PASSES", "Candidate", "search"]

#: front-to-back passes of the per-segment phase (the bisection, then single cuts)
MAX_PASSES = 1


@dataclass
class Candidate:
    """A planned timing."""

    counts: np.ndarray  #: (n,) samples per segment
    result: PlanResult | None  #: None when abandoned (infeasible) or failed
    simulation: Simulation | None
    feasible: bool

    @property
    def steps(self) -> int:
        """Samples of the sequence (the plan's duration without the settling tail)."""
        return int(self.counts.sum())


#: plans ``counts`` from ``resume`` (or from the start), remembering the states at ``keep``
PlanAt = Callable[[np.ndarray, Resume | None, Sequence[int]], tuple[PlanResult, Simulation]]


def search(plan_at: PlanAt, st: Settings, segments: Sequence[Segment]) -> tuple[Candidate | None, int]:
    """The fastest feasible timing (module docstring) and the number of candidates planned;
    ``None`` if no uniform timing up to the limits is feasible."""
    n = len(segments)
    N = st.N
    evaluations = 0

    def starts(counts: np.ndarray) -> np.ndarray:
        return np.concatenate(([0], np.cumsum(counts)))

    def resume_steps(counts: np.ndarray) -> list[int]:
        """The step from which a change of segment i shows, for every moving segment."""
        s = starts(counts)
        return sorted({max(int(s[i]) - N, 0) for i in range(1, n)})

    def run(counts: np.ndarray, base: Candidate | None = None, changed: int = 0) -> Candidate:
        nonlocal evaluations
        evaluations += 1
        resume = None
        if base is not None and base.simulation is not None:
            r = max(int(starts(counts)[changed]) - N, 0)
            resume = base.simulation.resumes.get(r)
        try:
            res, sim = plan_at(counts, resume, resume_steps(counts))
        except PlannerError:  # infeasible at some step (abandoned there), or diverged, not settled
            return Candidate(counts, None, None, False)
        return Candidate(counts, res, sim, feasible(res))

    # 1. uniform
    s_max = min(MAX_SAMPLES_PER_SEGMENT, MAX_TOTAL_STEPS // n)
    tried: dict[int, Candidate] = {}

    def uniform(S: int) -> bool:
        if S not in tried:
            tried[S] = run(np.full(n, S, np.int64))
        return tried[S].feasible

    S = min(max(N // 2, 1), s_max)
    hi: int | None
    if uniform(S):
        hi, lo = S, 0
        while hi > 1:
            cand = max(hi // 2, 1)
            if uniform(cand):
                hi = cand
            else:
                lo = cand
                break
    else:
        lo, hi = S, None
        while hi is None:
            cand = min(lo * 2, s_max)
            if uniform(cand):
                hi = cand
            elif cand >= s_max:
                break
            else:
                lo = cand
    if hi is None:
        return None, evaluations
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if uniform(mid):
            hi = mid
        else:
            lo = mid
    if hi > 1:
        uniform(hi - 1)
    best = tried[hi]

    def better(cand: Candidate) -> bool:  # feasible and a shorter plan (settling tail included)
        return cand.feasible and duration(cand) < duration(best)

    # 2. the start wait and the end hold: one sample each
    if n >= 3 and segments[0].is_point and segments[-1].is_point:
        counts = best.counts.copy()
        counts[0] = counts[-1] = 1
        cand = run(counts)
        if better(cand):
            best = cand

    # 3. per segment, front to back: bisection on the segment's count, then passes of single
    # cuts (one sample fewer) while one shortens the plan
    for i in range(1, n - 1):
        ok, bad = int(best.counts[i]), 0  # feasible at ok (the current plan), not at bad
        while ok - bad > 1:
            mid = (ok + bad) // 2
            counts = best.counts.copy()
            counts[i] = mid
            cand = run(counts, best, i)
            if better(cand):
                best, ok = cand, mid
            else:
                bad = mid
    for _ in range(MAX_PASSES - 1):
        shorter = False
        for i in range(1, n - 1):
            if best.counts[i] > 1:
                counts = best.counts.copy()
                counts[i] -= 1
                cand = run(counts, best, i)
                if better(cand):
                    best, shorter = cand, True
        if not shorter:
            break
    return best, evaluations


def duration(c: Candidate) -> int:
    """A feasible candidate's samples, the settling tail included."""
    assert c.result is not None
    return int(c.result.metrics.steps)
