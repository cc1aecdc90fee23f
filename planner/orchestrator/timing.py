"""Segment timing: samples per segment from a speed target, a total time, per-segment
counts, or the fastest timing the drive limits allow.

The range sequence holds each segment for its count of samples: the same ``S`` for every
segment (paper Section V.B, ``samples_per_segment``) or one count per segment
(``segment_samples``). The first segment is the start point (the robot waits there) and the
range reaches the end point at the last sample of segment ``n-2`` (the taper), after which
the end point is held. The robot therefore moves during the samples of segments ``1..n-2``.

* ``speed_m_s = v``: the path is the polyline through the segment centres from the start
  point to the end point, length ``L``; ``S = round(L / (v Ts (n - 2)))`` (at least 1),
  so the moving time ``(n - 2) S Ts`` is ``L / v`` to within half a sample per segment.
* ``total_time_s = T``: ``S = round(T / (n Ts))`` (at least 1): the whole range sequence
  (start wait, motion, end hold) takes ``T`` to within half a sample per segment. Settling
  after the sequence (the tail) is not included.
* ``segment_samples``: the counts as given (one per segment).
* ``fastest``: the shortest feasible timing, per segment (:mod:`planner.orchestrator.fastest`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..corridor import segment_counts
from ..errors import PlannerError, invalid
from ..schema import MAX_SAMPLES_PER_SEGMENT, MAX_TOTAL_STEPS, PlanResult, Segment, Settings, Timing

__all__ = ["centre_path_length", "moving_segments", "resolve_timing", "timing_info", "feasible"]


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
    """Which timing setting decides the samples per segment."""
    return ("speed_m_s" if st.speed_m_s is not None else "total_time_s" if st.total_time_s is not None
            else "fastest" if st.fastest else "segment_samples" if st.segment_samples is not None
            else "samples_per_segment")


def resolve_timing(st: Settings, segments: Sequence[Segment] | None) -> Settings:
    """Settings with ``samples_per_segment`` set from ``speed_m_s`` or ``total_time_s``, which
    are cleared: the settings a plan ran with, which planned again give the same plan (the
    result's ``timing.method`` says how the count was chosen). Unchanged otherwise.
    ``segments`` is ``None`` for a reference trajectory, which has its own timing (one pose
    per sample): then these settings are an error."""
    method = method_of(st)
    if method == "samples_per_segment":
        return st
    field = f"settings.{method}"
    if segments is None:
        raise invalid(field, "applies to a corridor (segments or layout); a reference trajectory "
                      "has one pose per sample")
    n = len(segments)
    if st.segment_samples is not None:
        if len(st.segment_samples) != n:  # a layout's corridor: its length known only now
            raise invalid(field, f"must have one count per segment ({n}), got {len(st.segment_samples)}")
        return st
    if st.speed_m_s is not None:
        L = centre_path_length(segments)
        if L <= 0:
            raise invalid(field, "the corridor's centre path has zero length; give samples_per_segment "
                          "or total_time_s instead")
        S = max(1, int(round(L / (st.speed_m_s * st.Ts * moving_segments(n)))))
        return st.model_copy(update={"samples_per_segment": _check_size(S, n, field), "speed_m_s": None})
    if st.total_time_s is not None:
        S = max(1, int(round(st.total_time_s / (n * st.Ts))))
        return st.model_copy(update={"samples_per_segment": _check_size(S, n, field), "total_time_s": None})
    return st


def timing_info(st: Settings, segments: Sequence[Segment] | None, **extra: object) -> Timing:
    """What the result reports under ``timing``."""
    info: dict = {"method": method_of(st), "samples_per_segment": st.samples_per_segment, "segment_samples": None,
                  "sequence_time_s": None, "moving_time_s": None, "path_length_m": None, "evaluations": None,
                  "feasible": None, "one_fewer_sample_infeasible": None}
    if segments is not None:
        n = len(segments)
        counts = segment_counts(st, n)
        if st.segment_samples is not None:
            info["segment_samples"] = [int(c) for c in counts]
            info["samples_per_segment"] = int(counts.max())
        info["sequence_time_s"] = float(counts.sum() * st.Ts)
        info["moving_time_s"] = float(counts[1:-1].sum() * st.Ts) if n > 2 else float(counts.sum() * st.Ts)
        info["path_length_m"] = centre_path_length(segments)
    info.update(extra)
    return Timing.model_construct(**info)


def feasible(result: PlanResult) -> bool:
    """A constrained plan that keeps everything it promises (see the module docstring)."""
    mt = result.metrics
    return bool(mt.infeasible_steps == 0 and mt.contained and mt.within_limits and mt.settled)
