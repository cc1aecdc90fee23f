"""Dynamics of the robot (paper eqs. 1-8) as stateless functions of the model and the state.

``R = ds/dy`` comes from the inverse kinematics and spans the null space of the constraint
Jacobian ``Phi_s`` (eq. 3); ``R_dot y_dot`` is the convective term of eq. (4). Drive forces
enter through ``R^T T``, the transposed leg Jacobian (4 forces, 3 DOF: redundant actuation).
The hot functions have compiled twins in :mod:`planner.model.kernels` (tested equal).
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any, cast

import numpy as np

from .kinematics import leg_rows, legs
from .robot import RobotModel

__all__ = ["R_matrix", "physical_coordinates", "loop_closure", "constraint_jacobian", "mass_matrix", "forces_g",
           "generalised_forces", "acceleration", "state_derivative", "factorised_blocks", "factorised",
           "kinetic_energy"]

@cache
def _gesv() -> Any:
    """LAPACK ``dgesv`` (scipy loaded on first use: the compiled planner never needs it)."""
    from scipy.linalg import get_lapack_funcs

    return cast(Any, get_lapack_funcs("gesv", dtype=np.float64))


def _solve(M: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve a small dense system with LAPACK gesv directly (numpy's wrapper costs 5x more
    than the solve itself at 3x3); raises on a singular matrix."""
    _, _, x, info = _gesv()(M, b)
    if info != 0:
        raise np.linalg.LinAlgError("singular reduced mass matrix")
    return x


def R_matrix(model: RobotModel, y: np.ndarray) -> np.ndarray:
    """``R = ds/dy`` (eq. 4), shape (3 + 2n, 3), rows ordered as ``s``."""
    l, e, r, rc, J_l, J_phi = leg_rows(model, y)
    Rc = np.array([[1.0, 0.0, -rc[1]], [0.0, 1.0, rc[0]], [0.0, 0.0, 1.0]])
    return np.vstack((Rc, J_l, J_phi))


def physical_coordinates(model: RobotModel, y: np.ndarray) -> np.ndarray:
    """``s(y)`` = (x_c, y_c, psi, l_1..l_n, phi_1..phi_n)."""
    l, e, r, rc = legs(model, y)
    return np.concatenate((y[:2] + rc, [y[2]], l, np.arctan2(e[:, 1], e[:, 0])))


def loop_closure(model: RobotModel, s: np.ndarray) -> np.ndarray:
    """Loop-closure constraints ``f(s) = 0`` (eq. 2), shape (2n,)."""
    n = model.n_legs
    c, psi, l, phi = s[:2], s[2], s[3:3 + n], s[3 + n:]
    rot = np.array([[math.cos(psi), -math.sin(psi)], [math.sin(psi), math.cos(psi)]])
    lhs = model.base + l[:, None] * np.column_stack((np.cos(phi), np.sin(phi)))
    return (lhs - (c + model.platform @ rot.T)).ravel()


def constraint_jacobian(model: RobotModel, s: np.ndarray) -> np.ndarray:
    """``Phi_s = df/ds`` (eq. 3), shape (2n, 3 + 2n)."""
    n = model.n_legs
    psi, l, phi = s[2], s[3:3 + n], s[3 + n:]
    c, sn = math.cos(psi), math.sin(psi)
    drot = np.array([[-sn, -c], [c, -sn]])  # d Rot / d psi
    Phi = np.zeros((2 * n, 3 + 2 * n))
    idx = np.arange(n)
    Phi[2 * idx, 0] = -1.0
    Phi[2 * idx + 1, 1] = -1.0
    Phi[:, 2] = -(model.platform @ drot.T).ravel()
    Phi[2 * idx, 3 + idx] = np.cos(phi)
    Phi[2 * idx + 1, 3 + idx] = np.sin(phi)
    Phi[2 * idx, 3 + n + idx] = -l * np.sin(phi)
    Phi[2 * idx + 1, 3 + n + idx] = l * np.cos(phi)
    return Phi


def mass_matrix(model: RobotModel, s: np.ndarray) -> np.ndarray:
    """``M(s)`` of eq. (1): diagonal in these coordinates [kg, kg m^2]."""
    n = model.n_legs
    l = s[3:3 + n]
    diag = np.concatenate((
        [model.platform_mass, model.platform_mass, model.platform_inertia],
        model.rod_mass,
        model.leg_inertia_const + model.rod_mass * (l - model.rod_com) ** 2,
    ))
    return np.diag(diag)


def forces_g(model: RobotModel, s: np.ndarray, s_dot: np.ndarray) -> np.ndarray:
    """``g(s, s_dot)`` of eq. (1): the legs' velocity-product terms and viscous friction [N, N m]."""
    n = model.n_legs
    l, l_dot, phi_dot = s[3:3 + n], s_dot[3:3 + n], s_dot[3 + n:]
    arm = l - model.rod_com
    g = np.zeros(3 + 2 * n)
    g[3:3 + n] = model.rod_mass * arm * phi_dot**2 - model.friction * l_dot
    g[3 + n:] = -2.0 * model.rod_mass * arm * l_dot * phi_dot
    return g


def _terms(model: RobotModel, y, v):
    """Shared pieces of eqs. (4)-(8) at state (y, v), all legs at once, from the leg rows of
    ``R`` (:func:`~planner.model.kinematics.leg_rows`).

    Returns ``W = [J_l; J_phi]`` (2n, 3) (the leg rows of ``R``), ``M_r = R^T M R`` (3, 3)
    and per-leg scalars: leg length ``l``, ``r x e``, ``r . e``, ``l_dot``, ``phi_dot``,
    the leg inertia about its base pivot ``J_leg``, and the platform centre ``rc`` (2,)
    relative to the tool point.
    """
    l, e, r, rc, J_l, J_phi = leg_rows(model, y)
    cross = J_l[:, 2]
    dot = np.einsum("ij,ij->i", r, e)
    w = v[2]
    l_dot = J_l @ v
    phi_dot = (e[:, 0] * v[1] - e[:, 1] * v[0] + dot * w) / l
    W = np.vstack((J_l, J_phi))
    arm = l - model.rod_com
    J_leg = model.leg_inertia_const + model.rod_mass * arm * arm
    M_r = (W.T * np.concatenate((model.rod_mass, J_leg))) @ W
    mp = model.platform_mass
    M_r[0, 0] += mp
    M_r[1, 1] += mp
    M_r[2, 2] += mp * (rc[0] * rc[0] + rc[1] * rc[1]) + model.platform_inertia
    M_r[0, 2] -= mp * rc[1]
    M_r[2, 0] -= mp * rc[1]
    M_r[1, 2] += mp * rc[0]
    M_r[2, 1] += mp * rc[0]
    return W, M_r, l, cross, dot, l_dot, phi_dot, J_leg, rc


def generalised_forces(model: RobotModel, y, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``R^T (g - M R_dot y_dot)`` of eqs. (5)/(6) and its pieces.

    Returns ``(M_r, h_r, J_l)``: reduced mass matrix (3, 3), reduced velocity-product and
    friction forces (3,) and the leg Jacobian (n, 3), so that ``M_r y_dd = h_r + J_l^T u``.
    In physical coordinates ``h = g - M R_dot y_dot`` has, per leg (``a`` = rod centre
    distance, ``w`` = psi_dot)::

        h_l   = -m_r a phi_dot^2 + m_r (r.e) w^2 - friction l_dot
        h_phi = 2 (J_leg / l - m_r (l - a)) l_dot phi_dot - J_leg (r x e) w^2 / l

    and ``m_p w^2 rc`` on the platform centre.
    """
    W, M_r, l, cross, dot, l_dot, phi_dot, J_leg, rc = _terms(model, y, v)
    return M_r, _h_r(model, W, l, cross, dot, l_dot, phi_dot, J_leg, rc, v[2]), W[:model.n_legs]


def _h_r(model: RobotModel, W, l, cross, dot, l_dot, phi_dot, J_leg, rc, w, u=None):
    m_r = model.rod_mass
    h_l = m_r * (dot * w * w - model.rod_com * phi_dot * phi_dot) - model.friction * l_dot
    if u is not None:
        h_l = h_l + u
    h_phi = (2.0 * (J_leg / l - m_r * (l - model.rod_com)) * l_dot * phi_dot - J_leg * cross * (w * w) / l)
    h_r = W.T @ np.concatenate((h_l, h_phi))
    h_r[:2] += model.platform_mass * w * w * rc
    return h_r


def acceleration(model: RobotModel, y, v, u) -> np.ndarray:
    """Reduced equations of motion (eq. 6):
    ``y_dd = (R^T M R)^-1 R^T (g - M R_dot y_dot) + (R^T M R)^-1 R^T T u`` [m/s^2, rad/s^2]."""
    W, M_r, l, cross, dot, l_dot, phi_dot, J_leg, rc = _terms(model, y, v)
    return _solve(M_r, _h_r(model, W, l, cross, dot, l_dot, phi_dot, J_leg, rc, v[2], u))


def state_derivative(model: RobotModel, x, u) -> np.ndarray:
    """State-space model (eq. 7): ``x_dot = f(x) + G(x) u`` with ``x = (y, y_dot)``."""
    out = np.empty(6)
    out[:3] = x[3:]
    out[3:] = acceleration(model, x[:3], x[3:], u)
    return out


def factorised_blocks(model: RobotModel, x) -> tuple[np.ndarray, np.ndarray]:
    """``A22`` (3, 3) and ``B2`` (3, n) of :meth:`factorised` (eq. 8)."""
    y, v = x[:3], x[3:]
    n = model.n_legs
    W, M_r, l, cross, dot, l_dot, phi_dot, J_leg, rc = _terms(model, y, v)
    w = v[2]
    m_r = model.rod_mass
    c1 = J_leg / l - m_r * (l - model.rod_com)  # half the coefficient of l_dot phi_dot in h_phi
    # K(v) with K v = h: half-gradients of the quadratic terms, gradients of the linear ones
    a_sw = np.concatenate((-m_r * model.rod_com * phi_dot, c1 * phi_dot))  # times the other row block
    a_own = np.concatenate((-model.friction, c1 * l_dot))  # times the own row block
    K = a_sw[:, None] * np.roll(W, n, axis=0) + a_own[:, None] * W
    K[:n, 2] += m_r * dot * w
    K[n:, 2] -= J_leg * cross * w / l
    rhs = np.empty((3, 3 + n))
    rhs[:, :3] = W.T @ K
    rhs[:, 3:] = W[:n].T
    rhs[:2, 2] += model.platform_mass * w * rc
    sol = _solve(M_r, rhs)
    return sol[:, :3], sol[:, 3:]


def factorised(model: RobotModel, x) -> tuple[np.ndarray, np.ndarray]:
    """State-dependent factorisation (eq. 8): ``x_dot = A(x) x + B(x) u``, exactly.

    ``A = [[0, I], [0, A22]]``. The free acceleration is ``Q(y, v) + L(y) v`` with ``Q``
    quadratic in ``v`` (velocity products) and ``L v`` the viscous friction. Since ``Q``
    is a quadratic form, ``(1/2) dQ/dv v = Q`` (Euler), so
    ``A22 = M_r^-1 R^T ((1/2) dh_quad/dv + dh_lin/dv)`` reproduces ``f(x)`` exactly:
    ``A(x) x == f(x)``. ``B = [[0], [M_r^-1 J_l^T]]`` is the paper's ``G(x)``.
    """
    A22, B2 = factorised_blocks(model, x)
    A = np.zeros((6, 6))
    A[:3, 3:] = np.eye(3)
    A[3:, 3:] = A22
    B = np.zeros((6, model.n_legs))
    B[3:] = B2
    return A, B


def kinetic_energy(model: RobotModel, x) -> float:
    """Kinetic energy ``1/2 y_dot^T R^T M R y_dot`` [J]."""
    M_r = _terms(model, x[:3], x[3:])[1]
    return 0.5 * float(x[3:] @ M_r @ x[3:])

