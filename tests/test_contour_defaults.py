"""The contour's sample time and horizon chosen from the program (issue 35 goal 3,
:mod:`planner.contour.defaults`): the drives' acceleration the rule starts from checked against
the force box by linear programming (scipy, not the planner's zonotope facets); the chosen
sample time gives the binding arc one tube chord per sample no faster than the speed it asks
and not more than a step slower; typed settings and programs the default serves are left
alone; the plan and the work estimate use the same sample time; and the chosen sample time
cuts the benchmark pass faster than the 10 ms it replaces (the time against the third-order
optimum is measured by benchmarks/bench_contour_optimum.py, not here)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import linprog

from planner.contour import plan_contour
from planner.contour.defaults import TS_FLOOR_S, TS_STEP_S, arc_speed, contour_settings, drive_acceleration
from planner.contour.estimate import estimate_contour
from planner.contour.passes import parse_contour_request, read_program, tolerance_of
from planner.contour.tube import SAGITTA_FRACTION
from planner.model import load_robot
from planner.model.dynamics import generalised_forces
from planner.schema import DEFAULT_FORCE_RISE_S
from tests.test_contour_feed import _bench_contour

BENCH_ORIGIN = [-0.013, -0.0075]  # benchmarks/bench_contour.py's


def bench_program(passes: int) -> str:
    """The benchmark part (benchmarks/bench_contour.py) in ``passes`` depth passes."""
    return _bench_contour().program(passes)

LINES = """G21 G90 G17
G64 P0.02
G0 X0 Y0 Z2
G1 Z-1 F300
G1 X10 F1200
G1 Y8
G1 X0
G1 Y0
G0 Z2
M2
"""


def settings_of(body: dict):
    req = parse_contour_request(body)
    program = read_program(req, None)
    tol = tolerance_of(req, program)
    return contour_settings(req, req.plan_settings(), program, tol, load_robot(req.robot)), program, tol


def reachable(model, y: np.ndarray, acc: np.ndarray) -> bool:
    """Some drive forces in the box give the tool (at rest at ``y``) the acceleration ``acc``
    (x, y; psi's 0): ``J_l^T f = M_r (acc, 0)``, ``|f| <= force_max`` (an LP)."""
    M, h, J = generalised_forces(model, y, np.zeros(3))
    fmax = np.asarray(model.force_max, float)
    got = linprog(np.zeros(model.n_legs), A_eq=J.T, b_eq=M @ np.array([acc[0], acc[1], 0.0]) - h,
                  bounds=list(zip(-fmax, fmax)), method="highs")
    return bool(got.status == 0)


def test_drive_acceleration_is_the_largest_in_every_direction():
    """At the centre of the base pivots every direction of the plane reaches the rule's
    acceleration within the force box; 3 % more is out of it in some direction."""
    model = load_robot("moving-slide")
    a = drive_acceleration(model)
    y = np.array([*np.asarray(model.base, float).mean(axis=0), 0.0])
    dirs = [np.array([math.cos(t), math.sin(t)]) for t in np.linspace(0, 2 * math.pi, 72, endpoint=False)]
    assert all(reachable(model, y, 0.999 * a * d) for d in dirs)
    assert not all(reachable(model, y, 1.03 * a * d) for d in dirs)


@pytest.mark.parametrize("name", ["bench", "freecad_linuxcnc.ngc", "fusion360.nc"])
def test_chosen_ts_keeps_a_chord_per_sample_within_the_arc_speed(name):
    """``fastest``: on every arc one tube chord per sample time is at most the speed the arc
    asks unless the floor binds (the chord never needs just over one sample, which would be
    two, at half the speed), and on the binding arc at least that speed at one step less; the
    horizon three force ramps."""
    from pathlib import Path

    text = bench_program(1) if name == "bench" else (Path(__file__).parent / "data" / "cam" / name).read_text()
    st, program, tol = settings_of({"program": text, "feed": "fastest"})
    model = load_robot("moving-slide")
    assert TS_FLOOR_S <= st.Ts < 0.01
    a = drive_acceleration(model)
    jerk = a / DEFAULT_FORCE_RISE_S
    s_a = SAGITTA_FRACTION * tol
    ratios = []  # chord per sample / the speed the arc asks
    for b in program.passes:
        for e in b.elements:
            if e.kind == "arc" and e.radius_m is not None:
                chord = 2 * math.sqrt(2 * e.radius_m * s_a - s_a * s_a)
                ratios.append(chord / arc_speed(e, a, jerk, 0.5, "fastest"))
    assert ratios
    assert min(ratios) / st.Ts <= 1.0 + 1e-9 or st.Ts == TS_FLOOR_S
    assert min(ratios) / (st.Ts - TS_STEP_S) > 1.0 or st.Ts == TS_FLOOR_S
    assert st.N == max(30, math.ceil(3 * DEFAULT_FORCE_RISE_S / st.Ts - 1e-9))


def test_defaults_left_alone_where_given_or_not_needed():
    """Typed Ts or N are kept; a program of lines (no chord bound) and the ``program`` feed
    (whose F one chord per 10 ms reaches on the benchmark part: 29 mm/s > 20 mm/s) keep the
    settings' 10 ms and horizon."""
    text = bench_program(1)
    for body in ({"program": text, "feed": "fastest", "settings": {"Ts": 0.01}},
                 {"program": text, "feed": "fastest", "settings": {"N": 40}},
                 {"program": LINES, "feed": "fastest"},
                 {"program": text, "feed": "program"}):
        st, _, _ = settings_of(body)
        req = parse_contour_request(body)
        assert st.Ts == req.plan_settings().Ts and st.N == req.plan_settings().N, body


@pytest.mark.slow
def test_chosen_ts_cuts_faster_and_within_tolerance():
    """The benchmark pass planned ``fastest`` at the chosen sample time is faster than at the
    10 ms it replaces, within the tolerance both ways; the work estimate counts that Ts."""
    body = {"program": bench_program(1), "origin": BENCH_ORIGIN, "feed": "fastest"}
    auto = plan_contour(body)
    typed = plan_contour({**body, "settings": {"Ts": 0.01}})
    assert auto.contour is not None and typed.contour is not None
    assert auto.settings.Ts < 0.01
    assert auto.contour.passes[0].time_s < 0.9 * typed.contour.passes[0].time_s
    assert auto.contour.max_deviation_m <= auto.contour.tolerance_m
    assert auto.metrics.within_limits
    assert f"Ts = {auto.settings.Ts:g} s" in estimate_contour(body)[1]
