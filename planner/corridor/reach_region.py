"""Where the robot can work: whether every pose in each of many boxes (the segmentation's
cells, the editor's grid squares) is within the legs' stroke and regular over an angle
range, and :func:`reachable_region`, the union of such squares for the editor to draw.

Stroke is exact over each box at every sampled angle (:func:`planner.model.reach.
boxes_within_stroke`); singularity is checked on each box's 3 x 3 grid of points, as the
planner's segment check does (:func:`planner.model.reach.check_segments`), by
:func:`planner.model.kinematics.singularity_measure_grid`; angles: :func:`psi_samples`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..errors import PlannerError, invalid
from ..model import SINGULAR_TOL, RobotModel, load_robot
from ..model.kinematics import singularity_measure_grid
from ..model.reach import boxes_within_stroke
from ..schema import MAX_CELLS

__all__ = ["PSI_STEP", "boxes_reachable", "psi_samples", "reachable_region", "regular_windows"]

#: largest angle step between the psi samples of the reach check [rad]
PSI_STEP = 0.05


def psi_samples(psi_range: Sequence[float] | np.ndarray) -> np.ndarray:
    """Angles [rad] at which reach is checked over ``psi_range`` [rad]: ``4k + 1`` evenly
    spaced samples (so they include the planner's 5-sample check), at most :data:`PSI_STEP`
    apart, capped at 33."""
    lo, hi = float(psi_range[0]), float(psi_range[1])
    if hi <= lo:
        return np.array([lo])
    k = min(max(1, math.ceil((hi - lo) / (4 * PSI_STEP))), 8)
    return np.linspace(lo, hi, 4 * k + 1)


def regular_windows(model: RobotModel, lattice: tuple, rows: np.ndarray, cols: np.ndarray,
                    psis: Sequence[float] | np.ndarray) -> np.ndarray:
    """Whether the robot is regular (singularity measure >= ``SINGULAR_TOL``) at every angle
    of ``psis`` [rad] on all 9 points of each 3 x 3 window of the lattice (C,) bool. The
    lattice ``(x0, y0, dx, dy, nx, ny)`` holds the points ``x0 + i dx, y0 + j dy`` [m]; window
    ``c`` has its first point at row ``rows[c]``, column ``cols[c]``. Shared points are
    evaluated once, and only those some window needs."""
    x0, y0, dx, dy, nx, _ = lattice
    a, b = np.divmod(np.arange(9), 3)
    flat = (rows[:, None] + a) * nx + (cols[:, None] + b)  # (C, 9)
    pts, inv = np.unique(flat, return_inverse=True)
    j, i = np.divmod(pts, nx)
    points = np.column_stack((x0 + dx * i, y0 + dy * j))
    ok = np.ones(len(pts), dtype=bool)
    for psi in psis:  # one angle at a time: the grid variant's closed form is per angle
        ok &= singularity_measure_grid(model, points, psi) >= SINGULAR_TOL
    return np.asarray(ok[inv.reshape(flat.shape)].all(axis=1))


def boxes_reachable(model: RobotModel, lo: np.ndarray, hi: np.ndarray, psis: Sequence[float] | np.ndarray,
                    lattice: tuple, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Whether every pose in each box ``[lo, hi]`` ((C, 2), m) at every angle of ``psis``
    [rad] keeps every leg within its stroke and, on the box's 3 x 3 window of the lattice
    (:func:`regular_windows`), is regular -> (C,) bool."""
    ok = boxes_within_stroke(model, lo, hi, psis)
    ok[ok] = regular_windows(model, lattice, rows[ok], cols[ok], psis)
    return ok


def reachable_region(robot: Any, bounds: dict | tuple, psi_range: Sequence[float] = (0.0, 0.0),
                     resolution: float = 0.005) -> list[dict]:
    """The part of ``bounds`` the robot's tool point reaches, regular, at every angle in
    ``psi_range`` [rad], at ``resolution`` [m]: the union of the grid squares whose every pose
    is within the legs' stroke and non-singular (the same test as the segmentation's cells).

    ``robot`` is a :class:`~planner.model.RobotModel` or what :func:`~planner.model.load_robot`
    takes; ``bounds`` is ``{"lower": [x, y], "upper": [x, y]}`` or ``(lower, upper)`` [m].
    Returns a list of polygons ``{"exterior": [[x, y], ...], "holes": [[[x, y], ...], ...]}``
    in m (rings not closed), for the editor to draw. At most ``MAX_CELLS`` grid squares.
    """
    model = load_robot(robot)
    if isinstance(bounds, dict):
        lower, upper = np.asarray(bounds.get("lower"), float), np.asarray(bounds.get("upper"), float)
    else:
        lower, upper = np.asarray(bounds[0], float), np.asarray(bounds[1], float)
    if lower.shape != (2,) or upper.shape != (2,) or not np.all(np.isfinite(np.concatenate((lower, upper)))):
        raise invalid("bounds", "must be {lower: [x, y], upper: [x, y]} in m")
    res = float(resolution)
    if not (math.isfinite(res) and res > 0):
        raise invalid("resolution", "must be a finite number > 0")
    if not np.all(upper > lower):
        raise invalid("bounds.upper", "must be greater than bounds.lower")
    nx, ny = (math.ceil((upper[i] - lower[i]) / res - 1e-9) for i in range(2))
    if nx * ny > MAX_CELLS:
        raise PlannerError("too_large", f"{nx} x {ny} grid squares exceed the limit of {MAX_CELLS}; use a coarser "
                           "resolution", "resolution")
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    i, j = i.ravel(), j.ravel()
    xs = np.minimum(lower[0] + res * np.arange(nx + 1), upper[0])  # shared edges: identical floats
    ys = np.minimum(lower[1] + res * np.arange(ny + 1), upper[1])
    lo = np.column_stack((xs[i], ys[j]))
    hi = np.column_stack((xs[i + 1], ys[j + 1]))
    lattice = (lower[0], lower[1], res / 2, res / 2, 2 * nx + 1, 2 * ny + 1)  # corners and midpoints
    ok = boxes_reachable(model, lo, hi, psi_samples(psi_range), lattice, 2 * j, 2 * i)
    if not ok.any():
        return []
    import shapely  # loaded on first use: plans of given segments never need it
    geom = shapely.coverage_union_all(shapely.box(lo[ok, 0], lo[ok, 1], hi[ok, 0], hi[ok, 1]))
    geom = shapely.simplify(geom, 0.0)  # drop the collinear grid vertices
    return [{"exterior": np.asarray(poly.exterior.coords)[:-1].tolist(),
             "holes": [np.asarray(r.coords)[:-1].tolist() for r in poly.interiors]}
            for poly in shapely.get_parts(geom)]
