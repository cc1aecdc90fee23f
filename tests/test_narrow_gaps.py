"""Narrow gaps (issue 31 goal 2): the cell remedy search tries both shapes and every size a
factor REMEDY_RATIO apart down to the limit of cells; a layout that leaves the cell size out
is segmented at the first of those that gives a path; a fixed-seed slice of the generator of
0.5-3 mm gaps, slots, holed obstacles and clearances (tests/gap_layouts.py) plans at the
defaults, or with the advice its refusal names, or no shape or size gives a path."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import shapely

from planner import PlannerError, plan
from planner import segment as segment_request
from planner.corridor import segment
from planner.corridor.segmentation import REMEDY_CELL_BUDGET, REMEDY_RATIO, _remedy_sizes
from planner.model import load_robot
from planner.schema import MAX_CELLS, cell_count
from tests.advice_support import apply_advice
from tests.certify_support import check_plan
from tests.gap_layouts import gap_layout

ROBOT = load_robot("moving-slide")


def _gap(free: float, clearance: float = 0.0, **cell) -> dict:
    """A wall across a 0.14 m x 0.10 m workspace with one gap ``free`` [m] wide after the clearance."""
    lo = 0.0123 + clearance  # off any grid's lines
    hi = lo + free + clearance
    return {"robot": "moving-slide", "layout": {
        "bounds": {"lower": [-0.07, -0.05], "upper": [0.07, 0.05]},
        "obstacles": [{"type": "rectangle", "lower": [-0.004, -0.06], "upper": [0.004, lo - clearance]},
                      {"type": "rectangle", "lower": [-0.004, hi], "upper": [0.004, 0.06]}],
        "clearance": clearance, "cell": cell, "start": [-0.05, -0.03, 0.0], "end": [0.05, -0.03, 0.0]}}


def _checked(req: dict, res) -> None:
    segs = [{"lower": s.lower.tolist(), "upper": s.upper.tolist(),
             "polygon": None if s.polygon is None else s.polygon.tolist()} for s in res.corridor.segments]
    v = check_plan(req, res, segs)
    assert v.ok, v.problems


def test_remedy_sizes_cover_both_shapes_at_every_size_down_to_the_limit_of_cells():
    lo, hi = np.array([-0.07, -0.05]), np.array([0.07, 0.05])
    cand = _remedy_sizes(lo, hi, "square", 0.02)
    shapes = {sh for sh, _ in cand}
    assert shapes == {"square", "triangle"}
    assert ("square", 0.02) not in cand and ("triangle", 0.02) in cand  # the given cells are not tried again
    for sh in ("square", "triangle"):
        sizes = [s for shape, s in cand if shape == sh]
        assert sizes == sorted(sizes, reverse=True)
        ratios = np.array(sizes[:-1]) / np.array(sizes[1:])
        assert np.all(ratios <= REMEDY_RATIO * 1.002), ratios  # no size skipped (halving did)
        assert all(cell_count(lo, hi, sh, s)[0] <= MAX_CELLS for s in sizes)
        # down to the limit: 0.1 % smaller cells are more than MAX_CELLS
        assert cell_count(lo, hi, sh, sizes[-1] / 1.001)[0] > MAX_CELLS
    assert sum(cell_count(lo, hi, sh, s)[0] for sh, s in cand) <= REMEDY_CELL_BUDGET * MAX_CELLS
    # a request's shape only: one shape
    assert {sh for sh, _ in _remedy_sizes(lo, hi, "triangle", 0.02, ("triangle",))} == {"triangle"}


@pytest.mark.parametrize("free", [0.0012, 0.0021])
def test_default_cells_pass_a_narrow_gap_and_plan(free):
    """The default size (cells of ~2 cm here) gives no path through a 1.2 or 2.1 mm gap; the
    default segmentation finds cells that pass it (no wider than the gap) and the plan keeps
    them, checked by the independent checker."""
    req = _gap(free)
    with pytest.raises(PlannerError) as info:
        segment(req["layout"], ROBOT, advise=False)  # the default size alone
    assert info.value.code == "no_path"
    seg = segment_request(req)
    assert seg.size <= free + 1e-12 if seg.shape == "square" else seg.size * np.sqrt(3) / 2 <= free + 1e-12
    # the corridor goes through the gap: some cell lies between the wall's ends
    boxes = np.array([[s.lower[0], s.upper[0]] for s in seg.segments[1:-1]])
    assert np.any((boxes[:, 0] >= -0.004 - 1e-12) & (boxes[:, 1] <= 0.004 + 1e-12))
    res = plan(req)
    assert res.metrics.contained and res.metrics.settled
    _checked(req, res)


def test_a_given_shape_is_kept_by_the_default_size_search():
    req = _gap(0.0025, shape="triangle")
    seg = segment_request(req)
    assert seg.shape == "triangle" and seg.size * np.sqrt(3) / 2 <= 0.0025
    # the shape left out: cells of either shape that pass
    req["layout"]["cell"] = {}
    assert len(segment_request(req).path) > 0


def test_advice_for_a_given_cell_size_names_cells_that_plan():
    """A given 5 mm cell cannot pass a 1.5 mm gap behind a 0.5 mm clearance: the advice names
    other cells (the size search between the halvings, either shape), and they plan."""
    req = _gap(0.0015, clearance=0.0005, shape="square", size=0.005)
    with pytest.raises(PlannerError) as info:
        plan(req)
    err = info.value
    assert err.code == "no_path" and "cells of" in err.message and "give a path" in err.message, err.message
    fixed = apply_advice(req, err.message)
    assert fixed is not None and fixed["layout"]["cell"] != req["layout"]["cell"]
    res = plan(fixed)
    assert res.metrics.contained and res.metrics.settled
    _checked(fixed, res)


def test_no_cell_within_the_limit_passes_a_gap_narrower_than_the_smallest_cells():
    """A 0.2 mm gap: the refusal says which cells it tried (both shapes, down to the limit of
    cells) and none of them, nor any size between, gives a path (the proof)."""
    req = _gap(0.0002)
    with pytest.raises(PlannerError) as info:
        segment_request(req)
    msg = info.value.message
    assert "square cells down to" in msg and "triangle cells down to" in msg and f"{MAX_CELLS} cells" in msg
    lay = req["layout"]
    for shape in ("square", "triangle"):
        size = 0.004
        while cell_count(lay["bounds"]["lower"], lay["bounds"]["upper"], shape, size)[0] <= MAX_CELLS:
            trial = copy.deepcopy(lay)
            trial["cell"] = {"shape": shape, "size": size}
            with pytest.raises(PlannerError):
                segment(trial, ROBOT, advise=False)
            size /= 1.1


#: (index, outcome) of seed 31 (benchmarks/bench_gaps.py: every kind, each outcome)
SLICE = [0, 1, 2, 3, 5, 6, 9, 10]


@pytest.mark.parametrize("i", SLICE)
def test_generated_gap_plans_at_the_defaults_or_with_its_advice_or_has_no_cells(i):
    req = gap_layout(31, i)
    try:
        res = plan(req)
    except PlannerError as exc:
        fixed = apply_advice(req, exc.message)
        if fixed is None:  # no remedy named: no shape or size within the limit gives a path
            assert exc.code == "no_path", exc.message
            lay = req["layout"]
            W = np.asarray(lay["bounds"]["upper"]) - np.asarray(lay["bounds"]["lower"])
            for shape in ("square", "triangle"):
                size = float(min(W)) / 4
                while cell_count(lay["bounds"]["lower"], lay["bounds"]["upper"], shape, size)[0] <= MAX_CELLS:
                    trial = copy.deepcopy(lay)
                    trial["cell"] = {"shape": shape, "size": size}
                    with pytest.raises(PlannerError):
                        segment(trial, ROBOT, advise=False)
                    size /= 1.15
            return
        req, res = fixed, plan(fixed)
    assert res.metrics.contained and res.metrics.settled
    _checked(req, res)
    # the plan passes the gap: the wall's pieces are not crossed (the corridor cells are free)
    obs = shapely.union_all([shapely.Polygon(o["points"], o.get("holes") or None)
                             for o in req["layout"]["obstacles"]])
    path = shapely.LineString(res.pose[:, :2])
    assert path.distance(obs) >= req["layout"]["clearance"] - 2e-6
