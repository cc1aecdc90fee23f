"""Placing an imported drawing where the robot reaches (numpy and shapely). The region and the
fit are the planner's (:mod:`planner.model.placement`, which the contour's ``origin: "fit"``
uses too); this module adds the start and end.

The reachable region of a robot at a platform angle psi is the set of tool points whose
legs are all within their stroke and whose pose is regular (:func:`planner.model.placement.reachable_points`).
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

import numpy as np
import shapely

from . import _geometry as geo
from ._planning import Placement, fit_shape, reachable_region

__all__ = ["Placement", "fit_drawing", "free_point", "reachable_region"]

Reach = Callable[[np.ndarray, np.ndarray, float], np.ndarray]
#: the drawing import places with the planner's one implementation (planner.model.placement)
fit_drawing = fit_shape


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
