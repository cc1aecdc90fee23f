"""Placing an imported drawing where the robot reaches (numpy and shapely; the robot's reach
comes from :mod:`._planning`).

The reachable region of a robot at a platform angle psi is the set of tool points whose
legs are all within their stroke and whose pose is regular (:func:`._planning.reachable_points`).
For the built-in robot at psi = 0 it spans x, y within about +-0.146 m (a pinwheel-shaped
region, not a square: :func:`reachable_region` gives its extent and centre). "Place drawing"
(:func:`fit_drawing`) centres the drawing on the region and scales it down, when it does not
fit, until the drawing grown by the margin lies wholly in the region (never up: a part keeps
its size when it fits); the region's extent becomes the layout's bounds (rounded out to whole
cells). :func:`free_point` keeps start and end where they are when their cell is free and
reachable, or moves them to the nearest such point next to the drawing.

Units: m, rad.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import shapely
from shapely import affinity

from . import _geometry as geo
from ._planning import Robot, reachable_mask

__all__ = ["Placement", "fit_drawing", "free_point", "reachable_region"]

REACH_SAMPLES = 241  #: grid samples per side when measuring the reachable region
_cache: dict[tuple, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
Reach = Callable[[np.ndarray, np.ndarray, float], np.ndarray]


def reachable_region(robot: Robot, psi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lower (2,), upper (2,) corners of the extent and the centroid (2,) [m] of the tool
    points reachable at angle ``psi`` [rad], sampled on a :data:`REACH_SAMPLES` grid over a
    square 1.1 times the base pivots' extent."""
    key = (id(robot), round(float(psi), 9))
    if key not in _cache:
        base = np.asarray(robot.base, float)
        c = base.mean(axis=0)
        span = 1.1 * float(np.max(np.abs(base - c)))
        xs, ys, mask = reachable_mask(robot, c - span, c + span, float(psi), n=REACH_SAMPLES)
        X, Y = np.meshgrid(xs, ys)
        if not mask.any():
            raise ValueError(f"the robot reaches no tool point at ψ {psi:g} rad")
        pts = np.column_stack((X[mask], Y[mask]))
        if len(_cache) > 16:
            _cache.clear()
        _cache[key] = (pts.min(axis=0), pts.max(axis=0), pts.mean(axis=0))
    return _cache[key]


@dataclass(frozen=True)
class Placement:
    """Where a drawing goes: ``factor`` (<= 1) times the user's scale, then ``offset`` [m]
    (x, y after scaling); ``shrunk`` whether the factor is below 1."""

    factor: float
    offset: tuple[float, float]
    shrunk: bool


def _outline_reachable(shape, reach: Reach, psi: float) -> bool:
    pts = np.asarray(shapely.get_coordinates(shapely.segmentize(shape.boundary, 0.002)))
    return bool(len(pts)) and bool(np.all(reach(pts[:, 0], pts[:, 1], psi)))


def fit_drawing(shapes: list, centre, margin: float, reach: Reach, psi: float) -> Placement:
    """Centre ``shapes`` (shapely polygons [m], the drawing at the user's scale) on ``centre``
    (x, y) [m] and find the largest factor <= 1 such that the scaled drawing grown by
    ``margin`` [m] lies in the reachable region (its outline sampled every 2 mm is reachable:
    the region has no holes). Raises ValueError when even a tiny drawing does not fit."""
    body = shapely.union_all(shapes)
    x0, y0, x1, y1 = body.bounds
    mid = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1)])
    c = np.asarray(centre, float)

    def fits(k: float) -> bool:
        placed = affinity.translate(affinity.scale(body, k, k, origin=(mid[0], mid[1])), *(c - mid))
        return _outline_reachable(placed.buffer(margin, quad_segs=4) if margin > 0 else placed, reach, psi)

    if fits(1.0):
        k = 1.0
    else:
        lo, hi = 0.0, 1.0
        if not fits(1e-3):
            raise ValueError(f"a margin of {margin:g} m around the drawing does not fit where the robot reaches")
        lo = 1e-3
        for _ in range(30):
            mid_k = math.sqrt(lo * hi)
            lo, hi = (mid_k, hi) if fits(mid_k) else (lo, mid_k)
            if hi / lo < 1.0005:
                break
        k = lo
    offset = c - k * mid
    return Placement(k, (float(offset[0]), float(offset[1])), k < 1.0)


def _cell_around(x: float, y: float, lower, cell: float, shape: str):
    """The cell holding (x, y) of a square grid of edge ``cell`` [m] from ``lower``, or for
    triangles a square of half-size ``cell`` about the point (which holds its triangle)."""
    if shape == "square":
        i, j = math.floor((x - lower[0]) / cell), math.floor((y - lower[1]) / cell)
        return shapely.box(lower[0] + i * cell, lower[1] + j * cell, lower[0] + (i + 1) * cell,
                           lower[1] + (j + 1) * cell)
    return shapely.box(x - cell, y - cell, x + cell, y + cell)


def free_point(pose, obstacles: list[dict], lower, upper, *, cell: float, shape: str, clearance: float,
               reach: Reach, target, taken=None, step: float = 0.0025) -> tuple[list[float], bool]:
    """``pose`` [x, y, psi] when it is valid, else the valid point nearest to ``target`` (x,
    y) [m] (at least a cell away from ``taken``), keeping psi. Valid: inside [lower, upper],
    its cell (``cell`` [m], ``shape``) wholly inside the bounds, clear of every obstacle by
    ``clearance`` [m] and reachable at its corners and centre. Returns the pose and whether it
    moved; raises ValueError when no point of the bounds is valid."""
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    blocked = (shapely.union_all([geo.obstacle_shape(ob) for ob in obstacles]).buffer(clearance)
               if obstacles else shapely.Polygon())
    bounds = shapely.box(lo[0] - 1e-9, lo[1] - 1e-9, hi[0] + 1e-9, hi[1] + 1e-9)
    psi = float(pose[2])

    def valid(x: float, y: float) -> bool:
        if taken is not None and math.hypot(x - taken[0], y - taken[1]) < cell:
            return False
        c = _cell_around(x, y, lo, cell, shape)
        if not bounds.contains(c) or c.intersects(blocked):
            return False
        pts = np.vstack((np.asarray(c.exterior.coords)[:4], [[x, y]]))
        return bool(np.all(reach(pts[:, 0], pts[:, 1], psi)))

    if lo[0] <= pose[0] <= hi[0] and lo[1] <= pose[1] <= hi[1] and valid(float(pose[0]), float(pose[1])):
        return [float(v) for v in pose], False
    gx = np.arange(lo[0] + 0.5 * step, hi[0], step)
    gy = np.arange(lo[1] + 0.5 * step, hi[1], step)
    X, Y = (a.ravel() for a in np.meshgrid(gx, gy))
    cand = ~shapely.intersects_xy(blocked.buffer(0.5 * cell), X, Y) if obstacles else np.ones(X.size, bool)
    order = np.flatnonzero(cand)[np.argsort(np.hypot(X[cand] - target[0], Y[cand] - target[1]))]
    for i in order[:4000]:
        if valid(float(X[i]), float(Y[i])):
            return [round(float(X[i]), 6) + 0.0, round(float(Y[i]), 6) + 0.0, psi], True
    raise ValueError("no free, reachable point in the bounds")
