"""Geometry for the browser editor (numpy and shapely only: no viser, no planner import):
what the editor draws, as arrays it can hand to the scene, clipped to the workspace bounds,
the snapping grid, and the screen <-> plane maps of a top-down camera.

Everything is in the workspace plane z = 0, SI units (m, rad, s). Kept apart from the
scene (:mod:`app.editor._scene`) so it can be tested without a browser or a server. The
robot's geometry (reach, leg lengths) comes from the planner through
:mod:`app.editor._planning`.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

# Colours (RGB 0-255) of the cell states and the drawing layers.
CELL_COLOURS = {"free": (222, 235, 247), "blocked": (90, 90, 90), "unreachable": (244, 204, 204)}
#: z of each layer [m] above the plane so that later layers draw on top
Z = {"cells": 0.0, "grid": 0.0005, "corridor": 0.001, "obstacles": 0.0015, "obstacle_edges": 0.0017,
     "reach": 0.002, "tube": 0.0022, "program": 0.0026,
     "trajectory": 0.003, "ticks": 0.0035, "preview": 0.0037, "robot": 0.004, "pivots": 0.0045,
     "handles": 0.006}


def polygon_mesh(polygons: list, z: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate convex polygons ``[[[x, y], ...], ...]`` [m] into one mesh:
    vertices (V, 3) [m] and faces (F, 3) (counter-clockwise seen from +z)."""
    verts, faces, base = [], [], 0
    for poly in polygons:
        p = np.asarray(poly, dtype=float)
        if len(p) >= 2 and np.allclose(p[0], p[-1]):
            p = p[:-1]
        n = len(p)
        if n < 3:
            continue
        area2 = np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
        if area2 < 0:  # clockwise: flip so the face normal points to the camera (+z)
            p = p[::-1]
        verts.append(np.column_stack((p, np.full(n, z))))
        faces.append(np.column_stack((np.zeros(n - 2, int), np.arange(1, n - 1), np.arange(2, n))) + base)
        base += n
    if not verts:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int32)
    return np.concatenate(verts), np.concatenate(faces).astype(np.int32)


def obstacle_shape(ob: dict) -> shapely.Polygon:
    """An obstacle of the layout (rectangle, polygon with its ``holes``, or circle) as a
    shapely polygon [m] (holes as interiors)."""
    holes = (ob.get("holes") or []) if ob.get("type") == "polygon" else []
    return shapely.Polygon(obstacle_polygon(ob), [[list(map(float, p)) for p in h] for h in holes])


def clip_shapes(shapes: list, lower, upper) -> list[shapely.Polygon]:
    """Shapely polygons (holes kept) cut to the rectangle [lower, upper] [m]: the parts
    inside, each a polygon (a cut may split one into several); invalid drawings are
    repaired with ``make_valid`` first (a self-touching outline)."""
    box = shapely.box(float(lower[0]), float(lower[1]), float(upper[0]), float(upper[1]))
    out: list[shapely.Polygon] = []
    for shape in shapes:
        if not shape.is_valid:
            shape = shapely.make_valid(shape)
        part = shape.intersection(box)
        geoms = getattr(part, "geoms", [part])
        out.extend(g for g in geoms if isinstance(g, shapely.Polygon) and not g.is_empty and g.area > 0)
    return out


def shape_mesh(shapes: list, z: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate shapely polygons with holes exactly (shapely's constrained Delaunay
    triangulation: the triangles tile the polygon, none lies in a hole, whatever the outline's
    concavity) into one mesh: vertices (V, 3) [m], faces (F, 3) counter-clockwise from +z."""
    tris = []
    for shape in shapes:
        cdt = shapely.constrained_delaunay_triangles(shape)
        tris.extend(np.asarray(t.exterior.coords)[:3] for t in getattr(cdt, "geoms", []) if t.area > 0)
    if not tris:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int32)
    t = np.asarray(tris, float)  # (F, 3, 2)
    a, b = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    area2 = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    t[area2 < 0] = t[area2 < 0][:, ::-1]  # clockwise: flip so the normal points to the camera (+z)
    verts = np.concatenate((t.reshape(-1, 2), np.full((3 * len(t), 1), z)), axis=1)
    return verts, np.arange(3 * len(t), dtype=np.int32).reshape(-1, 3)


def shape_edges(shapes: list, z: float = 0.0) -> np.ndarray:
    """Outlines and hole outlines of shapely polygons as line segments (M, 2, 3) [m]."""
    rings = [np.asarray(r.coords)[:-1, :2] for s in shapes for r in (s.exterior, *s.interiors)]
    return polygon_edges(rings, z)


def polygon_edges(polygons: list, z: float = 0.0) -> np.ndarray:
    """Closed outlines of polygons as line segments (M, 2, 3) [m]."""
    segs = []
    for poly in polygons:
        p = np.asarray(poly, dtype=float)
        if len(p) < 2:
            continue
        q = np.roll(p, -1, axis=0)
        segs.append(np.stack((np.column_stack((p, np.full(len(p), z))),
                              np.column_stack((q, np.full(len(q), z)))), axis=1))
    return np.concatenate(segs) if segs else np.zeros((0, 2, 3))


def rectangle(lower, upper) -> list[list[float]]:
    """Corners of an axis-aligned rectangle, counter-clockwise [m]."""
    (x0, y0), (x1, y1) = lower, upper
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]


def circle(center, radius, n: int = 32) -> list[list[float]]:
    """A circle of ``radius`` [m] about ``center`` [m] as a polygon of ``n`` corners [m]."""
    a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    return np.column_stack((center[0] + radius * np.cos(a), center[1] + radius * np.sin(a))).tolist()


def obstacle_polygon(ob: dict) -> list[list[float]]:
    """An obstacle of the layout (rectangle, polygon or circle) as a polygon [m]."""
    if ob.get("type") == "rectangle":
        return rectangle(ob["lower"], ob["upper"])
    if ob.get("type") == "circle":
        return circle(ob["center"], ob["radius"])
    return [list(map(float, p)) for p in ob.get("points", [])]


def point_in_convex(point, polygon) -> bool:
    """Whether ``point`` [m] lies in the convex ``polygon`` (either orientation, edges included)."""
    p = np.asarray(polygon, dtype=float)
    q = np.roll(p, -1, axis=0)
    cross = (q[:, 0] - p[:, 0]) * (point[1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (point[0] - p[:, 0])
    return bool(np.all(cross >= -1e-12) or np.all(cross <= 1e-12))


def shrink(polygon, factor: float) -> list[list[float]]:
    """Polygon scaled by ``factor`` about its vertex centroid."""
    p = np.asarray(polygon, dtype=float)
    c = p.mean(axis=0)
    return (c + factor * (p - c)).tolist()


def mask_boundary(xs: np.ndarray, ys: np.ndarray, mask: np.ndarray, z: float = 0.0) -> np.ndarray:
    """Boundary between True and False samples of a grid mask as line segments (M, 2, 3):
    a staircase through the midpoints between neighbouring samples (resolution = grid step)."""
    hx = np.diff(xs).mean() / 2 if len(xs) > 1 else 0.0
    hy = np.diff(ys).mean() / 2 if len(ys) > 1 else 0.0
    segs = []
    iy, ix = np.nonzero(mask[:, 1:] != mask[:, :-1])  # change between columns ix and ix+1
    if len(ix):
        x = 0.5 * (xs[ix] + xs[ix + 1])
        segs.append(np.stack((np.column_stack((x, ys[iy] - hy)), np.column_stack((x, ys[iy] + hy))), axis=1))
    iy, ix = np.nonzero(mask[1:, :] != mask[:-1, :])  # change between rows iy and iy+1
    if len(ix):
        y = 0.5 * (ys[iy] + ys[iy + 1])
        segs.append(np.stack((np.column_stack((xs[ix] - hx, y)), np.column_stack((xs[ix] + hx, y))), axis=1))
    if not segs:
        return np.zeros((0, 2, 3))
    s = np.concatenate(segs)
    return np.concatenate((s, np.full(s.shape[:2] + (1,), z)), axis=2)


def sample_at(time: np.ndarray, values: np.ndarray, t: float) -> np.ndarray:
    """Linear interpolation of per-sample ``values`` (K, d) at time ``t`` [s] (clamped)."""
    t = float(np.clip(t, time[0], time[-1]))
    return np.array([np.interp(t, time, values[:, j]) for j in range(values.shape[1])])


def time_ticks(time: np.ndarray, poses: np.ndarray, every: float = 0.1) -> np.ndarray:
    """Tool positions (M, 2) [m] at t = 0, every, 2 every, ... [s] along the trajectory."""
    ts = np.arange(0.0, time[-1] + 1e-9, every)
    return np.column_stack((np.interp(ts, time, poses[:, 0]), np.interp(ts, time, poses[:, 1])))


def view_extent(bounds_lower, bounds_upper, robot) -> tuple[np.ndarray, float]:
    """Centre (2,) [m] and half-size [m] of a square view that shows the workspace bounds
    and the robot's base pivots."""
    pts = np.vstack((np.asarray(bounds_lower, float), np.asarray(bounds_upper, float), robot.base))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    return 0.5 * (lo + hi), 0.5 * float(np.max(hi - lo)) * 1.04


def camera_height(half_size: float, fov_rad: float) -> float:
    """Height [m] of a camera looking straight down with vertical field of view ``fov_rad``
    that sees a square of half-size ``half_size`` [m] from edge to edge (vertically)."""
    return half_size / math.tan(fov_rad / 2)


def yaw_quaternion(psi: float) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation by ``psi`` [rad] about +z."""
    return np.array([math.cos(psi / 2), 0.0, 0.0, math.sin(psi / 2)])


def quat_to_matrix(wxyz) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = (float(v) for v in wxyz)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def screen_to_plane(screen_uv, cam_position, cam_wxyz, fov_rad: float, aspect: float):
    """Point [x, y] [m] on the plane z = 0 under a screen position ``(u, v)`` in 0..1
    (OpenCV image coordinates: (0, 0) upper left) of a camera in viser's convention
    (camera frame: +z forward, +x right, +y down), or None if the ray misses the plane."""
    t = math.tan(fov_rad / 2)
    d_cam = np.array([(2 * screen_uv[0] - 1) * t * aspect, (2 * screen_uv[1] - 1) * t, 1.0])
    d = quat_to_matrix(cam_wxyz) @ d_cam
    o = np.asarray(cam_position, dtype=float)
    if abs(d[2]) < 1e-12:
        return None
    s = -o[2] / d[2]
    if s <= 0:
        return None
    p = o + s * d
    return np.array([p[0], p[1]])


def plane_to_screen(point, cam_position, cam_wxyz, fov_rad: float, aspect: float):
    """Inverse of :func:`screen_to_plane`: screen (u, v) in 0..1 of the plane point [x, y, (z)] [m]."""
    p = np.zeros(3)
    p[:len(point)] = point
    R = quat_to_matrix(cam_wxyz)
    c = R.T @ (p - np.asarray(cam_position, dtype=float))
    t = math.tan(fov_rad / 2)
    return np.array([(c[0] / c[2] / (t * aspect) + 1) / 2, (c[1] / c[2] / t + 1) / 2])


# ---------------------------------------------------------------------------- snapping
def snap(value: float, step: float | None, origin: float = 0.0, *, resolution: float = 1e-4) -> float:
    """``value`` [m] on the grid ``origin + k * step`` (the nearest line); without a grid
    (``step`` None or <= 0), to ``resolution`` [m] (a dragged point keeps 0.1 mm, not the
    mouse's 17 digits). Rounded to 10 decimals so that -0.16 + 4 * 0.02 is -0.08."""
    if step is not None and step > 0:
        v = origin + round((value - origin) / step) * step
    else:
        v = round(value / resolution) * resolution
    v = round(v, 10)
    return 0.0 if v == 0 else v


def snap_point(point, step: float | None, origin=(0.0, 0.0)) -> list[float]:
    """A point (x, y) [m] snapped by :func:`snap` per coordinate."""
    return [snap(float(point[0]), step, float(origin[0])), snap(float(point[1]), step, float(origin[1]))]


# ---------------------------------------------------------------------------- clipping to the bounds
def clip_polygons(polygons: list, lower, upper) -> list:
    """Polygons [[x, y], ...] [m] cut to the rectangle [lower, upper]; those inside are
    returned as they are, those outside are dropped (convex in, convex out)."""
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    out, cut = [], []
    for poly in polygons:
        p = np.asarray(poly, float)
        if len(p) < 3:
            continue
        if np.all(p >= lo - 1e-12) and np.all(p <= hi + 1e-12):
            out.append(poly)
        elif np.all(p.max(axis=0) > lo) and np.all(p.min(axis=0) < hi):
            cut.append(p)
    if cut:
        box = shapely.box(lo[0], lo[1], hi[0], hi[1])
        for g in shapely.intersection(shapely.polygons(cut), box):
            if isinstance(g, shapely.Polygon) and not g.is_empty and g.area > 0:
                out.append(np.asarray(g.exterior.coords)[:-1].tolist())
    return out


def clip_segments(segments: np.ndarray, lower, upper) -> np.ndarray:
    """Line segments (M, 2, 3) [m] cut to the rectangle [lower, upper] in x, y
    (Liang-Barsky); segments outside are dropped."""
    segs = np.asarray(segments, float)
    if not len(segs):
        return segs.reshape(0, 2, 3)
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    a, d = segs[:, 0], segs[:, 1] - segs[:, 0]
    t0, t1 = np.zeros(len(segs)), np.ones(len(segs))
    keep = np.ones(len(segs), bool)
    for k in (0, 1):
        for p, q in ((-d[:, k], a[:, k] - lo[k]), (d[:, k], hi[k] - a[:, k])):
            parallel = np.abs(p) < 1e-15
            keep &= ~(parallel & (q < 0))
            with np.errstate(divide="ignore", invalid="ignore"):
                r = np.where(parallel, 0.0, q / np.where(parallel, 1.0, p))
            t0 = np.where(~parallel & (p < 0), np.maximum(t0, r), t0)
            t1 = np.where(~parallel & (p > 0), np.minimum(t1, r), t1)
    keep &= t0 <= t1
    out = np.stack((a + t0[:, None] * d, a + t1[:, None] * d), axis=1)[keep]
    return out[np.linalg.norm(out[:, 1, :2] - out[:, 0, :2], axis=1) > 1e-12]


def dashes(segments: np.ndarray, dash: float) -> np.ndarray:
    """Segments (M, 2, 2) [m] cut into dashes ``dash`` [m] long with gaps as long (a short
    segment keeps one dash), as (K, 2, 2): how a rapid move is drawn."""
    out = []
    for a, b in np.asarray(segments, float).reshape(-1, 2, 2):
        length = float(np.hypot(*(b - a)))
        n = max(1, math.floor(length / (2 * dash)))
        s0 = np.arange(n) * 2 * dash / max(length, 1e-300)
        s1 = np.minimum(s0 + dash / max(length, 1e-300), 1.0)
        s0, s1 = (np.zeros(1), np.ones(1)) if length <= 2 * dash else (s0, s1)
        out.append(np.stack((a + s0[:, None] * (b - a), a + s1[:, None] * (b - a)), axis=1))
    return np.concatenate(out) if out else np.zeros((0, 2, 2))


def polyline_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance [m] of a vertex of polyline ``a`` (n, 2) from polyline ``b`` (m, 2)
    and of a vertex of ``b`` from ``a`` (a symmetric Hausdorff distance on the vertices)."""
    def line(p: np.ndarray):
        return shapely.LineString(p) if len(p) > 1 and np.ptp(p, axis=0).any() else shapely.Point(p[0])
    la, lb = line(a), line(b)
    d_ab = shapely.distance(shapely.points(a), lb)
    d_ba = shapely.distance(shapely.points(b), la)
    return float(max(np.max(d_ab), np.max(d_ba)))
