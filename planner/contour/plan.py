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
scale; each to the largest feasible scale (:func:`~planner.contour.search.largest_feasible`; each candidate abandoned
at its first step that needs slack). The time-optimal one wins where the drive forces bind
(fine sample times, no force-rate limit); the heuristic one where the force-rate limit does
(its start and stop rise at a bounded jerk). Where a feed's own search finds no timing the
other's is tried (:func:`~planner.contour.search.search_timing`), so a pass one feed plans is planned by both; an
``infeasible`` verdict's advice is checked before it is given (:func:`~planner.contour.search.confirmed_infeasible`).
Rapids and feed moves above the cutting height are free moves inside a box about the
straight move (the ``fastest`` timing of :func:`planner.plan`); plunges, retracts, G4 and
M0 are the robot at rest. The parts are joined sample to sample: each part starts at the pose
where the previous one settled.

The modules (issue 34): :mod:`.passes` reads the program into passes and a pass's pieces into
tube corridors; :mod:`.profiles` turns speed profiles into sample counts per cell; :mod:`.search`
finds a piece's timing; :mod:`.join` plans the moves between passes and the rests, and joins
the parts into one result; :mod:`.placement` checks and fits the program's origin;
:mod:`.estimate` counts the work before it starts; :mod:`.zaxis` plans a cut's Z within the Z axis
speed and acceleration (issue 32, goal 3). This module walks the program.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np

from .._jit import numpy_only
from ..errors import PlannerError
from ..model import RobotModel, load_robot
from ..schema import ContourRequest, PassSummary, PathElement, PlanResult, Program, ProgramBlock, Settings
from .defaults import contour_settings, drive_jerk
from .estimate import (
    CONTOUR_CELL_PLAN_S,
    CONTOUR_CELL_S,
    CONTOUR_PIECE_S,
    CONTOUR_STEP_S,
    CONTOUR_TRAVEL_S,
    estimate_contour,
)
from .join import (
    Part,
    contour_section,
    cut_z,
    dwell_z,
    held_force,
    join_parts,
    plan_dwell,
    plan_hold,
    plan_travel,
    rest_breaks,
    seam_breaks,
    travel_z,
)
from .passes import (
    TubeSizes,
    chunks,
    measure_deviation,
    parse_contour_request,
    read_program,
    tolerance_of,
    travel_run_end,
)
from .path import move_of, move_speeds, progress
from .placement import CONTOUR_PSI, check_reach, check_reachable, fit_origin, proposal
from .profiles import OptimalProfiles
from .search import Scale, confirmed_infeasible, largest_feasible, piece_key, search_timing, z_caps
from .tube import PathGeometry, path_to_cut
from .zaxis import Z_EASE, Z_TRIES, ZCaps, ZPlan, accel_dwell, plan_z, slope_stops

# the names this module had before issue 34 split it (the estimate's constants, the search's
# scale finder) stay importable from it
__all__ = ["CONTOUR_CELL_PLAN_S", "CONTOUR_CELL_S", "CONTOUR_PIECE_S", "CONTOUR_STEP_S", "CONTOUR_TRAVEL_S",
           "estimate_contour", "largest_feasible", "parse_contour_request", "plan_contour", "plan_cut"]

def plan_contour(request: Any, *, program: Program | None = None, work_limit_s: float | None = None,
                 progress: Callable[[int, int], None] | None = None) -> PlanResult:
    """Plan a whole G-code program (module docstring). ``program``: the parsed program, if the
    caller has read it already. ``work_limit_s``: the compute time [s] the caller allows (a
    server's limit, which admitted the program by :func:`estimate_contour`): an infeasible
    pass's advice is checked only within what it leaves. Raises
    :class:`~planner.errors.PlannerError` naming the field (``program`` with the line,
    ``tolerance_m``, ``origin``, ``settings.*``). ``progress``: called with (cut passes done,
    cut passes in the program) once the program is placed and after each cut pass."""
    t0 = time.perf_counter()
    limit_at = time.process_time() + work_limit_s if work_limit_s is not None and work_limit_s > 0 else None
    req = parse_contour_request(request)
    st = req.plan_settings()
    with numpy_only(st.backend == "reference"):  # the numpy reference compiles nothing (issue 24)
        try:
            return _plan_contour(req, st, program, t0, limit_at, progress)
        except PlannerError as err:
            if req.origin == "fit" or err.code not in ("unreachable", "singular") or "origin that fits" in err.message \
                    or "no origin fits" in err.message:
                raise
            # a typed origin the path leaves the reach at (found while planning): propose one
            program = read_program(req, program)
            tol = tolerance_of(req, program)
            raise PlannerError(err.code, f"{err.message}; {proposal(program, load_robot(req.robot), tol)}",
                               err.field) from None


def _plan_contour(req: ContourRequest, st: Settings, program: Program | None, t0: float,
                  limit_at: float | None = None, progress: Callable[[int, int], None] | None = None) -> PlanResult:
    """:func:`plan_contour` of a validated request: the program read, its tolerance checked,
    its origin placed and checked (:mod:`.placement`), its blocks planned in order
    (:class:`_Walk`), the parts joined (:func:`~planner.contour.join.join_parts`) with the
    ``contour`` section."""
    program = read_program(req, program)
    tol = tolerance_of(req, program)
    if req.tolerance_m is None and program.tolerance_m is not None and not 1e-5 <= tol <= 0.01:
        raise PlannerError("invalid_input", f"the program's G64 P gives a tolerance of {tol * 1e3:g} mm, outside "
                           "0.01..10 mm, what the planner holds (its cells keep a 1e-06 m margin for the model's "
                           "one-step error); give tolerance_m (CLI: --tolerance) in metres within it, e.g. "
                           f"{min(max(tol, 1e-5), 0.01):g} to plan as close to the program's as it can", "tolerance_m")
    model = load_robot(req.robot)
    st = contour_settings(req, st, program, tol, model)  # Ts and N for the program's arcs unless given
    if req.origin == "fit":
        origin = fit_origin(program, model, tol)
    else:
        origin = np.array(req.origin, float)
        check_reach(program, origin)
        check_reachable(program, model, origin, tol)
    walk = _Walk(req, st, model, program, origin, tol, limit_at)
    walk.progress = progress
    walk.run()
    result = join_parts(walk.parts, req, st, model)
    result.contour = contour_section(walk.parts, walk.summaries, result, req, program, origin, tol, st.Ts)
    result.metrics.compute_ms = (time.perf_counter() - t0) * 1e3
    return result


class _Walk:
    """The program's blocks planned in order, each part starting where the robot settled after
    the one before (``pos``, robot frame) with the tool at Z ``z`` (program frame; the reader
    starts at Z 0, as LinuxCNC): :attr:`parts` and a :class:`~planner.schema.PassSummary` per
    cut pass."""

    def __init__(self, req: ContourRequest, st: Settings, model: RobotModel, program: Program, origin: np.ndarray,
                 tol: float, limit_at: float | None = None) -> None:
        self.req, self.st, self.model, self.program, self.origin, self.tol = req, st, model, program, origin, tol
        self.limit_at = limit_at  # ``time.process_time`` past which no advice is checked
        self.pos = program.start + origin
        self.z = 0.0
        self.parts: list[Part] = []
        self.summaries: list[PassSummary] = []
        self.hints: dict[tuple, Scale] = {}  # fastest: the timing of the piece before of the same shape
        self.hint: Scale | None = None  # fastest: the timing of the level piece before (search.piece_hint)
        self.memo: dict = {}  # fastest: the time-optimal profiles of the passes (alike passes share one)
        self.progress: Callable[[int, int], None] | None = None  # (cut passes done, cut passes)
        self.geo: PathGeometry | None = None  # the cut pass being planned (a release in it measures its deviation)

    def held(self) -> np.ndarray:
        """The drive forces [N] the last part left held (zero before the first, after a rest)."""
        return held_force(self.parts[-1] if self.parts else None, self.model.n_legs)

    def seamed(self, planned: Callable[[np.ndarray, np.ndarray | None], Part], line: int) -> Part:
        """The next part, ``planned(pos, start_force)`` from where the robot is, its first force
        step within the force-rate limit from the forces the last part left (issue 35: a cut
        piece's last braking force, 1.4 % over on fusion360 at Ts 3 ms). Where those forces are
        more than the drives can drop in one sample (:func:`~planner.contour.join.rest_breaks`),
        the seam is predicted to break and the part is planned from them at once (its first
        step's force-rate rows start from them); else from rest (``None``: zero forces), and
        only where its first force still steps too far from them (it can, the other way) again
        from them. Where the plan from the held forces finds no timing (the forces push the
        tool off a fine tolerance before they fall: fusion360 at 2 ms; no advice checked, the
        rest's plan is the one that answers), the robot is first held while they fall
        (:meth:`release`) and the part planned from rest. A seam within the limit from forces a
        rest could take keeps the plan it had. (Before, every part was planned from
        rest first and again where its seam broke: fusion360 ``fastest`` at Ts 2 ms 23.1 CPU s
        against an estimate of 7.14, a piece planned three times and its failure's advice
        checked.)"""
        before = self.held()
        if not rest_breaks(before, self.model, self.st):
            part = planned(self.pos, None)
            if not seam_breaks(before, part, self.model, self.st):
                return part
        try:
            return planned(self.pos, before)
        except PlannerError as err:
            if err.code != "infeasible":
                raise
        self.release(0.0, line)
        before = self.held()
        part = planned(self.pos, None)
        return planned(self.pos, before) if seam_breaks(before, part, self.model, self.st) else part

    def release(self, duration: float, line: int) -> Part:
        """A rest of at least ``duration`` [s] planned from the forces the last part left: the
        robot held where it is while they fall within the force-rate limit
        (:func:`~planner.contour.join.plan_hold`), appended to the parts, at the last part's Z,
        source line and cutting state (between two pieces of a pass the tool is in the cut: its
        deviation measured against the pass, :func:`~planner.contour.passes.measure_deviation`)."""
        last = self.parts[-1]
        st = self.st.model_copy(update=cut_settle(self.st, self.tol, drive_jerk(self.model, self.st)))
        part = plan_hold(self.req, self.model, st, self.pos, CONTOUR_PSI, duration, self.held(), line,
                         HOLD_ROOM * self.tol)
        part.z[:], part.source[:] = last.z[-1], last.source[-1]
        part.cutting[:], part.line[:], part.elem[:] = last.cutting[-1], last.line[-1], last.elem[-1]
        if last.cutting[-1] and self.geo is not None:  # in a pass: measured as its pieces are
            part.deviation = measure_deviation(part.result.pose[:, :2], part.elem, self.geo, self.tol)
        self.parts.append(part)
        self.pos = part.result.pose[-1, :2].copy()
        return part

    def run(self) -> None:
        """Every block: a run of travels as one free move, a dwell at rest, a cut pass."""
        blocks = self.program.blocks
        if self.progress is not None:
            self.progress(0, len(self.program.passes))
        i = 0
        while i < len(blocks):
            b = blocks[i]
            if b.kind == "travel":
                j = travel_run_end(blocks, i)
                self.travel(blocks[i:j + 1])
                i = j + 1
            elif b.kind == "dwell":
                self.dwell(b)
                i += 1
            else:
                self.cut_pass(b)
                i += 1

    def travel(self, run: list[ProgramBlock]) -> None:
        """Consecutive travel blocks: one free move from where the robot is to where the last
        ends (none where it is there already)."""
        target = run[-1].elements[-1].end + self.origin
        if np.hypot(*(target - self.pos)) > 1e-9:
            part = self.seamed(lambda p, f: plan_travel(self.req, self.model, self.st, p, target, CONTOUR_PSI,
                                                        run[0].line, f), run[0].line)
            travel_z(part, [e for bb in run for e in bb.elements], self.pos, target)
            self.parts.append(part)
            self.pos = part.result.pose[-1, :2].copy()
        self.z = run[-1].elements[-1].z_end_m

    def dwell(self, b: ProgramBlock) -> None:
        """A plunge, retract, G4 or pause: the robot at rest; a plunge's or retract's Z moves
        within the Z acceleration (:func:`~planner.contour.zaxis.accel_dwell`)."""
        b, z_at = accel_dwell(b, self.z, self.req.z_accel_m_s2)  # Z from rest to rest within its acceleration
        part = plan_dwell(self.pos, CONTOUR_PSI, b.duration_s, self.st.Ts)
        if seam_breaks(self.held(), part, self.model, self.st):
            # the part before left forces the drives cannot drop to a rest's zero in one sample:
            # the rest planned, the robot held there while they fall (issue 35)
            part = self.release(b.duration_s, b.line)
            self.parts.pop()  # (appended below, with its Z, source line and dwell)
            part.cutting[:], part.deviation[:] = False, 0.0  # a rest, as the unplanned one
        dwell_z(part, b, self.z)
        if z_at is not None:
            part.z = z_at(np.linspace(0.0, b.duration_s, len(part.z)))
        self.parts.append(part)
        self.z = float(part.z[-1])

    def cut_pass(self, b: ProgramBlock) -> None:
        """A cut pass: a travel to its start where the tool is more than half the tolerance
        away, then its pieces (:func:`~planner.contour.passes.chunks`) each planned rest to rest
        (:func:`plan_cut`), and its summary."""
        req, model, st, origin, tol = self.req, self.model, self.st, self.origin, self.tol
        gap = float(np.hypot(*(b.elements[0].start + origin - self.pos)))
        if gap > 0.5 * tol:
            # a cut that starts away from where the tool is: travel there first (at rest)
            part = self.seamed(lambda p, f: plan_travel(req, model, st, p, b.elements[0].start + origin,
                                                        CONTOUR_PSI, b.line, f), b.line)
            part.z[:], part.source[:] = self.z, b.line
            self.parts.append(part)
            self.pos = part.result.pose[-1, :2].copy()
        first = len(self.parts)
        geo = self.geo = PathGeometry(b.elements, origin)
        for chunk in chunks(b.elements, slope_stops(req.feed, b.elements, tol, req.z_accel_m_s2)):
            key, level = piece_key([b.elements[k] for k in chunk])
            hint = self.hints.get(key, self.hint if level else None)
            part = self.seamed(partial(self.piece, b, geo, first, chunk, hint), b.elements[chunk[0]].line)
            if part.scale is not None:
                self.hints[key] = part.scale
                self.hint = part.scale if level else self.hint
            self.parts.append(part)
            self.pos = part.result.pose[-1, :2].copy()
        self.summaries.append(_pass_summary(len(self.summaries), b, self.parts[first:], geo, tol))
        self.geo = None
        self.z = b.elements[-1].z_end_m
        if self.progress is not None:
            self.progress(len(self.summaries), len(self.program.passes))


    def piece(self, b: ProgramBlock, geo: PathGeometry, first: int, chunk: list[int], hint: Scale | None,
              pos: np.ndarray, start_force: np.ndarray | None) -> Part:
        """A piece of the cut pass ``b`` (:func:`plan_cut`) from ``pos`` and ``start_force``; its Z
        from the last part's, as the robot leaves it (a release's, if one came between), where that
        is a part of this pass (from index ``first`` on)."""
        z_first = self.parts[-1].z[-2:] if len(self.parts) > first else None
        return plan_cut(self.req, self.model, self.st, chunk, self.origin, self.tol, CONTOUR_PSI, pos, geo,
                        b.elements, hint, len(self.program.passes), self.memo, self.limit_at, z_first, start_force)


def _pass_summary(index: int, b: ProgramBlock, cut_parts: list[Part], geo: PathGeometry, tol: float) -> PassSummary:
    """A cut pass's summary: its time, the larger of its two deviations (the cut from the path,
    and, issue 32, the programmed path from its cut: the samples of its parts in order, each
    part starting where the one before settled), its top speed and programmed feed."""
    t_pass = sum(p.result.time[-1] for p in cut_parts)
    dev = max(float(p.deviation.max()) for p in cut_parts)
    path_dev = path_to_cut(geo, np.concatenate([p.result.pose[:, :2] for p in cut_parts]), tol)
    speed = max(float(np.hypot(*p.result.velocity[:, :2].T).max()) for p in cut_parts)
    return PassSummary(
        index=index, first_line=b.elements[0].line, last_line=b.elements[-1].line,
        elements=len(b.elements), cells=sum(p.cells for p in cut_parts),
        length_m=float(sum(e.length_m for e in b.elements)), time_s=float(t_pass),
        max_deviation_m=max(dev, path_dev), max_path_deviation_m=path_dev,
        max_speed_m_s=speed, max_programmed_feed_m_s=max(e.feed_m_s for e in b.elements),
        max_feed_ratio=max(feed_ratio(p, b.elements) for p in cut_parts))


def feed_ratio(part: Part, elements: list[PathElement]) -> float:
    """A cut part's largest tool speed over the programmed F of the move being cut: each
    sample's speed against its move's F, each straight move between two samples (its length
    over its time, as the exported program runs it) against the smaller F of its two ends."""
    res = part.result
    f = np.array([e.feed_m_s for e in elements])[part.elem]
    ratio = np.hypot(*res.velocity[:, :2].T) / np.maximum(f, 1e-12)
    dt = np.maximum(np.diff(res.time), 1e-12)
    chord = np.hypot(*np.diff(res.pose[:, :2], axis=0).T) / dt / np.maximum(np.minimum(f[:-1], f[1:]), 1e-12)
    return float(max(ratio.max(), chord.max(initial=0.0)))


def speed_caps(feed: str, els: list[PathElement], z_max_m_s: float | None) -> np.ndarray:
    """Per move, the bound on the XY speed of its time-optimal profile [m/s]: the Z axis speed's
    (:func:`~planner.contour.search.z_caps`), and in ``program`` feed its own F (F is the
    process limit: each move capped at its own, not the pass at its slowest)."""
    cap = z_caps(els, z_max_m_s)
    return np.minimum(cap, [e.feed_m_s for e in els]) if feed == "program" else cap


def plan_cut(req: ContourRequest, model: RobotModel, st: Settings, chunk: list[int], origin: np.ndarray, tol: float,
             psi: float, pos: np.ndarray, geo: PathGeometry, elements: list[PathElement],
             hint: Scale | None = None, passes: int = 1, memo: dict | None = None,
             limit_at: float | None = None, z_first: np.ndarray | None = None,
             start_force: np.ndarray | None = None) -> Part:
    """One piece of a pass planned rest to rest, its Z planned with it (:func:`plan_piece_z`;
    ``z_first``: the Z of the piece before, its last samples; ``start_force``: the forces the
    part before left held [N], every candidate planned from them, None: from zero).
    ``hint``: the ``fastest`` scale found for the piece before (where its search starts; the
    search's result is bracketed the same way from any start). No timing found: the
    ``infeasible`` error with its advice checked (:func:`confirmed_infeasible`, its checks
    stopped at the ``time.process_time`` ``limit_at``)."""
    els0 = [elements[k] for k in chunk]
    st = st.model_copy(update=cut_settle(st, tol, drive_jerk(model, st)))
    # the Z axis acceleration's XY speed bounds (issue 32, goal 3), shaping the profiles; where the Z
    # planned misses, fastest once more with a gentler XY acceleration there (zaxis.Z_EASE), then the piece
    # again as a program feed whose F is lower on the moves Z missed on (the program feed keeps every
    # sample under its move's F, and sizes its cells by it)
    slow, gentle = np.full(len(chunk), np.inf), np.ones(len(chunk))
    feed, els, top0, eased = req.feed, els0, None, False
    # the start point held no sample (profiles.start_free) until Z misses, then one, as before; the
    # end point's own sample dropped at a pass's last piece (search.TimingSearch.end_trimmed)
    start, last = None, chunk[-1] == len(elements) - 1
    for _ in range(Z_TRIES + 1):  # (one more: the start held)
        zc = ZCaps(els0, chunk, tol, req.z_rapid_m_s, req.z_accel_m_s2, slow, gentle)
        found = search_timing(feed, model, st, TubeSizes(model, st, chunk, els, origin, tol, psi, pos, elements),
                              chunk, els, hint, z_max_m_s=req.z_rapid_m_s, cell_caps=zc if zc.active else None,
                              optimal=OptimalProfiles(model, st, chunk, els, origin, psi, memo,
                                                      speed_caps(feed, els, req.z_rapid_m_s),
                                                      zc if zc.active else None), start_force=start_force,
                              start_samples=start, trim_end=last)
        if found.result is None:
            if start_force is not None:  # the caller holds the robot while the forces fall and plans from rest:
                # that plan's verdict is the one to check (no advice checked here: the check plans the piece twice)
                raise PlannerError("infeasible", f"line {els0[0].line}: no timing keeps the tool within "
                                   f"{tol * 1e3:g} mm of the path from the drive forces the part before left",
                                   "program")
            raise confirmed_infeasible(req, model, st, chunk, els, origin, tol, psi, pos, elements, found, hint,
                                       passes, limit_at)
        part = _cut_part(found, geo, tol)
        zp = plan_piece_z(part, elements, origin, tol, st.Ts, req, z_first)
        if zp.ok:
            return part
        if found.untrimmed is not None:  # Z within its limits on the plan before its end was shortened?
            found.result = found.untrimmed
            part = _cut_part(found, geo, tol)
            zp = plan_piece_z(part, elements, origin, tol, st.Ts, req, z_first)
            if zp.ok:
                return part
        if start is None:
            # Z starts from rest within its acceleration: on a ramp the tool starts on (a piece
            # after a slope stop, planned from the forces the last one left: fusion360's line 23 at
            # Ts 3 ms, 12.8 um over Z's tolerance) it needs the sample the start point was held:
            # the timing found with it (one plan), else the search again with it
            assert found.search is not None and found.tube is not None
            held = found.search.start_held(found.result, found.tube)
            if held is not None:
                found.result = held
                part = _cut_part(found, geo, tol)
                zp = plan_piece_z(part, elements, origin, tol, st.Ts, req, z_first)
                if zp.ok:
                    return part
            start = 1
            continue
        if feed == "fastest" and not eased:  # once: fastest again, gentler along the slopes Z missed on
            eased = True
            for k in np.unique(part.elem[zp.miss > 0]):
                j = chunk.index(int(k))
                for jj in [jj for jj in range(max(j - 1, 0), min(j + 2, len(chunk))) if zc.g[jj] != 0.0] or [j]:
                    gentle[jj] *= Z_EASE
            continue
        # per move the top speed it ran at, by the samples' progress along the path (a move passed
        # between two samples has one too: never 0, which as an F takes a hundred thousand samples)
        res = part.result
        top = move_speeds(res.time, np.hypot(*res.velocity[:, :2].T), part.elem,
                          progress(res.pose, part.elem, elements, origin).s, chunk, elements)
        switch = feed != "program"  # fastest's first miss: the bounds as a program feed first (cells by F)
        if top0 is None:  # fastest: the speeds its first timing ran each move at stand for F
            top0 = top
        for k in np.unique(part.elem[zp.miss > 0]) if not switch else []:
            j = chunk.index(int(k))
            near = [jj for jj in range(max(j - 1, 0), min(j + 2, len(chunk))) if zc.g[jj] != 0.0]
            for jj in near or [j]:  # the sloped moves at the slope change: a level one's Z needs no cap
                cap = zc.junction_cap(jj)
                slow[jj] = min(slow[jj], Z_SLOWER * top[jj] if top[jj] > 0 else np.inf, 2.0 * cap)
                gentle[jj] *= Z_SLOWER
        feed = "program"
        base = [e.feed_m_s if req.feed == "program" else max(float(t) * Z_ROOM, 1e-4) for e, t in zip(els0, top0)]
        els = [e.model_copy(update={"feed_m_s": float(min(f, c))}) if min(f, c) != e.feed_m_s else e
               for e, f, c in zip(els0, base, slow)]
    line = elements[int(part.elem[int(np.argmax(zp.miss))])].line
    raise PlannerError("infeasible", f"line {line}: the Z axis cannot follow the path within the tolerance "
                       f"({tol * 1e3:g} mm) at a Z acceleration of {req.z_accel_m_s2:g} m/s^2 and a Z speed of "
                       f"{req.z_rapid_m_s:g} m/s, even {Z_TRIES} times slower there; give a larger z_accel_m_s2 "
                       "or tolerance_m", "z_accel_m_s2")


#: each time a piece is planned again (at most :data:`~planner.contour.zaxis.Z_TRIES` times) the
#: moves Z missed on (and their neighbours) are capped at this share of the speed their samples
#: ran, and their XY speed's rise along a slope at this share of the one before
Z_SLOWER = 0.7
#: fastest, planned again as a program feed: each move's F the speed its first timing ran it at
#: times this (the moves Z missed on lower)
Z_ROOM = 1.1


def plan_piece_z(part: Part, elements: list[PathElement], origin: np.ndarray, tol: float, Ts: float,
                 req: ContourRequest, z_first: np.ndarray | None = None) -> ZPlan:
    """Fill the Z and source line of a cut part: the programmed Z where each sample projects
    onto its move, planned within the Z axis speed and acceleration and the 3-D tolerance
    (:func:`planner.contour.zaxis.plan_z`); the plan (``ok``: it holds). ``z_first``: the last
    samples' Z of the piece before [m]; its last sample is this piece's first (the join keeps one
    of the two), so the plan starts there and its first acceleration is taken with the sample
    before it: Z's acceleration holds across the two pieces. (At a slope change the two pieces'
    end and start project onto different moves, micrometres of Z apart; planned apart, each from
    rest, the joined Z accelerated at up to twice the axis's limit.)"""
    d = cut_z(part, elements, origin)
    budget = np.sqrt(np.maximum(tol * tol - d * d, 0.0))
    before = None
    if z_first is not None and len(part.z):
        part.z[0], before = z_first[-1], (z_first[-2] if len(z_first) > 1 else z_first[-1])
    got = plan_z(part.z, budget, Ts, req.z_rapid_m_s, req.z_accel_m_s2, before)
    part.z = got.z
    return got


def _cut_part(found: Any, geo: PathGeometry, tol: float) -> Part:
    """The part of a piece's timing found: per sample its move, source line and deviation."""
    result, t = found.result, found.tube
    assert t is not None
    K = len(result.time)
    elem = move_of(result, t)
    cutting = np.ones(K, bool)
    line = geo.line[elem].astype(np.int64)
    dev = measure_deviation(result.pose[:, :2], elem, geo, tol)
    part = Part(result, cutting, line, dev, cells=len(t.segments) - 2, segments=t.segments)
    part.scale = found.scale
    part.elem = elem
    return part


#: a rest planned while the drives release their forces (:func:`~planner.contour.join.plan_hold`)
#: keeps the tool within this share of the tolerance of where it stopped, in x and y
HOLD_ROOM = 0.25

#: a cut piece's end (:func:`cut_settle`): the tool's travel in a sample at the speed that counts
#: as stopped, at most this share of the tolerance
SETTLE_TOL_SHARE = 0.5


def cut_settle(st: Settings, tol: float, jerk: float | None) -> dict:
    """The stopping rule of a cut piece (:func:`plan_cut`, issue 35 goal 2): settled where the
    tool is within half the tolerance of the end point, moves at most :data:`SETTLE_TOL_SHARE`
    of the tolerance in a sample, and no faster than the drives' ``jerk`` (:func:`drive_jerk`)
    changes its speed in a sample, ``jerk Ts^2 / 2`` (each at most the settings' bound: 0.1 mm,
    1 mm/s by default). The next piece starts at rest where this one settled: the seam is within
    the tolerance of the end point and of the tool's next sample, and the force it leaves is
    about one sample's rise under the force-rate limit (at Ts 1 ms the rule without the jerk
    bound let the seam's force step reach 3x the limit). Before, a cut settled below 1e-4 m/s
    (the travel's bound, kept for rapids) and its last samples crept the last micrometres:
    pcb_gcode's first pass ended 3 samples after it was first within 4 um of its end at
    0.63 mm/s, now 1 (2.01 -> 1.99 s); fusion360 at 6.25 ms 1.244 + 0.488 -> 1.231 + 0.475 s
    (``benchmarks/README.md``)."""
    v = min(st.settle_speed_m_s, SETTLE_TOL_SHARE * tol / st.Ts)
    if jerk is not None:
        v = min(v, 0.5 * jerk * st.Ts ** 2)
    return {"settle_position_m": min(st.settle_position_m, 0.5 * tol), "settle_speed_m_s": v}
