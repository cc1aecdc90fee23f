"""The paper-mode receding-horizon loop compiled whole (numba), from the compiled model
(:mod:`planner.model.kernels`) and horizon solve (:mod:`planner.horizon.kernels`). Its numpy
reference is :func:`planner.orchestrator.simulate.simulate` with ``backend: "reference"``
(tested to give the same trajectory).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..horizon.kernels import riccati
from ..model.kernels import acceleration, factorised_blocks, rk4, zoh

__all__ = ["simulate_paper", "OK", "DIVERGED", "SINGULAR"]

#: status codes of :func:`simulate_paper`
OK, DIVERGED, SINGULAR = 0, 1, 2


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
        for i in range(3):
            xdot[i] = x[3 + i]
            acc = 0.0
            for j in range(3):
                acc += A22[i, j] * x[3 + j]
            for j in range(n):
                acc += B2[i, j] * u[j]
            xdot[3 + i] = acc
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
