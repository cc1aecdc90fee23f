"""The receding-horizon loops compiled whole (numba): the paper mode's, from the compiled
model (:mod:`planner.model.kernels`) and horizon solve (:mod:`planner.horizon.kernels`), and
the constrained mode's, from the compiled constrained step
(:func:`planner.constraints.step_kernels.constrained_step`). Their numpy reference is
:func:`planner.orchestrator.simulate.simulate` with ``backend: "reference"`` (tested to give
the same trajectory).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import njit
from ..constraints.dual_kernels import SOLVED
from ..constraints.step_kernels import constrained_step
from ..horizon.kernels import riccati
from ..model.kernels import acceleration, blocks_derivative, factorised_blocks, rk4, zoh

__all__ = ["simulate_constrained", "simulate_paper", "OK", "DIVERGED", "SINGULAR", "PYTHON_STEP"]

#: status codes of :func:`simulate_paper` and :func:`simulate_constrained`
OK, DIVERGED, SINGULAR, PYTHON_STEP = 0, 1, 2, 3


@njit(cache=True)
def simulate_paper(packed, x0, lo, hi, qa, qb, qu, K, N, Ts, substeps, max_steps, end, settle):
    """The paper-mode receding-horizon loop of :func:`planner.orchestrator.simulate.simulate`, compiled:
    at each sample eq. (8), eq. (9), the Riccati minimisation of eqs. (22)-(23) over the
    next ``N`` ranges (``lo, hi, qa, qb`` padded with the end held: ``K + N`` rows), the
    first move applied to the nonlinear model by RK4; stops when settled after sample ``K``.
    ``settle = (position m, angle rad, speed m/s, rate rad/s)``.

    Returns ``(X, U, ACC, steps, settled, status)`` with ``status`` one of ``OK``,
    ``DIVERGED`` (non-finite or runaway state) or ``SINGULAR`` (singular mass matrix or
    ill-posed horizon problem), and ``steps`` the samples simulated."""
    n = int(packed[-1])
    X = np.empty((max_steps + 1, 6))
    U = np.zeros((max_steps + 1, n))
    ACC = np.empty((max_steps + 1, 3))
    x = x0.copy()
    X[0] = x
    A22 = np.empty((3, 3))
    B2 = np.empty((3, n))
    Ad = np.empty((6, 6))
    Bd = np.empty((6, n))
    Uh = np.empty((N, n))
    xdot = np.empty(6)
    settled = False
    status = OK
    steps = 0
    for k in range(max_steps):
        if not factorised_blocks(packed, x, A22, B2):
            status = SINGULAR
            steps = k
            break
        zoh(A22, B2, Ts, Ad, Bd)
        w0 = min(k, K)
        if not riccati(Ad, Bd, x, qa[w0:w0 + N], qb[w0:w0 + N], qu, lo[w0:w0 + N], hi[w0:w0 + N], Uh):
            # a finite model whose horizon problem is ill-posed is degenerate; an overflowing
            # one (runaway velocities) means the loop diverged
            status = SINGULAR if np.all(np.isfinite(Ad)) and np.all(np.isfinite(Bd)) else DIVERGED
            steps = k
            break
        u = Uh[0]
        blocks_derivative(A22, B2, x, u, xdot)
        U[k] = u
        ACC[k] = xdot[3:]
        x = rk4(packed, x, u, Ts, substeps, xdot)
        X[k + 1] = x
        steps = k + 1
        finite = True
        for i in range(6):
            if not math.isfinite(x[i]):
                finite = False
        if not finite or abs(x[0]) + abs(x[1]) > 1e3:
            status = DIVERGED
            break
        if (k + 1 >= K and math.hypot(x[0] - end[0], x[1] - end[1]) < settle[0]
                and abs(x[2] - end[2]) < settle[1] and math.hypot(x[3], x[4]) < settle[2]
                and abs(x[5]) < settle[3]):
            settled = True
            break
    if status == OK:
        a = np.empty(3)
        if not acceleration(packed, X[steps], U[steps], a):
            status = SINGULAR
        ACC[steps] = a
    return X[:steps + 1], U[:steps + 1], ACC[:steps + 1], steps, settled, status


@njit(cache=True)
def simulate_constrained(packed, k0, max_steps, K, Ts, substeps, end, settle, X, U, ACC, z_prev, y_nom, u_prev, warm,
                         x1_pred, flags, iterations, counts, worst, umax, zmax, du, unit, N, refine_tol_m,
                         refine_tol_rad, refine_max, tol, dep_tol, warm_tol, relax, max_iter, V, Lm, proof, inputs):
    """The constrained-mode loop of :func:`planner.orchestrator.simulate.simulate` from step
    ``k0`` (state ``X[k0]``), compiled: at each sample eq. (8), eq. (9), the constrained step
    (:func:`~planner.constraints.step_kernels.constrained_step`, its arguments from ``umax``
    on), the first move applied to the nonlinear model by RK4; stops when settled after
    sample ``K``. Writes ``X``, ``U``, ``ACC`` (preallocated for ``max_steps``) and the
    controller's memory (``z_prev .. flags``: :class:`planner.constraints.controller.Memory`)
    and statistics in place: ``iterations[k]``, ``counts`` (refinements, relaxed steps),
    ``worst`` (largest row violation [m], one-step mismatch [m], [rad]).

    Returns ``(status, k, settled)``: ``OK`` (``k`` the samples simulated), ``PYTHON_STEP``
    (the step at ``k`` is for the controller's Python path: the stage-wise solve did not
    finish it), ``DIVERGED`` or ``SINGULAR`` (at ``k``)."""
    m = umax.shape[0]
    A22 = np.empty((3, 3))
    B2 = np.empty((3, m))
    Ad = np.empty((6, 6))
    Bd = np.empty((6, m))
    xdot = np.empty(6)
    u0 = np.zeros(m)
    no_poses = np.zeros((0, 3))
    no_warm = np.zeros(0)
    nx = 6 * N
    x = X[k0].copy()
    b = min(1, N - 1)
    for k in range(k0, max_steps):
        if not factorised_blocks(packed, x, A22, B2):
            return SINGULAR, k, False
        zoh(A22, B2, Ts, Ad, Bd)
        if flags[2]:
            worst[1] = max(worst[1], math.hypot(x[0] - x1_pred[0], x[1] - x1_pred[1]))
            worst[2] = max(worst[2], abs(x[2] - x1_pred[2]))
        for lg in range(m):
            u0[lg] = z_prev[b * m + lg] * umax[lg] if flags[0] else 0.0
        status, Y, z, Xp, y_next, it, ref, wv, relaxed = constrained_step(
            k, x, Ad, Bd, y_nom if flags[0] else no_poses, u_prev, u0, warm if flags[1] else no_warm, packed, Ts,
            substeps, umax, zmax, du, unit, N, refine_tol_m, refine_tol_rad, refine_max, tol, dep_tol, warm_tol,
            relax, max_iter, V, Lm, proof, inputs)
        if status != SOLVED:
            return PYTHON_STEP, k, False
        iterations[k] = it
        counts[0] += ref
        counts[1] += 1 if relaxed else 0
        worst[0] = max(worst[0], wv * unit)
        # remember (Memory.remember): moves, nominal poses, forces, prediction, warm start
        for q in range(N * m):
            z_prev[q] = z[q]
        for j in range(N):
            s = min(j + 1, N - 1)
            for a in range(3):
                y_nom[j, a] = y_next[j, a]
            for a in range(6):
                warm[6 * j + a] = Y[6 * s + a]
            for lg in range(m):
                warm[nx + m * j + lg] = Y[nx + m * s + lg]
        for a in range(6):
            x1_pred[a] = Xp[0, a]
        flags[0] = flags[1] = flags[2] = 1
        for lg in range(m):
            u_prev[lg] = z[lg] * umax[lg]
        blocks_derivative(A22, B2, x, u_prev, xdot)
        U[k] = u_prev
        ACC[k] = xdot[3:]
        x = rk4(packed, x, u_prev, Ts, substeps, xdot)
        X[k + 1] = x
        finite = True
        for i in range(6):
            if not math.isfinite(x[i]):
                finite = False
        if not finite or abs(x[0]) + abs(x[1]) > 1e3:
            return DIVERGED, k, False
        if (k + 1 >= K and math.hypot(x[0] - end[0], x[1] - end[1]) < settle[0]
                and abs(x[2] - end[2]) < settle[1] and math.hypot(x[3], x[4]) < settle[2]
                and abs(x[5]) < settle[3]):
            return OK, k + 1, True
    return OK, max_steps, False
