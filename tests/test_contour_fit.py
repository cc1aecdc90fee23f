"""``origin: "fit"`` (issue 32, goal 4): a program placed inside the robot's reach, the origin
used reported; a typed origin out of reach refused naming the line and an origin that fits; a
program too large for any origin refused saying by how much."""

from __future__ import annotations

import re

import numpy as np
import pytest

from planner import PlannerError, load_robot
from planner.contour import plan_contour
from planner.model.reach import check_pose
from planner.schema import ContourRequest


def square(x0: float, y0: float, side: float) -> str:
    """A square pass of ``side`` mm from (x0, y0) mm, the tool starting at program zero."""
    return (f"G21 G90 G17\nG64 P0.05\nG0 X{x0} Y{y0} Z2\nG1 Z-1 F300\nG1 X{x0 + side} F1200\nG1 Y{y0 + side}\n"
            f"G1 X{x0}\nG1 Y{y0}\nG0 Z2\nM2\n")


FAR = square(120, 120, 40)  # out of reach with program zero at [0, 0]


def test_fit_places_a_program_out_of_reach_at_zero_inside_the_reach():
    with pytest.raises(PlannerError) as exc:
        plan_contour({"program": FAR, "origin": [0.0, 0.0]})
    assert exc.value.code == "unreachable"
    res = plan_contour({"program": FAR, "origin": "fit"})
    c = res.contour
    assert c is not None and c.origin != [0.0, 0.0]
    model = load_robot("moving-slide")
    cutting = np.flatnonzero(c.cutting)
    assert len(cutting) > 100
    for k in cutting:  # the model's own reach test, sample by sample
        check_pose(model, res.pose[k])
    # the cut is where the program says, shifted by the origin reported
    xy = res.pose[cutting, :2] - np.asarray(c.origin)
    assert np.all(xy >= 0.12 - 1e-3) and np.all(xy <= 0.16 + 1e-3)


def test_a_typed_origin_out_of_reach_names_the_line_and_an_origin_that_plans():
    with pytest.raises(PlannerError) as exc:
        plan_contour({"program": FAR, "origin": [0.02, 0.0]})
    msg = exc.value.message
    assert exc.value.code == "unreachable" and msg.startswith("line 3:"), msg
    m = re.search(r"an origin that fits: \[(-?[\d.e-]+), (-?[\d.e-]+)\] m", msg)
    assert m, msg
    res = plan_contour({"program": FAR, "origin": [float(m[1]), float(m[2])]})
    assert res.contour is not None and res.contour.origin == [float(m[1]), float(m[2])]


def test_a_program_too_large_for_any_origin_says_by_how_much():
    for origin in ("fit", [0.0, 0.0]):
        with pytest.raises(PlannerError) as exc:
            plan_contour({"program": square(0, 0, 300), "origin": origin})
        msg = exc.value.message
        assert exc.value.code == "unreachable" and "no origin fits" in msg, msg
        m = re.search(r"([\d.]+) times too large \(about ([\d.]+) m too wide and ([\d.]+) m too tall\)", msg)
        assert m and float(m[1]) > 1 and 0 < float(m[2]) < 0.3, msg


def test_origin_is_a_pair_or_fit():
    assert ContourRequest(program="M2", origin="fit").origin == "fit"
    for bad in ("middle", [0.0], [0.0, 0.0, 0.0]):
        with pytest.raises(ValueError):
            ContourRequest(program="M2", origin=bad)  # type: ignore[arg-type]
