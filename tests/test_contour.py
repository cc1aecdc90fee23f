"""Contour plans of G-code programs (issue 22): the deviation of every sample and of every
straight move between samples from the path LinuxCNC's interpreter (rs274) makes of the
program, measured here with shapely on that path (independent of the planner's geometry),
the programmed feed never exceeded, the drive limits, rest at plunges, the bad programs."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
import shapely

from planner.contour import plan_contour
from planner.errors import PlannerError
from tests.test_gcode_in import canonical_moves

SMALL = """(a small contour: lines and arcs, mm)
G21 G90 G17
G64 P0.05
F1200
G0 X0 Y0 Z2
G1 Z-1 F300
G1 X20 F1200
G3 X30 Y10 I0 J10
G1 Y20 F900
G2 X20 Y30 R10
G1 X0
G1 Y0
G0 Z2
G0 X-10 Y-10
M2
"""
ORIGIN = [-0.01, -0.01]


def rs274_cut_path(program: str, origin) -> shapely.MultiLineString:
    """The cutting moves (feed, Z < 0) of rs274's canonical program as polylines, arcs densified
    to 1e-8 m sagitta, in the robot frame [m]."""
    moves, _ = canonical_moves(program)
    prev = np.zeros(3)
    lines = []
    for mv in moves:
        if mv[0] == "dwell":
            continue
        if mv[0] == "line":
            end = np.array(mv[1:4])
            if not mv[4] and min(prev[2], end[2]) < 0 and np.hypot(*(end[:2] - prev[:2])) > 0:
                lines.append(np.array([prev[:2], end[:2]]))
        else:
            end = np.array([mv[1], mv[2], mv[6]])
            c = np.array(mv[3:5])
            r = np.hypot(*(prev[:2] - c))
            a0 = math.atan2(prev[1] - c[1], prev[0] - c[0])
            a1 = math.atan2(end[1] - c[1], end[0] - c[0])
            sweep = a1 - a0
            if mv[5] > 0:
                while sweep <= 1e-12:
                    sweep += 2 * math.pi
            else:
                while sweep >= -1e-12:
                    sweep -= 2 * math.pi
            n = max(2, math.ceil(abs(sweep) / (2 * math.acos(1 - 1e-8 / r))))
            a = a0 + sweep * np.linspace(0, 1, n + 1)
            lines.append(c + r * np.stack((np.cos(a), np.sin(a)), axis=1))
        prev = end
    return shapely.MultiLineString([ln + np.asarray(origin) for ln in lines])


def chord_deviation(result, path: shapely.MultiLineString, step: float) -> float:
    """Largest distance from ``path`` of the cutting samples and of the straight moves from each
    cutting sample to the next, on points ``step`` apart (plus step / 2: a bound from above)."""
    cut = np.asarray(result.contour.cutting)
    pose = result.pose[:, :2]
    worst = 0.0
    idx = np.nonzero(cut[:-1] & cut[1:])[0]
    a, b = pose[idx], pose[idx + 1]
    L = np.hypot(*(b - a).T)
    m = np.maximum(np.ceil(L / step).astype(int), 1) + 1
    owner = np.repeat(np.arange(len(idx)), m)
    start = np.repeat(np.cumsum(m) - m, m)
    frac = (np.arange(owner.size) - start) / np.repeat(m - 1, m)
    pts = a[owner] + frac[:, None] * (b - a)[owner]
    # the path's pieces in a tree: the nearest piece of each point (exact, and much faster
    # than the distance to the whole multi-line of densified arcs)
    coords = [np.asarray(g.coords) for g in path.geoms]
    pieces = shapely.linestrings(np.concatenate([np.stack((c[:-1], c[1:]), axis=1) for c in coords]))
    _, d = shapely.STRtree(pieces).query_nearest(shapely.points(pts), return_distance=True, all_matches=False)
    worst = float(d.max()) + step / 2
    return worst


def feed_excess(result, program: str) -> float:
    """The largest excess over the programmed F of the line being cut [m/s], of the cut samples'
    speed and of each chord between two cut samples over Ts (the larger F of its two ends):
    F in effect at each source line read from the text here (modal F, G20/G21), not from the
    planner's parser."""
    unit, f, feed = 1e-3, 0.0, {}
    for n, text in enumerate(program.splitlines(), start=1):
        code = text.split("(")[0].split(";")[0].upper()
        if "G20" in code:
            unit = 0.0254
        if "G21" in code:
            unit = 1e-3
        m = re.search(r"F\s*([-+0-9.]+)", code)
        if m:
            f = float(m.group(1)) * unit / 60
        feed[n] = f
    c = result.contour
    cut = np.asarray(c.cutting)
    F = np.array([feed.get(x, np.inf) if x is not None else np.inf for x in c.program_line])
    speed = np.hypot(*result.velocity[:, :2].T)
    excess = float(np.max(np.where(cut, speed - F, -np.inf), initial=0.0))
    both = cut[:-1] & cut[1:]
    chord = np.hypot(*np.diff(result.pose[:, :2], axis=0).T) / result.settings.Ts
    f2 = np.maximum(F[:-1], F[1:])
    return max(excess, float(np.max(np.where(both, chord - f2, -np.inf), initial=0.0)))


@pytest.fixture(scope="module")
def small():
    return plan_contour({"program": SMALL, "origin": ORIGIN, "feed": "program"})


def test_small_program_within_tolerance_of_rs274_path(small):
    c = small.contour
    assert c.tolerance_m == pytest.approx(5e-5)  # G64 P0.05
    path = rs274_cut_path(SMALL, ORIGIN)
    measured = chord_deviation(small, path, c.tolerance_m / 50)
    assert measured <= c.tolerance_m
    # the planner's own figure agrees with the independent one
    assert c.max_deviation_m <= c.tolerance_m
    assert abs(c.max_deviation_m - measured) < c.tolerance_m / 20
    # the whole programmed path is realised: the cut samples reach both ends of every move
    cut = small.pose[np.asarray(c.cutting), :2]
    assert shapely.distance(shapely.points(cut), path).max() <= c.tolerance_m
    assert np.hypot(*(cut[0] - np.array(ORIGIN))) < 1e-5
    hull = shapely.MultiPoint(cut).buffer(c.tolerance_m)
    assert hull.covers(shapely.Point(np.array([0.03, 0.01]) + ORIGIN))  # a corner of the part


def test_small_program_feed_and_limits(small):
    c, mt = small.contour, small.metrics
    assert mt.within_limits and mt.contained and mt.infeasible_steps == 0
    assert mt.max_force_ratio <= 1.0 + 1e-9
    lines = np.array([x if x is not None else 0 for x in c.program_line])
    cut = np.asarray(c.cutting)
    speed = np.hypot(*small.velocity[:, :2].T)
    feed = {7: 0.02, 8: 0.02, 9: 0.015, 10: 0.015, 11: 0.015, 12: 0.015}  # m/s per line
    f = np.array([feed.get(int(x), np.inf) for x in lines])
    assert np.all(speed[cut] <= f[cut] + 1e-9)
    assert set(lines[cut]) == set(feed)
    assert not np.any(lines[~cut])
    # plunge (Z 2 -> -1 at F300: 0.6 s) and retract: at rest
    rest = ~cut & (speed < 1e-9)
    assert rest.sum() * small.settings.Ts >= 0.6
    assert len(c.passes) == 1 and c.passes[0].first_line == 7 and c.passes[0].last_line == 12
    assert c.cycle_time_s == pytest.approx(small.time[-1])
    assert c.passes[0].length_m == pytest.approx(0.02 + 0.01 * math.pi / 2 + 0.01 + 0.01 * math.pi / 2 + 0.02 + 0.03)


@pytest.mark.slow
def test_fastest_is_faster_and_within_tolerance(small):
    fast = plan_contour({"program": SMALL, "origin": ORIGIN, "feed": "fastest"})
    assert fast.contour.passes[0].time_s < small.contour.passes[0].time_s
    path = rs274_cut_path(SMALL, ORIGIN)
    assert chord_deviation(fast, path, fast.contour.tolerance_m / 50) <= fast.contour.tolerance_m
    assert fast.metrics.within_limits and fast.metrics.contained


def test_drive_forces_across_the_joins_of_the_parts(small):
    """The program is planned in parts (rapid, plunge, cut, retract) joined sample to sample; the
    drive forces held from a shared sample on are the next part's first step's: the joined
    forces' energy (sum of f^2 Ts, computed here from the rows) equals the parts' summed energy,
    and no step of the joined forces, the joins included, exceeds the force-rate limit (the
    first step of every part was dropped: 0 N to the part's second force at a join) beyond the
    widening of a relaxed step (``RELAX_M`` of a row, force rows in units of force_max)."""
    from planner.constraints.rows import RELAX_M

    for res in (small, plan_contour({"program": SMALL, "origin": ORIGIN, "feed": "fastest"})):
        f = np.asarray(res.drives.force)
        Ts = res.settings.Ts
        assert float(np.sum(f * f) * Ts) == pytest.approx(res.metrics.energy, rel=1e-12)
        step = np.abs(np.diff(np.vstack((np.zeros((1, f.shape[1])), f)), axis=0)).max()
        assert step <= 150.0 / 0.05 * Ts + RELAX_M * 150.0 + 1e-9
        assert len(f) == len(res.time) == len(res.acceleration)


@pytest.mark.parametrize("body, code, words", [
    ({"origin": [0.2, 0.0]}, "unreachable", ["line 7", "reach"]),
    ({"tolerance_m": 0.02}, "invalid_input", ["at most"]),
    ({"program": SMALL.replace("G1 X0", "G41 X0")}, "invalid_input", ["line 11", "G41"]),
    ({"program": "G1 X1\n" * 400_000}, "too_large", ["bytes"]),
    ({"settings": {"speed_m_s": 0.1}}, "invalid_input", ["feed"]),
    ({"feed": "max"}, "invalid_input", []),
])
def test_bad_requests_name_the_cause(body, code, words):
    req = {"program": SMALL, "origin": ORIGIN, **body}
    with pytest.raises(PlannerError) as err:
        plan_contour(req)
    assert err.value.code == code, err.value
    for w in words:
        assert w in err.value.message, err.value.message


def test_tolerance_below_what_the_planner_can_hold():
    with pytest.raises(PlannerError) as err:
        plan_contour({"program": SMALL, "origin": ORIGIN, "tolerance_m": 5e-6})
    assert err.value.field == "tolerance_m" and "below what the planner can hold" in err.value.message


def test_program_tolerance_is_used_and_a_too_small_one_refused():
    with pytest.raises(PlannerError) as err:
        plan_contour({"program": SMALL.replace("P0.05", "P0.001"), "origin": ORIGIN})
    assert err.value.field == "tolerance_m" and "G64 P" in err.value.message


def test_bad_settings_name_the_field():
    with pytest.raises(PlannerError) as err:
        plan_contour({"program": SMALL, "origin": ORIGIN, "settings": {"Ts": -1}})
    assert err.value.field == "settings.Ts"
    with pytest.raises(PlannerError) as err:
        plan_contour({"program": SMALL, "origin": ORIGIN, "settings": {"bogus": 1}})
    assert err.value.field is not None and err.value.field.startswith("settings")


@pytest.mark.slow
def test_consecutive_cells_hull_within_tolerance():
    """The tube's guarantee (planner.contour.tube): the convex hull of any two consecutive cells
    (where two consecutive samples and the straight move between them lie) is within 0.95 tol
    of the path; measured with shapely on the rs274 path at the points of a grid (tol / 4)
    inside each hull and at points tol / 16 apart on its boundary; the chords of one arc share
    no junction."""
    from planner.contour.tube import tube
    from planner.exchange import read_gcode

    els = read_gcode(SMALL).passes[0].elements
    tol = 2e-5
    t = tube(els, np.array(ORIGIN), tol, 0.0, 0.002)
    path = rs274_cut_path(SMALL, ORIGIN)
    polys = [np.asarray(s.polygon) for s in t.segments if s.polygon is not None]
    h = tol / 4
    worst = 0.0
    for a, b in zip(polys, polys[1:]):
        hull = shapely.MultiPoint(np.vstack((a, b))).convex_hull
        local = path.intersection(hull.buffer(2 * tol))
        x0, y0, x1, y1 = hull.bounds
        gx, gy = np.meshgrid(np.arange(x0, x1 + h, h), np.arange(y0, y1 + h, h))
        pts = shapely.points(np.column_stack((gx.ravel(), gy.ravel())))
        pts = pts[shapely.intersects(hull, pts)]
        edge = shapely.points(np.asarray(shapely.segmentize(hull.exterior, h / 4).coords))
        d = shapely.distance(np.concatenate((pts, edge)), local)
        worst = max(worst, float(d.max()))
    assert worst <= 0.95 * tol + 1e-10
    assert worst >= 0.5 * tol  # the tube uses the room it has
    arcs = [k for k, e in enumerate(els) if e.kind == "arc"]
    inner = np.isin(t.element, arcs) & (np.roll(t.element, 1) == t.element) & (np.roll(t.element, -1) == t.element)
    assert not np.any((t.turn > 0) & inner)
    assert (np.isin(t.element, arcs) & (t.length > 0)).sum() > 10


@pytest.mark.parametrize("start", [1 / 64, 0.3, 1.0, 1.37, 1.3701, 5.0, 64.0])
@pytest.mark.parametrize("threshold", [0.02, 0.5, 1.37, 1.3705, 40.0])
def test_largest_feasible_brackets_the_threshold(start, threshold):
    """fastest's scale search: from any start, ok(lam) and not ok(lam (1 + 1/64)) for a
    monotone feasibility; from a start at the answer, two plans."""
    from planner.contour.plan import SCALE_RESOLUTION, largest_feasible

    calls = []

    def ok(x):
        calls.append(x)
        return x <= threshold

    lam = largest_feasible(ok, start)
    assert lam is not None and lam <= threshold < lam * (1 + SCALE_RESOLUTION) * (1 + 1e-9)
    assert len(calls) < 25
    calls.clear()
    assert largest_feasible(ok, lam) == pytest.approx(lam) and len(calls) == 2


def test_largest_feasible_at_the_limits():
    from planner.contour.plan import SCALE_MAX, SCALE_MIN, largest_feasible

    assert largest_feasible(lambda x: True, 1.0) == SCALE_MAX
    assert largest_feasible(lambda x: x < SCALE_MIN, 1.0) is None
