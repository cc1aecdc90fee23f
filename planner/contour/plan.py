"""Contour a CAM program (issue 22): :func:`plan_contour` turns a
:class:`~planner.schema.ContourRequest` into ONE :class:`~planner.schema.PlanResult` for the
whole program, with its ``contour`` section.

Each cut pass becomes a tube corridor of convex cells (:mod:`.tube`) planned in the
constrained mode from rest to rest, so every sample and every straight move between two
samples is within the tolerance of the programmed path, and every point of the programmed path,
its corners included, within the tolerance of the cut (the two-sided tolerance of G64 P, issue
32: ``max_deviation_m`` the larger of both directions, ``max_path_deviation_m`` the second,
:func:`planner.contour.tube.path_to_cut`). Timing: a speed profile along the
pass turned into sample counts per cell. ``program`` feed: a heuristic profile (the cell
speed ``v``, the curvature and corner limits ``sqrt(a R)``, acceleration ``a`` forwards and
backwards) with ``v`` capped at each move's F, lowered until the plan is feasible and no sample
is faster than F. ``fastest``: two timings, the faster kept (the passes after the first use the
first's, from its scale): the heuristic profile scaled (``v = lambda v0``, ``a = lambda^2 a0``),
and the exact path's time-optimal profile under the drive forces and leg speeds
(:mod:`.timing`, bounded at the corners and on the arcs by what the tube allows) slowed by a
scale; each to the largest feasible scale (:func:`largest_feasible`; each candidate abandoned
at its first step that needs slack). The time-optimal one wins where the drive forces bind
(fine sample times, no force-rate limit); the heuristic one where the force-rate limit does
(its start and stop rise at a bounded jerk). Where a feed's own search finds no timing the
other's is tried (:func:`_search`), so a pass one feed plans is planned by both; an
``infeasible`` verdict's advice is checked before it is given (:func:`_confirmed`).
Rapids and feed moves above the cutting height are free moves inside a box about the
straight move (the ``fastest`` timing of :func:`planner.plan`); plunges, retracts, G4 and
M0 are the robot at rest. The parts are joined sample to sample: each part starts at the pose
where the previous one settled.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from .._jit import numpy_only
from ..constraints import force_rate
from ..errors import PlannerError
from ..exchange import read_gcode
from ..model import RobotModel, load_robot
from ..model.placement import fit_shape, reach_extent, reachable_points
from ..model.reach import check_segments
from ..orchestrator import feasible, plan, plan_timed
from ..schema import (
    DEFAULT_CONTOUR_TOLERANCE_M,
    MAX_CONTOUR_TOLERANCE_M,
    MAX_COORDINATE,
    MAX_HORIZON,
    MAX_SEGMENTS,
    MAX_TOTAL_STEPS,
    MIN_TS,
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
    planner_error,
)
from .timing import PathSamples, time_optimal
from .tube import SAGITTA_FRACTION, PathGeometry, Tube, path_to_cut, tube

__all__ = ["CONTOUR_CELL_PLAN_S", "CONTOUR_CELL_S", "CONTOUR_PIECE_S", "CONTOUR_STEP_S", "CONTOUR_TRAVEL_S",
           "estimate_contour", "largest_feasible", "parse_contour_request", "plan_contour"]

#: fastest: the reference cell speed and acceleration the scale multiplies [m/s, m/s^2]
V0_M_S = 0.1
A0_M_S2 = 1.0
#: fastest: the reference jerk of the start and stop [m/s^3] (the scale's cube multiplies it)
J0_M_S3 = 50.0
#: program feed: the acceleration of the profile [m/s^2]
A_PROGRAM_M_S2 = 2.0
#: program feed: the profile's cell speed starts at this fraction of F (the robot, pulled to the
#: cells' centres, runs a little faster than the profile between them)
PROGRAM_MARGIN = 0.9
#: fastest: the scale is found to this relative resolution: ``lam`` feasible, ``lam (1 + r)`` not
SCALE_RESOLUTION = 1 / 64
#: fastest: the range of scales searched
SCALE_MIN, SCALE_MAX = 1 / 64, 64.0
#: the longest cell along the path, in samples at the cell speed (short cells keep the
#: criterion's pull on the cell centre near the path's progress)
CELL_SAMPLES = 4
#: program feed: the profile's scales tried (from PROGRAM_MARGIN down by 0.7 each)
PROGRAM_TRIES = 8
#: an infeasible piece's advice, checked: the tolerance times this, then the sample time times this
ADVICE_TOLERANCE = 2.0
ADVICE_TS = 0.5
#: the checks of the advice take at most this many times the piece's estimate (estimate_contour
#: adds it for the largest pass), and at least ADVICE_MIN_S [s]
ADVICE_WORK = 3.0
ADVICE_MIN_S = 4.0
#: the deviation's candidate elements: those within this many tolerances along the pass of the
#: sample's own (and its neighbours), at most NEAR_MAX of them
NEAR_TOLERANCES = 2.0
NEAR_MAX = 32
#: the cut-to-path deviation's refinement (:func:`_deviation`): rounds, each on points 8 times
#: closer along the moves whose bound exceeds the largest distance measured, while a round
#: measures at most CHORD_POINTS_MAX points
CHORD_ROUNDS = 2
CHORD_POINTS_MAX = 200_000
#: fastest, the time-optimal timing (:func:`_search`): its cells hold this many samples at
#: the profile's top speed (shorter cells keep the robot nearer the profile's progress, longer
#: ones lose fewer samples to cells shorter than a sample's travel)
OPT_CELL_SAMPLES = 1.5
#: the time-optimal timing's scale is found to this relative resolution (its profile is near
#: the drives' limits everywhere: the scale found is near 1, and a finer step is worth its plans)
OPT_RESOLUTION = 1 / 256
#: the samples a tube plan takes beyond the profile's time (the start point, the lead cells, the
#: end point): the time-optimal timing is tried where its profile's time plus these beats the other
OPT_END_SAMPLES = 4
#: the time-optimal profile's grid spacing: the pass's length over this many points, within
#: [GRID_H_MIN, GRID_H_MAX] [m], and at least GRID_POINTS_MIN points (a move from rest to rest
#: on two points would never move)
GRID_POINTS = 400
GRID_H_MIN, GRID_H_MAX = 2e-5, 2e-4
GRID_POINTS_MIN = 16
#: with the force-rate limit a free move's horizon spans at least this many of the drives' force
#: ramps (force_max over the rate: 0.05 s by default) unless settings.N is given: a shorter one
#: (30 samples at a fine sample time) sees the stop too late to brake within the rate, and the
#: move crawls (a 3 mm rapid at Ts = 2 ms: 0.29 s with 30 samples, 0.10 s with 50; the cut
#: passes, whose timing brakes ahead, gain nothing from it)
HORIZON_RAMPS = 2.0
#: the first cells of a pass contain a disk of this radius about where the robot starts [m]
#: (twice the corridor margin: the robot is inside with room to spare)
START_ROOM_M = 2e-6
_RING = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
#: room for the box about a rapid [m]
RAPID_MARGIN_M = 0.002


def parse_contour_request(request: Any) -> ContourRequest:
    """Validate a contour request (dict or model); errors name the field."""
    if isinstance(request, ContourRequest):
        return request
    from pydantic import ValidationError

    try:
        return ContourRequest.model_validate(request)
    except ValidationError as exc:
        raise planner_error(exc) from None


def _check_reach(program: Program, origin: np.ndarray) -> None:
    """Raise ``invalid_input`` naming the first line whose move reaches beyond
    ``MAX_COORDINATE`` m of the robot frame's origin once ``origin`` is added (an arc: its
    ends and the points of its circle it sweeps that are farthest along x or y)."""
    for b in program.blocks:
        for el in b.elements:
            pts = [np.asarray(el.start, float), np.asarray(el.end, float)]
            if el.kind == "arc" and el.centre is not None and el.radius_m and el.start_angle_rad is not None \
                    and el.sweep_rad is not None:
                a0, sweep = float(el.start_angle_rad), float(el.sweep_rad)
                for k in range(4):  # the axis extremes of the circle within the sweep
                    angle = k * math.pi / 2
                    if ((angle - a0) * np.sign(sweep)) % (2 * math.pi) <= abs(sweep):
                        pts.append(np.asarray(el.centre, float) + el.radius_m * np.array([math.cos(angle),
                                                                                           math.sin(angle)]))
            reach = max(float(np.max(np.abs(p + origin))) for p in pts)
            if not reach <= MAX_COORDINATE:
                raise PlannerError("invalid_input", f"line {el.line}: the move reaches {reach:.3g} m from the robot "
                                   f"frame's origin (program zero at {origin.tolist()} m), beyond the limit of "
                                   f"{MAX_COORDINATE:g} m; check the program's units (G20/G21) and the origin",
                                   "program")


def plan_contour(request: Any, *, program: Program | None = None) -> PlanResult:
    """Plan a whole G-code program (module docstring). ``program``: the parsed program, if the
    caller has read it already. Raises :class:`~planner.errors.PlannerError` naming the
    field (``program`` with the line, ``tolerance_m``, ``origin``, ``settings.*``)."""
    t0 = time.perf_counter()
    req = parse_contour_request(request)
    st = req.plan_settings()
    with numpy_only(st.backend == "reference"):  # the numpy reference compiles nothing (issue 24)
        try:
            return _plan_contour(req, st, program, t0)
        except PlannerError as err:
            if req.origin == "fit" or err.code not in ("unreachable", "singular") or "origin that fits" in err.message \
                    or "no origin fits" in err.message:
                raise
            # a typed origin the path leaves the reach at (found while planning): propose one
            program = program or read_gcode(req.program, cut_below=req.cut_below_m, z_rapid_m_s=req.z_rapid_m_s)
            tol = req.tolerance_m if req.tolerance_m is not None else (program.tolerance_m
                                                                         or DEFAULT_CONTOUR_TOLERANCE_M)
            raise PlannerError(err.code, f"{err.message}; {_proposal(program, load_robot(req.robot), tol)}",
                               err.field) from None


#: the margin [m] between the program's moves and the edge of the reach that ``origin: "fit"``
#: keeps (beyond the tolerance): the tube's cells and the travel boxes are boxes about the path
FIT_MARGIN_M = 0.003
#: the platform angle a contour plans at [rad]
CONTOUR_PSI = 0.0


def _travel_run_end(blocks: Sequence[Any], i: int) -> int:
    """The index of the last travel block of the run that starts at ``blocks[i]``: consecutive
    travels are one move, from where the first starts to where the last ends."""
    j = i
    while j + 1 < len(blocks) and blocks[j + 1].kind == "travel":
        j += 1
    return j


def _program_shapes(program: Program, tol: float) -> list[tuple[int, Any]]:
    """What of the program must be reachable, in the program frame, as (source line, shapely
    geometry): each cut move's path (sampled every mm) and the box each travel plans in (the
    straight move from where the tool is grown by ``RAPID_MARGIN_M``), as :func:`_plan_contour`
    moves."""
    import shapely

    out: list[tuple[int, Any]] = []
    pos = np.asarray(program.start, float)

    def travel(a: np.ndarray, b: np.ndarray, line: int) -> None:
        lo, hi = np.minimum(a, b) - RAPID_MARGIN_M, np.maximum(a, b) + RAPID_MARGIN_M
        out.append((line, shapely.box(lo[0], lo[1], hi[0], hi[1])))

    blocks = program.blocks
    i = 0
    while i < len(blocks):
        b = blocks[i]
        if b.kind == "travel":
            j = _travel_run_end(blocks, i)
            target = np.asarray(blocks[j].elements[-1].end, float)
            travel(pos, target, b.line)
            pos, i = target, j + 1
            continue
        if b.kind == "cut":
            if np.hypot(*(np.asarray(b.elements[0].start) - pos)) > 0.5 * tol:
                travel(pos, np.asarray(b.elements[0].start, float), b.line)
            for el in b.elements:
                n = max(2, math.ceil(el.length_m / 1e-3) + 1)
                pts = el.point_at(np.linspace(0.0, el.length_m, n))
                out.append((el.line, shapely.LineString(pts) if el.length_m > 0 else shapely.Point(pts[0])))
            pos = np.asarray(b.elements[-1].end, float)
        i += 1
    if not out:
        out.append((1, shapely.Point(pos)))
    return out


def _reach(model: RobotModel) -> Callable[[np.ndarray, np.ndarray, float], np.ndarray]:
    return lambda x, y, psi: reachable_points(model, x, y, psi)


def _fit(program: Program, model: RobotModel, tol: float) -> tuple[np.ndarray | None, str]:
    """The origin [m] that centres the program's moves (:func:`_program_shapes`) on the robot's
    reachable region, grown by ``FIT_MARGIN_M`` + ``tol``, all of it reachable (the drawing
    import's placement, :func:`planner.model.placement.fit_shape`, unscaled); or None and
    why none does and by how much the program is too large."""
    import shapely

    shapes = [g for _, g in _program_shapes(program, tol)]
    margin = FIT_MARGIN_M + tol
    x0, y0, x1, y1 = shapely.union_all(shapes).bounds
    size = f"{x1 - x0:.4g} m x {y1 - y0:.4g} m"
    try:
        _, _, centre = reach_extent(model, CONTOUR_PSI)
        p = fit_shape(shapes, centre, margin, _reach(model), CONTOUR_PSI)
    except ValueError:
        return None, (f"no origin fits: the program's moves ({size}) grown by a margin of {margin:g} m do not fit "
                      "where the robot reaches at any scale")
    if p.shrunk:
        k = p.factor
        return None, (f"no origin fits: the program's moves span {size} (cuts, and the boxes its travel moves plan "
                      f"in); centred on the robot's reach with a margin of {margin:g} m they fit only at {k:.1%} of "
                      f"their size, {1 / k:.3g} times too large (about {(1 - k) * (x1 - x0):.3g} m too wide and "
                      f"{(1 - k) * (y1 - y0):.3g} m too tall)")
    origin = np.round(np.asarray(p.offset, float), 4) + 0.0
    if not _reachable_at(program, model, origin, tol):  # rounded off the fit: the unrounded one
        origin = np.asarray(p.offset, float)
    return origin, ""


def _reachable_at(program: Program, model: RobotModel, origin: np.ndarray, tol: float) -> bool:
    import shapely

    shapes = [g for _, g in _program_shapes(program, tol)]
    from shapely import affinity

    placed = affinity.translate(shapely.union_all(shapes), *origin).buffer(FIT_MARGIN_M + tol, quad_segs=4)
    pts = np.asarray(shapely.get_coordinates(shapely.segmentize(placed.boundary, 0.002)))
    return bool(np.all(reachable_points(model, pts[:, 0], pts[:, 1], CONTOUR_PSI)))


def fit_origin(program: Program, model: RobotModel, tol: float) -> np.ndarray:
    """The origin ``origin: "fit"`` places the program at (:func:`_fit`); raises ``unreachable``
    saying by how much the program is too large when none fits."""
    origin, why = _fit(program, model, tol)
    if origin is None:
        raise PlannerError("unreachable", why, "origin")
    return origin


def _proposal(program: Program, model: RobotModel, tol: float) -> str:
    origin, why = _fit(program, model, tol)
    if origin is None:
        return why
    return (f"an origin that fits: [{origin[0]:g}, {origin[1]:g}] m (--origin={origin[0]:g},{origin[1]:g}, or "
            "'fit')")


def _check_reachable(program: Program, model: RobotModel, origin: np.ndarray, tol: float) -> None:
    """Raise ``unreachable`` naming the first move (source line) some point of which (a cut's
    path sampled every mm, a travel's box) the robot does not reach at ``origin`` [m], with an
    origin that fits (or why none does)."""
    import shapely

    for line, g in _program_shapes(program, tol):
        edge = g.boundary if g.geom_type == "Polygon" else g
        # a zero-length move (a full circle's chord, a repeated point) is its point: GEOS cannot segmentize it
        dense = edge if edge.length == 0 else shapely.segmentize(edge, 1e-3)
        pts = np.asarray(shapely.get_coordinates(dense)) + origin
        ok = reachable_points(model, pts[:, 0], pts[:, 1], CONTOUR_PSI)
        if not ok.all():
            x, y = pts[int(np.argmin(ok))]
            raise PlannerError("unreachable", f"line {line}: the move passes ({x:.4f} m, {y:.4f} m) in the robot "
                               f"frame, out of the robot's reach with program zero at origin [{origin[0]:g}, "
                               f"{origin[1]:g}] m; {_proposal(program, model, tol)}", "origin")


def _plan_contour(req: ContourRequest, st: Settings, program: Program | None, t0: float) -> PlanResult:
    if program is None:
        program = read_gcode(req.program, cut_below=req.cut_below_m, z_rapid_m_s=req.z_rapid_m_s)
    tol = req.tolerance_m if req.tolerance_m is not None else (program.tolerance_m or DEFAULT_CONTOUR_TOLERANCE_M)
    if req.tolerance_m is None and program.tolerance_m is not None and not 1e-5 <= tol <= 0.01:
        raise PlannerError("invalid_input", f"the program's G64 P gives a tolerance of {tol * 1e3:g} mm, outside "
                           "0.01..10 mm; give tolerance_m", "tolerance_m")
    model = load_robot(req.robot)
    if req.origin == "fit":
        origin = fit_origin(program, model, tol)
    else:
        origin = np.array(req.origin, float)
        _check_reach(program, origin)
        _check_reachable(program, model, origin, tol)
    warnings = list(program.warnings)
    psi = 0.0
    pos = program.start + origin
    z = 0.0  # the tool's Z [m] (program frame; the reader starts at Z 0, as LinuxCNC)
    parts: list[_Part] = []
    pass_summaries: list[PassSummary] = []
    blocks = program.blocks
    hint: _Scale | None = None  # fastest: the timing of the cut before
    memo: dict = {}  # fastest: the time-optimal profiles of the passes (alike passes share one)
    i = 0
    while i < len(blocks):
        b = blocks[i]
        if b.kind == "travel":
            j = _travel_run_end(blocks, i)
            target = blocks[j].elements[-1].end + origin
            if np.hypot(*(target - pos)) > 1e-9:
                part = _travel(req, model, st, pos, target, psi, b.line)
                _travel_z(part, [e for bb in blocks[i:j + 1] for e in bb.elements], pos, target)
                parts.append(part)
                pos = part.result.pose[-1, :2].copy()
            z = blocks[j].elements[-1].z_end_m
            i = j + 1
            continue
        if b.kind == "dwell":
            part = _dwell(pos, psi, b.duration_s, st.Ts)
            _dwell_z(part, b, z)
            parts.append(part)
            z = float(part.z[-1])
            i += 1
            continue
        start_pose = pos.copy()
        gap = float(np.hypot(*(b.elements[0].start + origin - pos)))
        if gap > 0.5 * tol:
            # a cut that starts away from where the tool is: travel there first (at rest)
            part = _travel(req, model, st, pos, b.elements[0].start + origin, psi, b.line)
            part.z[:], part.source[:] = z, b.line
            parts.append(part)
            pos = part.result.pose[-1, :2].copy()
            start_pose = pos.copy()
        first = len(parts)
        geo = PathGeometry(b.elements, origin)
        for chunk in _chunks(b.elements):
            part = _cut(req, model, st, chunk, origin, tol, psi, pos, geo, b.elements, hint,
                        len(program.passes), memo)
            hint = part.scale if part.scale is not None else hint
            _cut_z(part, b.elements, origin)
            parts.append(part)
            pos = part.result.pose[-1, :2].copy()
        cut_parts = parts[first:]
        t_pass = sum(p.result.time[-1] for p in cut_parts)
        dev = max(float(p.deviation.max()) for p in cut_parts)
        # the other direction (issue 32): the pass's programmed path from its cut, the samples
        # of its parts in order (each part starts where the one before settled)
        path_dev = path_to_cut(geo, np.concatenate([p.result.pose[:, :2] for p in cut_parts]), tol)
        speed = max(float(np.hypot(*p.result.velocity[:, :2].T).max()) for p in cut_parts)
        pass_summaries.append(PassSummary(
            index=len(pass_summaries), first_line=b.elements[0].line, last_line=b.elements[-1].line,
            elements=len(b.elements), cells=sum(p.cells for p in cut_parts),
            length_m=float(sum(e.length_m for e in b.elements)), time_s=float(t_pass),
            max_deviation_m=max(dev, path_dev), max_path_deviation_m=path_dev,
            max_speed_m_s=speed, max_programmed_feed_m_s=max(e.feed_m_s for e in b.elements)))
        del start_pose
        z = b.elements[-1].z_end_m
        i += 1
    result = _join(parts, req, st, model)
    cutting = np.concatenate([p.cutting if k == 0 else p.cutting[1:] for k, p in enumerate(parts)])
    lines = np.concatenate([p.line if k == 0 else p.line[1:] for k, p in enumerate(parts)])
    deviation = np.concatenate([p.deviation if k == 0 else p.deviation[1:] for k, p in enumerate(parts)])
    z_m = np.concatenate([p.z if k == 0 else p.z[1:] for k, p in enumerate(parts)])
    source = np.maximum.accumulate(np.concatenate([p.source if k == 0 else p.source[1:]
                                                   for k, p in enumerate(parts)]))
    dwell = [d for k, p in enumerate(parts) for d in (p.dwell if k == 0 else p.dwell[1:])]
    Ts = st.Ts
    path_max = max((p.max_path_deviation_m for p in pass_summaries), default=0.0)
    result.contour = ContourSection(
        cutting=[bool(c) for c in cutting], program_line=[int(x) if x > 0 else None for x in lines],
        tolerance_m=tol, max_deviation_m=max(float(deviation.max()), path_max), max_path_deviation_m=path_max,
        deviation_m=deviation, feed=req.feed,
        cycle_time_s=float(result.time[-1]), cut_time_s=float(cutting.sum() * Ts), passes=pass_summaries,
        origin=[float(x) for x in origin], words=program.words, comments=program.comments, warnings=warnings,
        z_m=z_m, source_line=[int(x) for x in source], dwell=dwell)
    result.metrics.compute_ms = (time.perf_counter() - t0) * 1e3
    return result


def _horizon(req: ContourRequest, st: Settings, model: RobotModel) -> Settings:
    """The settings with the horizon of :data:`HORIZON_RAMPS` force ramps where the force-rate
    limit holds and ``settings.N`` is not given."""
    rate = force_rate(model, st)
    if req.settings.get("N") is not None or rate is None:
        return st
    ramp = float(np.max(np.asarray(model.force_max, float) / rate))
    n = min(math.ceil(HORIZON_RAMPS * ramp / st.Ts - 1e-9), MAX_HORIZON)
    return st if n <= st.N else st.model_copy(update={"N": n})


class _Scale(NamedTuple):
    """``fastest``: the timing a cut found, where the next cut's search starts: its family
    (``optimal``: the time-optimal profile scaled in time by ``lam``; ``profile``: the
    heuristic profile, ``lam`` the whole of it, ``mu`` its speeds) and scales."""

    family: str
    lam: float
    mu: float = 1.0


class _Part:
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
        self.scale: _Scale | None = None
        #: a cut: per sample the index of its element in the pass
        self.elem = np.zeros(len(cutting), np.int64)


def _chunks(elements: list[PathElement]) -> list[list[int]]:
    """The element indices of a pass in pieces the robot plans rest to rest: split after each
    exact-stop move (G61)."""
    out: list[list[int]] = [[]]
    for k, e in enumerate(elements):
        out[-1].append(k)
        if e.exact_stop and k < len(elements) - 1:
            out.append([])
    return out


def _corner_radius(turn: np.ndarray, rho: float) -> np.ndarray:
    """The largest circle that turns a corner of angle ``turn`` [rad] within ``rho`` of its
    vertex: ``rho sin(h) / (1 - sin(h))``, ``h = (pi - turn) / 2`` [m]."""
    half = np.clip((math.pi - turn) / 2, 1e-6, math.pi / 2)
    return rho * np.sin(half) / np.maximum(1 - np.sin(half), 1e-12)


def _profile(t: Tube, v_cap: np.ndarray, a: float, Ts: float, a_turn: float | None = None,
             jerk: float | None = None) -> np.ndarray:
    """Sample counts per segment of the tube from a speed profile: cell speed at most
    ``v_cap`` (per segment), ``sqrt(a_turn R)`` on arcs, ``sqrt(a_turn R_corner)`` at junctions
    (``a_turn``: ``a`` if not given), reached with acceleration ``a`` from rest and back to rest;
    ``jerk``: within ``(jerk / 2)^(1/3) (3 d)^(2/3)`` at a distance ``d`` from the rest at either
    end (the speed of a start from rest at that jerk: the drive forces rise at a bounded rate)."""
    n = len(t.segments)
    a_turn = a if a_turn is None else a_turn
    v = v_cap.astype(float).copy()
    finite = np.isfinite(t.radius)
    v[finite] = np.minimum(v[finite], np.sqrt(a_turn * t.radius[finite]))
    j = t.turn > 0
    v[j] = np.minimum(v[j], np.sqrt(a_turn * _corner_radius(t.turn[j], t.rho)))
    if jerk is not None:
        d = np.concatenate(([0.0], np.cumsum(t.length)))
        d = np.minimum(d[:-1] + t.length, d[-1] - d[:-1])  # the cell's far end from the nearer rest
        v = np.minimum(v, np.cbrt(jerk / 2) * np.cbrt(3 * d) ** 2)
    # speeds at the nodes between segments, from rest to rest
    node = np.empty(n + 1)
    node[0] = 0.0
    for k in range(n):
        node[k + 1] = min(v[k], math.sqrt(node[k] ** 2 + 2 * a * t.length[k]))
    node[n] = 0.0
    for k in range(n - 1, -1, -1):
        node[k] = min(node[k], math.sqrt(node[k + 1] ** 2 + 2 * a * t.length[k]))
    counts = np.ones(n, np.int64)
    cells = t.length > 0
    mean = np.maximum(0.5 * (node[:-1] + node[1:]), 1e-9)
    speed = np.minimum(v, np.maximum(mean, 0.25 * v))[cells]
    counts[cells] = np.maximum(1, np.ceil(t.length[cells] / np.maximum(speed, 1e-12) / Ts - 1e-9)).astype(np.int64)
    counts[t.lead] = 1  # the lead cells at the pass's ends (planner.contour.tube)
    return counts


def _cut(req: ContourRequest, model: RobotModel, st: Settings, chunk: list[int], origin: np.ndarray, tol: float,
         psi: float, pos: np.ndarray, geo: PathGeometry, elements: list[PathElement],
         hint: _Scale | None = None, passes: int = 1, memo: dict | None = None) -> _Part:
    """One piece of a pass planned rest to rest. ``hint``: the ``fastest`` scale found for the
    piece before (where its search starts; the search's result is bracketed the same way from
    any start). No timing found: the ``infeasible`` error with its advice checked
    (:func:`_confirmed`)."""
    els = [elements[k] for k in chunk]
    st = st.model_copy(update={"settle_speed_m_s": min(st.settle_speed_m_s, 1e-4)})
    found = _search(req.feed, model, st, _tubes(model, st, chunk, els, origin, tol, psi, pos, elements), chunk,
                    els, hint, optimal=_optimal_of(model, st, chunk, els, origin, psi, memo))
    if found.result is None:
        raise _confirmed(req, model, st, chunk, els, origin, tol, psi, pos, elements, found, hint, passes)
    result, t = found.result, found.tube
    assert t is not None
    K = len(result.time)
    seg = _segment_of(counts_of(result, len(t.segments)), K)
    elem = t.element[seg]
    cutting = np.ones(K, bool)
    line = geo.line[elem].astype(np.int64)
    dev = _deviation(result.pose[:, :2], elem, geo, tol)
    part = _Part(result, cutting, line, dev, cells=len(t.segments) - 2, segments=t.segments)
    part.scale = found.scale
    part.elem = elem
    return part


def _optimal_of(model: RobotModel, st: Settings, chunk: list[int], els: list[PathElement], origin: np.ndarray,
                psi: float, memo: dict | None) -> Callable[[Tube], _Optimal]:
    """The time-optimal profile of a piece (:func:`planner.contour.timing.time_optimal`) for a
    tube of it (:class:`_Optimal`). Bounds on the speed beyond the drives': at a corner (a
    tangent jump of angle ``theta``) ``sqrt(a r)``, ``a`` the acceleration the drives give in
    every direction, ``r = rho sin(h) / (1 - sin(h))``, ``h = (pi - theta) / 2`` (the
    largest circle that turns there within the cells' radius ``rho``); on an arc, one of its
    chords per sample (a cell holds at least one sample). ``memo``: profiles by the piece's
    geometry and bounds (the depth passes of a program are alike: one profile)."""
    memo = {} if memo is None else memo
    geo = tuple((e.kind, *e.start, *e.end, *(e.centre if e.centre is not None else (0.0, 0.0)), e.sweep_rad or 0.0)
                for e in els)
    lengths = np.array([e.length_m for e in els])
    start = np.concatenate(([0.0], np.cumsum(lengths)))
    h = min(max(float(start[-1]) / GRID_POINTS, GRID_H_MIN), GRID_H_MAX, float(start[-1]) / GRID_POINTS_MIN)
    chunk_a = np.asarray(chunk)

    def at(t: Tube) -> _Optimal:
        loc = np.searchsorted(chunk_a, t.element)
        arc = np.isfinite(t.radius) & (t.length > 0)
        chord = np.zeros(len(els))
        np.maximum.at(chord, loc[arc], t.length[arc])
        key = (geo, float(origin[0]), float(origin[1]), psi, st.Ts, t.rho, tuple(np.round(chord, 12)))
        if key not in memo:
            def caps(path: PathSamples, a_all: np.ndarray) -> np.ndarray:
                cap = np.where(path.corner > 0, a_all * _corner_radius(path.corner, t.rho), np.inf)
                c = chord[path.element]
                return np.minimum(cap, np.where(c > 0, (c / st.Ts) ** 2, np.inf))

            path, w, T = time_optimal(model, els, origin, psi, h, caps)
            memo[key] = (path.s, T, float(np.sqrt(w.max())))
        s_grid, T, v_peak = memo[key]
        # the path length at the end of every segment: its element's start plus its share of the
        # element's cells (points and junctions: at the boundary)
        total = np.bincount(loc, weights=t.length, minlength=len(els))
        before = np.concatenate(([0.0], np.cumsum(total)))[loc]
        frac = (np.cumsum(t.length) - before) / np.maximum(total[loc], 1e-300)
        s_end = start[loc] + np.clip(frac, 0.0, 1.0) * lengths[loc]
        return _Optimal(np.interp(s_end, s_grid, T), v_peak)

    return at


class _Optimal(NamedTuple):
    """The time-optimal profile for one tube."""

    times: np.ndarray  #: the profile's time at the end of each of the tube's segments [s]
    v_peak: float  #: its top speed [m/s]


def _optimal_counts(t: Tube, times: np.ndarray, step: float) -> np.ndarray:
    """Sample counts per segment of the tube from the profile's times at the segments' ends
    (``step``: the sample time over the scale): the samples up to each end, rounded. A sample
    of a segment the profile crosses in no time is taken from the cell before where that has
    two: a junction cell's (it lies inside both its neighbours) and the end's lead cell's (the
    range sequence narrows it onto the end point: its sample is the one that arrives there).
    Every segment at least one sample, the lead cells one."""
    b = np.round(times / step).astype(np.int64)
    counts = np.diff(np.concatenate(([0], b)))
    take = (t.length == 0) & (t.turn > 0)
    if len(take) > 2 and t.lead[-2]:
        take[-2] = True
    j = np.flatnonzero(take & (counts <= 0))
    j = j[(j > 0) & (counts[np.maximum(j - 1, 0)] >= 2)]
    counts[j - 1] -= 1
    counts[j] = 1
    counts = np.maximum(counts, 1)
    counts[t.lead] = 1
    return counts


def _tubes(model: RobotModel, st: Settings, chunk: list[int], els: list[PathElement], origin: np.ndarray,
           tol: float, psi: float, pos: np.ndarray, elements: list[PathElement]) -> Callable[[float], Tube]:
    """The tube of a piece with cells sized for a speed [m/s] (:data:`CELL_SAMPLES` samples at
    it, at least 4 tolerances long), each size built once."""
    made: dict[float, Tube] = {}

    def at(v: float) -> Tube:
        piece_max = max(v * st.Ts * CELL_SAMPLES, 4 * tol)
        key = round(math.log(piece_max) * 8)  # sizes within 13 % share a tube
        if key not in made:
            made[key] = _tube(model, chunk, els, origin, tol, psi, pos, elements, piece_max)
        return made[key]

    return at


def _tube(model: RobotModel, chunk: list[int], els: list[PathElement], origin: np.ndarray, tol: float, psi: float,
          pos: np.ndarray, elements: list[PathElement], piece_max: float) -> Tube:
    """The tube of a piece, starting where the robot is, its reach checked."""
    t = tube(els, origin, tol, psi, piece_max)
    t.element = np.asarray(chunk)[t.element]
    # the first point: where the robot is (within half the tolerance of the path's start, a few
    # um after a move there); the first two cells (the lead cell, held one sample, and the next)
    # are widened to the hull of themselves and a disk of START_ROOM_M about it: the robot at rest
    # there, its forces rising at a bounded rate, moves a few um only in the first samples of a
    # fine sample time (the hull stays within the tolerance: the point is within half of it)
    here = [float(pos[0]), float(pos[1]), psi]
    t.segments[0] = Segment.model_validate({"lower": here, "upper": here})
    import shapely  # loaded on first use (planner._lazy)

    ring = pos + START_ROOM_M * np.column_stack((np.cos(_RING), np.sin(_RING)))
    for k in (1, 2):
        if k < len(t.segments) - 1 and t.segments[k].polygon is not None:
            pts = shapely.multipoints(np.vstack((np.asarray(t.segments[k].polygon, float), ring)))
            poly = shapely.get_coordinates(shapely.get_exterior_ring(shapely.convex_hull(pts)))[:-1]
            lo, hi = poly.min(axis=0), poly.max(axis=0)
            t.segments[k] = Segment.model_validate({"lower": [lo[0], lo[1], psi], "upper": [hi[0], hi[1], psi],
                                                    "polygon": poly.tolist()})
    if len(t.segments) > MAX_SEGMENTS:
        raise PlannerError("too_large", f"line {els[0].line}: the pass needs {len(t.segments)} tube cells at a "
                           f"tolerance of {tol * 1e3:g} mm, more than the limit of {MAX_SEGMENTS}; split the pass "
                           "or give a larger tolerance_m", "program")
    try:
        check_segments(model, t.segments)
    except PlannerError as err:
        k = int(err.field.split("[")[1].split("]")[0]) if err.field and err.field.startswith("segments[") else 0
        line = elements[int(t.element[min(k, len(t.element) - 1)])].line
        raise PlannerError(err.code, f"line {line}: the path leaves the robot's reach at origin "
                           f"[{origin[0]:g}, {origin[1]:g}] m: {err.message}", "program") from None
    return t


class _Found:
    """A timing search's outcome: the plan (None: none found), the ``fastest`` scales, and
    where the candidates stopped (the source line of the first step that needed slack, the
    latest of them)."""

    def __init__(self, Ts: float) -> None:
        self.Ts = Ts
        self.result: PlanResult | None = None
        self.tube: Tube | None = None  #: the tube of the result
        self.scale: _Scale | None = None
        self.stop_line: int | None = None
        self.plans = 0

    def failed(self, err: PlannerError, t: Tube, counts: np.ndarray, els_line: Callable[[int], int]) -> None:
        """Note where a candidate stopped (``at t = ... s`` in the controller's message)."""
        self.plans += 1
        try:
            ts = float(err.message.split("at t = ")[1].split(" s")[0])
        except (IndexError, ValueError):
            return
        k = int(round(ts / self.Ts))
        seg = _segment_of(counts, k + 1)[-1] if k > 0 else 0
        self.stop_line = els_line(int(t.element[min(int(seg), len(t.element) - 1)]))


def _search(feed_mode: str, model: RobotModel, st: Settings, tube_at: Callable[[float], Tube], chunk: list[int],
            els: list[PathElement], hint: _Scale | None, deadline: float | None = None,
            optimal: Callable[[Tube], _Optimal] | None = None) -> _Found:
    """A timing of the piece for the feed mode, in the tube ``tube_at(v)`` with cells sized for
    the profile's speed ``v`` (``program``: the programmed F times the profile's scale, so that
    a slower profile has shorter cells: the criterion pulls the robot toward each cell's
    centre, and a cell of many samples let it run ahead of the profile, faster than F, at
    every scale; ``fastest``: :data:`V0_M_S` for the heuristic profile, the time-optimal
    profile's top speed for its timing ``optimal``, :func:`_optimal_of`; without a ``hint`` the
    heuristic one, then the time-optimal one where it can be faster, else the hint's first). If
    the mode's own search finds none, the other mode's (a timing under the programmed F is one
    ``fastest`` may use; ``program`` retries the ``fastest`` profile capped by F, kept where no sample exceeds F).
    ``deadline`` (``time.process_time``: compute time, as :func:`estimate_contour` counts it):
    candidates after it are not planned."""
    feed = np.array([e.feed_m_s for e in els])
    name = f"line {els[0].line}"
    found = _Found(st.Ts)
    lines = dict(zip(chunk, (e.line for e in els)))

    def feed_on(t: Tube) -> np.ndarray:
        return feed[np.searchsorted(chunk, t.element)]

    def attempt(t: Tube, counts: np.ndarray) -> PlanResult | None:
        if deadline is not None and time.process_time() > deadline:
            return None
        _check_counts(counts, els[0].line)
        try:
            res = plan_timed(name, model, st, t.segments, counts.tolist())
        except PlannerError as err:
            if err.code not in ("infeasible", "not_settled"):
                raise
            found.failed(err, t, counts, lines.__getitem__)
            return None
        found.plans += 1
        return res if feasible(res) else None

    def program_loop() -> tuple[PlanResult, Tube] | None:
        scale = PROGRAM_MARGIN
        for _ in range(PROGRAM_TRIES):
            t = tube_at(float(feed.max()) * scale)
            feed_of = feed_on(t)
            counts = _profile(t, feed_of * scale, A_PROGRAM_M_S2 * scale * scale, st.Ts)
            res = attempt(t, counts)
            if res is None:
                scale *= 0.7
                continue
            over = _overspeed(res, t, counts, feed_of)
            if over <= 1.0:
                return res, t
            scale *= min(0.95 / max(over, 1e-9), 0.9)
        return None

    def scaled(t: Tube, v_cap: np.ndarray, capped: bool, lam0: float, mu0: float, high: float
               ) -> tuple[PlanResult, tuple[float, float]] | None:
        feed_of = feed_on(t)
        tried: dict[bytes, PlanResult | None] = {}  # by the sample counts (scales often give the same)

        def run(lam: float, mu: float = 1.0) -> PlanResult | None:
            counts = _profile(t, v_cap * lam * mu, A0_M_S2 * lam * lam, st.Ts, A0_M_S2 * (lam * mu) ** 2,
                              J0_M_S3 * lam ** 3)
            key = counts.tobytes()
            if key not in tried:
                res = attempt(t, counts)
                if res is not None and capped and _overspeed(res, t, counts, feed_of) > 1.0:
                    res = None
                tried[key] = res
            return tried[key]

        # 1. the whole profile (speeds, accelerations); 2. the speeds alone (cell speed and the
        # curvature and corner limits), the accelerations between them as found: where the
        # start and the stop bound the first scale, the path between them can go faster
        lam = largest_feasible(lambda x: run(x) is not None, lam0, high=high)
        if lam is None:
            return None
        mu = largest_feasible(lambda x: run(lam, x) is not None, max(mu0, 1.0), low=1.0, high=max(high / lam, 1.0))
        assert mu is not None  # mu = 1 is lam's plan
        best = run(lam, mu)
        assert best is not None
        return best, (lam, mu)

    def heuristic(h: _Scale | None) -> tuple[PlanResult, Tube, _Scale] | None:
        h = h if h is not None and h.family == "profile" else None  # the other family's scale means nothing here
        t = tube_at(V0_M_S)
        got = scaled(t, np.full(len(t.segments), V0_M_S), False, h.lam if h else 1.0, h.mu if h else 1.0,
                     SCALE_MAX)
        return (got[0], t, _Scale("profile", *got[1])) if got is not None else None

    def optimal_search(h: _Scale | None, beat: float | None = None) -> tuple[PlanResult, Tube, _Scale] | None:
        """The time-optimal profile's timing (:func:`_optimal_of`) scaled in time by ``1 / lam``
        (speeds ``lam``, accelerations ``lam^2``), the largest feasible ``lam``. ``beat``: the time
        of a timing found already [s]: first the one scale at which this one would be as fast
        (the profile's time over it, a few samples for the ends); not feasible there, none
        slower can win (one plan to know it); else the search starts at the profile itself."""
        assert optimal is not None
        ref = optimal(tube_at(V0_M_S))
        t = tube_at(OPT_CELL_SAMPLES * ref.v_peak / CELL_SAMPLES)
        times = optimal(t).times
        if not (np.all(np.isfinite(times)) and times[-1] > 0):  # pragma: no cover - a profile that never moves
            return None
        tried: dict[bytes, PlanResult | None] = {}

        def run(lam: float) -> PlanResult | None:
            counts = _optimal_counts(t, times, lam * st.Ts)
            key = counts.tobytes()
            if key not in tried:
                tried[key] = attempt(t, counts)
            return tried[key]

        lam0, low = (h.lam if h else 1.0), SCALE_MIN
        if beat is not None:
            room = beat - OPT_END_SAMPLES * st.Ts
            if room <= 0:
                return None
            low = min(max(float(times[-1]) / room, SCALE_MIN), SCALE_MAX)
            if run(low) is None:
                return None
            lam0 = max(low, 1.0)
        lam = largest_feasible(lambda x: run(x) is not None, lam0, OPT_RESOLUTION, low=low, high=SCALE_MAX)
        if lam is None:
            return None
        best = run(lam)
        assert best is not None
        if beat is not None and best.time[-1] >= beat:
            return None
        return best, t, _Scale("optimal", lam)

    if feed_mode == "program":
        got_p = program_loop()
        if got_p is None:  # the fastest profile under F
            t = tube_at(float(feed.max()) * 0.5)
            got = scaled(t, feed_on(t) * PROGRAM_MARGIN, True, 0.5, 1.0, 1.0)
            got_p = (got[0], t) if got is not None else None
        if got_p is not None:
            found.result, found.tube = got_p
    else:
        best: tuple[PlanResult, Tube, _Scale] | None = None
        if hint is None or optimal is None:  # the heuristic first, then the time-optimal one if it can beat it
            best = heuristic(hint)
            if optimal is not None:
                best = optimal_search(None, best[0].time[-1] if best is not None else None) or best
        elif hint.family == "optimal":  # the first pass's timing; the other where it finds none
            best = optimal_search(hint) or heuristic(None)
        else:
            best = heuristic(hint) or optimal_search(None)
        if best is not None:
            found.result, found.tube, found.scale = best
        else:  # a timing under the programmed F
            got_p = program_loop()
            if got_p is not None:
                found.result, found.tube = got_p
    return found


def _confirmed(req: ContourRequest, model: RobotModel, st: Settings, chunk: list[int], els: list[PathElement],
               origin: np.ndarray, tol: float, psi: float, pos: np.ndarray, elements: list[PathElement],
               found: _Found, hint: _Scale | None, passes: int) -> PlannerError:
    """The ``infeasible`` error of a piece no timing plans, its advice checked (issue 22, as
    :func:`planner.orchestrator.plan._more_time_advice` does for plans): the piece planned
    again, by the same search, at :data:`ADVICE_TOLERANCE` times the tolerance, then at
    :data:`ADVICE_TS` times the sample time; the first that plans is named ("tolerance_m
    0.02 plans, checked"), else the error says neither helps and where the plans stop.
    Bounded: the checks together take at most :data:`ADVICE_WORK` times the piece's own
    estimate (:func:`estimate_contour` counts it), at least :data:`ADVICE_MIN_S`; a candidate
    not planned within that is said so."""
    line = els[0].line
    where = f"line {found.stop_line}" if found.stop_line is not None else f"line {line}"
    head = (f"line {line}: no timing keeps the tool within {tol * 1e3:g} mm of the path within the drive limits "
            f"at a sample time of {st.Ts:g} s (the plans stop at {where})")
    budget = max(ADVICE_WORK * _piece_estimate(req.feed, els, st.Ts, passes, tol), ADVICE_MIN_S)
    deadline = time.process_time() + budget
    candidates: list[tuple[str, float, float]] = []
    if tol * ADVICE_TOLERANCE <= MAX_CONTOUR_TOLERANCE_M:
        candidates.append((f"tolerance_m {tol * ADVICE_TOLERANCE:g} ({tol * ADVICE_TOLERANCE * 1e3:g} mm)",
                           tol * ADVICE_TOLERANCE, st.Ts))
    if st.Ts * ADVICE_TS >= MIN_TS:
        candidates.append((f"settings.Ts {st.Ts * ADVICE_TS:g} s", tol, st.Ts * ADVICE_TS))
    tried: list[str] = []
    for what, tol2, Ts2 in candidates:
        if time.process_time() > deadline:
            break
        st2 = st.model_copy(update={"Ts": Ts2})
        try:
            got = _search(req.feed, model, st2, _tubes(model, st2, chunk, els, origin, tol2, psi, pos, elements),
                          chunk, els, hint, deadline)
        except PlannerError:
            got = None
        if got is not None and got.result is not None:
            before = "".join(f"{w} does not plan; " for w in tried)
            return PlannerError("infeasible", f"{head}; {before}{what} plans, checked",
                                "tolerance_m" if tol2 != tol else "settings.Ts")
        if time.process_time() <= deadline:
            tried.append(what)
    not_tried = [w for w, _, _ in candidates if w not in tried]
    if tried and not not_tried:
        return PlannerError("infeasible", f"{head}; neither {' nor '.join(tried)} plans either (checked): the "
                            f"path at {where} asks more of the drives than a tube of that width allows",
                            "tolerance_m")
    msg = f"{head}; {' and '.join(tried)} do not plan either (checked); " if tried else f"{head}; "
    return PlannerError("infeasible", msg + f"{' and '.join(not_tried)} not checked within the work bound "
                        f"({budget:.2g} s); give a larger tolerance_m or a smaller settings.Ts", "tolerance_m")


def largest_feasible(ok: Callable[[float], bool], start: float, resolution: float = SCALE_RESOLUTION,
                     low: float = SCALE_MIN, high: float = SCALE_MAX) -> float | None:
    """The largest scale ``lam`` in ``[low, high]`` with ``ok(lam)`` and not ``ok(lam (1 + resolution))``
    (or ``lam`` at ``high``), found from ``start``: steps growing geometrically (``resolution``,
    twice that, ...) up from a feasible start or down from an infeasible one bracket it, then
    bisection (in the logarithm) narrows the bracket to ``1 + resolution``. From the scale of
    the piece before (identical depth passes), that is two plans: ``start`` and the step above.
    ``None``: nothing from ``low`` up is feasible (assumes slower is never worse, as the
    bisection it replaces did)."""
    start = min(max(start, low), high)
    step = resolution
    if ok(start):
        lo = start
        while True:
            if lo >= high:
                return lo
            cand = min(lo * (1 + step), high)
            if not ok(cand):
                hi = cand
                break
            lo = cand
            step *= 2
    else:
        hi = start
        while True:
            if hi <= low:
                return None
            cand = max(hi / (1 + step), low)
            if ok(cand):
                lo = cand
                break
            hi = cand
            step *= 2
    while hi > lo * (1 + resolution) * (1 + 1e-12):
        mid = math.sqrt(lo * hi)
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return lo


def counts_of(res: PlanResult, n: int) -> np.ndarray:
    ss = res.settings.segment_samples
    return np.asarray(ss if ss is not None else [res.settings.samples_per_segment] * n, np.int64)


def _check_counts(counts: np.ndarray, line: int) -> None:
    if counts.sum() > MAX_TOTAL_STEPS // 2:
        raise PlannerError("too_large", f"line {line}: the pass needs {int(counts.sum())} samples, more than the "
                           f"limit of {MAX_TOTAL_STEPS // 2}; give a larger settings.Ts or split the program",
                           "program")


def _segment_of(counts: np.ndarray, K: int) -> np.ndarray:
    """Segment index of every sample 0..K-1 (sample 0: the start point; past the sequence: the end point)."""
    seg = np.repeat(np.arange(len(counts)), counts)
    idx = np.clip(np.arange(K) - 1, 0, len(seg) - 1)
    out = seg[idx]
    out[0] = 0
    return out


def _overspeed(res: PlanResult, t: Tube, counts: np.ndarray, feed: np.ndarray) -> float:
    """Largest tool speed / the programmed F of the move being cut (samples and chords)."""
    K = len(res.time)
    seg = _segment_of(counts, K)
    speed = np.hypot(*res.velocity[:, :2].T)
    chord = np.zeros(K)
    chord[:-1] = np.hypot(*np.diff(res.pose[:, :2], axis=0).T) / res.settings.Ts
    f = feed[seg]
    return float(np.max(np.maximum(speed, chord) / np.maximum(f, 1e-12)))


def _deviation(pose: np.ndarray, elem: np.ndarray, geo: PathGeometry, tol: float) -> np.ndarray:
    """Per sample: the largest distance from the programmed path of the sample and of the
    straight move to the next, measured on points ``h = tol / 10`` apart along the move plus
    ``h / 2`` (the distance is 1-Lipschitz, so this bounds the maximum from above; the cells
    keep 0.95 tol, so the bound stays within the tolerance) [m]; the moves whose bound exceeds
    the largest distance measured are measured again on points ``h / 8`` apart, and those still
    above it on points ``h / 64`` apart (:data:`CHORD_ROUNDS`: the pass's largest figure is
    within ``h / 128`` of the true maximum, 4e-8 m at a tolerance of 0.05 mm; a round of more
    than :data:`CHORD_POINTS_MAX` points is not measured, the figure then within ``h / 16``).
    Candidates: the elements of both ends and those within :data:`NEAR_TOLERANCES` tolerances
    of them along the pass (a move shorter than the tolerance may be nearer than its
    neighbour; at most :data:`NEAR_MAX` candidates, beyond which the figure can only be too
    large)."""
    K = len(pose)
    h = tol / 10
    lo, hi = geo.near(NEAR_TOLERANCES * tol)
    first = np.minimum(lo[elem[:-1]], lo[elem[1:]])
    last = np.maximum(hi[elem[:-1]], hi[elem[1:]])
    width = int(min(int((last - first).max(initial=0)) + 1, NEAR_MAX))
    cand = np.minimum(first[:, None] + np.arange(width), last[:, None])
    a, b = pose[:-1], pose[1:]
    dev = np.zeros(K)
    seen, bound = _chords(a, b, cand, geo, h)
    dev[:-1] = bound
    top = float(seen.max(initial=0.0))
    for _ in range(CHORD_ROUNDS):
        again = np.nonzero(dev[:-1] > top + 1e-12)[0]
        if not again.size or np.sum(np.hypot(*(b[again] - a[again]).T)) * 8 / h > CHORD_POINTS_MAX:
            break
        h /= 8
        seen_again, dev[again] = _chords(a[again], b[again], cand[again], geo, h)
        top = max(top, float(seen_again.max()))
    e = int(elem[-1])
    end = geo.distance(pose[-1:], np.minimum(lo[e] + np.arange(min(hi[e] - lo[e] + 1, NEAR_MAX)), hi[e])[None, :])
    dev[-1] = max(dev[-1], float(end[0]))
    return dev


def _chords(a: np.ndarray, b: np.ndarray, cand: np.ndarray, geo: PathGeometry, h: float
            ) -> tuple[np.ndarray, np.ndarray]:
    """Per straight move ``a -> b``: the largest distance to the candidate elements ``cand``
    on points at most ``h`` apart, and that plus ``h / 2`` where the move has more than one
    point (a bound from above) [m]."""
    L = np.hypot(*(b - a).T)
    m = np.maximum(np.ceil(L / h).astype(np.int64), 1) + 1
    owner = np.repeat(np.arange(len(a)), m)
    start = np.repeat(np.cumsum(m) - m, m)
    frac = (np.arange(owner.size) - start) / np.repeat(m - 1, m)
    pts = a[owner] + frac[:, None] * (b - a)[owner]
    d = geo.distance(pts, cand[owner])
    seen = np.zeros(len(a))
    np.maximum.at(seen, owner, d)
    return seen, seen + np.where(m > 1, 0.5 * h, 0.0)


def _travel(req: ContourRequest, model: RobotModel, st: Settings, a: np.ndarray, b: np.ndarray, psi: float,
            line: int) -> _Part:
    """A free move from ``a`` to ``b`` (at rest at both) inside a box about the straight move."""
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
                   robot=model)
    except PlannerError as err:
        raise PlannerError(err.code, f"line {line}: the move from [{a[0]:.4f}, {a[1]:.4f}] to [{b[0]:.4f}, "
                           f"{b[1]:.4f}] m (robot frame): {err.message}", "program") from None
    K = len(res.time)
    return _Part(res, np.zeros(K, bool), np.zeros(K, np.int64), np.zeros(K),
                 segments=[Segment.model_validate(s) for s in segs])


def _dwell(pos: np.ndarray, psi: float, duration: float, Ts: float) -> _Part:
    """The robot at rest for ``duration`` (a plunge, retract, G4 or pause)."""
    n = max(int(math.ceil(duration / Ts - 1e-9)), 1)
    K = n + 1
    pose = np.tile([pos[0], pos[1], psi], (K, 1))
    res = _rest_result(pose)
    return _Part(res, np.zeros(K, bool), np.zeros(K, np.int64), np.zeros(K))


def _travel_z(part: _Part, elements: list[PathElement], a: np.ndarray, b: np.ndarray) -> None:
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


def _dwell_z(part: _Part, block: ProgramBlock, z: float) -> None:
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


def _cut_z(part: _Part, elements: list[PathElement], origin: np.ndarray) -> None:
    """Fill the Z and source line of a cut part: per sample the Z of its element where the
    sample projects onto it (program frame)."""
    pose = part.result.pose[:, :2] - origin
    elem = part.elem
    z = np.zeros(len(pose))
    for e_index in np.unique(elem):
        e = elements[int(e_index)]
        mask = elem == e_index
        p = pose[mask]
        if e.kind == "arc" and e.centre is not None and e.sweep_rad and e.start_angle_rad is not None:
            c = np.asarray(e.centre, float)
            ang = np.arctan2(p[:, 1] - c[1], p[:, 0] - c[0])
            rel = ((ang - e.start_angle_rad) * np.sign(e.sweep_rad)) % (2 * math.pi)
            sweep = abs(e.sweep_rad)
            # beyond the arc's end: the nearer end
            f = np.where(rel <= sweep, rel / sweep, np.where(rel - sweep < 2 * math.pi - rel, 1.0, 0.0))
        else:
            a, d = np.asarray(e.start, float), np.asarray(e.end, float) - np.asarray(e.start, float)
            f = np.clip((p - a) @ d / max(float(d @ d), 1e-24), 0.0, 1.0)
        z[mask] = e.z_start_m + f * (e.z_end_m - e.z_start_m)
    part.z = z
    part.source = part.line.copy()


def _rest_result(pose: np.ndarray) -> PlanResult:
    """A placeholder result of rest samples; :func:`_join` fills the drive columns."""
    K = len(pose)
    z = np.zeros((K, 3))
    return PlanResult.model_construct(time=np.arange(K, dtype=float), pose=pose, velocity=z, acceleration=z,
                                      drives=None, corridor=None, metrics=None)


def _join(parts: list[_Part], req: ContourRequest, st: Settings, model: RobotModel) -> PlanResult:
    """One result: the parts' samples in order (each part's first sample, the previous part's
    last, dropped), the metrics combined over the parts. The rows held from a sample to the
    next (drive forces, and the acceleration under them) at a shared sample are the next
    part's: its first step's force (the previous part's row after its last sample is a 0
    placeholder)."""
    from ..model import kinematics

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
    md["max_force_rate_n_s"] = float(np.abs(np.diff(np.vstack((np.zeros((1, a["force"].shape[1])), a["force"])),
                                                    axis=0)).max() / Ts)
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
                                               segments=[CorridorSegment(lower=s.lower, upper=s.upper,
                                                                         polygon=s.polygon) for s in segments]),
                      metrics=Metrics(**md), timing=timing)


#: seconds per receding-horizon step of a tube plan (polygon cells with eight half-planes,
#: junctions): measured ~0.5-1.3 ms per step on the benchmark programs (benchmarks/bench_contour.py);
#: the estimate takes the low end for the samples the feed asks for (the cells' own cost is
#: counted apart: :data:`CONTOUR_CELL_PLAN_S`)
CONTOUR_STEP_S = 3e-4
#: seconds a tube cell costs each candidate plan (its ~1.5-2.5 samples at least, its range and
#: polygon rows): 0.35-0.55 ms measured (issue 33: 1 000 lines of 0.5 mm, 1 000 circles of
#: 0.1 mm, ``benchmarks/bench_estimates.py``)
CONTOUR_CELL_PLAN_S = 6e-4
#: seconds a tube cell costs once a piece: built, its deviation and join (``program`` feed,
#: 0.36-0.49 ms measured); ``fastest`` adds the time-optimal profile (~1.9 ms measured)
CONTOUR_CELL_S = {"program": 5e-4, "fastest": 2.2e-3}
#: seconds of a piece besides its cells and samples (the search, the plan's start and settling)
CONTOUR_PIECE_S = 0.01
#: seconds of a free move between passes (a ``fastest`` plan of three segments, ~5 candidates:
#: 38-62 ms measured at Ts 10 ms), at Ts 10 ms; its samples, and so its cost, grow as 1 / Ts
CONTOUR_TRAVEL_S = 0.065


def _cells(feed: str, elements: list[PathElement], tol: float, Ts: float) -> int:
    """The tube cells of a piece, counted as :func:`planner.contour.tube.tube` makes them:
    each line in pieces of at most ``piece_max`` (:data:`CELL_SAMPLES` samples at the cell
    speed, at least 4 tolerances), each arc in chords of sagitta ``0.18 tol`` (and
    ``piece_max``), a junction at each element boundary, the two end points."""
    if not elements:
        return 0
    s_a = SAGITTA_FRACTION * tol
    v = max(e.feed_m_s for e in elements) * PROGRAM_MARGIN if feed == "program" else V0_M_S
    piece_max = max(v * Ts * CELL_SAMPLES, 4 * tol)
    n = 0
    for e in elements:
        if e.length_m < 1e-9:
            continue
        if e.kind == "arc" and e.radius_m and e.sweep_rad is not None:
            r = e.radius_m
            step = 2 * math.acos(max(1 - s_a / r, -1.0)) if s_a < r else math.pi / 2
            step = min(step, piece_max / r, math.pi / 2)
            n += max(1, math.ceil(abs(e.sweep_rad) / step))
        else:
            n += max(1, math.ceil(e.length_m / piece_max))
    return n + len(elements) + 1


def estimate_contour(request: Any, program: Program | None = None) -> tuple[float, str]:
    """The estimated compute time of :func:`plan_contour` [s] and the arithmetic in words,
    from the program's counts (no tube built, no plan): per piece (a pass, or its parts
    between exact stops) its tube cells (:func:`_cells`: lines, arc chords, junctions) built
    once and planned by each candidate, and its cut samples at the programmed feed
    (``program``; ~1.5 plans) or at the reference speed (``fastest``: ~17 candidate plans for
    the first pass, ~2.5 for the next) (:func:`_piece_estimate`); the free moves between passes
    (:data:`CONTOUR_TRAVEL_S` each); plus the bound on the check of an infeasible verdict's
    advice (:func:`_confirmed`: :data:`ADVICE_WORK` times the largest piece, at least
    :data:`ADVICE_MIN_S`). Measured <= 1.5x it on generated programs of many lines, many tiny
    circles and many short passes (``benchmarks/bench_estimates.py``)."""
    req = parse_contour_request(request)
    st = req.plan_settings()
    if program is None:
        program = read_gcode(req.program, cut_below=req.cut_below_m, z_rapid_m_s=req.z_rapid_m_s)
    tol = req.tolerance_m if req.tolerance_m is not None else (program.tolerance_m or DEFAULT_CONTOUR_TOLERANCE_M)
    n = len(program.passes)
    pieces = [[b.elements[k] for k in chunk] for b in program.passes for chunk in _chunks(b.elements)]
    per_piece = [_piece_estimate(req.feed, els, st.Ts, n, tol) for els in pieces]
    cells = sum(_cells(req.feed, els, tol, st.Ts) for els in pieces)
    samples = sum(_samples(req.feed, b.elements, st.Ts) for b in program.passes)
    travels = sum(1 for k, b in enumerate(program.blocks) if b.kind == "travel"
                  and (k + 1 == len(program.blocks) or program.blocks[k + 1].kind != "travel"))
    travels += 1  # a cut that starts away from the tool: one more
    travel_s = travels * CONTOUR_TRAVEL_S * max(1.0, 0.01 / st.Ts)
    plans = _plans(req.feed, n)
    check = max(ADVICE_WORK * max(per_piece, default=0.0), ADVICE_MIN_S)
    cut_s = sum(per_piece)
    seconds = cut_s + travel_s + check
    parts = {"travel": travel_s, "cells": cells * (CONTOUR_CELL_S[req.feed] + plans * CONTOUR_CELL_PLAN_S),
             "samples": samples * plans * CONTOUR_STEP_S}
    most = max(parts, key=parts.__getitem__)
    advice = {"travel": "fewer passes (each is a move there, planned with the fastest timing)",
              "cells": "a coarser tolerance_m (fewer arc chords) or fewer, longer moves",
              "samples": "a larger settings.Ts or a higher programmed feed"}[most]
    if req.feed == "fastest":
        advice += ", or feed 'program' instead of 'fastest' (one plan a pass instead of a search)"
    return seconds, (f"{n} passes in {len(pieces)} pieces, {cells} tube cells and ~{samples:.0f} cut samples at "
                     f"Ts = {st.Ts:g} s x {plans:.3g} plans: {cut_s:.3g} s; {travels} moves between them: "
                     f"{travel_s:.3g} s; + {check:.2g} s to check the advice of an infeasible pass; most of it "
                     f"{most}: {advice}")


def _samples(feed: str, elements: list[PathElement], Ts: float) -> float:
    """The cut samples of ``elements`` at the programmed feed or the reference speed."""
    return sum(e.length_m / max(e.feed_m_s if feed == "program" else V0_M_S * 2, 1e-9) for e in elements) / Ts


def _plans(feed: str, passes: int) -> float:
    """Candidate plans per pass: ~1.5 (``program``); ``fastest``: ~17 for the first pass (both
    timings, ~8 candidates each), ~2.5 for each next (the first pass's faster timing, its search
    started at the scale found before: two plans when the passes are alike)."""
    return 1.5 if feed == "program" else 2.5 + 15.0 / max(passes, 1)


def _piece_estimate(feed: str, elements: list[PathElement], Ts: float, passes: int = 1,
                    tol: float = DEFAULT_CONTOUR_TOLERANCE_M) -> float:
    """:func:`estimate_contour`'s share of one piece (a pass, or its part between exact stops)
    [s]: :data:`CONTOUR_PIECE_S`, its cells (:func:`_cells`) built once and planned by each
    candidate, its cut samples planned by each candidate."""
    plans = _plans(feed, passes)
    cells = _cells(feed, elements, tol, Ts)
    return (CONTOUR_PIECE_S + cells * (CONTOUR_CELL_S[feed] + plans * CONTOUR_CELL_PLAN_S)
            + _samples(feed, elements, Ts) * plans * CONTOUR_STEP_S)
