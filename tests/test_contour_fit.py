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


def rect(w: float, h: float, feed: float = 3000) -> str:
    """A rectangular pass of ``w`` x ``h`` mm from program zero (where the tool starts)."""
    return (f"G21 G90 G17\nG64 P0.05\nG0 X0 Y0 Z2\nG1 Z-1 F300\nG1 X{w} F{feed}\nG1 Y{h}\nG1 X0\nG1 Y0\nG0 Z2\nM2\n")


def _outline_reachable(model, w_mm: float, h_mm: float, lower_left: np.ndarray, margin: float) -> bool:
    """Whether the rectangle's outline grown by ``margin`` [m] from ``lower_left`` [m] is
    reachable (points every 0.5 mm on the grown rectangle's sides), by the model's reach."""
    from planner.model.placement import reachable_points

    w, h = w_mm * 1e-3 + 2 * margin, h_mm * 1e-3 + 2 * margin
    x0, y0 = lower_left - margin
    t = np.linspace(0.0, 1.0, 1000)
    pts = np.concatenate([np.column_stack((x0 + w * t, np.full_like(t, y0))),
                          np.column_stack((x0 + w * t, np.full_like(t, y0 + h))),
                          np.column_stack((np.full_like(t, x0), y0 + h * t)),
                          np.column_stack((np.full_like(t, x0 + w), y0 + h * t))])
    return bool(np.all(reachable_points(model, pts[:, 0], pts[:, 1], 0.0)))


#: parts that do not fit centred on the robot's reach but fit elsewhere (the reach of the
#: default robot is a rounded square turned about 15 degrees: a long part fits along a diagonal)
OFF_CENTRE = [(225, 60), (60, 220)]


@pytest.mark.parametrize("size", OFF_CENTRE, ids=[f"{w}x{h}" for w, h in OFF_CENTRE])
def test_fit_places_a_part_that_fits_only_off_centre(size):
    """A rectangle that does not fit centred on the reachable region (its grid-sampled
    centroid, checked here with the model's reach) is placed off-centre: planned, every
    cutting sample a pose the model reaches, the cut where the program says shifted by the
    reported origin, and the whole part with the 3 mm margin reachable there."""
    from planner.model.placement import reachable_mask

    w, h = size
    model = load_robot("moving-slide")
    xs, ys, mask = reachable_mask(model, [-0.2, -0.2], [0.2, 0.2], 0.0, n=401)
    X, Y = np.meshgrid(xs, ys)
    centroid = np.array([X[mask].mean(), Y[mask].mean()])
    half = 0.5e-3 * np.array([w, h])
    assert not _outline_reachable(model, w, h, centroid - half, 0.003), "fits centred: not a test of the search"
    res = plan_contour({"program": rect(w, h), "origin": "fit"})
    c = res.contour
    assert c is not None
    origin = np.asarray(c.origin)
    assert np.hypot(*(origin + half - centroid)) > 0.005  # placed away from the centre
    assert _outline_reachable(model, w, h, origin, 0.003)
    cutting = np.flatnonzero(c.cutting)
    assert len(cutting) > 100
    for k in cutting:
        check_pose(model, res.pose[k])
    xy = res.pose[cutting, :2] - origin
    assert np.all(xy >= -1e-4) and np.all(xy <= np.array([w, h]) * 1e-3 + 1e-4)
    assert c.max_deviation_m <= c.tolerance_m + 1e-12


def test_a_typed_origin_for_an_off_centre_part_proposes_one_that_plans():
    """The long part at program zero [0, 0] is out of reach: refused naming its first line out of
    reach and proposing an origin, with which it plans."""
    with pytest.raises(PlannerError) as exc:
        plan_contour({"program": rect(225, 60), "origin": [0.0, 0.0]})
    msg = exc.value.message
    assert exc.value.code == "unreachable" and re.match(r"line \d+:", msg), msg
    m = re.search(r"an origin that fits: \[(-?[\d.e-]+), (-?[\d.e-]+)\] m", msg)
    assert m, msg
    res = plan_contour({"program": rect(225, 60), "origin": [float(m[1]), float(m[2])]})
    assert res.contour is not None and res.contour.origin == [float(m[1]), float(m[2])]


def test_a_too_large_part_is_refused_with_the_amount_that_fits():
    """A rectangle too large for any origin: refused with the factor by which it is too large;
    the part shrunk 2 % more than that factor is placed, 2 % less is refused as well."""
    w, h = 240, 100
    with pytest.raises(PlannerError) as exc:
        plan_contour({"program": rect(w, h), "origin": "fit"})
    msg = exc.value.message
    m = re.search(r"([\d.]+) times too large \(about ([\d.]+) m too wide and ([\d.]+) m too tall\)", msg)
    assert exc.value.code == "unreachable" and m, msg
    factor = float(m[1])
    assert factor > 1.0
    assert abs(float(m[2]) - (1 - 1 / factor) * (w + 0.0) * 1e-3) < 2e-3 * w * 1e-3 + 1e-3
    from planner.contour.placement import fit_origin
    from planner.exchange import read_gcode

    model = load_robot("moving-slide")
    small = rect(w / factor * 0.98, h / factor * 0.98)
    origin = fit_origin(read_gcode(small), model, 5e-5)
    assert _outline_reachable(model, w / factor * 0.98, h / factor * 0.98, origin, 0.003)
    with pytest.raises(PlannerError):
        fit_origin(read_gcode(rect(w / factor * 1.02, h / factor * 1.02)), model, 5e-5)
