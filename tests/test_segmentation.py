"""Free-space segmentation (issue 3): layouts -> square/triangle cells -> a corridor.

The properties are checked independently of the implementation where possible: cell
freedom with exact shapely distances to the *raw* obstacles, edge sharing with shapely
intersections, shortest path lengths with a plain Python BFS over an independently built
grid, reach with the robot's own leg lengths.
"""

from __future__ import annotations

import itertools
import json
import math
from collections import deque

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import planner
from planner import segment as segment_request
from planner.corridor import count_turns, reachable_region, segment
from planner.corridor.cells import default_cell_size
from planner.corridor.geometry import halfplanes
from planner.corridor.reach_region import psi_samples
from planner.corridor.workspace import parse_layout
from planner.errors import PlannerError
from planner.model import SINGULAR_TOL, load_robot
from planner.model.kinematics import leg_lengths, singularity_measure, singularity_measure_grid
from planner.model.reach import check_pose
from planner.schema import (
    MAX_CELLS,
    MAX_COORDINATE,
    MAX_HOLES,
    MAX_POLYGON_POINTS,
    PlanRequest,
    SegmentationResult,
    Settings,
    cell_count,
    parse_request,
)
from tests.support import plan_json

ROBOT = load_robot("moving-slide")
H3 = math.sqrt(3.0) / 2.0


def base_layout(**kw) -> dict:
    lay = {"bounds": {"lower": [-0.08, -0.06], "upper": [0.08, 0.06]}, "obstacles": [], "clearance": 0.0,
           "cell": {"shape": "square", "size": 0.01}, "start": [-0.06, -0.04, 0.0], "end": [0.06, -0.04, 0.0]}
    lay.update(kw)
    return lay


def wall_layout(gap_lo: float, gap_hi: float, shape="square", size=0.01, clearance=0.002) -> dict:
    """A wall x in [-0.01, 0.01] across the workspace with one gap gap_lo..gap_hi (y, before clearance)."""
    return base_layout(obstacles=[{"type": "rectangle", "lower": [-0.01, -0.06], "upper": [0.01, gap_lo]},
                                  {"type": "rectangle", "lower": [-0.01, gap_hi], "upper": [0.01, 0.06]}],
                       clearance=clearance, cell={"shape": shape, "size": size})


def exact_obstacles(lay: dict) -> list:
    """The raw obstacles as exact-ish shapely geometry (circles with 1024 segments, inscribed)."""
    out = []
    for o in lay.get("obstacles", []):
        if o["type"] == "rectangle":
            out.append(shapely.box(*o["lower"], *o["upper"]))
        elif o["type"] == "polygon":
            out.append(shapely.Polygon(o["points"]))
        else:
            out.append(shapely.Point(o["center"]).buffer(o["radius"], quad_segs=256))
    return out


def check_corridor(seg, lay: dict) -> None:
    """Every corridor cell free (exact distance to every raw obstacle >= clearance, inside the
    bounds), consecutive cells share an edge, start in the first and end in the last cell,
    segments as Table I."""
    obstacles = exact_obstacles(lay)
    clearance = lay.get("clearance", 0.0)
    lo, hi = np.array(lay["bounds"]["lower"]), np.array(lay["bounds"]["upper"])
    polys = [shapely.Polygon(seg.polygons[c]) for c in seg.path]
    for c, poly in zip(seg.path, polys):
        assert seg.state[c] == 0
        P = seg.polygons[c]
        assert np.all(P >= lo - 1e-12) and np.all(P <= hi + 1e-12)
        for ob in obstacles:
            assert shapely.distance(poly, ob) >= clearance - 1e-9 * seg.size, (c, poly, ob)
            assert shapely.intersection(poly, ob).area <= 1e-12 * seg.size ** 2
    for a, b in itertools.pairwise(polys):
        shared = shapely.intersection(a, b)
        assert shared.geom_type in ("LineString", "MultiLineString") and shared.length > 0.5 * seg.size, shared
    start, end = np.array(lay["start"]), np.array(lay["end"])
    assert polys[0].distance(shapely.Point(start[:2])) < 1e-12
    assert polys[-1].distance(shapely.Point(end[:2])) < 1e-12
    segs = seg.segments
    assert len(segs) == len(seg.path) + 2
    np.testing.assert_array_equal(segs[0].lower, start)
    np.testing.assert_array_equal(segs[0].upper, start)
    np.testing.assert_array_equal(segs[-1].lower, end)
    np.testing.assert_array_equal(segs[-1].upper, end)
    for c, s in zip(seg.path, segs[1:-1]):
        P = seg.polygons[c]
        np.testing.assert_allclose(s.lower[:2], P.min(axis=0), atol=1e-15)
        np.testing.assert_allclose(s.upper[:2], P.max(axis=0), atol=1e-15)
        np.testing.assert_array_equal([s.lower[2], s.upper[2]], seg.psi_range)
        np.testing.assert_array_equal(s.polygon, P)


def independent_turns(shape: str, polygons, path) -> int:
    """Squares: the centre-to-centre direction changes. Triangles: a strip of triangles is
    crossed through edges of two alternating orientations; a turn is an edge orientation that
    differs from the one two crossings back."""
    if shape == "square":
        c = np.array([polygons[p].mean(axis=0) for p in path])
        d = np.sign(np.round(np.diff(c, axis=0) / 1e-9))
        return int(sum(np.any(d[i] != d[i - 1]) for i in range(1, len(d))))
    ori = []
    for a, b in itertools.pairwise(path):
        A, B = np.asarray(polygons[a]), np.asarray(polygons[b])
        shared = [p for p in A if np.min(np.linalg.norm(B - p, axis=1)) < 1e-9]
        assert len(shared) == 2, (A, B)
        (x0, y0), (x1, y1) = shared
        ori.append(round(math.degrees(math.atan2(y1 - y0, x1 - x0))) % 180)
    return sum(1 for i in range(2, len(ori)) if ori[i] != ori[i - 2])


# ---------------------------------------------------------------------------------------
# hand-made layouts
# ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("shape", ["square", "triangle"])
def test_hand_made_layout_corridor_is_free_connected_and_table_i_shaped(shape):
    lay = base_layout(obstacles=[{"type": "rectangle", "lower": [-0.03, -0.06], "upper": [-0.01, 0.03]},
                                 {"type": "circle", "center": [0.04, 0.0], "radius": 0.012},
                                 {"type": "polygon", "points": [[0.015, -0.06], [0.045, -0.06], [0.03, -0.035]]}],
                      clearance=0.003, cell={"shape": shape, "size": 0.008},
                      start=[-0.06, -0.04, 0.0], end=[0.065, -0.03, 0.0])
    seg = segment(lay, ROBOT)
    check_corridor(seg, lay)
    # the path must go round the wall's top (y above 0.03 + clearance)
    assert max(seg.polygons[c][:, 1].max() for c in seg.path) > 0.033
    assert seg.turns == independent_turns(shape, seg.polygons, seg.path) == count_turns(seg)
    d = seg.to_dict()
    json.dumps(d)
    assert d["cell"] == {"shape": shape, "size": 0.008}
    assert d["path"] == seg.path and len(d["cells"]) == len(seg.state)
    assert {c["state"] for c in d["cells"]} <= {"free", "blocked", "unreachable"}
    assert all(d["cells"][c]["state"] == "free" for c in d["path"])
    # the segments are a valid explicit corridor (polygons kept) and round-trip
    again = parse_request({"segments": d["segments"]}).segments
    assert len(again) == len(seg.segments)
    assert again[1].polygon is not None and again[0].polygon is None
    np.testing.assert_allclose(again[1].polygon, seg.segments[1].polygon)


def test_to_result_is_the_schema_model_of_to_dict():
    """One definition: the result model validates the dict the API sends and dumps to it again."""
    lay = wall_layout(-0.002, 0.022, shape="triangle", size=0.01)
    lay["obstacles"].append({"type": "circle", "center": [-0.035, -0.02], "radius": 0.008})
    seg = segment(lay, ROBOT)
    res = seg.to_result()
    assert isinstance(res, SegmentationResult)
    assert res.model_dump(mode="json") == seg.to_dict()
    assert res.path == seg.path and res.counts == seg.counts and res.turns == seg.turns
    np.testing.assert_array_equal(res.cells[seg.path[0]].polygon, np.round(seg.polygons[seg.path[0]], 12))
    assert len(res.grown_obstacles) == len(lay["obstacles"])


@pytest.mark.parametrize("shape", ["square", "triangle"])
def test_blocked_cells_really_overlap_an_obstacle(shape):
    lay = base_layout(obstacles=[{"type": "circle", "center": [0.0, 0.0], "radius": 0.02},
                                 {"type": "rectangle", "lower": [0.03, -0.05], "upper": [0.05, -0.01]}],
                      clearance=0.004, cell={"shape": shape, "size": 0.01})
    seg = segment(lay, ROBOT)
    obstacles = exact_obstacles(lay)
    lo, hi = np.array(lay["bounds"]["lower"]), np.array(lay["bounds"]["upper"])
    for c in range(len(seg.state)):
        poly = shapely.Polygon(seg.polygons[c])
        inside = np.all(seg.polygons[c] >= lo - 1e-12) and np.all(seg.polygons[c] <= hi + 1e-12)
        dist = min(shapely.distance(poly, ob) for ob in obstacles)
        if seg.state[c] == 1:  # blocked: outside the bounds, or closer than the clearance (+0.13 % margin)
            assert (not inside) or dist < 0.004 * 1.0013, (c, dist)
        else:
            assert inside and dist >= 0.004 - 1e-12, (c, dist)


def test_empty_square_grid_path_is_shortest_with_one_turn():
    lay = base_layout(start=[-0.075, -0.055, 0.0], end=[-0.025, -0.025, 0.0])  # cells (0,0) -> (5,3)
    seg = segment(lay, ROBOT)
    assert len(seg.path) == 5 + 3 + 1  # Manhattan distance + 1 cells
    assert seg.turns == 1
    check_corridor(seg, lay)


def test_straight_triangle_row_has_no_turn():
    size = 0.01
    y = -0.06 + 3.5 * size * H3  # the middle of row 3
    lay = base_layout(cell={"shape": "triangle", "size": size}, start=[-0.05, y, 0.0], end=[0.05, y, 0.0])
    seg = segment(lay, ROBOT)
    check_corridor(seg, lay)
    assert seg.turns == 0
    ys = {round(float(seg.polygons[c][:, 1].min()), 9) for c in seg.path}
    assert len(ys) == 1  # one row of triangles


def test_turn_minimisation_picks_the_l_over_the_staircase():
    """Start (0,0) to end (4,4) in an empty 16 x 12 grid: 9 cells either way; the chosen one has 1 turn."""
    lay = base_layout(start=[-0.075, -0.055, 0.0], end=[-0.035, -0.015, 0.0])
    seg = segment(lay, ROBOT)
    assert len(seg.path) == 9 and seg.turns == 1
    assert independent_turns("square", seg.polygons, seg.path) == 1


@pytest.mark.parametrize("shape", ["square", "triangle"])
def test_narrow_gap_one_cell_wide_is_used(shape):
    # gap 0.0 .. 0.02 (+ clearance 0.002 each side): free y in [0.0, 0.02]; cells of 0.01
    lay = wall_layout(-0.002, 0.022, shape=shape, size=0.01 if shape == "square" else 0.008)
    seg = segment(lay, ROBOT)
    check_corridor(seg, lay)
    through = [c for c in seg.path if seg.polygons[c][:, 0].min() < 0.0 < seg.polygons[c][:, 0].max()
               or abs(seg.polygons[c][:, 0].mean()) < 0.012]
    assert through, "the corridor must cross the wall"
    for c in through:
        assert seg.polygons[c][:, 1].min() >= -1e-12 and seg.polygons[c][:, 1].max() <= 0.02 + 1e-12


def test_gap_exactly_one_cell_wide_square():
    # free gap y in [0.0, 0.01] after clearance: exactly one row of cells fits
    lay = wall_layout(-0.002, 0.012, size=0.01)
    seg = segment(lay, ROBOT)
    check_corridor(seg, lay)
    crossing = [c for c in seg.path if abs(seg.polygons[c][:, 0].mean()) < 0.02]
    assert crossing and all(abs(seg.polygons[c][:, 1].min()) < 1e-12 for c in crossing)


def test_gap_narrower_than_a_cell_is_no_path():
    lay = wall_layout(-0.002, 0.011, size=0.01)  # free gap 0.009 m < one 0.01 m cell
    with pytest.raises(PlannerError) as e:
        segment(lay, ROBOT)
    assert e.value.code == "no_path" and e.value.field == "layout"
    assert "no chain of free" in e.value.message
    # smaller cells get through the same gap
    lay["cell"]["size"] = 0.0045
    seg = segment(lay, ROBOT)
    check_corridor(seg, lay)


def test_psi_range_goes_into_every_cell_segment_and_default_is_start_end_span():
    lay = base_layout(start=[-0.06, -0.04, 0.02], end=[0.06, -0.04, -0.03])
    seg = segment(lay, ROBOT)
    np.testing.assert_allclose(seg.psi_range, [-0.03, 0.02])
    for s in seg.segments[1:-1]:
        assert s.lower[2] == -0.03 and s.upper[2] == 0.02
    lay["psi_range"] = [-0.05, 0.05]
    seg = segment(lay, ROBOT)
    for s in seg.segments[1:-1]:
        assert s.lower[2] == -0.05 and s.upper[2] == 0.05
    assert seg.segments[0].lower[2] == 0.02 and seg.segments[-1].lower[2] == -0.03


def test_unreachable_cells_are_really_unreachable_and_free_cells_reachable():
    """Bounds reaching past the robot's stroke: check every cell with the robot's own leg lengths."""
    lay = base_layout(bounds={"lower": [-0.2, -0.2], "upper": [0.2, 0.2]}, cell={"shape": "square", "size": 0.02},
                      start=[-0.05, -0.05, 0.0], end=[0.05, 0.05, 0.0], psi_range=[-0.1, 0.1])
    seg = segment(lay, ROBOT)
    assert seg.counts["unreachable"] > 0 and seg.counts["free"] > 0
    psis = np.linspace(-0.1, 0.1, 5)
    t = np.linspace(0.0, 1.0, 5)
    for c in range(len(seg.state)):
        lo, hi = seg.polygons[c].min(axis=0), seg.polygons[c].max(axis=0)
        X, Y, PSI = np.meshgrid(lo[0] + (hi[0] - lo[0]) * t, lo[1] + (hi[1] - lo[1]) * t, psis)
        poses = np.column_stack((X.ravel(), Y.ravel(), PSI.ravel()))
        L = leg_lengths(ROBOT, poses)
        ok = np.all((L >= ROBOT.length_min - 1e-12) & (L <= ROBOT.length_max + 1e-12))
        ok = ok and singularity_measure(ROBOT, poses).min() >= SINGULAR_TOL
        if seg.state[c] == 0:
            assert ok, c
        elif seg.state[c] == 2:
            # the test is exact over the box (nearest point, farthest corner): a 5 x 5 x 5 sample
            # may miss the violating point, so check the exact extremes of each leg
            viol = False
            for psi in np.linspace(-0.1, 0.1, 5):
                cs, sn = math.cos(psi), math.sin(psi)
                P = ROBOT.base - ROBOT.r0 @ np.array([[cs, sn], [-sn, cs]])
                near = np.linalg.norm(np.clip(P, lo, hi) - P, axis=1)
                far = np.linalg.norm(np.maximum(np.abs(P - lo), np.abs(P - hi)), axis=1)
                viol |= bool(np.any(near < ROBOT.length_min) or np.any(far > ROBOT.length_max))
            assert viol or not ok, c
    check_corridor(seg, lay)


def test_grid_singularity_measure_matches_the_robot_svd():
    rng = np.random.default_rng(1)
    P = rng.uniform(-0.15, 0.15, (500, 2))
    for robot in (ROBOT, load_robot("tri-slide")):
        for psi in (0.0, 0.3, -1.0):
            a = singularity_measure_grid(robot, P, psi)
            b = singularity_measure(robot, np.column_stack((P, np.full(len(P), psi))))
            np.testing.assert_allclose(a, b, atol=1e-9)


def test_psi_samples_include_the_planner_five_and_a_point_range_is_one_sample():
    assert psi_samples([0.2, 0.2]).tolist() == [0.2]
    s = psi_samples([-0.5, 0.5])
    assert np.all(np.isin(np.round(np.linspace(-0.5, 0.5, 5), 12), np.round(s, 12)))
    assert np.max(np.diff(s)) <= 0.05 + 1e-12


def test_default_cell_size_rule():
    lay = parse_layout(base_layout(start=[-0.08, 0.0, 0.0], end=[0.06, 0.04, 0.0],
                                   bounds={"lower": [-0.1, -0.06], "upper": [0.1, 0.08]}))
    # Table I: Ts 0.01 s, N 20 -> 0.1 m/s x 20 x 0.01 s = 0.02 m, the paper's cell
    assert default_cell_size(lay, Settings(Ts=0.01, N=20)) == pytest.approx(0.02)
    # denser for a shorter sample period
    assert default_cell_size(lay, Settings(Ts=0.005, N=20)) == pytest.approx(0.01)
    # clamped: the straight start-end line spans 4 .. 50 cells
    d = math.hypot(0.14, 0.04)
    assert default_cell_size(lay, Settings(Ts=0.1, N=100)) == pytest.approx(d / 4)
    assert default_cell_size(lay, Settings(Ts=0.0001, N=5)) == pytest.approx(d / 50)
    # and a layout without a cell size uses it
    raw = base_layout(cell={"shape": "square", "size": None}, start=[-0.06, -0.04, 0.0], end=[0.06, 0.04, 0.0])
    seg = segment(raw, ROBOT, Settings(Ts=0.01, N=20))
    assert seg.size == pytest.approx(0.02)


def test_default_cell_size_respects_the_cell_cap():
    raw = base_layout(bounds={"lower": [-10.0, -10.0], "upper": [10.0, 10.0]}, cell={"shape": "triangle"},
                      start=[-0.001, 0.0, 0.0], end=[0.001, 0.0, 0.0])
    lay = parse_layout(raw)
    s = default_cell_size(lay, Settings(Ts=0.001, N=5))
    n = math.ceil(2 * 20.0 / s) * math.ceil(20.0 / (s * H3))
    assert n <= MAX_CELLS


def test_halfplanes_describe_the_triangle():
    lay = base_layout(cell={"shape": "triangle", "size": 0.01})
    seg = segment(lay, ROBOT)
    d = seg.to_dict()
    for s, hp in zip(d["segments"][1:-1], d["halfplanes"][1:-1]):
        A, b = np.array(hp["A"]), np.array(hp["b"])
        P = np.array(s["polygon"])
        assert A.shape == (3, 2)
        np.testing.assert_allclose(np.linalg.norm(A, axis=1), 1.0)
        assert np.all(A @ P.T <= b[:, None] + 1e-12)  # vertices on or inside
        assert np.all(A @ P.mean(axis=0) < b - 1e-4)  # centroid strictly inside
        # the box centre, where the soft criterion pulls, lies inside the triangle
        assert np.all(A @ (0.5 * (np.array(s["lower"][:2]) + np.array(s["upper"][:2]))) <= b + 1e-12)
    assert d["halfplanes"][0] is None and d["halfplanes"][-1] is None
    A, b = halfplanes([[0, 0], [0, 1], [1, 0]])  # clockwise input is handled
    assert np.all(A @ np.array([0.2, 0.2]) < b)


def test_reachable_region_is_reachable():
    bounds = {"lower": [-0.2, -0.2], "upper": [0.2, 0.2]}
    region = reachable_region(ROBOT, bounds, (-0.1, 0.1), 0.01)
    assert region
    geom = shapely.union_all([shapely.Polygon(p["exterior"], p["holes"]) for p in region])
    assert 0.0 < geom.area < 0.16
    assert geom.contains(shapely.Point(0.0, 0.0))
    assert not geom.contains(shapely.Point(0.19, 0.19))
    pts = shapely.get_coordinates(shapely.sample_points(geom, 300, seed=1)) if hasattr(shapely, "sample_points") \
        else None
    if pts is None:
        rng = np.random.default_rng(0)
        cand = rng.uniform(-0.2, 0.2, (3000, 2))
        pts = cand[shapely.contains_xy(geom, cand[:, 0], cand[:, 1])]
    for psi in (-0.1, 0.0, 0.1):
        L = leg_lengths(ROBOT, np.column_stack((pts, np.full(len(pts), psi))))
        assert np.all(L >= ROBOT.length_min - 1e-12) and np.all(L <= ROBOT.length_max + 1e-12)


# ---------------------------------------------------------------------------------------
# random layouts (hypothesis)
# ---------------------------------------------------------------------------------------

def reference_grid(lay: dict):
    """Independent cells (square or equilateral triangle) with states computed per cell by
    exact shapely distances (clearance 0 layouts) -> (polygons, free, adjacency)."""
    lo, hi = np.array(lay["bounds"]["lower"]), np.array(lay["bounds"]["upper"])
    s, shape = lay["cell"]["size"], lay["cell"]["shape"]
    cells = []
    if shape == "square":
        for j in range(math.ceil((hi[1] - lo[1]) / s - 1e-9)):
            for i in range(math.ceil((hi[0] - lo[0]) / s - 1e-9)):
                x, y = lo[0] + i * s, lo[1] + j * s
                cells.append([(x, y), (x + s, y), (x + s, y + s), (x, y + s)])
    else:
        h = s * H3
        for b in range(math.ceil((hi[1] - lo[1]) / h - 1e-9)):
            y0, y1 = lo[1] + b * h, lo[1] + (b + 1) * h
            for m in range(-1, math.ceil(2 * (hi[0] - lo[0]) / s - 1e-9)):
                x = lo[0] + m * s / 2
                if (m - b) % 2 == 0:
                    cells.append([(x, y0), (x + s, y0), (x + s / 2, y1)])
                else:
                    cells.append([(x, y1), (x + s / 2, y0), (x + s, y1)])
    obstacles = exact_obstacles(lay)
    free = []
    for c in cells:
        P = np.array(c)
        inside = np.all(P >= lo - 1e-12) and np.all(P <= hi + 1e-12)
        poly = shapely.Polygon(c)
        free.append(bool(inside and all(shapely.intersection(poly, ob).area <= 1e-9 * s * s for ob in obstacles)))

    def key(p):
        return (round(p[0] / (s / 4)), round(p[1] / (s * H3 / 2 if shape == "triangle" else s / 4)))

    edges = {}
    for k, c in enumerate(cells):
        for a, b in zip(c, c[1:] + c[:1]):
            edges.setdefault(frozenset((key(a), key(b))), []).append(k)
    adj = {k: [] for k in range(len(cells))}
    for ks in edges.values():
        if len(ks) == 2:
            adj[ks[0]].append(ks[1])
            adj[ks[1]].append(ks[0])
    return cells, free, adj


def reference_shortest(lay: dict, with_turns: bool = False):
    """Fewest cells from a free cell holding the start to one holding the end, or None; with
    ``with_turns`` also the fewest turns over all shortest paths (brute force; None when
    the path is longer than 16 cells or there are more than 2000 shortest paths)."""
    cells, free, adj = reference_grid(lay)

    def holding(p):
        pt = shapely.Point(p[:2])
        return [k for k, c in enumerate(cells) if free[k] and shapely.Polygon(c).distance(pt) < 1e-12]

    src, dst = holding(lay["start"]), set(holding(lay["end"]))
    if not src or not dst:
        return "endpoint"

    def bfs(seeds):
        dist = {k: 1 for k in seeds}
        q = deque(seeds)
        while q:
            u = q.popleft()
            for v in adj[u]:
                if free[v] and v not in dist:
                    dist[v] = dist[u] + 1
                    q.append(v)
        return dist

    ds = bfs(src)
    reach = [ds[k] for k in dst if k in ds]
    if not reach:
        return None
    n = min(reach)
    if not with_turns or n > 16:
        return n if not with_turns else (n, None)
    dt = bfs(list(dst))
    polys = [np.array(c) for c in cells]
    best, count = [None], [0]

    def walk(path):
        if count[0] > 2000:
            return
        u = path[-1]
        if len(path) == n:
            if u in dst:
                count[0] += 1
                t = independent_turns(lay["cell"]["shape"], polys, path)
                best[0] = t if best[0] is None else min(best[0], t)
            return
        for v in adj[u]:
            if free[v] and ds.get(v) == len(path) + 1 and dt.get(v) == n - len(path):
                walk(path + [v])

    for s0 in src:
        if dt.get(s0) == n:
            walk([s0])
    return n, (best[0] if count[0] <= 2000 else None)


coord = st.integers(-14, 14).map(lambda k: k * 0.004)  # on a 4 mm lattice: touching cases happen


@st.composite
def random_layout(draw, shape):
    obstacles = []
    for _ in range(draw(st.integers(0, 7))):
        x0, y0 = draw(coord), draw(coord)
        w, h = draw(st.integers(1, 6)) * 0.004, draw(st.integers(1, 6)) * 0.004
        if draw(st.booleans()):
            obstacles.append({"type": "rectangle", "lower": [x0, y0], "upper": [x0 + w, y0 + h]})
        else:
            obstacles.append({"type": "polygon", "points": [[x0, y0], [x0 + w, y0], [x0, y0 + h]]})
    if draw(st.booleans()):  # a wall across the workspace with a gap of 0 .. 5 lattice steps (maybe closed)
        y, xg, wg = draw(coord), draw(coord), draw(st.integers(0, 5)) * 0.004
        if xg > -0.06:
            obstacles.append({"type": "rectangle", "lower": [-0.06, y], "upper": [xg, y + 0.008]})
        if xg + wg < 0.06 - 1e-9:
            obstacles.append({"type": "rectangle", "lower": [xg + wg, y], "upper": [0.06, y + 0.008]})
    start = [draw(coord), draw(coord), 0.0]
    end = [draw(coord), draw(coord), 0.0]
    size = draw(st.sampled_from([0.008, 0.01, 0.012]))
    return {"bounds": {"lower": [-0.06, -0.06], "upper": [0.06, 0.06]}, "obstacles": obstacles, "clearance": 0.0,
            "cell": {"shape": shape, "size": size}, "start": start, "end": end}


def _endpoint_clear(lay):
    obs = exact_obstacles(lay)
    return all(not shapely.intersects(ob, shapely.Point(p[:2])) for ob in obs for p in (lay["start"], lay["end"]))


@pytest.mark.parametrize("shape", ["square", "triangle"])
@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(data=st.data())
def test_random_layouts_corridor_free_connected_and_shortest(shape, data):
    lay = data.draw(random_layout(shape))
    assume(_endpoint_clear(lay))
    ref = reference_shortest(lay, with_turns=True)
    ref, ref_turns = ref if isinstance(ref, tuple) else (ref, None)
    try:
        seg = segment(lay, ROBOT)
    except PlannerError as e:
        assert e.code == "no_path", e
        assert ref is None or ref == "endpoint", (ref, e)
        if ref == "endpoint":
            assert e.field in ("layout.start", "layout.end")
        return
    check_corridor(seg, lay)
    assert seg.counts["unreachable"] == 0  # the layout is well inside the robot's reach
    assert len(seg.path) == ref  # fewest cells
    assert seg.turns == independent_turns(shape, seg.polygons, seg.path)
    if ref_turns is not None:
        assert seg.turns == ref_turns  # fewest turns among the shortest paths (brute force)


@st.composite
def random_mixed_layout(draw):
    obstacles = []
    for _ in range(draw(st.integers(0, 10))):
        c = [draw(st.floats(-0.06, 0.06)), draw(st.floats(-0.06, 0.06))]
        r = draw(st.floats(0.002, 0.02))
        kind = draw(st.sampled_from(["rectangle", "circle", "polygon"]))
        if kind == "rectangle":
            obstacles.append({"type": "rectangle", "lower": [c[0] - r, c[1] - r / 2], "upper": [c[0] + r, c[1] + r]})
        elif kind == "circle":
            obstacles.append({"type": "circle", "center": c, "radius": r})
        else:
            a = np.sort(np.array([draw(st.floats(0, 2 * math.pi)) for _ in range(5)]))
            assume(np.min(np.diff(np.concatenate((a, [a[0] + 2 * math.pi])))) > 0.2)
            obstacles.append({"type": "polygon", "points": (np.array(c) + r * np.column_stack((np.cos(a), np.sin(a))))
                              .tolist()})
    return {"bounds": {"lower": [-0.07, -0.07], "upper": [0.07, 0.07]}, "obstacles": obstacles,
            "clearance": draw(st.sampled_from([0.0, 0.001, 0.004])),
            "cell": {"shape": draw(st.sampled_from(["square", "triangle"])),
                     "size": draw(st.sampled_from([0.005, 0.009]))},
            "start": [draw(st.floats(-0.06, 0.06)), draw(st.floats(-0.06, 0.06)), 0.0],
            "end": [draw(st.floats(-0.06, 0.06)), draw(st.floats(-0.06, 0.06)), 0.0],
            "psi_range": draw(st.sampled_from([None, [-0.05, 0.05]]))}


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(lay=random_mixed_layout())
def test_random_mixed_layouts_with_clearance(lay):
    obs = exact_obstacles(lay)
    c = lay["clearance"]
    # keep start and end clear of the obstacles' clearance zones (those are input errors, tested below)
    assume(all(shapely.distance(ob, shapely.Point(p[:2])) > c + 1e-6 for ob in obs for p in (lay["start"], lay["end"])))
    try:
        seg = segment(lay, ROBOT)
    except PlannerError as e:
        assert e.code == "no_path", e
        return
    check_corridor(seg, lay)


# ---------------------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------------------

def _err(lay, code, field, *words):
    with pytest.raises(PlannerError) as e:
        segment(lay, ROBOT)
    assert e.value.code == code, e.value
    assert e.value.field == field, e.value
    for w in words:
        assert w in e.value.message, e.value.message
    return e.value


def test_error_start_or_end_inside_an_obstacle_or_its_clearance():
    lay = base_layout(obstacles=[{"type": "circle", "center": [-0.06, -0.04], "radius": 0.005}])
    _err(lay, "invalid_input", "layout.start", "inside obstacle 0")
    lay = base_layout(obstacles=[{"type": "rectangle", "lower": [0.0, 0.0], "upper": [0.01, 0.01]},
                                 {"type": "rectangle", "lower": [0.062, -0.05], "upper": [0.07, -0.03]}],
                      clearance=0.003)
    _err(lay, "invalid_input", "layout.end", "within the clearance", "obstacle 1")


def test_error_start_or_end_outside_the_bounds():
    _err(base_layout(start=[-0.09, 0.0, 0.0]), "invalid_input", "layout.start", "outside the bounds")
    _err(base_layout(end=[0.0, 0.07, 0.0]), "invalid_input", "layout.end", "outside the bounds")


def test_error_start_unreachable_by_the_robot():
    lay = base_layout(bounds={"lower": [-0.4, -0.4], "upper": [0.4, 0.4]}, start=[0.35, 0.35, 0.0],
                      cell={"shape": "square", "size": 0.02})
    e = _err(lay, "unreachable", "layout.start", "leg")
    assert "longer than its maximum" in e.message or "shorter than its minimum" in e.message


def test_error_start_cell_not_wholly_reachable():
    # the start is reachable but the big cell around it reaches out of the stroke
    size = 0.05
    found = None
    for cx in -0.2 + size * (np.arange(8) + 0.5):  # a cell centre that is reachable, a corner that is not
        for cy in -0.2 + size * (np.arange(8) + 0.5):
            corners = np.array([[cx + a * size / 2, cy + b * size / 2, 0.0] for a in (-1, 1) for b in (-1, 1)])
            L, Lc = leg_lengths(ROBOT, corners), leg_lengths(ROBOT, np.array([[cx, cy, 0.0]]))
            centre_ok = np.all((Lc >= ROBOT.length_min) & (Lc <= ROBOT.length_max))
            corners_ok = np.all((L >= ROBOT.length_min) & (L <= ROBOT.length_max))
            if centre_ok and not corners_ok and found is None:
                found = (cx, cy)
    assert found is not None
    lay = base_layout(bounds={"lower": [-0.2, -0.2], "upper": [0.2, 0.2]}, start=[found[0], found[1], 0.0],
                      end=[0.0, 0.0, 0.0], cell={"shape": "square", "size": size})
    check_pose(ROBOT, np.array(lay["start"]))  # reachable itself
    _err(lay, "unreachable", "layout.start", "not wholly reachable")


def test_error_start_cell_overlaps_an_obstacle():
    lay = base_layout(obstacles=[{"type": "rectangle", "lower": [-0.055, -0.05], "upper": [-0.05, -0.03]}],
                      start=[-0.057, -0.035, 0.0])  # in the cell x -0.06..-0.05, y -0.04..-0.03
    _err(lay, "no_path", "layout.start", "not wholly free", "obstacle 0")


def test_error_no_path_wall():
    lay = base_layout(obstacles=[{"type": "rectangle", "lower": [-0.005, -0.06], "upper": [0.005, 0.06]}])
    e = _err(lay, "no_path", "layout", "no chain of free", "blocked")
    # issue 20: no cell size passes a wall across the bounds, so none is advised; the wall is named
    assert "smaller cells" not in e.message and "give a path" not in e.message
    assert "obstacle 0 (layout.obstacles[0]) spans the bounds from y = -0.0600 m to 0.0600 m" in e.message
    assert "no cell size can pass it" in e.message


def test_error_too_many_cells():
    e = _err(base_layout(cell={"shape": "square", "size": 1e-4}), "too_large", "layout.cell.size", "limit")
    assert str(MAX_CELLS) in e.message
    _err(base_layout(cell={"shape": "triangle", "size": 2e-4}), "too_large", "layout.cell.size")


def test_error_bounds_near_the_float_range_are_refused_not_an_overflow():
    # found by the API fuzzing: (upper - lower) / size overflowed to infinity in cell_count.
    # A request's coordinates are bounded (|value| <= MAX_COORDINATE): such bounds are refused
    # up front, naming the coordinate and the bound
    lay = base_layout(bounds={"lower": [0.0, -8.98846567431158e307], "upper": [1.0, 0.0]},
                      cell={"shape": "square", "size": 0.5})
    _err(lay, "invalid_input", "layout.bounds.lower[1]", f"{MAX_COORDINATE:g}")
    lay["cell"] = {"shape": "triangle", "size": 0.5}
    _err(lay, "invalid_input", "layout.bounds.lower[1]", f"{MAX_COORDINATE:g}")
    # and the cell count itself saturates instead of overflowing: far more cells than any limit
    for shape in ("square", "triangle"):
        n, cols, rows = cell_count(np.array([0.0, -8.98846567431158e307]), np.array([1.0, 0.0]), shape, 0.5)
        assert n > MAX_CELLS and rows > MAX_CELLS and cols >= 1


def _plate(holes: int, hole_vertices: int) -> dict:
    """A square plate (0.04 m, in the workspace's upper half) with ``holes`` small regular
    polygons of ``hole_vertices`` vertices in a row, each inside it and apart."""
    r = 0.015 / max(holes, 1)
    holes_xy = [[[-0.015 + (2 * k + 1) * r + 0.5 * r * math.cos(t), 0.03 + 0.5 * r * math.sin(t)]
                 for t in np.linspace(0.0, 2 * math.pi, hole_vertices, endpoint=False)] for k in range(holes)]
    return {"type": "polygon", "points": [[-0.02, 0.01], [0.02, 0.01], [0.02, 0.05], [-0.02, 0.05]],
            "holes": holes_xy}


def test_error_polygon_holes_are_bounded():
    # within the bounds: a plate with holes is an obstacle like any other
    lay = base_layout(obstacles=[_plate(MAX_HOLES, 3)])
    assert segment(lay, ROBOT).segments
    # more holes than MAX_HOLES, or more vertices in the outline and holes than a polygon may have
    _err(base_layout(obstacles=[_plate(MAX_HOLES + 1, 3)]), "too_large", "layout.obstacles[0].holes")
    per_hole = MAX_POLYGON_POINTS // 4
    e = _err(base_layout(obstacles=[_plate(4, per_hole)]), "too_large", "layout.obstacles[0].holes")
    assert str(MAX_POLYGON_POINTS) in e.message and str(4 + 4 * per_hole) in e.message


def test_error_cell_larger_than_the_bounds():
    _err(base_layout(cell={"shape": "square", "size": 0.2}), "invalid_input", "layout.cell.size", "does not fit")


@pytest.mark.parametrize("obstacle, field, words", [
    ({"type": "polygon", "points": [[0, 0], [0.01, 0.01], [0.02, 0.02]]}, "layout.obstacles[0].points", ["degenerate"]),
    ({"type": "polygon", "points": [[0, 0], [0.01, 0.01], [0.01, 0], [0, 0.01]]}, "layout.obstacles[0].points",
     ["degenerate", "Self-intersection"]),
    ({"type": "polygon", "points": [[0, 0], [0.01, 0.01]]}, "layout.obstacles[0].points", ["at least 3"]),
    ({"type": "rectangle", "lower": [0, 0], "upper": [0.01, 0]}, "layout.obstacles[0].upper", ["degenerate"]),
    ({"type": "circle", "center": [0, 0], "radius": 0.0}, "layout.obstacles[0].radius", ["> 0"]),
    ({"type": "circle", "center": [0, 0], "radius": -1.0}, "layout.obstacles[0].radius", ["> 0"]),
    ({"type": "hexagon"}, "layout.obstacles[0].type", ["must be"]),
    ({"type": "circle", "center": [0, 0], "radius": 0.01, "points": [[0, 0]]}, "layout.obstacles[0].points",
     ["not a field"]),
])
def test_error_degenerate_obstacles(obstacle, field, words):
    _err(base_layout(obstacles=[obstacle]), "invalid_input", field, *words)


@pytest.mark.parametrize("mutate, field", [
    (lambda l: l["bounds"].__setitem__("lower", [float("nan"), 0.0]), "layout.bounds.lower[0]"),
    (lambda l: l.__setitem__("start", [0.0, float("inf"), 0.0]), "layout.start[1]"),
    (lambda l: l.__setitem__("end", [0.0, 0.0, float("-inf")]), "layout.end[2]"),
    (lambda l: l.__setitem__("clearance", float("nan")), "layout.clearance"),
    (lambda l: l["cell"].__setitem__("size", float("inf")), "layout.cell.size"),
    (lambda l: l.__setitem__("obstacles", [{"type": "circle", "center": [0.0, float("nan")], "radius": 0.01}]),
     "layout.obstacles[0].center[1]"),
    (lambda l: l.__setitem__("obstacles", [{"type": "polygon", "points": [[0, 0], [0.01, 0], [0.0, float("nan")]]}]),
     "layout.obstacles[0].points[2][1]"),
    (lambda l: l.__setitem__("psi_range", [float("nan"), 0.1]), "layout.psi_range[0]"),
])
def test_error_non_finite_numbers(mutate, field):
    lay = base_layout()
    mutate(lay)
    e = _err(lay, "invalid_input", field)
    assert "finite" in e.message


@pytest.mark.parametrize("lay, field, word", [
    (base_layout(bounds={"lower": [0.1, -0.06], "upper": [0.08, 0.06]}), "layout.bounds.upper", "greater"),
    (base_layout(clearance=-0.001), "layout.clearance", ">= 0"),
    (base_layout(cell={"shape": "hexagon", "size": 0.01}), "layout.cell.shape", "square"),
    (base_layout(cell={"shape": "square", "size": 0.0}), "layout.cell.size", ">= 1e-06"),
    (base_layout(psi_range=[0.1, -0.1]), "layout.psi_range", "min <= max"),
    (base_layout(psi_range=[0.05, 0.1]), "layout.psi_range", "start angle"),
    (base_layout(colour="red"), "layout.colour", "unknown"),
    ({k: v for k, v in base_layout().items() if k != "end"}, "layout.end", "required"),
])
def test_error_malformed_layout(lay, field, word):
    _err(lay, "invalid_input", field, word)


# ---------------------------------------------------------------------------------------
# requests and planning
# ---------------------------------------------------------------------------------------

def test_top_level_start_end_are_shorthands_for_the_layout():
    lay = {k: v for k, v in base_layout().items() if k not in ("start", "end")}
    req = parse_request({"layout": lay, "start": [-0.06, -0.04, 0.0], "end": [0.06, -0.04, 0.0],
                         "psi_range": [-0.01, 0.01]})
    assert req.layout.start.tolist() == [-0.06, -0.04, 0.0] and req.layout.psi_range.tolist() == [-0.01, 0.01]
    assert "start" not in lay  # the caller's dict is not modified
    # planner.schema.PlanRequest is also the HTTP body's model: the shorthand reaches the corridor
    model = PlanRequest.model_validate({"layout": lay, "start": [-0.06, -0.04, 0.0], "end": [0.06, -0.04, 0.0]})
    seg = segment_request(parse_request(model), robot=ROBOT)
    np.testing.assert_array_equal(seg.segments[0].lower, [-0.06, -0.04, 0.0])
    # the layout's own start wins over the shorthand
    req = parse_request({"layout": base_layout(), "start": [0.0, 0.0, 0.0]})
    assert req.layout.start.tolist() == [-0.06, -0.04, 0.0]


def test_segment_request_helper_returns_the_dict():
    d = planner.segment({"robot": "moving-slide", "layout": base_layout()}).to_dict()
    assert d["segments"][0]["lower"] == [-0.06, -0.04, 0.0] and d["path"]
    with pytest.raises(PlannerError) as e:
        planner.segment({"segments": [{"lower": [0, 0, 0], "upper": [0, 0, 0]}] * 2})
    assert e.value.field == "layout"


@pytest.mark.parametrize("shape", ["square", "triangle"])
def test_plan_a_layout_end_to_end_paper_mode(shape):
    lay = wall_layout(-0.002, 0.022, shape=shape, size=0.01)
    res = plan_json({"robot": "moving-slide", "layout": lay})
    pose = np.array(res["pose"])
    np.testing.assert_array_equal(pose[0], lay["start"])
    assert np.linalg.norm(pose[-1, :2] - np.array(lay["end"][:2])) <= 1e-4
    assert abs(pose[-1, 2] - lay["end"][2]) <= 1e-4
    assert np.all(np.isfinite(pose))
    assert len(res["corridor"]["segments"]) >= 3


@pytest.mark.parametrize("shape", ["square", "triangle"])
def test_constrained_mode_trajectory_avoids_every_obstacle(shape):
    """The hard corridor (planner.constraints) keeps every sampled pose inside free cells,
    hence at least the clearance from every obstacle."""
    lay = wall_layout(-0.002, 0.022, shape=shape, size=0.01)
    lay["obstacles"].append({"type": "circle", "center": [-0.035, -0.02], "radius": 0.008})
    res = plan_json({"robot": "moving-slide", "layout": lay, "settings": {"mode": "constrained"}})
    pose = np.array(res["pose"])
    pts = shapely.points(pose[:, :2])
    for ob in exact_obstacles(lay):
        assert shapely.distance(ob, pts).min() >= lay["clearance"] - 1e-7
    assert np.linalg.norm(pose[-1, :2] - np.array(lay["end"][:2])) <= 1e-4
