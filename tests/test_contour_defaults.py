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
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from planner.contour import plan_contour
from planner.contour.defaults import (
    FEED_CORNER_RAD,
    FEED_MOVE_MIN_TOL,
    FEED_MOVE_SAMPLES,
    TS_FLOOR_S,
    TS_STEP_S,
    arc_speed,
    contour_settings,
    drive_acceleration,
)
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


FUSION = (Path(__file__).parent / "data" / "cam" / "fusion360.nc").read_text()
#: a square of 10 mm sides cut at F1200 whose first side is a polyline of 0.1 mm moves (5 tolerances
#: each at G64 P0.02: under FEED_MOVE_MIN_TOL, they choose nothing); at 10 ms 50 samples a side
TINY = "G21 G90 G17\nG64 P0.02\nG0 X0 Y0 Z2\nG1 Z-1 F300\n" + "".join(
    f"G1 X{0.1 * k:.1f} F1200\n" for k in range(1, 101)) + "G1 Y10\nG1 X0\nG1 Y0\nG0 Z2\nM2\n"


def _bench_estimates():
    """benchmarks/bench_estimates.py's program generators (benchmarks/ is no package: by path)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "bench_estimates", Path(__file__).resolve().parent.parent / "benchmarks" / "bench_estimates.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _counted(program, tol):
    """(length, F) of the moves that start or end a pass or turn a corner, at least
    FEED_MOVE_MIN_TOL tolerances long (independently of feed_ts: turns from the moves' ends)."""
    out = []
    for b in program.passes:
        els = [e for e in b.elements if e.length_m > 1e-12]
        for k, e in enumerate(els):
            if e.length_m < FEED_MOVE_MIN_TOL * tol:
                continue
            turns = [math.pi if k == 0 else _turn_of(els[k - 1], e),
                     math.pi if k == len(els) - 1 else _turn_of(e, els[k + 1])]
            if max(turns) > FEED_CORNER_RAD:
                out.append((e.length_m, e.feed_m_s))
    return out


def _direction(e, at_end: bool) -> np.ndarray:
    """A move's direction of travel at its start or end, from a point 1e-7 of its length away."""
    if e.kind == "line":
        d = np.subtract(e.end, e.start)
    else:
        a = e.start_angle_rad + (e.sweep_rad if at_end else 0.0)
        b = a + (-1e-7 if at_end else 1e-7) * e.sweep_rad
        p, q = (np.array([math.cos(x), math.sin(x)]) for x in (a, b))
        d = (p - q) if at_end else (q - p)
    return d / np.hypot(*d)


def _turn_of(a, b) -> float:
    return math.acos(float(np.clip(_direction(a, True) @ _direction(b, False), -1.0, 1.0)))


def test_program_feed_ts_gives_short_moves_their_samples():
    """fusion360's 2 mm lines at F1000 (12 samples at 10 ms): the ``program`` feed's chosen Ts
    gives every move that starts, ends or turns at least FEED_MOVE_SAMPLES samples at its F, and
    a step coarser would not; the horizon is the force ramps' (at least 30), as for ``fastest``;
    the work estimate counts that Ts."""
    body = {"program": FUSION, "origin": "fit", "feed": "program"}
    st, program, tol = settings_of(body)
    moves = _counted(program, tol)
    assert moves and st.Ts < 0.01
    samples = [L / (F * st.Ts) for L, F in moves]
    assert min(samples) >= FEED_MOVE_SAMPLES - 1e-6 or st.Ts == TS_FLOOR_S
    coarser = st.Ts + TS_STEP_S
    assert min(L / (F * coarser) for L, F in moves) < FEED_MOVE_SAMPLES
    assert st.N == max(30, math.ceil(3 * DEFAULT_FORCE_RISE_S / st.Ts - 1e-9))
    assert f"Ts = {st.Ts:g} s" in estimate_contour(body)[1]


def test_program_feed_ts_ignores_moves_within_the_tolerance_scale():
    """Moves shorter than FEED_MOVE_MIN_TOL tolerances (a polyline's 0.1 mm pieces) do not choose
    the sample time: the square's 10 mm sides (50 samples at F1200 and 10 ms) keep 10 ms; typed
    settings are kept in the ``program`` feed too."""
    st, program, tol = settings_of({"program": TINY, "feed": "program"})
    assert 0.1e-3 < FEED_MOVE_MIN_TOL * tol and min(L / (F * 0.01) for L, F in _counted(program, tol)) >= 50 - 1e-6
    assert st.Ts == 0.01
    # tiny arcs the drives turn slower than their F keep the default, though their rows' 4.5 mm
    # lines at F3000 have 9 samples at 10 ms (the feed's search near the edge of feasibility)
    circles = {"program": _bench_estimates().gcode_circles(60), "feed": "program"}
    st, program, tol = settings_of(circles)
    model = load_robot(parse_contour_request(circles).robot)
    a, jerk = drive_acceleration(model), drive_acceleration(model) / DEFAULT_FORCE_RISE_S
    arcs = [e for b in program.passes for e in b.elements if e.kind == "arc"]
    assert arcs and all(arc_speed(e, a, jerk, float(np.min(model.speed_max)), "program") < e.feed_m_s for e in arcs)
    assert min(L / (F * 0.01) for L, F in _counted(program, tol)) < FEED_MOVE_SAMPLES
    assert st.Ts == 0.01
    for typed in ({"Ts": 0.01}, {"N": 40}):
        st, _, _ = settings_of({"program": FUSION, "feed": "program", "settings": typed})
        req = parse_contour_request({"program": FUSION, "feed": "program", "settings": typed})
        assert st.Ts == req.plan_settings().Ts and st.N == req.plan_settings().N


@pytest.mark.slow
def test_program_feed_chosen_ts_cuts_faster_and_never_over_F():
    """fusion360 in the ``program`` feed at the chosen Ts against the 10 ms it replaces: faster
    (measured 1.97 -> 1.85 s, benchmarks/README.md; 1.730 -> 1.694 s since each piece no longer
    holds its start point a sample nor its end point a sample after it settled, branch
    fixedsamples: those samples cost a Ts each, more at 10 ms), and no sample nor straight move
    between samples faster than its move's F (finite differences of the sampled tool point)."""
    body = {"program": FUSION, "origin": "fit", "feed": "program"}
    auto = plan_contour(body)
    typed = plan_contour({**body, "settings": {"Ts": 0.01}})
    assert auto.contour is not None and typed.contour is not None
    assert auto.settings.Ts < 0.01
    assert auto.contour.cut_time_s < 0.985 * typed.contour.cut_time_s
    c = auto.contour
    feed: dict[int, float] = {}
    f = 0.0
    for n, line in enumerate(FUSION.splitlines(), start=1):
        m = re.search(r"F\s*([-+0-9.]+)", line.split("(")[0].upper())
        f = float(m.group(1)) * 1e-3 / 60 if m else f
        feed[n] = f
    cut = np.asarray(c.cutting)
    F = np.array([feed[x] if x is not None else np.inf for x in c.program_line])
    speed = np.hypot(*np.diff(auto.pose[:, :2], axis=0).T) / np.diff(auto.time)
    both = cut[:-1] & cut[1:]
    assert (speed[both] / np.minimum(F[:-1], F[1:])[both]).max() <= 1 + 1e-6
    assert c.max_deviation_m <= c.tolerance_m
