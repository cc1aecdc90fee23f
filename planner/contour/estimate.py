"""The compute time of a contour plan, estimated before it starts (issue 33): from the
program's counts (passes, pieces, tube cells, cut samples, moves between passes), no tube
built and no plan. :func:`estimate_contour` is what the service admits a contour job by;
:func:`piece_estimate` also bounds the check of an ``infeasible`` verdict's advice
(:func:`planner.contour.search.confirmed_infeasible`)."""

from __future__ import annotations

import math
from typing import Any

from ..model import load_robot
from ..schema import DEFAULT_CONTOUR_TOLERANCE_M, PathElement, Program
from .defaults import contour_settings
from .passes import CELL_SAMPLES, PROGRAM_MARGIN, V0_M_S, chunks, parse_contour_request, read_program, tolerance_of
from .tube import SAGITTA_FRACTION

#: program feed's tube cells: a whole number of samples at F, this much shorter
#: (:data:`planner.contour.search.FEED_MARGIN`, which imports this module)
FEED_MARGIN = 0.01

__all__ = ["ADVICE_MIN_S", "ADVICE_WORK", "CONTOUR_CELL_PLAN_S", "CONTOUR_CELL_S", "CONTOUR_PIECE_S", "CONTOUR_STEP_S",
           "CONTOUR_TRAVEL_S", "estimate_contour", "piece_estimate"]

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
#: measured at Ts 10 ms), at Ts 10 ms; its samples, and so its cost, grow as 1 / Ts
CONTOUR_TRAVEL_S = 0.019


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


def estimate_contour(request: Any, program: Program | None = None) -> tuple[float, str]:
    """The estimated compute time of :func:`plan_contour` [s] and the arithmetic in words,
    from the program's counts (no tube built, no plan): per piece (a pass, or its parts
    between exact stops) its tube cells (:func:`_cells`: lines, arc chords, junctions) built
    once and planned by each candidate, and its cut samples at the programmed feed
    (``program``; ~3 plans) or at the reference speed (``fastest``: ~17 candidate plans for
    the first pass, ~2.5 for the next) and its moves (:func:`piece_estimate`); the free moves
    between passes (:data:`CONTOUR_TRAVEL_S` each); the program's lines read. Not counted: the
    check of an infeasible verdict's advice, bounded apart
    (:func:`~planner.contour.search.confirmed_infeasible`: :data:`ADVICE_WORK` times the largest
    piece, at least :data:`ADVICE_MIN_S`, within what ``work_limit_s`` leaves; the detail names
    it). Measured 0.44-1.21x it on generated programs of many lines, many tiny circles, many short
    passes and arcs (``benchmarks/bench_estimates.py``, benchmarks/README.md)."""
    req = parse_contour_request(request)
    st = req.plan_settings()
    program = read_program(req, program)
    tol = tolerance_of(req, program)
    st = contour_settings(req, st, program, tol, load_robot(req.robot))  # the Ts the plan will use
    n = len(program.passes)
    pieces = [[b.elements[k] for k in chunk] for b in program.passes for chunk in chunks(b.elements)]
    per_piece = [piece_estimate(req.feed, els, st.Ts, n, tol) for els in pieces]
    cells = sum(_cells(req.feed, els, tol, st.Ts) for els in pieces)
    samples = sum(_samples(req.feed, b.elements, st.Ts) for b in program.passes)
    travels = sum(1 for k, b in enumerate(program.blocks) if b.kind == "travel"
                  and (k + 1 == len(program.blocks) or program.blocks[k + 1].kind != "travel"))
    travels += 1  # a cut that starts away from the tool: one more
    travel_s = travels * CONTOUR_TRAVEL_S * max(1.0, 0.01 / st.Ts)
    lines = req.program.count("\n") + 1
    read_s = lines * CONTOUR_LINE_S
    plans = _plans(req.feed, n)
    check = max(ADVICE_WORK * max(per_piece, default=0.0), ADVICE_MIN_S)
    cut_s = sum(per_piece)
    seconds = cut_s + travel_s + read_s
    f = req.feed
    parts = {"travel": travel_s, "cells": cells * (CONTOUR_CELL_S[f] + plans * CONTOUR_CELL_PLAN_S[f]),
             "samples": samples * plans * CONTOUR_STEP_S[f], "lines": read_s,
             "elements": CONTOUR_ELEMENT_S * sum(len(els) for els in pieces)}
    most = max(parts, key=parts.__getitem__)
    advice = {"travel": "fewer passes (each is a move there, planned with the fastest timing)",
              "cells": "a coarser tolerance_m (fewer arc chords) or fewer, longer moves",
              "elements": "fewer, longer moves (join short moves in the CAM program)",
              "lines": "a shorter program (split it)",
              "samples": "a larger settings.Ts or a higher programmed feed"}[most]
    if req.feed == "fastest":
        advice += ", or feed 'program' instead of 'fastest' (one plan a pass instead of a search)"
    return seconds, (f"{n} passes in {len(pieces)} pieces, {cells} tube cells and ~{samples:.0f} cut samples at "
                     f"Ts = {st.Ts:g} s x {plans:.3g} plans: {cut_s:.3g} s; {travels} moves between them: "
                     f"{travel_s:.3g} s; {lines} lines read: {read_s:.2g} s; most of it {most}: {advice}; an "
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
