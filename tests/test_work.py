"""Bounded work (issue 15): the bounds every number of a request is validated against, the
work estimate a server checks before planning, and the corridor metric that used to take
memory proportional to samples x segments."""

from __future__ import annotations

import copy
import math
import time

import numpy as np
import pytest
from pydantic import ValidationError

from planner import estimate_work, plan, segment
from planner.corridor.geometry import box_distance, corridor_violation
from planner.orchestrator.timing import resolve_timing
from planner.schema import (
    MAX_COORDINATE,
    MAX_PENALTY_RATIO,
    MAX_SEGMENTS,
    MIN_CELL_SIZE,
    WORK_COSTS,
    PlanRequest,
    error_details,
)
from tests.support import with_settings

LAYOUT = {"bounds": {"lower": [-0.08, -0.06], "upper": [0.08, 0.06]}, "obstacles": [], "clearance": 0.0,
          "cell": {"shape": "square", "size": 0.01}, "start": [-0.06, -0.04, 0.0], "end": [0.06, -0.04, 0.0]}


def first_error(raw: dict) -> dict:
    with pytest.raises(ValidationError) as exc:
        PlanRequest.model_validate(raw)
    return error_details(exc.value.errors())[0]


# ---------------------------------------------------------------------------------------
# bounds, validated up front with the field named

@pytest.mark.parametrize("path, value, field, bound", [
    (("layout", "bounds", "upper", 0), 1e300, "layout.bounds.upper[0]", f"<= {MAX_COORDINATE}"),
    (("layout", "start", 1), -1e9, "layout.start[1]", f">= {-MAX_COORDINATE}"),
    (("layout", "cell", "size"), 5e-324, "layout.cell.size", f">= {MIN_CELL_SIZE}"),
    (("layout", "clearance"), 1e300, "layout.clearance", f"<= {MAX_COORDINATE}"),
])
def test_layout_numbers_out_of_bounds_name_the_field(path, value, field, bound):
    raw = {"layout": copy.deepcopy(LAYOUT)}
    node = raw
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    err = first_error(raw)
    assert err["field"] == field and bound in err["message"], err


def test_obstacle_far_outside_is_refused_before_the_grid_arithmetic_overflows(table1):
    raw = {"layout": {**LAYOUT, "obstacles": [{"type": "rectangle", "lower": [-1e308, 0.05], "upper": [1e308, 1e308]}]}}
    assert first_error(raw)["field"] == "layout.obstacles[0].lower[0]"
    table1["segments"][1]["upper"][2] = 1e300
    assert first_error(table1)["field"] == "segments[1].upper[2]"


def test_tiny_speed_and_huge_penalties_are_refused(table1):
    assert first_error(with_settings(table1, speed_m_s=5e-324))["field"] == "settings.speed_m_s"
    assert first_error(with_settings(table1, q_ra=[1e300, 1, 1]))["field"] == "settings.q_ra[0]"
    assert first_error(with_settings(table1, q_u=[1e13] * 4))["field"] == "settings.q_u[0]"


def test_paper_mode_penalty_ratio_bound_is_where_planning_starts_to_fail(table1):
    """k_r / k_u up to MAX_PENALTY_RATIO plans; 10x beyond is refused up front (it failed as a
    misleading 'singular robot' before), in the constrained mode (no such failure) it is not."""
    ok = with_settings(table1, mode="paper", k_r=MAX_PENALTY_RATIO * 1e-3, k_u=1e-3, require_settled=False)
    assert plan(ok).metrics.steps > 0
    bad = with_settings(table1, mode="paper", k_r=10 * MAX_PENALTY_RATIO * 1e-3, k_u=1e-3)
    err = first_error(bad)
    assert err["field"] == "settings.k_r" and "ill-conditioned" in err["message"]
    per_segment = with_settings(table1, mode="paper")
    per_segment["segments"][3]["q_rb"] = [1e12, 1.0, 1.0]
    assert first_error(per_segment)["field"] == "segments[3].q_rb"
    PlanRequest.model_validate(with_settings(bad, mode="constrained"))


# ---------------------------------------------------------------------------------------
# the corridor metric in blocks

def test_corridor_violation_in_blocks_equals_the_dense_minimum():
    """Distance outside the union of boxes, computed in blocks of poses, against the dense
    (samples x segments) minimum of box_distance; 3 000 segments make blocks of 21 poses."""

    class Seg:
        def __init__(self, lo, hi):
            self.lower, self.upper = lo, hi

    rng = np.random.default_rng(7)
    lo = rng.uniform(-1, 1, (3000, 3))
    segs = [Seg(a, a + rng.uniform(0, 0.01, 3)) for a in lo]
    poses = rng.uniform(-1.2, 1.2, (1001, 3))
    dense = box_distance(poses[:, None, :2], np.array([s.lower[:2] for s in segs]),
                         np.array([s.upper[:2] for s in segs])).min(axis=1)
    np.testing.assert_allclose(corridor_violation(poses, segs), dense, rtol=1e-12, atol=1e-15)


# ---------------------------------------------------------------------------------------
# the work estimate

def test_estimate_counts_the_steps_the_planner_takes(table1):
    """Table I: 12 segments x 20 samples and a settling tail; the plan took ~290 steps, the
    estimate counts 240 + 300 (the whole tail the request allows, tail_max_s 3 s at Ts = 0.01 s:
    an upper bound of the steps, issue 20)."""
    est = estimate_work(table1)
    res = plan(table1)
    assert est.steps == 12 * 20 + 300 and est.plans == 1
    assert 12 * 20 <= res.metrics.steps <= est.steps


def test_estimate_grows_with_each_factor(table1):
    def work(**settings) -> float:  # the part that depends on the request
        return estimate_work(with_settings(table1, **settings)).seconds - WORK_COSTS["fixed"]

    base = work(mode="paper")
    # 4x the corridor's samples (240 -> 960; the 300 samples of the settling tail stay)
    assert work(mode="paper", samples_per_segment=80) > 2 * base
    assert work(mode="constrained") > 2 * base  # the QP makes a step dearer (~4x measured, Table I)
    # 4x the horizon: 4x the samples (samples_per_segment follows N) and a dearer step
    assert work(mode="constrained", N=120) > 5 * work(mode="constrained")
    assert work(mode="paper", plant_substeps=10) > base
    fastest = estimate_work(with_settings(table1, mode="constrained", fastest=True))
    assert fastest.plans > 1 and fastest.seconds > 3 * work(mode="constrained")


def test_estimate_names_the_field_to_change(table1):
    assert estimate_work(with_settings(table1, mode="constrained", N=150)).field == "settings.N"
    assert estimate_work(with_settings(table1, samples_per_segment=2000)).field == "settings.samples_per_segment"
    long = {"segments": [{"lower": [0.001 * i, 0, 0], "upper": [0.001 * i, 0, 0]} for i in range(MAX_SEGMENTS)]}
    assert estimate_work(long).field == "segments"
    est = estimate_work(with_settings(table1, mode="constrained", N=150))
    assert "N = 150" in est.detail and "constrained" in est.message(30.0) and "30 s" in est.message(30.0)


@pytest.mark.parametrize("shape, size", [("square", 0.01), ("square", 0.005), ("triangle", 0.01)])
@pytest.mark.parametrize("start, end", [([-0.06, -0.04, 0.0], [0.06, -0.04, 0.0]),
                                        ([-0.06, -0.04, 0.0], [0.05, 0.04, 0.0])])
def test_layout_estimate_is_a_lower_bound_on_the_corridor(shape, size, start, end):
    """The estimated corridor of a layout (the fewest cells between start and end) is never
    longer than the corridor the segmentation finds (here with a wall in the way)."""
    lay = {**LAYOUT, "cell": {"shape": shape, "size": size}, "start": start, "end": end,
           "obstacles": [{"type": "rectangle", "lower": [-0.01, -0.06], "upper": [0.01, 0.03]}]}
    req = {"layout": lay}
    seg = segment(req)
    est = estimate_work(req)
    # the samples per segment the plan runs with: a layout is timed at the default tool speed
    S = resolve_timing(PlanRequest.model_validate(req).settings, seg.segments).samples_per_segment
    tail = PlanRequest.model_validate(req).settings.tail_steps
    assert est.steps - tail <= len(seg.segments) * S


@pytest.mark.serial  # a bound of 0.05 s
def test_estimate_is_fast_for_the_largest_requests():
    """Microseconds, not a plan: 2 000 segments with a speed target (one pass over the
    segments), and a layout at the cell limit."""
    long = PlanRequest.model_validate({"segments": [{"lower": [0.001 * i, 0, 0], "upper": [0.001 * i, 0, 0]}
                                                    for i in range(MAX_SEGMENTS)],
                                       "settings": {"speed_m_s": 0.01}})
    lay = PlanRequest.model_validate({"layout": {**LAYOUT, "cell": {"shape": "square", "size": 0.0007}}})
    for req in (long, lay):
        estimate_work(req)
        t = time.perf_counter()
        est = estimate_work(req)
        assert time.perf_counter() - t < 0.05 and math.isfinite(est.seconds)
