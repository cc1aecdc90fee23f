"""Issue 20: the default (constrained) mode never fails wrongly, its advice works, and every
answer is certified by the independent checker of ``tests/certify_support.py``.

One test per error code applies the remedy the error suggests and gets a plan (or confirms
independently that no remedy exists); a fixed-seed slice of the certification run
(``benchmarks/certify.py``) certifies several hundred random cases in both modes.
"""

from __future__ import annotations

import copy
import re

import numpy as np
import pytest

from planner import PlannerError, estimate_work, plan
from planner import segment as segment_layout
from planner.schema import MAX_CELLS
from tests.certify_support import (
    ZERO_FIGURE,
    box_leg_range,
    certify_case,
    check_plan,
    confirm_error,
    draw_cases,
    grid_path_exists,
    robot_of,
    user_case,
)
from tests.support import TABLE1, with_settings

WALL = {"bounds": {"lower": [-0.08, -0.06], "upper": [0.08, 0.06]},
        "obstacles": [{"type": "rectangle", "lower": [-0.01, -0.06], "upper": [0.01, 0.06]}],
        "clearance": 0.002, "cell": {"shape": "square", "size": 0.01},
        "start": [-0.06, -0.04, 0.0], "end": [0.06, -0.04, 0.0]}


def _error(request: dict) -> PlannerError:
    with pytest.raises(PlannerError) as info:
        plan(request)
    return info.value


def test_checker_certifies_table1_in_both_modes():
    for mode in ("constrained", "paper"):
        req = with_settings(TABLE1, mode=mode)
        res = plan(req)
        v = check_plan(req, res, req["segments"])
        assert v.ok, v.problems
    # and it is not a checker that cannot fail: a result moved out of the corridor is caught
    res = plan(TABLE1).to_json_dict()
    res["pose"][40][1] += 0.03
    v = check_plan(TABLE1, res, TABLE1["segments"])
    assert not v.ok and any("outside the corridor" in p or "metric" in p for p in v.problems)


def test_checker_leg_kinematics_agree_with_the_plan_arrays():
    """The checker's own leg geometry (from the robot's JSON) against both robots' plans."""
    for robot in ("moving-slide", "tri-slide"):
        req = {**copy.deepcopy(TABLE1), "robot": robot}
        res = plan(req)
        v = check_plan(req, res, req["segments"])
        assert v.ok, (robot, v.problems)


def test_no_path_through_a_wall_names_the_wall_and_gives_no_cell_advice():
    """An obstacle spanning the bounds' height: no cell size can pass it, and the error says so
    (issue 20: it advised smaller cells, which never help); the independent fine-grid search
    agrees."""
    req = {"robot": "moving-slide", "layout": copy.deepcopy(WALL)}
    err = _error(req)
    assert err.code == "no_path"
    msg = err.message
    assert "spans the bounds from y = -0.0600 m to 0.0600 m" in msg and "no cell size can pass it" in msg
    assert "smaller cells" not in msg and "give a path" not in msg
    assert not ZERO_FIGURE.search(msg)
    assert not grid_path_exists(req["layout"], robot_of("moving-slide"), 0.0005)


def test_no_path_advice_of_smaller_cells_gives_a_path():
    """A gap of 8 mm beside a clearance of 1 mm: 10 mm cells cannot pass, the advised size does."""
    lay = copy.deepcopy(WALL)
    lay["obstacles"][0]["upper"][1] = 0.046  # an 14 mm gap at the top, 12 mm after the clearance
    lay["clearance"] = 0.001
    lay["cell"]["size"] = 0.02
    req = {"robot": "moving-slide", "layout": lay}
    err = _error(req)
    assert err.code == "no_path" and err.field == "layout"
    m = re.search(r"cells of ([0-9.e-]+) m \(layout\.cell\.size", err.message)
    assert m, err.message
    lay["cell"]["size"] = float(m.group(1))
    res = plan(req)
    v = check_plan(req, res, [{"lower": s.lower.tolist(), "upper": s.upper.tolist(),
                               "polygon": None if s.polygon is None else np.asarray(s.polygon).tolist()}
                              for s in res.corridor.segments])
    assert v.ok, v.problems


def test_no_path_advice_of_a_smaller_clearance_gives_a_path():
    lay = copy.deepcopy(WALL)
    lay["obstacles"][0]["upper"][1] = 0.04  # a 20 mm gap, closed by a 21 mm clearance
    lay["clearance"] = 0.021
    lay["start"], lay["end"] = [-0.06, -0.02, 0.0], [0.06, -0.02, 0.0]
    lay["cell"]["size"] = 0.01
    req = {"robot": "moving-slide", "layout": lay}
    err = _error(req)
    assert err.code == "no_path"
    assert "cells of" not in err.message.split("; ")[1]  # no cell size helps at this clearance
    c = re.search(r"a clearance of ([0-9.e-]+) m \(layout\.clearance; now 0\.021 m\)(?: with cells of ([0-9.e-]+) m)? "
                  r"gives a path", err.message)
    assert c, err.message
    fixed = copy.deepcopy(req)
    fixed["layout"]["clearance"] = float(c.group(1))
    if c.group(2):
        fixed["layout"]["cell"]["size"] = float(c.group(2))
    assert len(segment_layout(fixed).path) > 0


def test_unreachable_is_confirmed_by_leg_lengths():
    req = copy.deepcopy(TABLE1)
    req["segments"][5]["upper"][0] = 0.3  # far beyond the legs' stroke
    err = _error(req)
    assert err.code == "unreachable" and err.field == "segments[5]"
    s = req["segments"][5]
    robot = robot_of("moving-slide")
    mins, maxs = box_leg_range(robot, np.array(s["lower"][:2]), np.array(s["upper"][:2]), np.array([0.0]))
    assert np.any(maxs > robot.lmax) or np.any(mins < robot.lmin)
    # the remedy: a segment within reach plans
    req["segments"][5]["upper"][0] = 0.0
    assert plan(req).metrics.contained


def test_infeasible_names_real_figures_and_more_time_helps():
    """Too little time: the error's figures are not zero, and the advised remedy plans."""
    req = with_settings(TABLE1, samples_per_segment=2, N=30)
    err = _error(req)
    assert err.code == "infeasible"
    assert not ZERO_FIGURE.search(err.message.split(";")[0]), err.message
    m = re.search(r"settings\.samples_per_segment = (\d+), checked", err.message)
    assert m, err.message
    res = plan(with_settings(req, samples_per_segment=int(m.group(1))))
    assert res.metrics.contained


#: case 4 of seed 22 (benchmarks/certify_seed22_problems.jsonl): a layout at 2 samples a
#: segment with the default cell size; 4 samples a segment alone would change that size (the
#: default follows the samples) and the request, segmented again, would have no path
DEFAULT_CELLS_AT_2_SAMPLES = {
    "robot": "moving-slide",
    "layout": {"bounds": {"lower": [-0.0595943913441878, -0.047655234028266255],
                          "upper": [0.0904056086558122, 0.07234476597173374]},
               "obstacles": [{"type": "polygon", "points": [[-0.04438352070960586, 0.002745721698923802],
                                                            [-0.06727436512429127, 0.015874449483240197],
                                                            [-0.06562322431778199, -0.011220324767388042]]}],
               "clearance": 0.001, "cell": {"shape": "square", "size": None},
               "start": [0.0902556086558122, 0.0712886472200782, 0.0],
               "end": [-0.05959439134418779, 0.07034526275421982, -0.1]},
    "settings": {"samples_per_segment": 2}}


def test_more_samples_advice_keeps_the_default_cell_size_it_was_checked_with():
    """Advice in samples a segment for a layout with the default cell size names that size
    too, and the request with both changes plans (the corridor the planner checked)."""
    err = _error(DEFAULT_CELLS_AT_2_SAMPLES)
    assert err.code == "infeasible", err.message
    m = re.search(r"settings\.samples_per_segment = (\d+) with layout\.cell\.size = ([0-9.e+-]+) m", err.message)
    assert m, err.message
    fixed = copy.deepcopy(DEFAULT_CELLS_AT_2_SAMPLES)
    fixed["settings"]["samples_per_segment"] = int(m.group(1))
    fixed["layout"]["cell"]["size"] = float(m.group(2))
    original = segment_layout(DEFAULT_CELLS_AT_2_SAMPLES)
    assert original.size == float(m.group(2))  # the corridor the planner checked the advice on
    res = plan(fixed)
    assert res.metrics.contained and res.metrics.settled


def test_estimate_counts_the_whole_settling_tail():
    """The issue's request: paper mode, Ts 1e-4, a 20 s settling tail, 50 plant substeps; it was
    estimated at 0.55 s and ran into the 30 s limit. Its estimate now counts every tail sample."""
    req = with_settings(TABLE1, mode="paper", Ts=1e-4, tail_max_s=20.0, settle_position_m=1e-12,
                        plant_substeps=50)
    est = estimate_work(req)
    assert est.steps >= 200_000
    assert est.seconds > 10.0


def test_a_segmented_layout_over_the_limit_is_refused_before_simulating():
    lay = {"bounds": {"lower": [-0.08, -0.06], "upper": [0.08, 0.06]}, "obstacles": [], "clearance": 0.0,
           "cell": {"shape": "square", "size": 0.005}, "start": [-0.07, -0.05, 0.0], "end": [0.07, 0.05, 0.0]}
    # a serpentine: walls from alternate sides
    xs = np.linspace(-0.06, 0.06, 7)
    for i, x in enumerate(xs):
        y0, y1 = (-0.06, 0.04) if i % 2 == 0 else (-0.04, 0.06)
        lay["obstacles"].append({"type": "rectangle", "lower": [float(x - 0.002), y0], "upper": [float(x + 0.002), y1]})
    req = {"robot": "moving-slide", "layout": lay, "settings": {"speed_m_s": 0.01}}
    before = estimate_work(req).seconds
    with pytest.raises(PlannerError) as info:
        plan(req, work_limit_s=before * 1.5)
    assert info.value.code == "too_much_work" and info.value.field


#: the slice: cases 0 .. 299 of seed 2020, in 4 parts of 75 (each case is drawn on its own from
#: (seed, index): the parts are the same 300 cases, which parallel test processes share out)
SLICE_CASES, SLICE_PARTS = 300, 4


@pytest.mark.slow
@pytest.mark.parametrize("part", range(SLICE_PARTS))
def test_certification_slice(part):
    """A fixed-seed slice of benchmarks/certify.py (300 cases, both modes; this part's 75):
    every plan certified by the independent checker, every error confirmed or its advice
    applied, no zero figure as a cause. (~40 s in all on the quiet 2-core machine.)"""
    n = SLICE_CASES // SLICE_PARTS
    assert n * SLICE_PARTS == SLICE_CASES
    problems = []
    for case in draw_cases(n, seed=2020, start=part * n):
        for mode, rec in certify_case(case).items():
            if rec.get("problem"):
                problems.append((mode, rec["outcome"], rec["problem"], case))
    assert not problems, problems[:3]


@pytest.mark.slow
def test_where_users_go_slice():
    """A fixed-seed slice of the issue 31 generator (:func:`tests.certify_support.user_case`:
    robots of 3-6 legs, platform x0.1-x10, leg friction 5-2000 N s/m, leg-speed limits; Ts 2-10
    ms with and without N; the default timing, speeds of 0.001-5 m/s, total times, fastest;
    force rates of 20 N/s to off; psi ranges) under a server's 30 s compute limit: every plan
    certified by the independent checker (force rates to 1e-9), every error confirmed or its
    advice applied (~30 s CPU)."""
    problems = []
    outcomes = []
    for i in range(12):
        case = user_case(np.random.default_rng([31, i]), (0.002, 0.005, 0.01))
        rec = certify_case(case, modes=("constrained",), work_limit_s=30.0)["constrained"]
        outcomes.append(rec["outcome"])
        if rec.get("problem"):
            problems.append((rec["outcome"], rec["problem"], case["settings"]))
    assert not problems, problems[:3]
    # 6 of 12 plan on branch fineest (the rest are refusals at 20-90 N/s or 0.05-1.5 s that the
    # checker confirms; whether a remedy plans them is issue 31 goal 2)
    assert outcomes.count("ok") >= 6, outcomes


def test_the_advice_bound_counts_every_cell_the_remedy_search_segments(monkeypatch):
    """``estimate_work(...).advice_seconds`` bounds an error's advice checks by the cells the
    remedy search may segment (:func:`planner.corridor.remedy_cells`): with no remedy that
    works (a wall with a 0.1 mm gap, narrower than the smallest cells within MAX_CELLS, a
    clearance, a psi range wider than the end angles) every candidate is tried, and the cells
    segmented are exactly that count; a wall across the bounds is named without a search of
    cell sizes (none can pass it), within that count."""
    from planner.corridor import remedy_cells, segmentation

    seen: list[int] = []
    real = segmentation._cells_and_path

    def counting(ws, model, s, *args, **kw):
        from planner.schema import cell_count

        seen.append(cell_count(ws.lower, ws.upper, ws.shape, s)[0])
        return real(ws, model, s, *args, **kw)

    lay = copy.deepcopy(WALL)
    lay["psi_range"] = [-0.1, 0.1]
    lay["clearance"] = 1e-5
    lay["obstacles"] = [{"type": "rectangle", "lower": [-0.01, -0.06], "upper": [0.01, 0.0]},
                        {"type": "rectangle", "lower": [-0.01, 0.0001 + 2 * lay["clearance"]], "upper": [0.01, 0.06]}]
    req = {"robot": "moving-slide", "layout": lay}
    monkeypatch.setattr(segmentation, "_cells_and_path", counting)
    err = _error(req)
    assert err.code == "no_path" and "were tried and give no path" in err.message, err.message
    first, remedies = seen[0], seen[1:]
    cells, runs = remedy_cells(np.array(lay["bounds"]["lower"]), np.array(lay["bounds"]["upper"]), "square",
                               lay["cell"]["size"], lay["clearance"], True)
    assert first == 16 * 12 and (sum(remedies), len(remedies)) == (cells, runs)
    assert cells > 2 * MAX_CELLS  # both shapes, down to the limit of cells
    est = estimate_work(req)
    assert est.advice_seconds > 0.0
    # a wall across the bounds: no search of cell sizes, within the bound
    seen.clear()
    wall = {"robot": "moving-slide", "layout": {**copy.deepcopy(WALL), "psi_range": [-0.1, 0.1]}}
    err = _error(wall)
    assert err.code == "no_path" and "no cell size can pass it" in err.message
    assert sum(seen[1:]) <= cells and len(seen) - 1 <= runs


#: found by the 10 000-case run (seed 20): an end point a few micrometres from a triangle's
#: acute corner or slanted edge; the stop box about it (end +- 3 um, cut to the cell's bounding
#: box) reached 0.1-0.3 um outside the triangle, where the robot settled
END_NEAR_A_SLANTED_EDGE = [{'robot': 'tri-slide',
      'layout': {'bounds': {'lower': [-0.068823928711244, -0.03200460615509513],
                            'upper': [0.06901542030519307, 0.03200460615509513]},
                 'obstacles': [{'type': 'rectangle',
                                'lower': [0.008848231704527313, -0.04731462104585976],
                                'upper': [0.027065988581708635, -0.016694591264330497]},
                               {'type': 'polygon',
                                'points': [[-0.07708057711911062, 0.006398394631928185],
                                           [-0.05467735281054403, 0.006398394631928185],
                                           [-0.05467735281054403, 0.028801618940494773],
                                           [-0.07708057711911062, 0.028801618940494773]],
                                'holes': [[[-0.06923944861111231, 0.014239523139926491],
                                           [-0.06251848131854235, 0.014239523139926491],
                                           [-0.06251848131854235, 0.020960490432496467],
                                           [-0.06923944861111231, 0.020960490432496467]]]}],
                 'clearance': 0.0,
                 'cell': {'shape': 'triangle', 'size': 0.005},
                 'start': [0.06414153848995077, -0.028582187267167526, 0.0],
                 'end': [-0.06882092871110616, -0.03200460615509513, 0.0]}},
     {'robot': 'moving-slide',
      'layout': {'bounds': {'lower': [-0.07010231598941512, -0.045774523861477935],
                            'upper': [0.07010231598941512, 0.04577452386127793]},
                 'obstacles': [{'type': 'polygon',
                                'points': [[-0.05715728777993725, 0.03940511993314701],
                                           [-0.08083806891552747, 0.04663819427630482],
                                           [-0.07406869172467193, 0.027082716804254347]]},
                               {'type': 'rectangle',
                                'lower': [0.01076876167919916, -0.045774523861477935],
                                'upper': [0.05451836447655653, 0.04577452386127793]},
                               {'type': 'polygon',
                                'points': [[0.01868919427463884, -0.045774523861477935],
                                           [0.008880289754376207, -0.04115965004698744],
                                           [0.011904682717121412, -0.051711655960459034]]}],
                 'clearance': 0.0,
                 'cell': {'shape': 'triangle', 'size': 0.005},
                 'start': [-0.02096965964057454, 0.03188358357052906, 0.0],
                 'end': [-0.031796705710474625, 0.009126953748853289, 0.05]}}]


@pytest.mark.parametrize("backend", ["compiled", "reference"])
@pytest.mark.parametrize("case", END_NEAR_A_SLANTED_EDGE, ids=["tri-slide", "moving-slide"])
def test_an_end_near_a_triangles_slanted_edge_settles_inside_the_cell(case, backend):
    req = {**copy.deepcopy(case), "settings": {"backend": backend}}
    res = plan(req)
    segs = [{"lower": s.lower.tolist(), "upper": s.upper.tolist(),
             "polygon": None if s.polygon is None else np.asarray(s.polygon).tolist()} for s in res.corridor.segments]
    v = check_plan(req, res, segs)
    assert v.ok, v.problems
    assert res.metrics.contained and res.metrics.settled


def test_clip_halfplanes_is_the_intersection_shapely_computes():
    import shapely

    from planner.corridor.geometry import clip_halfplanes, halfplanes

    rng = np.random.default_rng(7)
    for _ in range(200):
        tri = rng.uniform(-1, 1, (3, 2))
        lo, hi = np.sort(rng.uniform(-1, 1, (2, 2)), axis=0)
        box = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        A, b = halfplanes(tri)
        cut = clip_halfplanes(box, A, b)
        want = shapely.Polygon(tri).intersection(shapely.box(lo[0], lo[1], hi[0], hi[1])).area
        got = shapely.Polygon(cut).area if len(cut) >= 3 else 0.0
        assert abs(got - want) <= 1e-12


#: seed 22's problem 2 (benchmarks/certify_seed22_problems.jsonl): a layout at 0.1 m/s whose psi
#: range is zero-width; the compiled stage-wise solve accepted an ill-conditioned working set
#: whose states were 2.8e-5 off the dynamics: "ok" but psi left by 1.9e-7 rad (not contained)
ZERO_WIDTH_PSI_FAST = {
    "robot": "moving-slide",
    "layout": {"bounds": {"lower": [-0.045000450000000004, -0.036], "upper": [0.045000450000000004, 0.036]},
               "obstacles": [{"type": "rectangle", "lower": [0.023105976022962077, -0.040067556908755825],
                              "upper": [0.024905994022962077, -0.007026057081837709]},
                             {"type": "polygon", "points": [[-0.0070801204376967075, -0.02268170204044822],
                                                            [-0.004797388684100924, -0.016010430139852816],
                                                            [-0.010130208649817282, -0.01994395355718831]]},
                             {"type": "polygon", "points": [[-0.0169228729750982, -0.01122117826324612],
                                                            [-0.009817491809792498, 0.012877352542322343],
                                                            [-0.031225975410230034, -0.004779442898816454]]}],
               "clearance": 0.0, "cell": {"shape": "triangle", "size": None},
               "start": [0.009900099000000002, 0.027760664589351947, 0.0],
               "end": [-0.04419956763337378, 0.03436546709080095, 0.0]},
    "settings": {"speed_m_s": 0.1}}


@pytest.mark.parametrize("backend", ["compiled", "reference"])
def test_a_zero_width_psi_range_is_kept_when_the_step_qp_is_ill_conditioned(backend):
    """Every constrained plan that answers ``ok`` with ``require_settled`` is contained: the
    compiled step does not accept a stage-wise solution whose own prediction of its moves
    breaks the rows (it is relaxed like an infeasible step, as DAQP's reference does)."""
    from planner.constraints.controller import CONTAIN_TOL_RAD
    from planner.constraints.rows import ROW_UNIT_M
    from planner.constraints.step_kernels import ACCEPT_TOL

    req = copy.deepcopy(ZERO_WIDTH_PSI_FAST)
    req["settings"]["backend"] = backend
    res = plan(req)
    m = res.metrics
    assert m.contained and m.settled
    assert m.max_corridor_violation_rad <= CONTAIN_TOL_RAD
    assert m.predicted_violation_max_m <= ACCEPT_TOL * ROW_UNIT_M
    segs = [{"lower": s.lower.tolist(), "upper": s.upper.tolist(),
             "polygon": None if s.polygon is None else np.asarray(s.polygon).tolist()} for s in res.corridor.segments]
    v = check_plan(req, res, segs)
    assert v.ok, v.problems


#: seed 22's case 268: the end point is the corner of the last box that the box before reaches
#: from beyond it; the approach direction from that box's centre left the last box only the
#: corner, and all 69 steps of its samples were infeasible (solved relaxed, 2.4x the estimate)
END_AT_A_CORNER_REACHED_FROM_BEYOND = [
    {"lower": [7.692676536679701e-05, 0.040196467785411485, 0.0052387491317081765],
     "upper": [7.692676536679701e-05, 0.040196467785411485, 0.0052387491317081765]},
    {"lower": [-0.003064129180900893, 0.03686360951143958, -0.0099999],
     "upper": [0.003064129180900893, 0.04286544056612708, 0.0100001]},
    {"lower": [-0.014730753354508056, 0.025466820173584148, -0.003422576539831396],
     "upper": [0.016070546313925946, 0.05626811984201814, 0.016577423460168605]},
    {"lower": [-0.015521845176733334, 0.018211321037716312, -0.0020774666544367756],
     "upper": [0.010719944850370375, 0.04445311106482002, 0.017922533345563225]},
    {"lower": [0.004094118565496924, 0.019386547195375192, 0.00586650728301589],
     "upper": [0.013879889761019615, 0.026149870808423216, 0.025866507283015892]},
    {"lower": [0.004094118565496924, 0.026149870808423216, 0.023866507283015898],
     "upper": [0.004094118565496924, 0.026149870808423216, 0.023866507283015898]}]


@pytest.mark.parametrize("backend", ["compiled", "reference"])
def test_an_end_at_a_corner_reached_from_beyond_it_plans_without_relaxed_steps(backend):
    from planner.corridor.geometry import APPROACH_ROOM_M, approach_direction
    from planner.schema import Segment

    segs = [Segment.model_validate(s) for s in END_AT_A_CORNER_REACHED_FROM_BEYOND]
    d = approach_direction(segs)
    assert d is not None
    lo, hi, end = segs[-2].lower[:2], segs[-2].upper[:2], segs[-1].centre[:2]
    corners = np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]])
    assert float(np.min((corners - end) @ d)) <= -APPROACH_ROOM_M  # the last box keeps room behind the end
    req = {"robot": "moving-slide", "segments": END_AT_A_CORNER_REACHED_FROM_BEYOND, "settings": {"backend": backend}}
    res = plan(req)
    assert res.metrics.qp_relaxed_steps == 0 and res.metrics.contained and res.metrics.settled
    v = check_plan(req, res, req["segments"])
    assert v.ok, v.problems


def test_the_checker_reads_a_list_of_remedies_that_do_not_plan_as_no_advice_to_apply():
    """A refusal whose bounded search lists the settings it checked ("settings.N = 100 and
    settings.N = 200 with 8x the time and settings.plant_substeps = 10 do not plan either") names
    no remedy: the checker confirms it rather than reporting "advice that names no setting to
    apply" (9 such false problems in 75 cases where users go, seed 31); a clause that says a
    setting plans is still applied and planned."""
    message = ("at t = 0.054 s (segment 1) the robot cannot keep the corridor within its drive limits (the "
               "corridor would be left by 244 um); set require_settled to false to get the plan with its violations "
               "reported; 4x, 8x, 16x, 32x the time do not help either (checked; more time exceeds the limits on "
               "samples); settings.N = 100 and settings.N = 200 with 8x the time and settings.plant_substeps = 10 do "
               "not plan either (checked)")
    assert confirm_error(TABLE1, "infeasible", message, "settings") is None
    # the same words with a remedy that plans: applied (N 30 at 1/8 of the samples does not plan Table I)
    wrong = message.replace("do not plan either (checked)", "do not plan either (checked); settings.N = 30 with 2x "
                            "the time (settings.samples_per_segment = 2) plans (checked)")
    found = confirm_error(TABLE1, "infeasible", wrong, "settings")
    assert found is not None and "still fails" in found, found
