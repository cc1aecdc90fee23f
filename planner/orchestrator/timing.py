"""Segment timing: samples per segment from a speed target, a total time, or the fastest
timing the drive limits allow.

The range sequence holds every segment for the same number ``S`` of samples (paper
Section V.B), so the corridor's sequence takes ``K Ts = n S Ts`` for ``n`` segments. The
first segment is the start point (the robot waits there ``S`` samples) and the range
reaches the end point at the last sample of segment ``n-2`` (the taper), after which the
end point is held ``S`` samples. The robot therefore moves during ``(n - 2) S`` samples.
One ``S`` for all segments is kept (not a count per segment) because the taper, the
metrics and the range sequence are defined with one ``S``; corridors from segmentation
have cells of one size, so a uniform count gives a near-uniform speed there.

* ``speed_m_s = v``: the path is the polyline through the segment centres from the start
  point to the end point, length ``L``; ``S = round(L / (v Ts (n - 2)))`` (at least 1),
  so the moving time ``(n - 2) S Ts`` is ``L / v`` to within half a sample per segment.
* ``total_time_s = T``: ``S = round(T / (n Ts))`` (at least 1): the whole range sequence
  (start wait, motion, end hold) takes ``T`` to within half a sample per segment. Settling
  after the sequence (the tail) is not included.
* ``fastest``: the smallest ``S`` whose constrained plan is feasible: no step needed slack
  (corridor kept by the QP), the actual trajectory is contained (violation <= 1e-9 m),
  drive forces, strokes and speeds are within their limits on the actual trajectory, and
  the robot settled. Method: an exponential search from ``S = N`` (halving while feasible,
  doubling while not) brackets the boundary, then bisection on the integer ``S``. This
  assumes feasibility is monotone in ``S`` (more time never hurts), which holds for these
  limits in practice but is not proved; the answer is verified both ways: ``S`` is
  feasible and ``S - 1`` was planned and is not. Cost: about ``2 log2(S)`` full
  constrained plans (each about as long as ``S``), reported as ``timing.evaluations``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ..errors import PlannerError, invalid
from ..schema import MAX_SAMPLES_PER_SEGMENT, MAX_TOTAL_STEPS, PlanResult, Segment, Settings, Timing

__all__ = ["centre_path_length", "moving_segments", "resolve_timing", "timing_info", "feasible", "search_fastest"]


def centre_path_length(segments: Sequence[Segment]) -> float:
    """Length [m] of the polyline through the segments' centres (x, y)."""
    c = np.array([s.centre[:2] for s in segments])
    return float(np.sum(np.hypot(*np.diff(c, axis=0).T)))


def moving_segments(n: int) -> int:
    """Segments over which the robot moves (all but the start and the end point)."""
    return max(n - 2, 1)


def _check_size(S: int, n: int, field: str) -> int:
    if S > MAX_SAMPLES_PER_SEGMENT:
        raise PlannerError("too_large", f"this timing needs {S} samples per segment, more than the limit "
                           f"{MAX_SAMPLES_PER_SEGMENT}; raise settings.Ts", field)
    if n * S > MAX_TOTAL_STEPS:
        raise PlannerError("too_large", f"{n} segments x {S} samples = {n * S} steps exceeds the limit "
                           f"{MAX_TOTAL_STEPS}", field)
    return S


def method_of(st: Settings) -> str:
    """Which timing setting decides ``samples_per_segment``."""
    return ("speed_m_s" if st.speed_m_s is not None else "total_time_s" if st.total_time_s is not None
            else "fastest" if st.fastest else "samples_per_segment")


def resolve_timing(st: Settings, segments: Sequence[Segment] | None) -> Settings:
    """Settings with ``samples_per_segment`` set from ``speed_m_s`` or ``total_time_s``
    (unchanged otherwise). ``segments`` is ``None`` for a reference trajectory, which has
    its own timing (one pose per sample): then these settings are an error."""
    method = method_of(st)
    if method == "samples_per_segment":
        return st
    field = f"settings.{method}"
    if segments is None:
        raise invalid(field, "applies to a corridor (segments or layout); a reference trajectory "
                      "has one pose per sample")
    n = len(segments)
    if st.speed_m_s is not None:
        L = centre_path_length(segments)
        if L <= 0:
            raise invalid(field, "the corridor's centre path has zero length; give samples_per_segment "
                          "or total_time_s instead")
        S = max(1, int(round(L / (st.speed_m_s * st.Ts * moving_segments(n)))))
        return st.model_copy(update={"samples_per_segment": _check_size(S, n, field)})
    if st.total_time_s is not None:
        S = max(1, int(round(st.total_time_s / (n * st.Ts))))
        return st.model_copy(update={"samples_per_segment": _check_size(S, n, field)})
    return st


def timing_info(st: Settings, segments: Sequence[Segment] | None, **extra: object) -> Timing:
    """What the result reports under ``timing``."""
    info: dict = {"method": method_of(st), "samples_per_segment": st.samples_per_segment, "sequence_time_s": None,
                  "moving_time_s": None, "path_length_m": None, "evaluations": None, "feasible": None,
                  "one_fewer_sample_infeasible": None}
    if segments is not None:
        n = len(segments)
        info["sequence_time_s"] = n * st.samples_per_segment * st.Ts
        info["moving_time_s"] = moving_segments(n) * st.samples_per_segment * st.Ts
        info["path_length_m"] = centre_path_length(segments)
    info.update(extra)
    return Timing.model_construct(**info)


def feasible(result: PlanResult) -> bool:
    """A constrained plan that keeps everything it promises (see the module docstring)."""
    mt = result.metrics
    return bool(mt.infeasible_steps == 0 and mt.contained and mt.within_limits and mt.settled)


#: one candidate timing: (feasible, the plan or None, the error code or None)
Candidate = tuple[bool, PlanResult | None, str | None]


def search_fastest(plan_at: Callable[[int], PlanResult], st: Settings,
                   n_segments: int) -> tuple[int, dict[int, Candidate]]:
    """The smallest feasible ``samples_per_segment`` (see the module docstring) by planning
    candidates with ``plan_at(S)``; returns ``(S, candidates)``, ``S = 0`` if none up to the
    limit is feasible (then the largest tried is ``max(candidates)``)."""
    cache: dict[int, Candidate] = {}

    def run(S: int) -> bool:
        if S not in cache:
            try:
                res = plan_at(S)
                cache[S] = (feasible(res), res, None)
            except PlannerError as exc:  # e.g. diverged: too fast
                cache[S] = (False, None, exc.code)
        return cache[S][0]

    s_max = min(MAX_SAMPLES_PER_SEGMENT, MAX_TOTAL_STEPS // n_segments)
    S = min(st.N, s_max)
    hi: int | None
    if run(S):
        hi, lo = S, 0
        while hi > 1:
            cand = max(hi // 2, 1)
            if run(cand):
                hi = cand
            else:
                lo = cand
                break
    else:
        lo, hi = S, None
        while hi is None:
            cand = min(lo * 2, s_max)
            if run(cand):
                hi = cand
            elif cand >= s_max:
                break
            else:
                lo = cand
    if hi is None:
        return 0, cache
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if run(mid):
            hi = mid
        else:
            lo = mid
    if hi > 1 and (hi - 1) not in cache:
        run(hi - 1)
    return hi, cache
