"""The compute time of a contour plan, estimated before it starts (issues 33 and 35): from the
program's counts (:func:`count_contour`: lines, passes, pieces, tube cells, cut samples, the
free moves between passes from their lengths, the time-optimal profiles' grid, at the sample
time and horizon of the request), no tube built and no plan. :func:`estimate_contour` is what
the service admits a contour job by; :func:`piece_estimate` also bounds the check of an ``infeasible`` verdict's advice
(:func:`planner.contour.search.confirmed_infeasible`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import PlannerError
from ..model import load_robot
from ..schema import DEFAULT_CONTOUR_TOLERANCE_M, MAX_SEGMENTS, PathElement, Program
from .defaults import bound_arcs, contour_settings
from .passes import (
    CELL_SAMPLES,
    PROGRAM_MARGIN,
    V0_M_S,
    chunks,
    parse_contour_request,
    read_program,
    tolerance_of,
    walk_program,
)
from .placement import check_reach
from .profiles import GRID_H_MAX, GRID_H_MIN, GRID_POINTS, GRID_POINTS_MIN
from .tube import SAGITTA_FRACTION
from .zaxis import Z_TRIES, slope_stops

#: program feed's tube cells: a whole number of samples at F, this much shorter, as first tried
#: (the one definition: :mod:`planner.contour.search` imports it; 1 % before issue 35 goal 2,
#: 0.5 % measured as fast or faster: benchmarks/README.md, branch feedcap2)
FEED_MARGIN = 0.005

__all__ = ["ADVICE_MIN_S", "ADVICE_WORK", "CONTOUR_CELL_PLAN_S", "CONTOUR_CELL_S", "CONTOUR_PIECE_S", "CONTOUR_STEP_S",
           "CONTOUR_TRAVEL_S", "ContourCounts", "count_contour", "estimate_contour", "piece_estimate"]

#: the checks of an infeasible verdict's advice take at most this many times the piece's
#: estimate, and at least ADVICE_MIN_S [s] (and no more than what a ``work_limit_s`` leaves):
#: not part of the estimate, which is the work of a program that plans (as
#: :class:`planner.WorkEstimate`'s ``advice_seconds``); :func:`estimate_contour` names the bound
ADVICE_WORK = 3.0
ADVICE_MIN_S = 4.0
#: All the estimate's constants are in this module (refit or re-check them after a change of the
#: planner's costs: ``benchmarks/bench_contour_estimate.py --json rows.jsonl`` measures,
#: ``benchmarks/refit_contour_estimate.py rows.jsonl`` re-estimates the rows with the constants as
#: they are). The unit costs [s] below are CPU seconds fitted (non-negative least squares on the relative
#: error) to 36 generated programs (issue 35 goal 5, ``tests/contour_programs.py`` and the
#: staircases, waves and circles of ``benchmarks/bench_estimates.py``,
#: ``benchmarks/bench_contour_estimate.py``: 1-100 tiny passes, single passes of 40-500 lines,
#: tiny full circles, arcs, ramps and helices, 1 000-20 000 rapid lines, depth passes; Ts 1, 2,
#: 5 and 10 ms; both feeds), then raised 10 %. A sample's cost grows faster than the horizon
#: at fine sample times (:func:`sample_factor`, measured).
#: seconds per sample of a candidate plan at Ts 10 ms (:func:`sample_factor` beyond), by feed
#: (``fastest``'s samples at the reference speed are fewer and each carries a cell's rows)
CONTOUR_STEP_S = {"program": 1.45e-4, "fastest": 1.15e-3}
#: seconds a tube cell costs each candidate plan at Ts 10 ms, by feed
CONTOUR_CELL_PLAN_S = {"program": 8.9e-5, "fastest": 0.0}
#: seconds a tube cell costs once a piece (folded into the plans' share since issue 35)
CONTOUR_CELL_S = {"program": 0.0, "fastest": 0.0}
#: seconds of a piece each candidate plan at Ts 10 ms (its start and its settling: samples
#: that grow as 1 / Ts), by feed
CONTOUR_PIECE_S = {"program": 4.4e-3, "fastest": 0.0}
#: seconds more a sample on an arc costs each candidate plan at Ts 10 ms, by feed (set from the
#: staircases, waves and tiny circles of bench_estimates.py, 1.7-1.9x under the fit without it;
#: program 1.45e-4 -> 2.2e-4 on 2026-11-28: 6 half circles in a pass measured 1.46x twice)
CONTOUR_ARC_STEP_S = {"program": 2.2e-4, "fastest": 0.0}
#: seconds of a corner (:attr:`ContourCounts.corners`) each candidate plan at Ts 10 ms, by feed
CONTOUR_CORNER_S = {"program": 2.8e-4, "fastest": 3.0e-4}
#: seconds of a grid point of a time-optimal profile (:func:`_grid`)
CONTOUR_GRID_S = 1.75e-4
#: seconds of a tight turn (:attr:`ContourCounts.bends`) each candidate plan
CONTOUR_BEND_S = 4.0e-4
#: seconds of a move of the program (its path geometry, deviation candidates, Z): fitted 0,
#: the cells and samples carry it
CONTOUR_ELEMENT_S = 0.0
#: seconds of a line of the program read (:func:`planner.exchange.read_gcode`) and walked
CONTOUR_LINE_S = 5.5e-5
#: seconds of a free move between passes besides its samples
CONTOUR_TRAVEL_S = 3.9e-4
#: seconds a sample of a free move costs at Ts 10 ms (a ``fastest`` plan of three segments,
#: its search's candidates included; :func:`sample_factor` beyond)
TRAVEL_STEP_S = 3.2e-3
#: a free move's samples (:func:`travel_samples`): acceleration [m/s^2], force ramps [s], end
#: samples; at sample times of 1 ms and less, moves over TRAVEL_SLOW_M [m] at TRAVEL_FINE_M_S
#: [m/s] (measured: 10 mm in 0.45 s, 20 mm in 0.95 s at Ts 1 ms; 9 mm in 0.1 s)
TRAVEL_ACCEL_M_S2 = 3.0
TRAVEL_RAMP_S = 0.015
TRAVEL_END_SAMPLES = 4.0
TRAVEL_SLOW_M = 0.0095
TRAVEL_FINE_M_S = 0.021
#: :func:`sample_factor`: a sample's cost [x Ts 10 ms] at the default horizon, measured at these
#: sample times [s] (the default horizon: 30, 51, 100 and 100 samples), by feed. Refitted on
#: the Ts sweep of ``benchmarks/bench_contour_estimate.py`` (2026-11-28): the factors of
#: 7.5 and 4.8 at 1 and 2 ms made ``program`` 0.33-0.69x at 1 ms and ``fastest`` 0.12-0.32x at
#: 1 ms, 0.27-0.61x at 2 ms; ``program`` at 2 ms 5.2 (one depth pass measured 1.31-1.43x at 4.8)
SAMPLE_FACTOR_TS = (0.001, 0.002, 0.005, 0.01)
SAMPLE_FACTOR = {"program": (4.5, 5.2, 1.2, 1.0), "fastest": (3.0, 2.4, 1.5, 1.0)}
SAMPLE_FACTOR_N = (100, 100, 51, 30)

#: program feed: an arc is cut at most at ``sqrt(ARC_ACCEL_M_S2 r)`` (a tiny circle at F3000 is
#: not cut at F: its samples are those of the speed the arc allows; the program feed's profile
#: acceleration, :data:`planner.contour.search.A_PROGRAM_M_S2`)
ARC_ACCEL_M_S2 = 2.0
#: program feed: seconds of a piece's tight turns squared (:func:`tight_turns`), by the sample
#: times of :data:`SAMPLE_FACTOR_TS` (interpolated in their logarithm; 0 at 5 ms and above).
#: On tiny arcs at fine Ts the plan at the F-capped profile's scale 1 is infeasible: the search
#: (:func:`planner.contour.search.largest_feasible`) steps its scale down (~7 plans that fail
#: early) and bisects it (~8 plans near the edge of feasibility, each 4-6x a comfortable plan of
#: its samples): measured at Ts 2 ms on one pass of 10, 20 and 50 full circles of r 0.1 mm at
#: F1200, 6.1, 27 and more than 130 CPU s (16 plans, 62 049 samples planned for a pass of 3 253);
#: the cost grows with the square of the circles in the pass (the edge is the worst circle's).
#: At 1 ms 8 such circles: 30.7 CPU s (2.1x the estimate without this term); at 5 ms 20 circles
#: at F1200 plan twice (1.0 CPU s), but at F3000 (``benchmarks/bench_estimates.py``'s circles,
#: 3.5x the arc's speed) one pass of 10, 20, 30 took 3.3, 16.2, 30.9 CPU s (0.029-0.039 s a turn
#: squared; 8-29x the estimate without this term), at 7.5 and 10 ms 10 of them 0.13 s
TIGHT_TURN2_S = (0.25, 0.05, 0.0, 0.0)
#: the same for the arcs whose F is over :data:`TIGHT_FAR` times the speed they are cut at, added
#: to :data:`TIGHT_TURN2_S` (at 5 ms those circles at F3000 cost 0.029-0.039 s a turn squared,
#: those at F1200 nothing)
TIGHT_FAR_TURN2_S = (0.0, 0.0, 0.04, 0.0)
TIGHT_FAR = 2.0
#: the plans of a piece with a slope beyond its first, in units of the piece's estimate
#: (:data:`~planner.contour.zaxis.Z_TRIES`; ``benchmarks/bench_contour_estimate.py --only ramp``),
#: by the sample times of :data:`SAMPLE_FACTOR_TS` (interpolated in their logarithm). Refitted
#: after the retrace fix (branch rampfix, benchmarks/README.md "A retraced line and a full
#: circle's seam"): most Z misses of the ramp-and-helix passes were the planner's own (the helix's
#: last samples given its start's Z, a ramp's return line skipped), each re-plan a search. Measured
#: since, the pieces' own estimate without this term: ``program`` 0.95-1.05x at 10 ms and already
#: over at 1-2 ms (0.53-0.70x): no re-plans counted there, 0.3 at 5 ms (2 passes 1.12 CPU s against
#: 1.02 without it; fusion360.nc at its 6 ms 1.23x without, 1.12x with); ``fastest`` still misses at fine sample times
#: (2 passes: 19.9 CPU s at 1 ms, 5.46 at 2 ms, 1.37 at 5 ms against 10.7 / 4.41 / 0.92 without
#: this term), none at 10 ms (0.29 s) nor at the chosen 4 ms (10 passes 3.31 s against 3.56)
Z_SLOPE_PLANS = {"program": (0.0, 0.0, 0.3, 0.0), "fastest": (1.8, 0.5, 0.7, 0.0)}
#: the ``program`` feed's search on a piece with a slope at a fine sample time: its candidate
#: plans beyond those the piece's estimate counts, in units of the piece's estimate, by the
#: sample times of :data:`SAMPLE_FACTOR_TS` (interpolated in their logarithm). Not Z misses
#: (none in these plans): since branch feedcap3's merge (the program feed's cells of whole
#: samples at F, a slope change's cells at the rising Z bound) the search plans a sloped piece
#: about three times as often at 1-2 ms, each plan dearer (2 ramp-and-helix passes at 2 ms: 30
#: plans, 17.1 CPU s of search, against 10 plans, 2.7 s at 49a5c63; at 1 ms 11.7 -> 38-43 CPU s,
#: bisected to that merge, benchmarks/README.md "fastest and the contour compute and estimates
#: re-measured"). With 0 at 1-2 ms those passes measured 2.60x and 2.12x their estimate; 1.8 and
#: 1.3 bound them (1.19x, 1.08x) and leave 10 ramp passes at 2 ms 0.28x (their search is cheaper
#: a pass: the bound takes the worst); 5 ms and above measured within the estimate (0.75-1.17x).
#: Re-measured on 2026-11-28 (branch seamest, benchmarks/README.md "seams predicted"): the search
#: is back to its cost before that merge, those 2 passes 11.4 CPU s at 1 ms and 4.54 s at 2 ms,
#: 10 passes at 2 ms 15.3 s (0.32x, 0.27x, 0.20x with 1.8 and 1.3; 0.70x, 0.52x, 0.39x without),
#: and the term put freecad_linuxcnc.ngc's gentle helix at 0.13-0.23x at 2-3 ms: 0 again, the
#: table kept for a refit
SLOPE_SEARCH_PLANS = {"program": (0.0, 0.0, 0.0, 0.0), "fastest": (0.0, 0.0, 0.0, 0.0)}
#: ``fastest``: seconds of the re-plans of a piece with a slope at least, per
#: :data:`Z_FASTEST_LENGTH_M` of its length (at least one such length), by the sample times of
#: :data:`SAMPLE_FACTOR_TS` (interpolated in their logarithm). It was 16 s at 10 ms, fitted to 2
#: ramp-and-helix passes that ended ``too_large`` after 39-42 CPU s (a full circle's seam and a
#: retraced line, fixed by branch rampfix: 0.29 CPU s now): none left
Z_FASTEST_PIECE_S = (0.0, 0.0, 0.0, 0.0)
Z_FASTEST_LENGTH_M = 0.015
#: ``fastest``: the work of a piece after a slope stop beyond what the pass's estimate counts, in
#: units of the piece's own estimate (:func:`piece_estimate`), by the sample times of
#: :data:`SAMPLE_FACTOR_TS` (interpolated in their logarithm). The planner ends a piece where Z's
#: slope changes sharply (:func:`planner.contour.zaxis.slope_stops`: a ramp's start and end), the
#: estimate's pieces do not; the piece after such a stop starts from the braking forces the one
#: before left, planned from them at once where the drives cannot drop them in a sample
#: (:meth:`planner.contour.plan._Walk.seamed`), and where that finds no timing the robot is held
#: while they fall and the piece planned from rest again (issue 35 goal 5, branch seamest).
#: Fitted with ``benchmarks/refit_contour_estimate.py`` on the rows of
#: ``benchmarks/bench_contour_estimate.py --cam`` (benchmarks/README.md, "seams predicted"): the
#: only program with such stops is fusion360.nc (its first pass: a ramp of slope 1 in, the level
#: cut, a ramp out), measured without this term at 0.96-1.94x (1.29-1.80x at 5-10 ms, 1.94x at
#: 2 ms where its level piece's plan from the ramp's forces found no timing, 1.4 CPU s, and its
#: plan from rest after the release took 6.9 s against 1.13 s estimated: its arc cells searched
#: at the edge of feasibility at 0.02 mm); one factor at every sample time (a table by Ts fitted
#: to one program would fit its noise), 2.5 puts its rows at 0.5-1.35x (2.0: 0.56-1.42x, the 2 ms
#: row's serial test failed once of three on a loaded machine). No generated program has such
#: stops (their ramps' slope changes are passed)
SLOPE_STOP_PLANS = (2.5, 2.5, 2.5, 2.5)


def sample_factor(Ts: float, N: int, feed: str = "program") -> float:
    """The cost of a sample of a candidate plan at ``Ts`` with the horizon ``N``, relative to
    one at Ts 10 ms and the default 30: interpolated (in the logarithms) between the measured
    :data:`SAMPLE_FACTOR` of the feed at :data:`SAMPLE_FACTOR_TS`, times ``N`` over the default
    horizon there (a longer horizon, more rows a step)."""
    lt = np.log(SAMPLE_FACTOR_TS)
    x = float(np.log(min(max(Ts, SAMPLE_FACTOR_TS[0] / 4), 0.1)))
    f = float(np.exp(np.interp(x, lt, np.log(SAMPLE_FACTOR[feed]))))
    n0 = float(np.exp(np.interp(x, lt, np.log(SAMPLE_FACTOR_N))))
    if Ts < SAMPLE_FACTOR_TS[0]:  # beyond the table: as the finest, per sample of its time
        f *= SAMPLE_FACTOR_TS[0] / Ts
    return f * max(N, 1) / n0


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
        if feed == "program":  # planner.contour.passes.TubeSizes.at_feed: a whole number of samples at F
            step_f = max(e.feed_m_s, 1e-9) * Ts
            piece_max = step_f * max(math.ceil(4 * tol / step_f - 1e-9), 1) / (1 + FEED_MARGIN)
        if e.kind == "arc" and e.radius_m and e.sweep_rad is not None:
            r = e.radius_m
            step = 2 * math.acos(max(1 - s_a / r, -1.0)) if s_a < r else math.pi / 2
            step = min(step, piece_max / r, math.pi / 2)
            n += max(1, math.ceil(abs(e.sweep_rad) / step))
        else:
            n += max(1, math.ceil(e.length_m / piece_max))
    return n + len(elements) + 1


@dataclass(frozen=True)
class ContourCounts:
    """What :func:`estimate_contour` counts of a program, before any tube is built: the
    program's text ``lines`` (each read), its cut ``passes`` and their ``pieces`` (split at exact
    stops), the feed ``moves`` cut and the ``arcs`` among them, the tube ``cells`` of the pieces
    (:func:`_cells`), the cut ``samples`` (at F in ``program`` feed, at the reference speed in
    ``fastest``), the free ``travels`` between passes and the candidate ``plans`` a piece."""

    lines: int
    passes: int
    pieces: int
    moves: int
    arcs: int
    cells: int
    samples: float
    travels: int
    plans: float
    #: the samples of the free moves between passes, each estimated from its length
    #: (:func:`travel_samples`)
    travel_samples: float = 0.0
    #: the horizon of the plans [samples] (the cost of a sample grows with it)
    N: int = 30
    #: the grid points of the pieces' time-optimal profiles (:func:`_grid`), each computed
    #: once a tube a piece (passes of the same moves share them)
    grid: float = 0.0
    #: the tight turns: per arc its turns (sweep over 2 pi) times 1 mm over its radius (at
    #: most 20): a sample on a tiny circle costs several on a line (measured: full circles of
    #: 0.1 mm ~3x)
    bends: float = 0.0
    #: the corners: move boundaries in a piece where the direction turns by more than
    #: :data:`CORNER_RAD` (the robot slows into each: its samples cost more)
    corners: int = 0
    #: program feed: the cut samples on arcs (counted in ``samples`` too; a sample on an arc costs
    #: more: :data:`CONTOUR_ARC_STEP_S`)
    arc_samples: float = 0.0


def count_contour(request: Any, program: Program | None = None) -> ContourCounts:
    """The counts of :class:`ContourCounts` of a contour request (its program read unless
    given)."""
    req = parse_contour_request(request)
    st = req.plan_settings()
    program = read_program(req, program)
    tol = tolerance_of(req, program)
    model = load_robot(req.robot)
    st = contour_settings(req, st, program, tol, model)  # the Ts the plan will use
    pieces = [[b.elements[k] for k in chunk] for b in program.passes for chunk in chunks(b.elements)]
    bound = sum(bool(bound_arcs(els, tol, model, st).any()) for els in pieces) if req.feed == "fastest" else 0
    moves = _travels(program, tol)
    return ContourCounts(
        lines=req.program.count("\n") + (not req.program.endswith("\n")), passes=len(program.passes),
        pieces=len(pieces),
        moves=sum(len(els) for els in pieces), arcs=sum(e.kind == "arc" for els in pieces for e in els),
        cells=sum(_cells(req.feed, els, tol, st.Ts) for els in pieces),
        samples=sum(_samples(req.feed, b.elements, st.Ts) for b in program.passes),
        travels=len(moves), plans=_plans(req.feed, len(program.passes)) + ARC_CELL_PLANS * bound / max(len(pieces), 1),
        travel_samples=sum(travel_samples(d, st.Ts) for d in moves), N=int(st.N),
        grid=_grid(program),
        corners=sum(_corners(els) for els in pieces),
        arc_samples=sum(_samples(req.feed, [e for e in els if e.kind == "arc"], st.Ts) for els in pieces)
        if req.feed == "program" else 0.0,
        bends=sum(abs(e.sweep_rad or 0.0) / (2 * math.pi) * min(1e-3 / max(e.radius_m or 1.0, 1e-9), 20.0)
                  for els in pieces for e in els if e.kind == "arc"))


def _grid(program: Program) -> float:
    """The grid points of the time-optimal profiles of the program's pieces
    (:class:`~planner.contour.profiles.OptimalProfiles`: spacing ``total / GRID_POINTS``
    within ``[GRID_H_MIN, GRID_H_MAX]``, at least ``GRID_POINTS_MIN`` points), passes of the
    same moves counted once (they share their profiles)."""
    seen: set = set()
    n = 0.0
    for b in program.passes:
        for chunk in chunks(b.elements):
            els = [b.elements[k] for k in chunk]
            key = tuple((e.kind, *np.round(e.start, 9), *np.round(e.end, 9), e.feed_m_s) for e in els)
            if key in seen:
                continue
            seen.add(key)
            total = sum(e.length_m for e in els)
            if total <= 0:
                continue
            h = min(max(total / GRID_POINTS, GRID_H_MIN), GRID_H_MAX, total / GRID_POINTS_MIN)
            n += total / h
    return n


#: a move boundary turning by more than this [rad] is a corner (:attr:`ContourCounts.corners`)
CORNER_RAD = 0.2


def _tangent(e: PathElement, at_end: bool) -> tuple[float, float]:
    """The unit direction of a move at its start or end (an arc's tangent there)."""
    if e.kind == "arc" and e.start_angle_rad is not None and e.sweep_rad:
        a = e.start_angle_rad + (e.sweep_rad if at_end else 0.0)
        sgn = 1.0 if e.sweep_rad > 0 else -1.0
        return (-sgn * math.sin(a), sgn * math.cos(a))
    dx, dy = float(e.end[0] - e.start[0]), float(e.end[1] - e.start[1])
    n = math.hypot(dx, dy)
    return (dx / n, dy / n) if n > 0 else (0.0, 0.0)


#: a move boundary where the signed curvature jumps by more than this [1/m] is a corner too
#: (a line into an arc of less than 10 mm, a wave of arcs: the drives' forces jump there)
CORNER_CURVATURE = 100.0


def _curvature(e: PathElement) -> float:
    if e.kind == "arc" and e.radius_m and e.sweep_rad:
        return math.copysign(1.0 / e.radius_m, e.sweep_rad)
    return 0.0


def _corners(els: list[PathElement]) -> int:
    """The move boundaries of a piece that turn by more than :data:`CORNER_RAD` or where the
    curvature jumps by more than :data:`CORNER_CURVATURE`."""
    out = 0
    for a, b in zip(els, els[1:]):
        ta, tb = _tangent(a, True), _tangent(b, False)
        if ta == (0.0, 0.0) or tb == (0.0, 0.0):
            continue
        turn = math.atan2(ta[0] * tb[1] - ta[1] * tb[0], ta[0] * tb[0] + ta[1] * tb[1])
        if abs(turn) > CORNER_RAD or abs(_curvature(a) - _curvature(b)) > CORNER_CURVATURE:
            out += 1
    return out


def _travels(program: Program, tol: float) -> list[float]:
    """The lengths [m] of the free moves :func:`~planner.contour.plan.plan_contour` plans, in
    the program frame (the origin moves both ends alike; :func:`~planner.contour.passes.walk_program`):
    the runs of travel blocks that move the tool and the approaches to cut passes."""
    out: list[float] = []
    for step in walk_program(program, tol):
        d = math.hypot(*(step.end - step.start))
        if step.kind != "cut" and d > 1e-9:
            out.append(d)
    return out


def travel_samples(d: float, Ts: float) -> float:
    """The samples of a free move of ``d`` [m] between passes (a ``fastest`` plan at rest at
    both ends): its time at :data:`TRAVEL_ACCEL_M_S2` speeding up half way and slowing down
    the other half, plus :data:`TRAVEL_RAMP_S` (the force ramps) and :data:`TRAVEL_END_SAMPLES`;
    at sample times under 5 ms a move longer than :data:`TRAVEL_SLOW_M` at
    :data:`TRAVEL_FINE_M_S` (measured: the plan of such a move is that slow there)."""
    t = 2 * math.sqrt(max(d, 0.0) / TRAVEL_ACCEL_M_S2) + TRAVEL_RAMP_S
    if Ts < 0.005 and d > TRAVEL_SLOW_M:
        t = max(t, d / TRAVEL_FINE_M_S)
    return t / Ts + TRAVEL_END_SAMPLES


def _coarsest_cells(elements: list[PathElement], tol: float, Ts: float) -> int:
    """``program`` feed: a lower bound on the cells of the coarsest tube its search plans a
    piece in (:meth:`~planner.contour.search.TimingSearch.program_loop`'s first: cells of
    :data:`CELL_SAMPLES` samples at the top F times :data:`PROGRAM_MARGIN`, at least 4
    tolerances; the finer ones have more): the moves' pieces and the two ends, no junction."""
    if not elements:
        return 0
    s_a = SAGITTA_FRACTION * tol
    piece_max = max(max(e.feed_m_s for e in elements) * PROGRAM_MARGIN * Ts * CELL_SAMPLES, 4 * tol)
    n = 2
    for e in elements:
        if e.length_m < 1e-9:
            continue
        if e.kind == "arc" and e.radius_m and e.sweep_rad is not None:
            r = e.radius_m
            step = 2 * math.acos(max(1 - s_a / r, -1.0)) if s_a < r else math.pi / 2
            n += max(1, math.ceil(abs(e.sweep_rad) / min(step, piece_max / r, math.pi / 2)))
        else:
            n += max(1, math.ceil(e.length_m / piece_max))
    return n


def estimate_contour(request: Any, program: Program | None = None) -> tuple[float, str]:
    """The estimated compute time of :func:`plan_contour` [s] and the arithmetic in words,
    from the program's counts (:func:`count_contour`; no tube built, no plan): per piece (a
    pass, or its parts between exact stops) its tube cells (:func:`_cells`: lines, arc chords,
    junctions) built once and planned by each candidate, and its cut samples at the programmed
    feed (``program``; ~3 plans) or at the reference speed (``fastest``: ~17 candidate plans
    for the first pass, ~2.5 for the next) and its moves (:func:`piece_estimate`); the free
    moves between passes (:data:`CONTOUR_TRAVEL_S` each); the program's lines read. Not
    counted: the check of an infeasible verdict's advice, bounded apart
    (:func:`~planner.contour.search.confirmed_infeasible`: :data:`ADVICE_WORK` times the largest
    piece, at least :data:`ADVICE_MIN_S`, within what ``work_limit_s`` leaves; the detail names
    it). The detail ends with what to change where it is too much: the part that costs most
    and what lowers it for a contour (``benchmarks/bench_contour_estimate.py``,
    benchmarks/README.md)."""
    req = parse_contour_request(request)
    st = req.plan_settings()
    program = read_program(req, program)
    if req.origin != "fit":  # a move beyond the workspace is refused naming its line, before any count
        check_reach(program, np.array(req.origin, float))
    tol = tolerance_of(req, program)
    st = contour_settings(req, st, program, tol, load_robot(req.robot))  # the Ts and N the plan will use
    c = count_contour(req, program)
    pieces = [[b.elements[k] for k in chunk] for b in program.passes for chunk in chunks(b.elements)]
    if req.feed == "program":  # a piece no tube of the search fits: refused now, as the planner would be
        for els in pieces:
            n = _coarsest_cells(els, tol, st.Ts)
            if n > MAX_SEGMENTS:
                raise PlannerError("too_large", f"line {els[0].line}: the pass needs at least {n} tube cells at a "
                                   f"tolerance of {tol * 1e3:g} mm, more than the limit of {MAX_SEGMENTS}; split the "
                                   "pass or give a larger tolerance_m", "program")
    per_piece = [piece_estimate(req.feed, els, st.Ts, c.passes, tol, st.N) for els in pieces]
    f = req.feed
    g = sample_factor(st.Ts, c.N, req.feed)
    parts = {"travel": c.travels * CONTOUR_TRAVEL_S  # a free move is a fastest plan, whatever the feed
             + c.travel_samples * sample_factor(st.Ts, c.N, "fastest") * TRAVEL_STEP_S,
             "cells": g * c.plans * c.cells * CONTOUR_CELL_PLAN_S[f] + c.cells * CONTOUR_CELL_S[f],
             "samples": g * c.plans * (c.samples * CONTOUR_STEP_S[f] + c.pieces * CONTOUR_PIECE_S[f] * 0.01 / st.Ts
                                       + c.corners * CONTOUR_CORNER_S[f] + c.arc_samples * CONTOUR_ARC_STEP_S[f]),
             "profiles": c.grid * CONTOUR_GRID_S + c.plans * c.bends * CONTOUR_BEND_S,
             "lines": c.lines * CONTOUR_LINE_S, "elements": CONTOUR_ELEMENT_S * c.moves,
             "search": sum(search_cost(f, els, st.Ts) for els in pieces),
             # a piece with a slope is planned again where its Z misses (at most Z_TRIES plans in
             # all; measured: a ramp and helix pass 7 times); fastest's first miss goes on as a program
             # feed, and costs twice that (measured on 10 ramp and helix passes: 2.05x without it)
             "z": sum(z_replans(f, els, p, st.Ts) for p, els in zip(per_piece, pieces, strict=True)),
             "slope_search": sum(slope_search(f, els, p, st.Ts) for p, els in zip(per_piece, pieces, strict=True)),
             "seams": seam_work(req, program, tol, st.Ts, c.passes, st.N)}
    travel_s, read_s = parts["travel"], parts["lines"]
    check = max(ADVICE_WORK * max(per_piece, default=0.0), ADVICE_MIN_S)
    seconds = sum(parts.values())
    cut_s = seconds - travel_s - read_s
    most = max(parts, key=parts.__getitem__)
    advice = {"travel": "fewer passes: split the program (each pass is a move there, planned with the fastest "
                        "timing)",
              "cells": "a larger tolerance_m (fewer arc chords and cells), or split the program",
              "elements": "fewer, longer moves (join short moves in the CAM program), or split the program",
              "lines": "a shorter program: split it",
              "z": (f"a larger z_accel_m_s2 or fewer ramps and helices (a piece with a slope is planned up to "
                    f"{Z_TRIES} times for its Z{', each a search as a program feed' if f == 'fastest' else ''}), "
                    "or split the program"),
              "profiles": "a larger tolerance_m or fewer, longer moves, or split the program",
              "slope_search": (f"settings.Ts 0.005 s or more instead of {st.Ts:g} s (at 1-2 ms the feed's search "
                               "plans a piece with a slope about three times as often), or fewer ramps and helices, "
                               "or split the program"),
              "seams": (f"a larger settings.Ts than {st.Ts:g} s, or gentler ramps (a pass is planned in pieces where "
                        "Z's slope changes sharply, each after the first from the forces the one before left), or "
                        "split the program"),
              "search": (f"settings.Ts 0.005 s or more instead of {st.Ts:g} s (at a fine Ts the feed's scale is "
                         f"searched on arcs of {_tight_radius_mm(pieces):.2g} mm of radius and less: ~16 plans), "
                         "or fewer such arcs a pass (split the pass)"),
              "samples": (f"a larger settings.Ts than {st.Ts:g} s (fewer samples a pass), or split the program"
                          if st.Ts < 0.01 else "split the program")}[most]
    if most in ("samples", "cells", "profiles") and 2 * c.arcs >= c.moves > 0:  # mostly arcs
        advice += ", or a larger tolerance_m (fewer arc chords)"
    if f == "fastest":
        advice = "feed 'program' instead of 'fastest' (one plan a pass instead of a search), or " + advice
    return seconds, (f"{c.passes} passes in {c.pieces} pieces, {c.cells} tube cells and ~{c.samples:.0f} cut samples "
                     f"at Ts = {st.Ts:g} s x {c.plans:.3g} plans: {cut_s:.3g} s; {c.travels} moves between them: "
                     f"{travel_s:.3g} s; {c.lines} lines read: {read_s:.2g} s; most of it {most}: {advice}; an "
                     f"infeasible pass's advice is checked within {check:.2g} s more")




def by_ts(table: tuple[float, ...], Ts: float) -> float:
    """A constant given at the sample times of :data:`SAMPLE_FACTOR_TS`, at ``Ts`` (interpolated
    in their logarithm, the ends held beyond)."""
    x = float(np.log(min(max(Ts, SAMPLE_FACTOR_TS[0]), SAMPLE_FACTOR_TS[-1])))
    return float(np.interp(x, np.log(SAMPLE_FACTOR_TS), table))


def z_replans(feed: str, els: list[PathElement], piece_s: float, Ts: float) -> float:
    """The seconds of the Z re-plans of a piece (its estimate ``piece_s`` [s]) at the sample
    time ``Ts``: 0 without a slope; :data:`Z_SLOPE_PLANS` times ``piece_s``, and in ``fastest``
    at least :data:`Z_FASTEST_PIECE_S` per :data:`Z_FASTEST_LENGTH_M` of the piece."""
    if not any(abs(e.z_end_m - e.z_start_m) > 1e-12 for e in els):
        return 0.0
    out = by_ts(Z_SLOPE_PLANS[feed], Ts) * piece_s
    floor = by_ts(Z_FASTEST_PIECE_S, Ts) if feed == "fastest" else 0.0
    if floor > 0:
        length = sum(e.length_m for e in els)
        out = max(out, floor * max(length / Z_FASTEST_LENGTH_M, 1.0))
    return out


def seam_work(req: Any, program: Program, tol: float, Ts: float, passes: int, N: int) -> float:
    """The seconds of the pieces after a slope stop beyond the pass's estimate
    (:data:`SLOPE_STOP_PLANS` times each such piece's :func:`piece_estimate`; ``fastest`` only:
    the program feed does not split its passes there)."""
    k = by_ts(SLOPE_STOP_PLANS, Ts)
    if req.feed != "fastest" or k <= 0:
        return 0.0

    out = 0.0
    for b in program.passes:
        stops = set(slope_stops(req.feed, b.elements, tol, req.z_accel_m_s2))
        for chunk in chunks(b.elements, stops)[1:]:
            if chunk[0] - 1 in stops and not b.elements[chunk[0] - 1].exact_stop:  # (exact stops: pieces counted)
                out += k * piece_estimate(req.feed, [b.elements[j] for j in chunk], Ts, passes, tol, N)
    return out


def slope_search(feed: str, els: list[PathElement], piece_s: float, Ts: float) -> float:
    """The seconds of the feed's search beyond the piece's estimate ``piece_s`` [s] on a piece
    with a slope at the sample time ``Ts`` (:data:`SLOPE_SEARCH_PLANS` times ``piece_s``; 0
    without a slope)."""
    if not any(abs(e.z_end_m - e.z_start_m) > 1e-12 for e in els):
        return 0.0
    return by_ts(SLOPE_SEARCH_PLANS[feed], Ts) * piece_s


def _samples(feed: str, elements: list[PathElement], Ts: float) -> float:
    """The cut samples of ``elements`` at the programmed feed (an arc's no faster than
    :data:`ARC_ACCEL_M_S2` allows on it) or the reference speed."""
    if feed != "program":
        return sum(e.length_m for e in elements) / (V0_M_S * 2) / Ts
    total = 0.0
    for e in elements:
        v = e.feed_m_s
        if e.kind == "arc" and e.radius_m:
            v = min(v, math.sqrt(ARC_ACCEL_M_S2 * e.radius_m))
        total += e.length_m / max(v, 1e-9)
    return total / Ts




def tight_turns(feed: str, elements: list[PathElement], far: float = 1.0) -> float:
    """The turns (sweep over 2 pi) of the arcs of a piece that ``program`` feed cannot cut at
    their F (:func:`_samples`: ``far sqrt(ARC_ACCEL_M_S2 r) < F``); 0 in ``fastest``."""
    if feed != "program":
        return 0.0
    return sum(abs(e.sweep_rad or 0.0) / (2 * math.pi) for e in elements
               if e.kind == "arc" and e.radius_m and far * math.sqrt(ARC_ACCEL_M_S2 * e.radius_m) < e.feed_m_s)


def search_cost(feed: str, elements: list[PathElement], Ts: float) -> float:
    """The seconds of a piece's scale search on its tight arcs at ``Ts`` (:func:`tight_cost`
    of its :func:`tight_turns`, and :data:`TIGHT_FAR_TURN2_S` of those far over their speed)."""
    far = tight_turns(feed, elements, TIGHT_FAR)
    return tight_cost(tight_turns(feed, elements), Ts) + (by_ts(TIGHT_FAR_TURN2_S, Ts) * far * far if far else 0.0)


def _tight_radius_mm(pieces: list[list[PathElement]]) -> float:
    """The largest radius of the tight arcs (:func:`tight_turns`) [mm]."""
    return 1e3 * max((e.radius_m or 0.0 for els in pieces for e in els if tight_turns("program", [e]) > 0),
                     default=0.0)


def tight_cost(turns: float, Ts: float) -> float:
    """The seconds the scale search costs a piece of ``turns`` tight turns at ``Ts``
    (:data:`TIGHT_TURN2_S`)."""
    if turns <= 0:
        return 0.0
    return by_ts(TIGHT_TURN2_S, Ts) * turns * turns


#: ``fastest``: the candidate plans a piece whose arcs the drives bound below a chord per sample
#: adds (:meth:`planner.contour.search.TimingSearch.arc_cells`: the re-cut cells' heuristic search
#: and its speed factor's, the piece searched afresh; measured +16 / +23 / +16 plans on dxf2gcode,
#: pcb_gcode and freecad, branch arccells), in the average over the pieces
ARC_CELL_PLANS = 20.0


def _plans(feed: str, passes: int) -> float:
    """Candidate plans per pass: ~3 (``program``: the F-capped time-optimal profile in cells at
    F, then shorter cells on the moves and more samples where the samples ran faster than F,
    issue 35); ``fastest``: ~17 for the first pass (both timings, ~8 candidates each), ~2.5 for
    each next (the first pass's faster timing, its search started at the scale found before:
    two plans when the passes are alike)."""
    return 3.0 if feed == "program" else 2.5 + 15.0 / max(passes, 1)


def piece_estimate(feed: str, elements: list[PathElement], Ts: float, passes: int = 1,
                    tol: float = DEFAULT_CONTOUR_TOLERANCE_M, N: int | None = None) -> float:
    """:func:`estimate_contour`'s share of one piece (a pass, or its part between exact stops)
    [s]: its cells, cut samples, start and settling planned by each candidate, its tight turns,
    its time-optimal profile's grid (``N``: the horizon, default the default robot's at
    ``Ts``)."""
    plans = _plans(feed, passes)
    cells = _cells(feed, elements, tol, Ts)
    n0 = float(np.exp(np.interp(np.log(min(max(Ts, 1e-4), 0.1)), np.log(SAMPLE_FACTOR_TS), np.log(SAMPLE_FACTOR_N))))
    g = sample_factor(Ts, int(round(n0)) if N is None else N, feed)
    total = sum(e.length_m for e in elements)
    grid = total / min(max(total / GRID_POINTS, GRID_H_MIN), GRID_H_MAX, total / GRID_POINTS_MIN) if total > 0 else 0.0
    bends = sum(abs(e.sweep_rad or 0.0) / (2 * math.pi) * min(1e-3 / max(e.radius_m or 1.0, 1e-9), 20.0)
                for e in elements if e.kind == "arc")
    return (g * plans * (cells * CONTOUR_CELL_PLAN_S[feed] + _samples(feed, elements, Ts) * CONTOUR_STEP_S[feed]
                         + CONTOUR_PIECE_S[feed] * 0.01 / Ts + _corners(elements) * CONTOUR_CORNER_S[feed]
                         + (_samples(feed, [e for e in elements if e.kind == "arc"], Ts) * CONTOUR_ARC_STEP_S[feed]
                            if feed == "program" else 0.0))
            + cells * CONTOUR_CELL_S[feed] + grid * CONTOUR_GRID_S + plans * bends * CONTOUR_BEND_S
            + CONTOUR_ELEMENT_S * len(elements) + search_cost(feed, elements, Ts))
