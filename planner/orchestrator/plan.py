"""The orchestrator: :func:`plan` turns a request into a :class:`~planner.schema.PlanResult`.

validate (:func:`planner.schema.parse_request`) -> robot model -> corridor (the request's
segments, or a layout segmented into cells) -> reach check -> timing -> range sequence ->
controller (the paper's, or the constrained mode's) -> receding-horizon simulation ->
result. This is the only place that composes the layers; the CLI, the HTTP workers and
the editor all call it.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..constraints import MARGIN_M, MARGIN_RAD, ConstrainedController
from ..corridor import RangeSequence, Segmentation, range_sequence, reference_sequence
from ..corridor import segment as segment_layout
from ..corridor.geometry import corridor_gaps
from ..errors import PlannerError, invalid
from ..model import RobotModel, load_robot
from ..model.reach import check_pose, check_segments
from ..schema import PlanRequest, PlanResult, Reference, Segment, Settings, parse_request
from .fastest import search as search_fastest
from .result import build_result
from .simulate import Resume, Simulation, simulate
from .timing import method_of, resolve_timing, timing_info

__all__ = ["plan", "plan_timed", "segment", "warm_up"]


def _robot(req: PlanRequest, robot: RobotModel | None) -> RobotModel:
    model = load_robot(robot if robot is not None else req.robot)
    st = req.settings
    if st.q_u is not None and len(st.q_u) != model.n_legs:
        raise invalid("settings.q_u", f"must have one entry per drive ({model.n_legs}), got {len(st.q_u)}")
    rate = st.force_rate_n_s
    if isinstance(rate, np.ndarray) and len(rate) != model.n_legs:
        raise invalid("settings.force_rate_n_s", f"must be one number or one per drive ({model.n_legs}), "
                      f"got {len(rate)}")
    return model


def segment(request: Any, *, robot: RobotModel | None = None) -> Segmentation:
    """Segment a request's ``layout`` into cells and a corridor (no planning)."""
    req = parse_request(request)
    if req.layout is None:
        raise invalid("layout", "the request has no layout to segment")
    return segment_layout(req.layout, _robot(req, robot), req.settings)


def plan(request: Any, *, robot: RobotModel | None = None, segments: Sequence[Segment] | None = None) -> PlanResult:
    """Plan a trajectory for ``request`` (a dict in the one JSON shape or a validated
    :class:`~planner.schema.PlanRequest`). ``robot`` overrides the request's robot model,
    ``segments`` its corridor. Raises :class:`~planner.errors.PlannerError` naming the cause."""
    t0 = time.perf_counter()
    req = parse_request(request)
    model = _robot(req, robot)
    st = req.settings
    if segments is None:
        segments = req.segments
    if segments is None and req.layout is not None:
        segments = segment_layout(req.layout, model, st).segments
    if segments is not None:
        check_segments(model, segments)
        if st.fastest:
            result = _fastest(req.name, model, st, segments)
            result.metrics.compute_ms = (time.perf_counter() - t0) * 1e3
            return result
    method = method_of(st)
    st = resolve_timing(st, segments)  # speed_m_s / total_time_s -> samples_per_segment
    result = _plan_once(req.name, model, st, segments, req.reference, method=method)
    result.metrics.compute_ms = (time.perf_counter() - t0) * 1e3  # everything, result arrays included
    mt = result.metrics
    if not mt.settled and st.require_settled:
        raise PlannerError("not_settled", f"the robot did not settle at the end point within "
                           f"{st.tail_max_s:g} s after the corridor (end error {mt.end_error_m * 1e3:.3f} mm, "
                           f"speed {mt.end_speed_m_s * 1e3:.3f} mm/s); lengthen settings.tail_max_s, "
                           "add samples per segment or raise k_r", "settings.tail_max_s")
    return result


def _plan_once(name: str | None, model: RobotModel, st: Settings, segments: Sequence[Segment] | None,
               reference: Reference | None, **timing: object) -> PlanResult:
    """One run of the loop at fixed timing; raises ``infeasible`` for a constrained plan that
    needed slack when ``require_settled`` asks for a guaranteed plan."""
    return _run(name, model, st, segments, reference, timing=timing)[0]


def _run(name: str | None, model: RobotModel, st: Settings, segments: Sequence[Segment] | None,
         reference: Reference | None,
         resume: Resume | None = None, keep: Sequence[int] = (), timing: dict | None = None,
         abandon: bool = False) -> tuple[PlanResult, Simulation]:
    """:func:`_plan_once` from ``resume`` (or the start), remembering the states at ``keep``;
    returns the simulation too. ``abandon``: stop at the first infeasible step (a candidate
    of the ``fastest`` search)."""
    seq: RangeSequence
    if segments is not None:
        seq = range_sequence(list(segments), st, model.n_legs)
    else:
        assert reference is not None
        for i, pose in enumerate(reference.pose):
            check_pose(model, pose, f"reference.pose[{i}]")
        seq = reference_sequence(reference.pose, st, model.n_legs)
    check_pose(model, seq.start, "segments[0]" if segments is not None else "reference.pose[0]")
    controller: ConstrainedController | None = None
    if st.mode == "constrained":
        controller = ConstrainedController(model, seq, st, segments, abandon=abandon)
    sim = simulate(model, seq, st, controller, resume, keep)
    report = controller.report() if controller is not None else {}
    result = build_result(model, name, st, seq, segments, sim, report, timing_info(st, segments, **(timing or {})))
    mt = result.metrics
    if controller is not None and (mt.infeasible_steps or 0) > 0 and st.require_settled:
        raise controller.infeasible_error(
            f"the constrained plan cannot keep the robot in the corridor within the drive limits: "
            f"{mt.infeasible_steps} of {mt.steps} steps needed slack (up to "
            f"{(mt.constraint_slack_max_m or 0.0) * 1e3:.4f} mm)")
    return result, sim


def plan_timed(name: str | None, model: RobotModel, st: Settings, segments: Sequence[Segment],
               counts: Sequence[int], *, abandon: bool = True) -> PlanResult:
    """One constrained plan of ``segments`` held ``counts`` samples each (a caller's own
    timing search, e.g. :mod:`planner.contour`). ``abandon``: raise ``infeasible`` at the first
    step that needs slack instead of planning on. The segments' reach is the caller's check."""
    t0 = time.perf_counter()
    sub = st.model_copy(update={"fastest": False, "segment_samples": [int(c) for c in counts],
                                "samples_per_segment": int(max(counts)), "require_settled": True})
    result = _run(name, model, sub, segments, None, abandon=abandon,
                  timing={"method": "segment_samples"})[0]
    result.metrics.compute_ms = (time.perf_counter() - t0) * 1e3
    return result


def _fastest(name: str | None, model: RobotModel, st: Settings, segments: Sequence[Segment]) -> PlanResult:
    """The plan at the fastest feasible timing (:mod:`.fastest`)."""
    gaps = corridor_gaps(segments, 2 * MARGIN_M, 2 * MARGIN_RAD)

    def plan_at(counts: np.ndarray, resume: Resume | None, keep: Sequence[int]) -> tuple[PlanResult, Simulation]:
        # require_settled: a candidate is abandoned at its first infeasible step
        sub = st.model_copy(update={"fastest": False, "segment_samples": [int(c) for c in counts],
                                    "samples_per_segment": int(counts.max()), "require_settled": True})
        return _run(name, model, sub, segments, None, resume, keep, abandon=True)

    best, evaluations = search_fastest(plan_at, st, segments)
    if best is None or best.result is None:
        why = (f"{gaps[0].describe()}; the robot would have to jump between them within one sample, which no "
               "timing allows: connect or widen the segments") if gaps else \
            "no timing up to the limits keeps the corridor within the drive limits"
        raise PlannerError("infeasible", why, f"segments[{gaps[0].index + 1}]" if gaps else "settings.fastest")
    res = best.result
    counts = [int(c) for c in best.counts]
    final = st.model_copy(update={"fastest": False, "segment_samples": counts, "samples_per_segment": max(counts)})
    res.settings = final
    res.timing = timing_info(final, segments, method="fastest", evaluations=evaluations, feasible=True,
                             one_fewer_sample_infeasible=True)
    return res


def warm_up() -> float:
    """Compile (first run after installing) or load (afterwards, from numba's on-disk cache)
    the compiled kernels of every path by planning tiny corridors: the paper mode; the
    constrained mode with equalities eliminated (psi fixed), with the QP in the inputs (a
    psi range) and the slack problem (too little time). Returns the seconds taken. Servers
    call it before taking jobs, ``make`` after installing (``python -m planner``)."""
    t0 = time.perf_counter()
    fixed = [{"lower": [0.0, 0.0, 0.0], "upper": [0.0, 0.0, 0.0]},
             {"lower": [0.0, 0.0, 0.0], "upper": [0.01, 0.01, 0.0]},
             {"lower": [0.01, 0.01, 0.0], "upper": [0.01, 0.01, 0.0]}]
    turning = [{"lower": [0.0, 0.0, 0.0], "upper": [0.0, 0.0, 0.0]},
               {"lower": [0.0, 0.0, 0.0], "upper": [0.04, 0.01, 0.02]},
               {"lower": [0.04, 0.01, 0.02], "upper": [0.04, 0.01, 0.02]}]
    base = {"N": 5, "require_settled": False, "tail_max_s": 0.05}
    runs: list[tuple[list, dict]] = [
        (fixed, {"mode": "paper"}), (fixed, {"mode": "constrained"}),
        (turning, {"mode": "constrained", "samples_per_segment": 30}),
        (turning, {"mode": "constrained", "samples_per_segment": 2})]
    for segs, extra in runs:
        plan({"robot": "moving-slide", "segments": segs, "settings": {**base, **extra}})
    return time.perf_counter() - t0
