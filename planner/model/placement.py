"""Placing a shape where the robot reaches: the one implementation behind the editor's
"place drawing" (a drawing, scaled down when it does not fit) and the contour's ``origin:
"fit"`` (a program, never scaled).

The reachable region at a platform angle psi is the set of tool points whose legs are all
within their stroke and whose pose is regular (:func:`reachable_points`, the planner's
``SINGULAR_TOL``). :func:`reach_extent` gives its extent and centroid (sampled on a grid);
:func:`fit_shape` centres a shape on a point and finds the largest factor <= 1 at which the
shape grown by a margin lies in the region (its outline sampled every 2 mm: the region has no
holes). shapely is imported on first use.

Units: m, rad.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .kinematics import SINGULAR_TOL, leg_lengths, singularity_measure
from .robot import RobotModel

__all__ = ["REACH_SAMPLES", "Placement", "fit_shape", "reachable_mask", "reachable_points", "reach_extent"]

REACH_SAMPLES = 241  #: grid samples per side when measuring the reachable region
_cache: dict[tuple, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
Reach = Callable[[np.ndarray, np.ndarray, float], np.ndarray]


def reachable_points(robot: RobotModel, x, y, psi: float) -> np.ndarray:
    """Whether the robot reaches the tool points (``x``, ``y``) [m] (1-D arrays) at angle
    ``psi`` [rad]: every leg within its stroke and the pose regular (singularity measure >=
    ``SINGULAR_TOL``)."""
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    poses = np.column_stack((x, y, np.full(x.size, float(psi))))
    L = leg_lengths(robot, poses)
    ok = np.all((L >= robot.length_min) & (L <= robot.length_max), axis=1)
    if ok.any():
        sing = np.zeros(len(poses))
        sing[ok] = singularity_measure(robot, poses[ok])
        ok &= sing >= SINGULAR_TOL
    return ok


def reachable_mask(robot: RobotModel, lower, upper, psi: float, n: int = 96):
    """Sample the rectangle [lower, upper] [m] on an ``n`` x ``n`` grid of points and mark
    the poses (x, y, psi [rad]) the robot reaches (:func:`reachable_points`). Returns ``(xs,
    ys, mask)``: grid coordinates [m] and a boolean (n, n) array indexed [iy, ix]."""
    xs = np.linspace(lower[0], upper[0], n)
    ys = np.linspace(lower[1], upper[1], n)
    X, Y = np.meshgrid(xs, ys)
    return xs, ys, reachable_points(robot, X.ravel(), Y.ravel(), psi).reshape(n, n)


def reach_extent(robot: RobotModel, psi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    """Where a shape goes: ``factor`` (<= 1) times its size, then ``offset`` [m] (x, y after
    scaling); ``shrunk`` whether the factor is below 1."""

    factor: float
    offset: tuple[float, float]
    shrunk: bool


def _outline_reachable(shape: Any, reach: Reach, psi: float) -> bool:
    import shapely

    pts = np.asarray(shapely.get_coordinates(shapely.segmentize(shape.boundary, 0.002)))
    return bool(len(pts)) and bool(np.all(reach(pts[:, 0], pts[:, 1], psi)))


def fit_shape(shapes: list, centre, margin: float, reach: Reach, psi: float) -> Placement:
    """Centre ``shapes`` (shapely geometries [m]) on ``centre`` (x, y) [m] and find the largest
    factor <= 1 such that the scaled shape grown by ``margin`` [m] lies in the reachable region
    (``reach``: :func:`reachable_points` of a robot; its outline sampled every 2 mm is
    reachable: the region has no holes). Raises ValueError when even a tiny shape does not fit."""
    import shapely
    from shapely import affinity

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
            raise ValueError(f"a margin of {margin:g} m around the shape does not fit where the robot reaches")
        lo = 1e-3
        for _ in range(30):
            mid_k = math.sqrt(lo * hi)
            lo, hi = (mid_k, hi) if fits(mid_k) else (lo, mid_k)
            if hi / lo < 1.0005:
                break
        k = lo
    offset = c - k * mid
    return Placement(k, (float(offset[0]), float(offset[1])), k < 1.0)
