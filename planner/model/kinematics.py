"""Leg geometry of a pose: the one implementation of leg vectors, lengths, Jacobians and
the singularity measure (inverse kinematics of paper Section III). Stateless functions of
the :class:`~planner.model.RobotModel` and the pose ``y = (x, y, psi)`` (m, m, rad) of the
tool point; batched over poses ``(k, 3)`` where the name says so.
"""

from __future__ import annotations

import math

import numpy as np

from .kernels import smallest_singular_values
from .robot import RobotModel

__all__ = ["legs", "leg_vectors", "leg_lengths", "leg_jacobians", "leg_rows", "singularity_measure",
           "SINGULAR_TOL"]

#: smallest singular value of the dimensionless leg Jacobian below which a pose is singular
SINGULAR_TOL = 1e-2


def leg_vectors(model: RobotModel, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For poses (k, 3): the platform pivots relative to the tool point, world frame,
    ``(rx, ry)``, and the leg vectors base pivot -> platform pivot ``(dx, dy)``, each (k, n) [m]."""
    poses = np.atleast_2d(poses)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    r0 = model.r0
    rx = c[:, None] * r0[:, 0] - s[:, None] * r0[:, 1]
    ry = s[:, None] * r0[:, 0] + c[:, None] * r0[:, 1]
    return rx, ry, poses[:, :1] + rx - model.base[:, 0], poses[:, 1:2] + ry - model.base[:, 1]


def leg_lengths(model: RobotModel, poses: np.ndarray) -> np.ndarray:
    """Leg lengths [m] of poses (k, 3) -> (k, n)."""
    _, _, dx, dy = leg_vectors(model, poses)
    return np.hypot(dx, dy)


def leg_jacobians(model: RobotModel, poses: np.ndarray) -> np.ndarray:
    """Leg Jacobians ``J_l`` of poses (k, 3) -> (k, n, 3): ``l_dot = J_l y_dot``; row ``i`` is
    ``(e_i, r_i x e_i)`` with ``e_i`` the unit leg direction and ``r_i`` the pivot relative to
    the tool point."""
    rx, ry, dx, dy = leg_vectors(model, poses)
    length = np.hypot(dx, dy)
    ex, ey = dx / length, dy / length
    return np.stack((ex, ey, rx * ey - ry * ex), axis=-1)


def legs(model: RobotModel, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Inverse kinematics at one pose ``y``: ``(l, e, r, rc)``: leg lengths (n,) [m], unit leg
    directions (n, 2), pivots relative to the tool point, world frame (n, 2) [m], and the
    platform centre relative to the tool point (2,) [m]."""
    c, s = math.cos(y[2]), math.sin(y[2])
    rot = np.array([[c, -s], [s, c]])
    r = model.r0 @ rot.T
    d = y[:2] + r - model.base
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    return length, d / length[:, None], r, -(rot @ model.tool)


def leg_rows(model: RobotModel, y: np.ndarray):
    """The leg rows of ``R = ds/dy`` (eq. 4) at one pose: ``(l, e, r, rc, J_l, J_phi)`` with
    ``J_l`` (n, 3), ``l_dot = J_l y_dot``, and ``J_phi`` (n, 3), ``phi_dot = J_phi y_dot``."""
    length, e, r, rc = legs(model, y)
    cross = r[:, 0] * e[:, 1] - r[:, 1] * e[:, 0]  # r x e
    dot = np.einsum("ij,ij->i", r, e)  # r . e
    J_l = np.column_stack((e, cross))
    J_phi = np.column_stack((-e[:, 1], e[:, 0], dot)) / length[:, None]
    return length, e, r, rc, J_l, J_phi


def singularity_measure(model: RobotModel, poses: np.ndarray) -> np.ndarray:
    """Smallest singular value of the dimensionless leg Jacobian ``J_l diag(1, 1, 1/L)``
    (``L`` = :attr:`RobotModel.char_length`) of poses (k, 3) -> (k,): 0 at a singular pose,
    ~1 well inside the workspace. Computed by the compiled one-sided Jacobi
    :func:`~planner.model.kernels.smallest_singular_values` (equal to numpy's SVD, tested)."""
    with np.errstate(invalid="ignore", divide="ignore"):  # a zero-length leg has no direction
        J = leg_jacobians(model, np.atleast_2d(np.asarray(poses, float)))
        Jn = J * np.array([1.0, 1.0, 1.0 / model.char_length])
    return smallest_singular_values(np.ascontiguousarray(Jn))
