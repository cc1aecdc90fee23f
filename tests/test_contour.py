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


def arc_points(mv, prev: np.ndarray, end: np.ndarray, n_of) -> np.ndarray:
    """The points (n + 1, 2) of rs274's arc move ``mv`` (its centre ``mv[3:5]``, its turn
    ``mv[5]``: > 0 counter-clockwise) from ``prev`` to ``end`` (x, y), ``n = n_of(sweep, r)``
    pieces (``sweep`` [rad] signed, a full circle where the two ends meet)."""
    c = np.array(mv[3:5])
    r = float(np.hypot(*(prev[:2] - c)))
    a0 = math.atan2(prev[1] - c[1], prev[0] - c[0])
    sweep = math.atan2(end[1] - c[1], end[0] - c[0]) - a0
    while mv[5] > 0 and sweep <= 1e-12:
        sweep += 2 * math.pi
    while mv[5] <= 0 and sweep >= -1e-12:
        sweep -= 2 * math.pi
    a = a0 + sweep * np.linspace(0, 1, n_of(sweep, r) + 1)
    return c + r * np.stack((np.cos(a), np.sin(a)), axis=1)


def sagitta_pieces(sweep: float, r: float) -> int:
    """Pieces of an arc of ``sweep`` [rad] and radius ``r`` [m] whose sagitta is at most 1e-8 m."""
    return max(2, math.ceil(abs(sweep) / (2 * math.acos(1 - 1e-8 / r))))


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
            lines.append(arc_points(mv, prev, end, sagitta_pieces))
        prev = end
    return shapely.MultiLineString([ln + np.asarray(origin) for ln in lines])


def rs274_cut_passes(program: str, origin) -> list[np.ndarray]:
    """rs274's cutting moves (feed, Z < 0) pass by pass (a pass ends at a move that does not
    cut: a rapid, a feed move above Z 0), each as one polyline (K, 2), arcs densified to 1e-8 m
    sagitta, robot frame [m]."""
    moves, _ = canonical_moves(program)
    prev = np.zeros(3)
    passes: list[list[np.ndarray]] = [[]]
    for mv in moves:
        if mv[0] == "dwell":
            continue
        end = np.array(mv[1:4]) if mv[0] == "line" else np.array([mv[1], mv[2], mv[6]])
        moved = np.hypot(*(end[:2] - prev[:2])) > 0
        if mv[0] == "line":
            if mv[4] or min(prev[2], end[2]) >= 0:
                if passes[-1]:
                    passes.append([])
            elif moved:
                passes[-1].append(np.array([prev[:2], end[:2]]))
        else:
            passes[-1].append(arc_points(mv, prev, end, sagitta_pieces))
        prev = end
    return [np.vstack(p) + np.asarray(origin) for p in passes if p]


def cut_runs(result) -> list[np.ndarray]:
    """The cut of each pass as the exported program runs it: the samples of each run of
    cutting samples, with the sample before it (where the tool rests as the cut begins) (K, 2)."""
    cut = np.asarray(result.contour.cutting)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], cut.astype(int), [0]))))
    return [result.pose[max(a - 1, 0):b, :2] for a, b in zip(edges[::2], edges[1::2])]


def _polyline_distance(pts: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance of the points (M, 2) to the polyline (K, 2), by shapely (the nearest of its
    segments in a tree: exact) [m]."""
    segs = shapely.linestrings(np.stack((line[:-1], line[1:]), axis=1)) if len(line) > 1 else \
        shapely.points(line)
    idx, d = shapely.STRtree(segs).query_nearest(shapely.points(pts), return_distance=True, all_matches=False)
    out = np.empty(len(pts))
    out[idx[0]] = d
    return out


def _dense(line: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points at most ``step`` apart on each segment of the polyline (its vertices included),
    and the index of the segment each point starts."""
    L = np.hypot(*np.diff(line, axis=0).T)
    m = np.maximum(np.ceil(L / step).astype(int), 1)
    owner = np.repeat(np.arange(len(L)), m)
    frac = (np.arange(owner.size) - np.repeat(np.cumsum(m) - m, m)) / np.repeat(m, m)
    pts = np.vstack((line[owner] + frac[:, None] * (line[owner + 1] - line[owner]), line[-1:]))
    return pts, owner


def farthest(line: np.ndarray, target: np.ndarray, step: float) -> float:
    """The largest distance of a point of the polyline ``line`` from the polyline ``target``
    [m], measured on points at most ``step`` apart where it may be (within ``step / 2`` below
    the true maximum: the distance is 1-Lipschitz along the line): on points ``1000 step``
    apart, then 10 times closer on the pieces between them whose bound ``(d_a + d_b +
    length) / 2`` reaches the largest distance measured, down to ``step``."""
    pts, _ = _dense(line, 1000 * step)
    d = _polyline_distance(pts, target)
    top = float(d.max())
    a, b, da, db = pts[:-1], pts[1:], d[:-1], d[1:]
    for level in (100, 10, 1):
        k = np.flatnonzero((da + db + np.hypot(*(b - a).T)) / 2 >= top - 1e-12)
        if not k.size:
            break
        # each piece a -> b in n pieces: its n + 1 points, the distance of each
        n = np.maximum(np.ceil(np.hypot(*(b[k] - a[k]).T) / (level * step)).astype(int), 1)
        owner = np.repeat(k, n + 1)
        t = (np.arange(owner.size) - np.repeat(np.cumsum(n + 1) - n - 1, n + 1)) / np.repeat(n, n + 1)
        fine = a[owner] + t[:, None] * (b[owner] - a[owner])
        d = _polyline_distance(fine, target)
        top = max(top, float(d.max()))
        inner = t[:-1] < 1  # consecutive points of one piece
        a, b, da, db = fine[:-1][inner], fine[1:][inner], d[:-1][inner], d[1:][inner]
    return top


def two_sided(result, program: str, origin, step: float) -> list[tuple[float, float]]:
    """Per pass, measured here independently of the planner: (the largest distance of the cut,
    its samples and the straight moves between them, from rs274's path of the pass; the largest
    distance of a point of that path, its corners included, from the cut) [m], each on points
    at most ``step`` apart (:func:`farthest`)."""
    paths, cuts = rs274_cut_passes(program, origin), cut_runs(result)
    assert len(paths) == len(cuts) == len(result.contour.passes)
    return [(farthest(c, p, step), farthest(p, c, step)) for p, c in zip(paths, cuts)]


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
    # the planner's own figure agrees with the independent one (the cut from the path: its
    # per-sample deviation; max_deviation_m is the larger of both directions)
    assert c.max_deviation_m <= c.tolerance_m
    assert abs(float(np.max(c.deviation_m)) - measured) < c.tolerance_m / 20
    assert c.max_deviation_m >= measured - c.tolerance_m / 20
    # and the other way (issue 32): the path within the tolerance of the cut, as reported
    assert_two_sided(small, SMALL, ORIGIN)
    # the whole programmed path is realised: the cut samples reach both ends of every move
    cut = small.pose[np.asarray(c.cutting), :2]
    assert shapely.distance(shapely.points(cut), path).max() <= c.tolerance_m
    # the cut leaves the pass's start from the sample before its first (the piece's sample 0,
    # shared with the move there): its first sample has moved since branch fixedsamples, which
    # holds no sample at rest at a piece's start
    first = int(np.flatnonzero(np.asarray(c.cutting))[0])
    assert np.hypot(*(small.pose[first - 1, :2] - np.array(ORIGIN))) < 1e-5
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
    from planner.contour.search import SCALE_RESOLUTION, largest_feasible

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
    from planner.contour.search import SCALE_MAX, SCALE_MIN, largest_feasible

    assert largest_feasible(lambda x: True, 1.0) == SCALE_MAX
    assert largest_feasible(lambda x: x < SCALE_MIN, 1.0) is None


# -- G64 P both ways (issue 32): the cut within P of the path AND the path within P of the cut --

#: the independent measure's step [m]: each figure within 5e-8 m below the true maximum
STEP_M = 1e-7
#: the planner's figures agree with the independent ones to this [m]: the measure's step plus the
#: planner's own resolution (the cut-to-path figure within tol / 1280 above the maximum, the
#: path-to-cut one within 1e-9 m)
AGREE_M = 1e-7


def assert_two_sided(res, prog: str, origin) -> list[tuple[float, float]]:
    """Every pass of ``res`` within its tolerance both ways, measured independently (on rs274's
    path: :func:`two_sided`, each figure plus ``STEP_M / 2`` a bound from above), and the
    planner's reported figures equal to the independent ones within ``AGREE_M``."""
    c = res.contour
    tol = c.tolerance_m
    sides = two_sided(res, prog, origin, STEP_M)
    for (cut_d, path_d), ps in zip(sides, c.passes):
        assert cut_d + STEP_M / 2 <= tol, (cut_d, tol)
        assert path_d + STEP_M / 2 <= tol, (path_d, tol)
        assert ps.max_path_deviation_m == pytest.approx(path_d, abs=AGREE_M)
        assert ps.max_deviation_m == pytest.approx(max(cut_d, path_d), abs=AGREE_M)
    assert c.max_path_deviation_m == max(ps.max_path_deviation_m for ps in c.passes)
    assert c.max_deviation_m == pytest.approx(max(max(s) for s in sides), abs=AGREE_M)
    assert c.max_path_deviation_m <= c.max_deviation_m <= tol
    return sides


def corner_program(angle_deg: float, p_mm: float, length_mm: float = 8.0) -> str:
    """Two lines meeting at ``angle_deg`` (the angle between them at the corner: 5 a hairpin,
    175 nearly straight), G64 P ``p_mm``."""
    a = math.radians(180.0 - angle_deg)
    x, y = 10 + length_mm * math.cos(a), length_mm * math.sin(a)
    return (f"G21 G90 G17\nG64 P{p_mm}\nG0 X{10 - length_mm:.4f} Y0 Z2\nG1 Z-1 F300\nG1 X10 F1200\n"
            f"G1 X{x:.4f} Y{y:.4f}\nG0 Z2\nM2\n")


@pytest.mark.parametrize("angle, p_mm", [(45, 0.05), (90, 0.02), (5, 0.05), (20, 0.02), (135, 0.05), (175, 0.02)])
def test_corner_point_within_tolerance_of_the_cut(angle, p_mm):
    """The issue-32 case, checked against LinuxCNC's reading: the programmed corner point (and
    every point of the path) within G64 P of the cut. Before, the cut turned inside the two
    cells' intersection, up to 0.95 P / sin(angle / 2) from the corner (0.1215 mm at 45 degrees
    with P0.05, 0.066 mm at 90 degrees with P0.02), while max_deviation_m said <= P."""
    prog = corner_program(angle, p_mm)
    res = plan_contour({"program": prog, "origin": ORIGIN, "feed": "program"})
    sides = assert_two_sided(res, prog, ORIGIN)
    corner = np.array([0.01, 0.0]) + ORIGIN
    cut = cut_runs(res)[0]
    assert float(_polyline_distance(corner[None, :], cut)[0]) <= p_mm * 1e-3
    assert res.contour.max_path_deviation_m >= sides[0][1] - AGREE_M > 0


def generated_program(rng: np.random.Generator, arcs: bool = True) -> str:
    """One pass of 3-6 moves (mm, G64 P 0.01-0.05 mm): lines of 0.5-6 mm and tiny ones
    (0.005-0.05 mm), arcs (radius 0.5-5 mm, 20-160 degrees, G2 or G3; not without ``arcs``:
    a line-only pass has the widest cells) either tangent to the move before or not; at every
    corner the two moves meet at 5-175 degrees."""
    p_mm = float(rng.choice([0.01, 0.02, 0.05]))
    pos = np.array([15.0, 15.0])
    heading = rng.uniform(0, 2 * math.pi)
    out = [f"G21 G90 G17\nG64 P{p_mm}", f"G0 X{pos[0]:.4f} Y{pos[1]:.4f} Z2", "G1 Z-1 F300", "F1000"]
    for k in range(int(rng.integers(3, 7))):
        kind = rng.choice(["line", "tiny", "arc", "tangent"] if arcs else ["line", "line", "tiny"])
        if k > 0 and kind != "tangent":  # a corner of 5-175 degrees between the moves
            heading += (math.pi - math.radians(rng.uniform(5, 175))) * rng.choice([-1, 1])
        d = np.array([math.cos(heading), math.sin(heading)])
        if kind in ("line", "tiny"):
            pos = pos + d * (rng.uniform(0.005, 0.05) if kind == "tiny" else rng.uniform(0.5, 6))
            out.append(f"G1 X{pos[0]:.4f} Y{pos[1]:.4f}")
            continue
        r, sweep, ccw = rng.uniform(0.5, 5), math.radians(rng.uniform(20, 160)), bool(rng.random() < 0.5)
        n = np.array([-d[1], d[0]]) * (1 if ccw else -1)
        c = pos + r * n
        a0 = math.atan2(pos[1] - c[1], pos[0] - c[0])
        a1 = a0 + (sweep if ccw else -sweep)
        end = c + r * np.array([math.cos(a1), math.sin(a1)])
        out.append(f"{'G3' if ccw else 'G2'} X{end[0]:.4f} Y{end[1]:.4f} I{c[0] - pos[0]:.4f} J{c[1] - pos[1]:.4f}")
        pos, heading = end, heading + (sweep if ccw else -sweep)
    return "\n".join(out + ["G0 Z2", "M2"]) + "\n"


@pytest.mark.parametrize("seed", range(8))
def test_generated_corners_arcs_and_tiny_moves_within_tolerance_both_ways(seed):
    """Seeded programs (:func:`generated_program`, odd seeds with arcs, even ones lines only),
    the programmed feed (and ``fastest`` for two of them): within G64 P both ways, the reported
    figures equal to the independent ones."""
    prog = generated_program(np.random.default_rng(3200 + seed), arcs=seed % 2 == 1)
    origin = [-0.015, -0.015]
    for feed in ("program", "fastest") if seed < 2 else ("program",):
        res = plan_contour({"program": prog, "origin": origin, "feed": feed})
        assert_two_sided(res, prog, origin)


def test_shipped_example_within_tolerance_both_ways():
    """app/static/examples/contour-part.ngc (two depth passes, G64 P0.02), both feeds."""
    from pathlib import Path

    prog = (Path(__file__).resolve().parent.parent / "app/static/examples/contour-part.ngc").read_text()
    origin = [-0.013, -0.0075]
    for feed in ("program", "fastest"):
        res = plan_contour({"program": prog, "origin": origin, "feed": feed})
        assert len(assert_two_sided(res, prog, origin)) == 2
