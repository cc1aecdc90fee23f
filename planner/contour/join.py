"""The parts of a contour plan and their join into one result (issue 22): the cut pieces
(:func:`planner.contour.plan.plan_cut`), the free moves between passes (:func:`plan_travel`:
rapids and feed moves above the cutting height, the ``fastest`` timing of :func:`planner.plan`
inside a box about the straight move), plunges, retracts, G4 and M0 as the robot at rest
(:func:`plan_dwell`); each part's per-sample Z, source line and dwell (:func:`travel_z`,
:func:`dwell_z`, :func:`cut_z`); the parts joined sample to sample, each starting at the pose
where the previous one settled (:func:`join_parts`), and the result's ``contour`` section
(:func:`contour_section`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..constraints import force_rate
from ..errors import PlannerError
from ..model import RobotModel, kinematics
from ..orchestrator import limit_metrics, plan, plan_timed, rates_within
from ..schema import (
    MAX_HORIZON,
    ContourRequest,
    ContourSection,
    CorridorSamples,
    CorridorSegment,
    Drives,
    Metrics,
    PassSummary,
    PathElement,
    PlanResult,
    Program,
    ProgramBlock,
    Segment,
    Settings,
    Timing,
)
from .passes import RAPID_MARGIN_M
from .search import Scale
from .zaxis import programmed_z

#: with the force-rate limit a free move's horizon spans at least this many of the drives' force
#: ramps (force_max over the rate: 0.05 s by default) unless settings.N is given: a shorter one
#: (30 samples at a fine sample time) sees the stop too late to brake within the rate, and the
#: move crawls (a 3 mm rapid at Ts = 2 ms: 0.29 s with 30 samples, 0.10 s with 50; the cut
#: passes, whose timing brakes ahead, gain nothing from it)
HORIZON_RAMPS = 2.0


class Part:
    """A planned piece of the program: a plan result (or rest) with its per-sample contour data."""

    def __init__(self, result: PlanResult, cutting: np.ndarray, line: np.ndarray, deviation: np.ndarray,
                 cells: int = 0, segments: list[Segment] | None = None):
        self.result, self.cutting, self.line, self.deviation = result, cutting, line, deviation
        self.cells = cells
        self.segments = segments or []
        K = len(cutting)
        #: per sample: Z [m] (program frame), the source line reached, the dwell realised (or None)
        self.z = np.zeros(K)
        self.source = np.zeros(K, np.int64)
        self.dwell: list[str | None] = [None] * K
        #: fastest: the profile's scales found for a cut (the next cut's search starts there)
        self.scale: Scale | None = None
        #: a cut: per sample the index of its element in the pass
        self.elem = np.zeros(len(cutting), np.int64)


def _horizon(req: ContourRequest, st: Settings, model: RobotModel) -> Settings:
    """The settings with the horizon of :data:`HORIZON_RAMPS` force ramps where the force-rate
    limit holds and ``settings.N`` is not given."""
    rate = force_rate(model, st)
    if req.settings.get("N") is not None or rate is None:
        return st
    ramp = float(np.max(np.asarray(model.force_max, float) / rate))
    n = min(math.ceil(HORIZON_RAMPS * ramp / st.Ts - 1e-9), MAX_HORIZON)
    return st if n <= st.N else st.model_copy(update={"N": n})


def held_force(part: Part | None, n_legs: int) -> np.ndarray:
    """The drive forces [N] a part leaves held at its end (its last force applied; a rest's, or
    before the first part: zero), from which the next part's first force steps."""
    if part is None or part.result.metrics is None or len(part.result.time) < 2:
        return np.zeros(n_legs)
    return np.asarray(part.result.drives.force[-2], float)


def rest_breaks(before: np.ndarray, model: RobotModel, st: Settings) -> bool:
    """Whether the forces ``before`` [N] are more than the drives can drop to zero in one sample
    within the force-rate limit (a rest after them breaks it; a part planned from rest, whose
    first force is within one sample's rise of zero, breaks it unless that force leans the same
    way: :meth:`planner.contour.plan._Walk.seamed` plans such a part from them at once)."""
    return not rates_within(model, st, np.asarray(before, float)[None, :])


def seam_breaks(before: np.ndarray, part: Part, model: RobotModel, st: Settings) -> bool:
    """Whether the step from the forces ``before`` [N] to ``part``'s first force (zero for a
    rest) exceeds the force-rate limit (as ``within_limits`` counts it:
    :func:`planner.orchestrator.rates_within`)."""
    first = np.asarray(part.result.drives.force[0], float) if part.result.metrics is not None \
        else np.zeros(model.n_legs)
    return not rates_within(model, st, (first - before)[None, :])


def plan_hold(req: ContourRequest, model: RobotModel, st: Settings, pos: np.ndarray, psi: float, duration: float,
              start_force: np.ndarray, line: int, room: float) -> Part:
    """A rest (plunge, retract, G4, pause) after a part that left forces the drives cannot
    release within one sample's rise (:func:`seam_breaks` with a rest): the robot held at
    ``pos`` for ``duration`` (at least), planned in the constrained mode from ``start_force``
    [N] (the forces fall within the rate limit while the controller keeps the tool within
    ``room`` [m] of ``pos`` in x and y), until it settles."""
    n = max(int(math.ceil(duration / st.Ts - 1e-9)), 2)
    # two boxes about the point (their centre the start and the end): no point to leave at the
    # first sample or to arrive at, which the forces still falling would push the tool past
    box = Segment.model_validate({"lower": [pos[0] - room, pos[1] - room, psi],
                                  "upper": [pos[0] + room, pos[1] + room, psi]})
    segs = [box, box]
    try:
        res = plan_timed(f"rest line {line}", model, st, segs, [1, n - 1], abandon=False, start_force=start_force)
    except PlannerError as err:
        raise PlannerError(err.code, f"line {line}: the drives' forces released at rest at [{pos[0]:.4f}, "
                           f"{pos[1]:.4f}] m (robot frame): {err.message}", "program") from None
    K = len(res.time)
    return Part(res, np.zeros(K, bool), np.zeros(K, np.int64), np.zeros(K), segments=segs)


def plan_travel(req: ContourRequest, model: RobotModel, st: Settings, a: np.ndarray, b: np.ndarray, psi: float,
                line: int, start_force: np.ndarray | None = None) -> Part:
    """A free move from ``a`` to ``b`` (at rest at both) inside a box about the straight move;
    ``start_force``: the forces the part before left [N] (:func:`planner.orchestrator.plan`)."""
    lo = np.minimum(a, b) - RAPID_MARGIN_M
    hi = np.maximum(a, b) + RAPID_MARGIN_M
    segs = [{"lower": [a[0], a[1], psi], "upper": [a[0], a[1], psi]},
            {"lower": [lo[0], lo[1], psi], "upper": [hi[0], hi[1], psi]},
            {"lower": [b[0], b[1], psi], "upper": [b[0], b[1], psi]}]
    settings = _horizon(req, st, model).model_dump(exclude_none=True, exclude={
        "samples_per_segment", "segment_samples", "speed_m_s", "total_time_s"})
    settings["fastest"] = True
    settings["settle_speed_m_s"] = min(st.settle_speed_m_s, 1e-4)
    try:
        res = plan({"name": f"travel line {line}", "robot": req.robot, "segments": segs, "settings": settings},
                   robot=model, start_force=start_force)
    except PlannerError as err:
        raise PlannerError(err.code, f"line {line}: the move from [{a[0]:.4f}, {a[1]:.4f}] to [{b[0]:.4f}, "
                           f"{b[1]:.4f}] m (robot frame): {err.message}", "program") from None
    K = len(res.time)
    return Part(res, np.zeros(K, bool), np.zeros(K, np.int64), np.zeros(K),
                 segments=[Segment.model_validate(s) for s in segs])


def plan_dwell(pos: np.ndarray, psi: float, duration: float, Ts: float) -> Part:
    """The robot at rest for ``duration`` (a plunge, retract, G4 or pause)."""
    n = max(int(math.ceil(duration / Ts - 1e-9)), 1)
    K = n + 1
    pose = np.tile([pos[0], pos[1], psi], (K, 1))
    res = _rest_result(pose)
    return Part(res, np.zeros(K, bool), np.zeros(K, np.int64), np.zeros(K))


def travel_z(part: Part, elements: list[PathElement], a: np.ndarray, b: np.ndarray) -> None:
    """Fill the Z and source line of a travel ``a -> b`` (the straight move over the travel
    ``elements``): each sample's progress along it, as a share of the elements' length."""
    pose = part.result.pose[:, :2]
    d = b - a
    f = np.clip((pose - a) @ d / max(float(d @ d), 1e-24), 0.0, 1.0)
    lengths = np.array([max(e.length_m, 0.0) for e in elements])
    ends = np.cumsum(lengths)
    total = float(ends[-1])
    s = f * total if total > 0 else np.full(len(f), 0.0)
    k = np.minimum(np.searchsorted(ends, s, side="left"), len(elements) - 1) if total > 0 \
        else np.full(len(f), len(elements) - 1)
    starts = ends - lengths
    share = np.clip((s - starts[k]) / np.maximum(lengths[k], 1e-24), 0.0, 1.0)
    z0 = np.array([e.z_start_m for e in elements])
    z1 = np.array([e.z_end_m for e in elements])
    part.z = z0[k] + share * (z1[k] - z0[k])
    part.source = np.array([elements[int(i)].line for i in k], np.int64)


def dwell_z(part: Part, block: ProgramBlock, z: float) -> None:
    """Fill the Z, source line and dwell of a dwell part: its pieces (Z moves and waits) in
    order, their times scaled to the part's samples (never faster than programmed: the part
    rounds up to whole samples); a sample's source line is that of the piece its step ends in."""
    K = len(part.z)
    moves = list(block.z_moves) or [(block.duration_s, z, block.line)]
    times = np.concatenate(([0.0], np.cumsum([max(m[0], 0.0) for m in moves])))
    zs = np.array([block.z_start_m if block.z_start_m is not None else z] + [m[1] for m in moves], float)
    total = float(times[-1])
    t = np.linspace(0.0, total, K)
    part.z = np.interp(t, times, zs) if total > 0 else np.full(K, zs[-1])
    piece = np.minimum(np.searchsorted(times[1:], t - 1e-12 * max(total, 1.0), side="left"), len(moves) - 1)
    part.source = np.array([moves[int(i)][2] for i in piece], np.int64) if total > 0 \
        else np.full(K, moves[-1][2], np.int64)
    part.source[0] = moves[0][2]
    part.dwell = [None] + [block.reason] * (K - 1)


def cut_z(part: Part, elements: list[PathElement], origin: np.ndarray) -> np.ndarray:
    """Fill the Z and source line of a cut part: per sample the Z of its element where the
    sample projects onto it (program frame; :func:`planner.contour.zaxis.programmed_z`). Returns
    each sample's XY distance from that point [m]."""
    part.z, d = programmed_z(part.result.pose[:, :2], part.elem, elements, origin)
    part.source = part.line.copy()
    return d


def _rest_result(pose: np.ndarray) -> PlanResult:
    """A placeholder result of rest samples; :func:`join_parts` fills the drive columns."""
    K = len(pose)
    z = np.zeros((K, 3))
    return PlanResult.model_construct(time=np.arange(K, dtype=float), pose=pose, velocity=z, acceleration=z,
                                      drives=None, corridor=None, metrics=None)


def join_parts(parts: list[Part], req: ContourRequest, st: Settings, model: RobotModel) -> PlanResult:
    """One result: the parts' samples in order (each part's first sample, the previous part's
    last, dropped), the metrics combined over the parts. The rows held from a sample to the
    next (drive forces, and the acceleration under them) at a shared sample are the next
    part's: its first step's force (the previous part's row after its last sample is a 0
    placeholder). The drive limits (``within_limits``, the largest force, force rate, leg speed,
    stroke and tool speed) are computed over the joined samples
    (:func:`planner.orchestrator.limit_metrics`), never combined from the parts'."""

    planned = [p.result for p in parts if p.result.metrics is not None]
    first = planned[0]
    Ts = st.Ts
    cols: dict[str, list[np.ndarray]] = {k: [] for k in ("pose", "velocity", "acceleration", "length", "legv",
                                                         "force", "lower", "upper", "viol")}
    for k, p in enumerate(parts):
        r = p.result
        sl = slice(0 if k == 0 else 1, None)  # rows at a sample
        held = slice(0, -1 if k < len(parts) - 1 else None)  # rows held from a sample to the next
        cols["pose"].append(r.pose[sl])
        cols["velocity"].append(r.velocity[sl])
        cols["acceleration"].append(r.acceleration[held])
        if r.metrics is not None:
            cols["length"].append(r.drives.length[sl])
            cols["legv"].append(r.drives.velocity[sl])
            cols["force"].append(r.drives.force[held])
            cols["lower"].append(r.corridor.lower[sl])
            cols["upper"].append(r.corridor.upper[sl])
            cols["viol"].append(r.corridor.violation_m[sl])
        else:
            poses = r.pose[sl]
            cols["length"].append(kinematics.leg_lengths(model, poses))
            cols["legv"].append(np.zeros((len(poses), model.n_legs)))
            cols["force"].append(np.zeros((len(r.pose[held]), model.n_legs)))
            cols["lower"].append(poses.copy())
            cols["upper"].append(poses.copy())
            cols["viol"].append(np.zeros(len(poses)))
    a = {k: np.concatenate(v) for k, v in cols.items()}
    K = len(a["pose"])
    mts = [r.metrics for r in planned]
    md: dict[str, Any] = first.metrics.model_dump()
    for f in md:
        vals = [getattr(m, f) for m in mts if getattr(m, f) is not None]
        if not vals:
            continue
        if isinstance(vals[0], bool):
            md[f] = all(vals)
        elif f.startswith("max_") or f in ("overshoot_m", "time_indexed_violation_m", "time_indexed_violation_rad",
                                           "qp_iterations_median", "qp_iterations_max", "constraint_slack_max_m",
                                           "speed_slack_max_m_s", "predicted_violation_max_m",
                                           "model_mismatch_max_m", "model_mismatch_max_rad"):
            md[f] = max(vals)
        elif f.startswith("min_"):
            md[f] = min(vals)
        elif f in ("energy", "path_length_m", "infeasible_steps", "qp_fallbacks", "qp_relaxed_steps",
                   "qp_refinements", "qp_failures", "qp_time_ms"):
            md[f] = sum(vals)
        elif f in ("end_error_m", "end_error_rad", "end_speed_m_s", "settled", "force_limit_n", "qp_solver"):
            md[f] = getattr(mts[-1], f)
    md["duration_s"] = (K - 1) * Ts
    md["steps"] = K - 1
    md["compute_ms"] = 0.0
    # the drive limits over the joined plan, as a plan's are (one implementation): a step over the
    # force-rate limit at a seam between two parts counts as anywhere else (issue 35)
    md.update(limit_metrics(model, st.model_copy(update={"mode": "constrained"}), a["velocity"], a["length"], a["legv"],
                            a["force"]))
    segments = [s for p in parts for s in p.segments]
    timing = Timing(method="fastest" if req.feed == "fastest" else "segment_samples",
                    samples_per_segment=first.settings.samples_per_segment, segment_samples=None,
                    sequence_time_s=(K - 1) * Ts, moving_time_s=None,
                    path_length_m=float(md["path_length_m"]), evaluations=None, feasible=None,
                    one_fewer_sample_infeasible=None)
    settings = st.model_copy(update={"segment_samples": None})
    return PlanResult(plan_id=None, contour=None, name=req.name, robot=first.robot, mode="constrained",
                      criterion="range-space",
                      settings=settings, units=first.units, time=np.arange(K) * Ts, pose=a["pose"],
                      velocity=a["velocity"], acceleration=a["acceleration"],
                      drives=Drives(length=a["length"], velocity=a["legv"], force=a["force"]),
                      corridor=CorridorSamples(lower=a["lower"], upper=a["upper"], violation_m=a["viol"],
                                               # the cells validated as the parts' Segments already
                                               segments=[CorridorSegment.model_construct(
                                                   lower=s.lower, upper=s.upper, polygon=s.polygon)
                                                   for s in segments]),
                      metrics=Metrics(**md), timing=timing)


def contour_section(parts: list[Part], summaries: list[PassSummary], result: PlanResult, req: ContourRequest,
                    program: Program, origin: np.ndarray, tol: float, Ts: float) -> ContourSection:
    """The ``contour`` section of the joined ``result``: the parts' per-sample data in order
    (each part's first sample, the previous part's last, dropped; the source line reached never
    goes back), the passes' summaries, the deviation the larger of both directions."""
    cutting = np.concatenate([p.cutting if k == 0 else p.cutting[1:] for k, p in enumerate(parts)])
    lines = np.concatenate([p.line if k == 0 else p.line[1:] for k, p in enumerate(parts)])
    deviation = np.concatenate([p.deviation if k == 0 else p.deviation[1:] for k, p in enumerate(parts)])
    z_m = np.concatenate([p.z if k == 0 else p.z[1:] for k, p in enumerate(parts)])
    source = np.maximum.accumulate(np.concatenate([p.source if k == 0 else p.source[1:]
                                                   for k, p in enumerate(parts)]))
    dwell = [d for k, p in enumerate(parts) for d in (p.dwell if k == 0 else p.dwell[1:])]
    path_max = max((p.max_path_deviation_m for p in summaries), default=0.0)
    return ContourSection(
        cutting=[bool(c) for c in cutting], program_line=[int(x) if x > 0 else None for x in lines],
        tolerance_m=tol, max_deviation_m=max(float(deviation.max()), path_max), max_path_deviation_m=path_max,
        deviation_m=deviation, feed=req.feed,
        cycle_time_s=float(result.time[-1]), cut_time_s=float(cutting.sum() * Ts), passes=summaries,
        max_feed_ratio=max((p.max_feed_ratio or 0.0 for p in summaries), default=None),
        origin=[float(x) for x in origin], words=program.words, comments=program.comments,
        warnings=list(program.warnings), z_m=z_m, source_line=[int(x) for x in source], dwell=dwell)
