"""Leg geometry of a pose: the one implementation of leg vectors, lengths, Jacobians and
the singularity measure (inverse kinematics of paper Section III). Stateless functions of
the :class:`~planner.model.RobotModel` and the pose ``y = (x, y, psi)`` (m, m, rad) of the
tool point; batched over poses ``(k, 3)`` where the name says so.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernels_off
from .kernels import smallest_singular_values
from .robot import RobotModel

__all__ = ["GRID_BLOCK", "GRID_TRUST", "SINGULAR_TOL", "leg_jacobians", "leg_lengths", "leg_rows", "leg_vectors",
           "legs",
           "singularity_measure", "singularity_measure_grid"]

#: smallest singular value of the dimensionless leg Jacobian below which a pose is singular
SINGULAR_TOL = 1e-2
#: :func:`singularity_measure_grid` keeps its closed form where ``lam sqrt(1 - r^2) >= GRID_TRUST q``
#: (rounding below ~1e-11 relative), and recomputes the other poses by :func:`singularity_measure`
GRID_TRUST = 1e-4
#: points per block of :func:`singularity_measure_grid` (its (n_legs, block) temporaries stay in
#: cache: whole-grid temporaries made reachable_region at 2 mm ~12 % slower)
GRID_BLOCK = 4096


def leg_vectors(model: RobotModel, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For poses (k, 3): the platform pivots relative to the tool point, world frame,
    ``(rx, ry)``, and the leg vectors base pivot -> platform pivot ``(dx, dy)``, each (k, n) [m]:
    the loop closure (eq. 2) solved for the legs, ``l_i e(phi_i) = y + Rot(psi) r0_i - A_i``.
    The one numpy statement of the leg geometry (every function here builds on it); its
    compiled twin is :func:`planner.model.kernels.leg` (``tests/test_kernels.py``)."""
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
    """Inverse kinematics at one pose ``y`` (:func:`leg_vectors`): ``(l, e, r, rc)``: leg lengths
    (n,) [m], unit leg directions (n, 2), pivots relative to the tool point, world frame (n, 2)
    [m], and the platform centre relative to the tool point ``-Rot(psi) tool`` (2,) [m]."""
    rx, ry, dx, dy = leg_vectors(model, y)
    r, d = np.column_stack((rx[0], ry[0])), np.column_stack((dx[0], dy[0]))
    length = np.hypot(d[:, 0], d[:, 1])
    c, s = math.cos(y[2]), math.sin(y[2])
    tx, ty = model.tool
    return length, d / length[:, None], r, np.array([-(c * tx - s * ty), -(s * tx + c * ty)])


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
    if kernels_off():  # the numpy reference (LAPACK's gesvd); 0 for a matrix with a non-finite entry
        bad = ~np.isfinite(Jn).all(axis=(1, 2))
        Jn[bad] = 0.0
        return np.linalg.svd(Jn, compute_uv=False)[:, -1]
    return smallest_singular_values(np.ascontiguousarray(Jn))


def singularity_measure_grid(model: RobotModel, points: np.ndarray, psi: float) -> np.ndarray:
    """:func:`singularity_measure` of many tool points at one angle, ~5x faster: the poses
    ``(x, y, psi)`` for ``points`` (k, 2) [m] and ``psi`` [rad] -> (k,), equal to the reference
    to 1e-10 relative (``tests/test_model_singularity.py``). For the segmentation's grids.

    The smallest singular value is ``sqrt(lam)``, ``lam`` the smallest eigenvalue of the 3 x 3
    Gram matrix ``Jn^T Jn`` of the dimensionless leg Jacobian, in closed form (trigonometric
    solution of the characteristic cubic: ``lam = q + 2 p cos(acos(r) / 3 + 2 pi / 3)``, ``q``
    the mean eigenvalue, ``p`` their spread, ``r`` in [-1, 1]). Its rounding error relative to
    ``sigma`` is about ``8 eps q / (2 lam sqrt(1 - r^2))``: large only near a singular pose
    (``lam`` small) or where the two smallest singular values nearly coincide (``r`` near 1,
    e.g. a symmetric robot at a symmetric pose). Those poses (``lam sqrt(1 - r^2) <`` GRID_TRUST
    ``q``, a handful in a workspace) are recomputed by :func:`singularity_measure`."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points) > GRID_BLOCK:
        return np.concatenate([singularity_measure_grid(model, points[i:i + GRID_BLOCK], psi)
                               for i in range(0, len(points), GRID_BLOCK)])
    rx, ry, dx0, dy0 = (a[0, :, None] for a in leg_vectors(model, np.array([[0.0, 0.0, float(psi)]])))
    dx = dx0 + points[:, 0]  # (n, k): leg vectors of the tool points (translated from the origin's)
    dy = dy0 + points[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):  # a zero-length leg: recomputed below
        inv = 1.0 / np.sqrt(dx * dx + dy * dy)
        ex, ey = dx * inv, dy * inv
    scale = 1.0 / model.char_length
    ez = (scale * rx) * ey - (scale * ry) * ex  # rows of Jn = (e, (r x e) / L)
    a11, a22, a33 = (ex * ex).sum(axis=0), (ey * ey).sum(axis=0), (ez * ez).sum(axis=0)
    a12, a13, a23 = (ex * ey).sum(axis=0), (ex * ez).sum(axis=0), (ey * ez).sum(axis=0)
    q = (a11 + a22 + a33) / 3.0
    b11, b22, b33 = a11 - q, a22 - q, a33 - q
    p = np.sqrt((b11 * b11 + b22 * b22 + b33 * b33 + 2.0 * (a12 * a12 + a13 * a13 + a23 * a23)) / 6.0)
    det = b11 * (b22 * b33 - a23 * a23) - a12 * (a12 * b33 - a23 * a13) + a13 * (a12 * a23 - b22 * a13)
    with np.errstate(invalid="ignore", divide="ignore"):  # p = 0 (all three equal): recomputed below
        r = np.clip(det / (2.0 * p**3), -1.0, 1.0)
        lam = q + 2.0 * p * np.cos(np.arccos(r) / 3.0 + 2.0 * math.pi / 3.0)
        redo = ~(lam * np.sqrt(1.0 - r * r) >= GRID_TRUST * q)
    sigma = np.sqrt(np.where(redo, 0.0, lam))
    if redo.any():
        poses = np.column_stack((points[redo], np.full(np.count_nonzero(redo), float(psi))))
        sigma[redo] = singularity_measure(model, poses)
    return sigma
