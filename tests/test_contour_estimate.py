"""The contour estimate is the work (issue 33, goal 2): on generated edge programs (many short
lines, tiny full circles, short passes, arcs, a long program of rapids; both feeds) the
measured CPU seconds of reading and planning are within [1/3, 1.5] x
:func:`planner.contour.estimate_contour` (before: 0.05-0.47, the estimate 2-16x the work and
programs refused needlessly). ``benchmarks/bench_estimates.py --only contour`` prints the
larger table (benchmarks/README.md)."""

from __future__ import annotations

import importlib.util
import time
from pathlib import Path

import pytest

from planner.contour import estimate_contour, plan_contour
from planner.exchange import read_gcode
from planner.schema import ContourRequest

# the benchmark's program generators (benchmarks/ is no package: loaded by path)
_spec = importlib.util.spec_from_file_location(
    "bench_estimates", Path(__file__).resolve().parent.parent / "benchmarks" / "bench_estimates.py")
assert _spec is not None and _spec.loader is not None
_bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_bench)
gcode_arcs, gcode_circles, gcode_lines = _bench.gcode_arcs, _bench.gcode_circles, _bench.gcode_lines
gcode_long, gcode_passes = _bench.gcode_long, _bench.gcode_passes

CASES = {
    "lines": {"program": gcode_lines(300), "feed": "program"},
    "circles": {"program": gcode_circles(60), "feed": "program"},
    "passes": {"program": gcode_passes(25), "feed": "program"},
    "arcs": {"program": gcode_arcs(20), "feed": "program"},
    "long program": {"program": gcode_long(8000), "feed": "program"},
    "lines fastest": {"program": gcode_lines(60), "feed": "fastest"},
    "arcs Ts 5 ms": {"program": gcode_arcs(10), "settings": {"Ts": 0.005}},
}


def _cpu_and_estimate(req: ContourRequest) -> tuple[float, float]:
    """CPU seconds of reading, estimating and planning ``req``, and its estimate [s]."""
    t0 = time.process_time()
    program = read_gcode(req.program, cut_below=req.cut_below_m, z_rapid_m_s=req.z_rapid_m_s)
    est = estimate_contour(req, program)[0]
    plan_contour(req, program=program)
    return time.process_time() - t0, est


@pytest.mark.serial  # compares CPU seconds with the estimate
@pytest.mark.parametrize("name", list(CASES))
def test_estimate_holds_both_ways(name, _warm):
    req = ContourRequest.model_validate(CASES[name])
    cpu, est = _cpu_and_estimate(req)
    assert est / 3 <= cpu <= 1.5 * est, (name, cpu, est)


def test_estimate_counts_the_program_lines():
    """A program of rapids alone is read and walked: its lines are counted (a long program
    of rapids around a few cuts is not estimated as the cuts alone)."""
    from planner.contour.estimate import CONTOUR_LINE_S

    short = estimate_contour({"program": gcode_long(100)})[0]
    long = estimate_contour({"program": gcode_long(20_100)})[0]
    assert CONTOUR_LINE_S > 0
    assert long - short == pytest.approx(20_000 * CONTOUR_LINE_S, rel=0.05)


# ------------------------------------------------------------------------------------------
# issue 35 goal 5: the estimate's counts on generated programs (tests/contour_programs.py),
# against what the generator wrote and the tubes the planner builds (no timing here: the
# benchmark bench_contour_estimate.py compares the estimate with the measured CPU)

def _slice() -> list:
    """A fixed-seed slice of the benchmark's programs small enough to count by building tubes."""
    from tests.contour_programs import cases

    return [(m, r) for m, r in cases(7, large=False) if m.moves <= 400 and m.passes <= 50]


@pytest.mark.parametrize("k", range(len(_slice())))
def test_estimate_counts_match_independent_counts(k):
    import math

    import numpy as np

    from planner.contour import count_contour
    from planner.contour.defaults import contour_settings
    from planner.contour.estimate import FEED_MARGIN
    from planner.contour.passes import V0_M_S, TubeSizes, chunks, tolerance_of
    from planner.contour.placement import CONTOUR_PSI, fit_origin
    from planner.model import load_robot

    made, raw = _slice()[k]
    req = ContourRequest.model_validate(raw)
    program = read_gcode(req.program, cut_below=req.cut_below_m, z_rapid_m_s=req.z_rapid_m_s)
    c = count_contour(req, program)
    assert c.lines == len(made.text.splitlines())
    assert (c.passes, c.moves, c.arcs) == (made.passes, made.moves, made.arcs)
    model = load_robot(req.robot)
    tol = tolerance_of(req, program)
    st = contour_settings(req, req.plan_settings(), program, tol, model)  # the Ts and N the plan uses
    Ts = st.Ts
    if req.feed == "program":  # the cut samples at F: the generator's length over F (an arc's
        # at most at the speed it allows: more samples, never fewer)
        if made.arcs == 0:
            assert c.samples == pytest.approx(made.time_at_f_s / Ts, rel=1e-6)
        else:
            assert c.samples >= made.time_at_f_s / Ts * (1 - 1e-6)
    # the tube cells: the moves' pieces the planner's own tubes have, within the lead splits
    # (at most two a piece) and the junctions (at most one a move boundary, and the two ends)
    origin = fit_origin(program, model, tol)
    real_pieces, real_cells, n_pieces = 0, 0, 0
    for b in program.passes:
        for chunk in chunks(b.elements):
            els = [b.elements[j] for j in chunk]
            sizes = TubeSizes(model, st, chunk, els, origin, tol, CONTOUR_PSI, b.elements[0].start + origin,
                              b.elements)
            t = sizes.at_feed(np.full(len(els), FEED_MARGIN)) if req.feed == "program" else sizes(V0_M_S)
            real_pieces += int((t.length > 0).sum())
            real_cells += len(t.segments)
            n_pieces += 1
    assert n_pieces == c.pieces
    est_pieces = c.cells - c.moves - c.pieces  # _cells: the pieces, a junction a move, one end
    assert est_pieces <= real_pieces <= est_pieces + 2 * c.pieces
    assert real_cells <= c.cells + 1 + 2 * c.pieces
    assert math.isfinite(c.plans) and c.plans >= 1


def test_refusals_and_timeouts_of_a_contour_name_contour_changes():
    """A contour refused by its estimate or stopped at the limit is told what lowers a
    contour's work (split the program, feed, Ts), never a corridor's (segments, tail_max_s)."""
    import numpy as np

    from app.executors import describe_failure
    from app.jobs import ContourJob, ContourWork, PlanJob
    from app.workers import JobTimeout
    from planner.contour import estimate_contour
    from planner.schema import PlanRequest
    from tests.contour_programs import long_pass

    req = ContourRequest.model_validate({"program": long_pass(np.random.default_rng(0), 200).text,
                                         "feed": "fastest", "settings": {"Ts": 0.002}})
    msg = ContourWork(*estimate_contour(req)).message(0.1)
    assert "split the program" in msg and "feed 'program'" in msg and "tail_max_s" not in msg
    out = describe_failure(JobTimeout("stopped"), ContourJob(req), 30.0)
    assert out.error.code == "timeout" and "split the program" in out.error.message
    assert "segments" not in out.error.message and "tail_max_s" not in out.error.message
    plan = PlanRequest.model_validate({"segments": [{"lower": [0, 0, 0], "upper": [0, 0, 0]},
                                                    {"lower": [0.001, 0, 0], "upper": [0.001, 0, 0]}]})
    assert "tail_max_s" in describe_failure(JobTimeout("stopped"), PlanJob(plan), 30.0).error.message


def test_a_pass_too_large_for_any_tube_is_refused_up_front():
    """``program`` feed: a pass whose coarsest tube (the search's first after the cells at F)
    has more cells than the planner allows is refused by the estimate, before any plan, with the
    planner's own verdict (``too_large`` naming the line); the planner refuses it as well, after
    building its tubes. A pass that fits is estimated."""
    import numpy as np

    from planner.errors import PlannerError
    from planner.schema import MAX_SEGMENTS
    from tests.contour_programs import circles, long_pass

    rng = np.random.default_rng(0)
    big = {"program": long_pass(rng, 3000).text}
    with pytest.raises(PlannerError) as err:
        estimate_contour(big)
    assert err.value.code == "too_large" and err.value.field == "program"
    assert "line 6" in err.value.message and str(MAX_SEGMENTS) in err.value.message
    with pytest.raises(PlannerError) as planned:
        plan_contour(big)
    assert planned.value.code == "too_large"
    with pytest.raises(PlannerError):
        estimate_contour({"program": circles(rng, 1000, per_pass=1000).text})
    assert estimate_contour({"program": long_pass(rng, 400).text})[0] > 0
    assert estimate_contour({"program": circles(rng, 300, per_pass=100).text})[0] > 0


def test_one_walk_for_the_estimate_and_the_placement():
    """The estimate's free moves and the placement's travel boxes come from one walk of the
    program (:func:`planner.contour.passes.walk_program`): two rapids in a row are one move
    from where the tool is to where the second ends (a rapid to where the tool is joins the
    next); each free move is a box the placement checks; each step starts where the one before
    ended (a cut within half the tolerance of it)."""
    import math

    import numpy as np

    from planner.contour.estimate import _travels
    from planner.contour.passes import walk_program
    from planner.contour.placement import _program_shapes

    text = ("G21 G90\nG0 Z2\nG0 X1 Y1\nG0 X2 Y2\nG1 Z-0.5 F300\nG1 X3 F600\nG0 Z2\nG0 X3\nG0 X5\n"
            "G1 Z-0.5 F300\nG1 X6 F600\nG0 Z2\nM2\n")
    program = read_gcode(text)
    tol = 5e-5
    steps = list(walk_program(program, tol))
    assert [s.kind for s in steps] == ["travel", "cut", "travel", "cut"]
    assert steps[0].start == pytest.approx([0, 0]) and steps[0].end == pytest.approx([0.002, 0.002])
    assert steps[2].start == pytest.approx([0.003, 0.002]) and steps[2].end == pytest.approx([0.005, 0.002])
    for a, b in zip(steps, steps[1:]):
        assert math.hypot(*(b.start - a.end)) <= (0.5 * tol if b.kind == "cut" else 1e-12)
    assert _travels(program, tol) == pytest.approx([math.hypot(0.002, 0.002), 0.002])
    shapes = _program_shapes(program, tol)
    boxes = [g for _, g in shapes if g.geom_type == "Polygon"]
    assert len(boxes) == 2  # one a travel run
    for box, s in zip(boxes, [steps[0], steps[2]]):
        x0, y0, x1, y1 = box.bounds
        lo, hi = np.minimum(s.start, s.end), np.maximum(s.start, s.end)
        assert (x0, y0) == pytest.approx(lo - 0.002) and (x1, y1) == pytest.approx(hi + 0.002)
    # the same walk on a generated program: every free move the estimate counts is a box
    from tests.contour_programs import tiny_passes

    p2 = read_gcode(tiny_passes(np.random.default_rng(3), 12).text)
    moves = _travels(p2, tol)
    free = [s for s in walk_program(p2, tol) if s.kind != "cut"]
    assert len(moves) == sum(math.hypot(*(s.end - s.start)) > 1e-9 for s in free)
    assert len([g for _, g in _program_shapes(p2, tol) if g.geom_type == "Polygon"]) >= len(moves) >= 12


# issue 35 goal 5: a fixed-seed slice of the benchmark's Ts sweep (tests/contour_programs.py):
# the cases the estimate was refitted on where it had been far off (tiny arcs at a fine Ts: 1.84x
# before the scale search was counted; fastest at fine Ts: 0.27x; program at 1 ms: 0.33x; Z ramps)
def _sweep_slice() -> dict[str, dict]:
    import numpy as np

    from tests.contour_programs import arcs, circles, long_pass, ramps

    rng = np.random.default_rng(5)
    return {
        "8 tiny circles, program, Ts 2 ms": {"program": circles(rng, 8, per_pass=8).text, "settings": {"Ts": 0.002}},
        "6 half circles, program, Ts 1 ms": {"program": arcs(rng, 6, per_pass=6).text, "settings": {"Ts": 0.001}},
        "60 lines, fastest, Ts 2 ms": {"program": long_pass(rng, 60).text, "feed": "fastest",
                                       "settings": {"Ts": 0.002}},
        "2 ramps, program, Ts 5 ms": {"program": ramps(rng, 2).text, "settings": {"Ts": 0.005}},
    }


@pytest.fixture(scope="module")
def _warm():
    """The kernels and the Z axis's LP loaded (once-a-process costs the estimate leaves out)."""
    import numpy as np

    from tests.contour_programs import long_pass, ramps

    plan_contour({"program": ramps(np.random.default_rng(0), 1).text})
    plan_contour({"program": long_pass(np.random.default_rng(0), 5).text, "feed": "fastest"})


@pytest.mark.serial  # compares CPU seconds with the estimate
@pytest.mark.parametrize("name", list(_sweep_slice()))
def test_estimate_holds_on_the_ts_sweep(name, _warm):
    req = ContourRequest.model_validate(_sweep_slice()[name])
    cpu, est = _cpu_and_estimate(req)
    assert est / 4 <= cpu <= 1.5 * est, (name, cpu, est)


def test_tiny_arcs_at_a_fine_ts_cost_their_scale_search():
    """``program`` feed: arcs it cannot cut at F (``sqrt(2 m/s^2 r) < F``) at a sample time under
    5 ms add the scale search's plans, growing with the square of their turns in a piece (20
    circles of r 0.1 mm at Ts 2 ms: 27 CPU s, 50: more than 130 s); at 5 ms and above, and on
    arcs cut at F, nothing; the refusal names what to change."""
    import numpy as np

    from planner.contour.estimate import search_cost, tight_cost, tight_turns
    from tests.contour_programs import circles

    def est(n: int, Ts: float, r_mm: float = 0.1) -> tuple[float, str]:
        return estimate_contour({"program": circles(np.random.default_rng(0), n, r_mm=r_mm, per_pass=n).text,
                                 "settings": {"Ts": Ts}})

    program = read_gcode(circles(np.random.default_rng(0), 20, per_pass=20).text)
    els = program.passes[0].elements
    assert tight_turns("program", els) == pytest.approx(20.0)
    assert tight_turns("fastest", els) == 0.0
    assert tight_cost(20.0, 0.002) == pytest.approx(4 * tight_cost(10.0, 0.002))
    assert tight_cost(20.0, 0.005) == tight_cost(20.0, 0.01) == 0.0
    assert tight_cost(20.0, 0.001) > tight_cost(20.0, 0.002) > tight_cost(20.0, 0.003) > 0.0
    assert est(20, 0.002)[0] >= 27.0 / 1.5
    assert est(50, 0.002)[0] >= 130.0 / 1.5
    assert est(20, 0.005)[0] < 27.0 / 4  # measured 1.0 s at 5 ms
    # far over their speed (F3000, 3.5x): at 5 ms one pass of 10 and 30 took 3.2 and 31 CPU s
    fast = read_gcode(circles(np.random.default_rng(0), 10, per_pass=10, f=3000.0).text).passes[0].elements
    assert tight_turns("program", fast, 2.0) == pytest.approx(10.0) and tight_turns("program", els, 2.0) == 0.0
    assert search_cost("program", fast, 0.005) >= 3.2 / 1.5 and search_cost("program", els, 0.005) == 0.0
    assert search_cost("program", fast, 0.01) == 0.0
    wide = read_gcode(circles(np.random.default_rng(0), 20, r_mm=0.5, per_pass=20).text)
    assert tight_turns("program", wide.passes[0].elements) == 0.0  # sqrt(2 * 0.5e-3) > 20 mm/s
    words = est(50, 0.002)[1]
    assert "most of it search" in words and "settings.Ts 0.005 s or more" in words


# issue 35 goal 5 after the fastest ramp change (branch fastopt): fastest's Z re-plans were counted
# at least 16 s per 15 mm of a sloped piece at any Ts, fitted to 2 ramp passes at Ts 10 ms (41.7
# CPU s); at the Ts fastest chooses (4 ms here) one ramp-and-helix pass measured 7.5 CPU s against
# 16.9 estimated (0.44x: a 202 job instead of a synchronous answer, over RANGEPLAN_ASYNC_AFTER_S 10 s),
# 2 passes 8.4 s against 33.1.
@pytest.mark.serial  # compares CPU seconds with the estimate
@pytest.mark.parametrize("passes", [1, 2])
def test_fastest_ramps_at_the_chosen_ts_are_not_overestimated(passes, _warm):
    import numpy as np

    from tests.contour_programs import ramps

    req = ContourRequest.model_validate({"program": ramps(np.random.default_rng(0), passes).text, "feed": "fastest"})
    cpu, est = _cpu_and_estimate(req)
    assert est / 2 <= cpu <= 1.5 * est, (passes, cpu, est)


def _generated(name: str, feed: str, Ts: float) -> dict:
    """The request of ``bench_contour_estimate.py``'s generated program (seed 0) of this name,
    feed and typed sample time."""
    from tests.contour_programs import cases

    for made, req in cases(0, large=False):
        if made.name == name and req["feed"] == feed and (req.get("settings") or {}).get("Ts") == Ts:
            return req
    raise LookupError((name, feed, Ts))


# issue 35 goal 5 re-measured on main after the feedcap3-5 merges (benchmarks/README.md): the
# program feed's search on 2 ramp-and-helix passes took 42.7 CPU s at Ts 1 ms and 18.5 s at 2 ms
# against 16.4 s and 8.72 s estimated (2.60x, 2.12x), and estimate.SLOPE_SEARCH_PLANS (1.8, 1.3 of
# a sloped piece's estimate) counted it. Re-measured on branch seamest (benchmarks/README.md,
# "seams predicted"): 11.4 and 4.54 CPU s (10 passes at 2 ms: 15.3 s), the search back to its
# cost before those merges, and the term put them at 0.27-0.32x (10 passes 0.20x) and freecad's
# gentle helix at 0.13x: 0 again. The estimate without it bounds them both ways
def test_the_program_feeds_search_on_slopes_at_a_fine_ts_is_counted():
    import numpy as np

    from planner.contour.estimate import slope_search
    from tests.contour_programs import long_pass

    sloped = read_gcode(_generated("2 ramp and helix passes", "program", 0.002)["program"]).passes[0].elements
    assert any(e.z_end_m != e.z_start_m for e in sloped)
    level = read_gcode(long_pass(np.random.default_rng(0), 10).text).passes[0].elements
    assert slope_search("program", level, 1.0, 0.002) == 0.0  # no slope: nothing
    for Ts in (0.001, 0.002, 0.005, 0.01):  # measured within the piece's own estimate at every Ts now
        assert slope_search("program", sloped, 1.0, Ts) == slope_search("fastest", sloped, 1.0, Ts) == 0.0
    for name, Ts, cpu in (("2 ramp and helix passes", 0.001, 11.4), ("2 ramp and helix passes", 0.002, 4.54),
                          ("10 ramp and helix passes", 0.002, 15.3), ("2 ramp and helix passes", 0.005, 0.785),
                          ("2 ramp and helix passes", 0.01, 0.371)):
        est = estimate_contour(_generated(name, "program", Ts))[0]
        assert cpu / 1.5 <= est <= cpu / 0.3, (name, Ts, est, cpu)


@pytest.mark.serial  # compares CPU seconds with the estimate
def test_the_program_feed_on_ramps_at_2_ms_within_its_estimate(_warm):
    req = ContourRequest.model_validate(_generated("2 ramp and helix passes", "program", 0.002))
    cpu, est = _cpu_and_estimate(req)
    assert est / 4 <= cpu <= 1.5 * est, (cpu, est)


# issue 35 goal 5, the seams (branch seamest): fusion360.nc in ``fastest`` at a typed Ts of 2 ms
# took 23.1 CPU s against an estimate of 7.14 (2.9x): its level piece after the ramp was planned
# from rest, again from the braking forces the ramp left (8.3 N where the drives drop 6 N a
# sample), that plan's infeasible verdict's advice checked (4 s), the robot held while the
# forces fell and the piece planned from rest a third time. Now the seam is predicted from the
# forces left (planned from them at once, no advice checked where that fails) and the estimate
# counts what remains (estimate.SEAM_PLANS)
@pytest.mark.serial  # compares CPU seconds with the estimate
def test_fusion360_fastest_at_a_typed_2_ms_within_its_estimate(_warm):
    cam = Path(__file__).resolve().parent / "data" / "cam" / "fusion360.nc"
    req = ContourRequest.model_validate({"program": cam.read_text(), "origin": "fit", "feed": "fastest",
                                         "settings": {"Ts": 0.002}})
    cpu, est = _cpu_and_estimate(req)
    assert est / 4 <= cpu <= 1.5 * est, (cpu, est)


def test_the_pieces_after_a_slope_stop_are_counted(monkeypatch):
    """``fastest`` plans a pass in pieces where Z's slope changes sharply (fusion360's ramps of
    slope 1), each after the first from the forces the one before left: the estimate counts
    :data:`~planner.contour.estimate.SLOPE_STOP_PLANS` of each such piece's own estimate
    (``seams``); nothing in ``program`` feed (no such pieces) nor on programs without such stops.
    fusion360 at a typed 2 ms measured 13.8 CPU s after the seam fix (benchmarks/README.md)."""
    import planner.contour.estimate as est_mod

    cam = Path(__file__).resolve().parent / "data" / "cam"

    def est(name: str, feed: str, Ts: float = 0.002) -> float:
        return estimate_contour({"program": (cam / name).read_text(), "origin": "fit", "feed": feed,
                                 "settings": {"Ts": Ts}})[0]

    with_term = {(n, f): est(n, f) for n in ("fusion360.nc", "estlcam.nc") for f in ("program", "fastest")}
    monkeypatch.setattr(est_mod, "SLOPE_STOP_PLANS", (0.0, 0.0, 0.0, 0.0))
    without = {(n, f): est(n, f) for n in ("fusion360.nc", "estlcam.nc") for f in ("program", "fastest")}
    assert with_term[("fusion360.nc", "fastest")] > without[("fusion360.nc", "fastest")]
    for key in (("fusion360.nc", "program"), ("estlcam.nc", "program"), ("estlcam.nc", "fastest")):
        assert with_term[key] == without[key], key
    assert with_term[("fusion360.nc", "fastest")] >= 13.8 / 1.5
