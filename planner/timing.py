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

import math
import time
from dataclasses import replace

import numpy as np

from .errors import PlannerError, invalid
from .request import MAX_SAMPLES_PER_SEGMENT, MAX_TOTAL_STEPS, Settings


def centre_path_length(segments) -> float:
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


def resolve_timing(st: Settings, segments) -> Settings:
    """Settings with ``samples_per_segment`` set from ``speed_m_s`` or ``total_time_s``
    (unchanged otherwise). ``segments`` is ``None`` for a reference trajectory, which has
    its own timing (one pose per sample): then these settings are an error."""
    if st.speed_m_s is None and st.total_time_s is None and not st.fastest:
        return st
    field = ("settings.speed_m_s" if st.speed_m_s is not None else
             "settings.total_time_s" if st.total_time_s is not None else "settings.fastest")
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
        return replace(st, samples_per_segment=_check_size(S, n, field))
    if st.total_time_s is not None:
        S = max(1, int(round(st.total_time_s / (n * st.Ts))))
        return replace(st, samples_per_segment=_check_size(S, n, field))
    return st


def timing_info(st: Settings, segments, method: str | None = None, **extra) -> dict:
    """What the result reports under ``timing``."""
    if method is None:
        method = ("speed_m_s" if st.speed_m_s is not None else "total_time_s" if st.total_time_s is not None
                  else "fastest" if st.fastest else "samples_per_segment")
    info = {"method": method, "samples_per_segment": st.S, "sequence_time_s": None,
            "moving_time_s": None, "path_length_m": None}
    if segments is not None:
        n = len(segments)
        info["sequence_time_s"] = n * st.S * st.Ts
        info["moving_time_s"] = moving_segments(n) * st.S * st.Ts
        info["path_length_m"] = centre_path_length(segments)
    info.update(extra)
    return info


def feasible(result: dict) -> bool:
    """A constrained plan that keeps everything it promises (see the module docstring)."""
    mt = result["metrics"]
    return bool(mt.get("infeasible_steps", 1) == 0 and mt.get("contained", False)
                and mt.get("within_limits", False) and mt["settled"])


def fastest_plan(req, robot, segments, t0: float) -> dict:
    """The plan at the smallest feasible ``samples_per_segment`` (see module docstring)."""
    from .plan import plan

    st = req.settings
    n = len(segments)
    cache: dict[int, tuple[bool, dict | None, str | None]] = {}

    def run(S: int):
        if S not in cache:
            sub = replace(st, fastest=False, samples_per_segment=S, require_settled=False)
            try:
                res = plan(replace(req, settings=sub), robot=robot, segments=segments)
                cache[S] = (feasible(res), res, None)
            except PlannerError as exc:  # e.g. diverged: too fast
                cache[S] = (False, None, exc.code)
        return cache[S][0]

    s_max = min(MAX_SAMPLES_PER_SEGMENT, MAX_TOTAL_STEPS // n)
    S = min(st.N, s_max)
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
        ok_res = cache[lo][1]
        if st.require_settled or ok_res is None:
            raise PlannerError("infeasible", f"no timing up to {lo} samples per segment keeps the corridor "
                               "within the drive limits", "settings.fastest")
        ok_res["timing"] = timing_info(replace(st, samples_per_segment=lo), segments, "fastest",
                                       evaluations=len(cache), feasible=False)
        return ok_res
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if run(mid):
            hi = mid
        else:
            lo = mid
    if hi > 1 and (hi - 1) not in cache:
        run(hi - 1)
    res = cache[hi][1]
    final = replace(st, samples_per_segment=hi)
    from .request import settings_dict

    res["settings"] = settings_dict(final)
    res["timing"] = timing_info(final, segments, "fastest", evaluations=len(cache), feasible=True,
                                one_fewer_sample_infeasible=bool(hi == 1 or not cache[hi - 1][0]))
    res["metrics"]["compute_ms"] = (time.perf_counter() - t0) * 1e3
    return res
