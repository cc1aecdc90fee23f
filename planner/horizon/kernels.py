"""The compiled twin of the horizon solve (numba): eqs. (22)-(23) by a backward Riccati
recursion, the same minimiser as the numpy references :func:`planner.horizon.solvers.solve_qr`
(the paper's route) and :func:`planner.horizon.solvers.solve_structured` (tested equal).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import njit

__all__ = ["riccati"]


@njit(cache=True)
def riccati(Ad, Bd, x0, qa, qb, qu, ra, r_b, U):
    """Eqs. (22)-(23), the same minimiser as :func:`planner.horizon.solvers.solve_qr`, by the backward
    Riccati recursion of the stage-wise problem (``O(N)``)::

        min sum_{j=1..N} x_j' H_j x_j - 2 q_j' x_j + sum_{j=0..N-1} u_j' Ru u_j,
        x_{j+1} = Ad x_j + Bd u_j,   H_j = C' (Qa_j^2 + Qb_j^2) C,  q_j = C' (Qa_j^2 ra_j + Qb_j^2 r_bj)

    with ``C = [I 0]`` (the pose), ``Ru = diag(qu)^2``. Value ``V_j(x) = x' P_j x - 2 p_j' x``,
    ``Lam = Ru + Bd' P Bd``, ``u_j = -K_j x_j + k_j`` with ``K_j = Lam^-1 Bd' P Ad`` and
    ``k_j = Lam^-1 Bd' p``; ``P_j = H_j + Ad' P Ad - Ad' P Bd K_j``, ``p_j = q_j + Ad' p - Ad' P Bd k_j``.
    Writes the input sequence into ``U`` (N, m) by a forward pass; returns False if ``Lam``
    is not positive definite."""
    N, m = U.shape
    n, ny = 6, 3  # state (pose, velocity) and pose sizes, fixed so that loops unroll
    # Products are written with the independent outputs innermost (axpy form), so that the
    # multiply-adds pipeline instead of waiting on one running sum. Ad = [[I, T1], [0, T0]]
    # (eq. 9) and P symmetric are used: (P Ad)[:, :3] = P[:, :3], (Bd' P Ad)[:, :3] = (P Bd)[:3]'.
    P = np.zeros((n, n))
    p = np.zeros(n)
    for i in range(ny):
        P[i, i] = qa[N - 1, i] ** 2 + qb[N - 1, i] ** 2
        p[i] = qa[N - 1, i] ** 2 * ra[N - 1, i] + qb[N - 1, i] ** 2 * r_b[N - 1, i]
    Ks = np.empty((N, m, n))
    ks = np.empty((N, m))
    PB = np.empty((n, m))
    PA = np.empty((n, n))  # only columns 3..5 are used
    Lam = np.empty((m, m))
    L = np.zeros((m, m))
    G = np.empty((m, n + 1))  # [Bd' P Ad, Bd' p], then overwritten by [K, k]
    BtPA = np.empty((m, n))
    pn = np.empty(n)
    for j in range(N - 1, -1, -1):
        PB[:, :] = 0.0
        PA[:, 3:] = 0.0
        for a in range(n):
            for c in range(n):
                pac = P[a, c]
                for b in range(m):
                    PB[a, b] += pac * Bd[c, b]
                for b in range(3, n):
                    PA[a, b] += pac * Ad[c, b]
        Lam[:, :] = 0.0
        BtPA[:, 3:] = 0.0
        for c in range(n):
            for a in range(m):
                bca = Bd[c, a]
                for b in range(m):
                    Lam[a, b] += bca * PB[c, b]
                for b in range(3, n):
                    BtPA[a, b] += bca * PA[c, b]
        for a in range(m):
            for b in range(3):
                BtPA[a, b] = PB[b, a]
            acc = 0.0
            for c in range(n):
                acc += Bd[c, a] * p[c]
            for b in range(n):
                G[a, b] = BtPA[a, b]
            G[a, n] = acc
            Lam[a, a] += qu[a] * qu[a]
        # Cholesky factor L of Lam = Ru + Bd' P Bd
        for a in range(m):
            for b in range(a + 1):
                acc = Lam[a, b]
                for c in range(b):
                    acc -= L[a, c] * L[b, c]
                if a == b:
                    if not acc > 0.0:
                        return False
                    L[a, a] = math.sqrt(acc)
                else:
                    L[a, b] = acc / L[b, b]
        # [K, k] = Lam^-1 [Bd' P Ad, Bd' p]: forward then backward substitution, all columns at once
        for a in range(m):
            for c in range(a):
                lac = L[a, c]
                for col in range(n + 1):
                    G[a, col] -= lac * G[c, col]
            inv = 1.0 / L[a, a]
            for col in range(n + 1):
                G[a, col] *= inv
        for a in range(m - 1, -1, -1):
            for c in range(a + 1, m):
                lca = L[c, a]
                for col in range(n + 1):
                    G[a, col] -= lca * G[c, col]
            inv = 1.0 / L[a, a]
            for col in range(n + 1):
                G[a, col] *= inv
        for a in range(m):
            for b in range(n):
                Ks[j, a, b] = G[a, b]
            ks[j, a] = G[a, n]
        if j == 0:
            break
        # P <- H_j + Ad' P Ad - (Bd' P Ad)' K,  p <- q_j + Ad' p - (Bd' P Ad)' k
        # (Ad' P Bd = (Bd' P Ad)' as P is symmetric). Ad' P Ad: [[P11, (P Ad)_12], [., Ad_2' (P Ad)_2]]
        for a in range(3):
            pn[a] = p[a]
            for b in range(3):
                PA[a, b] = P[a, b]  # reuse PA's first columns as the new P's work space
        for a in range(3, n):
            acc = 0.0
            for c in range(n):
                acc += Ad[c, a] * p[c]
            pn[a] = acc
        for a in range(3):
            for b in range(3, n):
                P[a, b] = PA[a, b]
        for a in range(3, n):
            for b in range(3, n):
                P[a, b] = 0.0
        for c in range(n):
            for a in range(3, n):
                aca = Ad[c, a]
                for b in range(3, n):
                    P[a, b] += aca * PA[c, b]
        for a in range(3):
            for b in range(3):
                P[a, b] = PA[a, b]
        for c in range(m):
            gk = G[c, n]
            for a in range(n):
                bta = BtPA[c, a]
                pn[a] -= bta * gk
                for b in range(a, n):
                    P[a, b] -= bta * G[c, b]
        for a in range(n):  # mirror the upper triangle
            for b in range(a):
                P[a, b] = P[b, a]
        for i in range(ny):
            P[i, i] += qa[j - 1, i] ** 2 + qb[j - 1, i] ** 2
            pn[i] += qa[j - 1, i] ** 2 * ra[j - 1, i] + qb[j - 1, i] ** 2 * r_b[j - 1, i]
        p[:] = pn
    x = x0.copy()
    xn = np.empty(n)
    for j in range(N):
        for a in range(m):
            acc = ks[j, a]
            for b in range(n):
                acc -= Ks[j, a, b] * x[b]
            U[j, a] = acc
        for a in range(n):
            acc = 0.0
            for b in range(n):
                acc += Ad[a, b] * x[b]
            for b in range(m):
                acc += Bd[a, b] * U[j, b]
            xn[a] = acc
        x[:] = xn
    return True
