"""The compute time of a contour plan, estimated before it starts (issue 33): from the
program's counts (passes, pieces, tube cells, cut samples, moves between passes), no tube
built and no plan. :func:`estimate_contour` is what the service admits a contour job by;
:func:`piece_estimate` also bounds the check of an ``infeasible`` verdict's advice
(:func:`planner.contour.search.confirmed_infeasible`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..schema import DEFAULT_CONTOUR_TOLERANCE_M, PathElement, Program
from .passes import CELL_SAMPLES, PROGRAM_MARGIN, V0_M_S, chunks, parse_contour_request, read_program, tolerance_of
from .tube import SAGITTA_FRACTION

#: program feed's tube cells: a whole number of samples at F, this much shorter
#: (:data:`planner.contour.search.FEED_MARGIN`, which imports this module)
FEED_MARGIN = 0.01

__all__ = ["ADVICE_MIN_S", "ADVICE_WORK", "CONTOUR_CELL_PLAN_S", "CONTOUR_CELL_S", "CONTOUR_PIECE_S", "CONTOUR_STEP_S",
           "CONTOUR_TRAVEL_S", "ContourCounts", "count_contour", "estimate_contour", "piece_estimate"]

#: the checks of an infeasible verdict's advice take at most this many times the piece's
#: estimate, and at least ADVICE_MIN_S [s] (and no more than what a ``work_limit_s`` leaves):
#: not part of the estimate, which is the work of a program that plans (as
#: :class:`planner.WorkEstimate`'s ``advice_seconds``); :func:`estimate_contour` names the bound
ADVICE_WORK = 3.0
ADVICE_MIN_S = 4.0
#: The unit costs [s] below are CPU seconds fitted (least squares on the relative error) to 23
#: generated programs (issue 33, ``benchmarks/bench_estimates.py``: 200-6 000 lines of 0.5 mm,
#: 50-1 000 full circles of 0.1 mm, 10-400 short passes, arcs of 1.5 mm at 0.05 and 0.01 mm,
#: Ts 2-10 ms, both feeds), then rounded up about 10 %: the estimate is the work, not a bound
#: far above it (before, 2-16x the work: a 4 s floor and costs taken at the high end).
#: seconds per receding-horizon step of a candidate plan (polygon cells, junctions), by feed
#: (``fastest``'s samples at the reference speed are fewer and each carries a cell's rows)
CONTOUR_STEP_S = {"program": 4.5e-4, "fastest": 1.1e-3}
#: seconds a tube cell costs each candidate plan (its rows), by feed
CONTOUR_CELL_PLAN_S = {"program": 3e-4, "fastest": 0.0}
#: seconds a tube cell costs once a piece (built, its deviation and join): ``fastest`` adds the
#: time-optimal profile and the search's candidates' cell rows; ``program`` the F-capped
#: time-optimal profile and the tubes of shorter cells (issue 35)
CONTOUR_CELL_S = {"program": 3e-4, "fastest": 3.5e-3}
#: seconds of a piece besides its cells and samples (the search, the plan's start and settling)
CONTOUR_PIECE_S = 0.017
#: seconds of a move of the program (its path geometry, deviation candidates, Z)
CONTOUR_ELEMENT_S = 1.1e-3
#: seconds of a line of the program read (:func:`planner.exchange.read_gcode`: 30-70 us a line, a
#: rapid with a comment the most)
CONTOUR_LINE_S = 7.5e-5
#: seconds of a free move between passes (a ``fastest`` plan of three segments: ~17 ms
#: measured at Ts 10 ms), at Ts 10 ms, besides its samples
CONTOUR_TRAVEL_S = 0.019
#: seconds a sample of a free move costs, per sample of the horizon (its ``fastest`` search's
#: candidates included)
TRAVEL_STEP_S = 1.3e-4
#: a free move's samples (:func:`travel_samples`): acceleration [m/s^2], force ramps [s], end
#: samples; at sample times under 5 ms, moves over TRAVEL_SLOW_M [m] at TRAVEL_FINE_M_S [m/s]
TRAVEL_ACCEL_M_S2 = 3.0
TRAVEL_RAMP_S = 0.015
TRAVEL_END_SAMPLES = 4.0
TRAVEL_SLOW_M = 0.008
TRAVEL_FINE_M_S = 0.02


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


def count_contour(request: Any, program: Program | None = None) -> ContourCounts:
    """The counts of :class:`ContourCounts` of a contour request (its program read unless
    given)."""
    req = parse_contour_request(request)
    st = req.plan_settings()
    program = read_program(req, program)
    tol = tolerance_of(req, program)
    pieces = [[b.elements[k] for k in chunk] for b in program.passes for chunk in chunks(b.elements)]
    moves = _travels(program, tol)
    return ContourCounts(
        lines=req.program.count("\n") + (not req.program.endswith("\n")), passes=len(program.passes),
        pieces=len(pieces),
        moves=sum(len(els) for els in pieces), arcs=sum(e.kind == "arc" for els in pieces for e in els),
        cells=sum(_cells(req.feed, els, tol, st.Ts) for els in pieces),
        samples=sum(_samples(req.feed, b.elements, st.Ts) for b in program.passes),
        travels=len(moves), plans=_plans(req.feed, len(program.passes)),
        travel_samples=sum(travel_samples(d, st.Ts) for d in moves), N=int(st.N))


def _travels(program: Program, tol: float) -> list[float]:
    """The lengths [m] of the free moves :func:`~planner.contour.plan.plan_contour` plans, in
    the program frame (the origin moves both ends alike): a run of travel blocks from where
    the tool is to where the last ends, and a cut pass that starts more than half the
    tolerance away from the tool (as its walk does, without planning)."""
    out: list[float] = []
    pos = np.asarray(program.start, float)
    blocks = program.blocks
    i = 0
    while i < len(blocks):
        b = blocks[i]
        if b.kind == "travel":
            j = i
            while j + 1 < len(blocks) and blocks[j + 1].kind == "travel":
                j += 1
            end = np.asarray(blocks[j].elements[-1].end, float)
            if math.hypot(*(end - pos)) > 1e-9:
                out.append(math.hypot(*(end - pos)))
            pos, i = end, j + 1
            continue
        if b.kind == "cut" and b.elements:
            gap = math.hypot(*(np.asarray(b.elements[0].start, float) - pos))
            if gap > 0.5 * tol:
                out.append(gap)
            pos = np.asarray(b.elements[-1].end, float)
        i += 1
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
    tol = tolerance_of(req, program)
    c = count_contour(req, program)
    pieces = [[b.elements[k] for k in chunk] for b in program.passes for chunk in chunks(b.elements)]
    per_piece = [piece_estimate(req.feed, els, st.Ts, c.passes, tol) for els in pieces]
    travel_s = c.travels * CONTOUR_TRAVEL_S + c.travel_samples * c.N * TRAVEL_STEP_S
    read_s = c.lines * CONTOUR_LINE_S
    check = max(ADVICE_WORK * max(per_piece, default=0.0), ADVICE_MIN_S)
    cut_s = sum(per_piece)
    seconds = cut_s + travel_s + read_s
    f = req.feed
    parts = {"travel": travel_s, "cells": c.cells * (CONTOUR_CELL_S[f] + c.plans * CONTOUR_CELL_PLAN_S[f]),
             "samples": c.samples * c.plans * CONTOUR_STEP_S[f], "lines": read_s,
             "elements": CONTOUR_ELEMENT_S * c.moves}
    most = max(parts, key=parts.__getitem__)
    advice = {"travel": "fewer passes: split the program (each pass is a move there, planned with the fastest "
                        "timing)",
              "cells": "a larger tolerance_m (fewer arc chords and cells), or split the program",
              "elements": "fewer, longer moves (join short moves in the CAM program), or split the program",
              "lines": "a shorter program: split it",
              "samples": (f"a larger settings.Ts than {st.Ts:g} s (fewer samples a pass), or split the program"
                          if st.Ts < 0.01 else "split the program")}[most]
    if f == "fastest":
        advice = "feed 'program' instead of 'fastest' (one plan a pass instead of a search), or " + advice
    return seconds, (f"{c.passes} passes in {c.pieces} pieces, {c.cells} tube cells and ~{c.samples:.0f} cut samples "
                     f"at Ts = {st.Ts:g} s x {c.plans:.3g} plans: {cut_s:.3g} s; {c.travels} moves between them: "
                     f"{travel_s:.3g} s; {c.lines} lines read: {read_s:.2g} s; most of it {most}: {advice}; an "
                     f"infeasible pass's advice is checked within {check:.2g} s more")


def _samples(feed: str, elements: list[PathElement], Ts: float) -> float:
    """The cut samples of ``elements`` at the programmed feed or the reference speed."""
    return sum(e.length_m / max(e.feed_m_s if feed == "program" else V0_M_S * 2, 1e-9) for e in elements) / Ts


def _plans(feed: str, passes: int) -> float:
    """Candidate plans per pass: ~3 (``program``: the F-capped time-optimal profile in cells at
    F, then shorter cells on the moves and more samples where the samples ran faster than F,
    issue 35); ``fastest``: ~17 for the first pass (both timings, ~8 candidates each), ~2.5 for
    each next (the first pass's faster timing, its search started at the scale found before:
    two plans when the passes are alike)."""
    return 3.0 if feed == "program" else 2.5 + 15.0 / max(passes, 1)


def piece_estimate(feed: str, elements: list[PathElement], Ts: float, passes: int = 1,
                    tol: float = DEFAULT_CONTOUR_TOLERANCE_M) -> float:
    """:func:`estimate_contour`'s share of one piece (a pass, or its part between exact stops)
    [s]: :data:`CONTOUR_PIECE_S`, its moves (:data:`CONTOUR_ELEMENT_S`), its cells
    (:func:`_cells`) built once and planned by each candidate, its cut samples planned by each
    candidate."""
    plans = _plans(feed, passes)
    cells = _cells(feed, elements, tol, Ts)
    return (CONTOUR_PIECE_S + CONTOUR_ELEMENT_S * len(elements)
            + cells * (CONTOUR_CELL_S[feed] + plans * CONTOUR_CELL_PLAN_S[feed])
            + _samples(feed, elements, Ts) * plans * CONTOUR_STEP_S[feed])
