"""The dense QP of a step in the scaled moves ``z`` (compiled, numba): the prediction matrix
of eq. (11), the Hessian by a backward recursion, the parts that depend on the free
response and the matrix of every row. The form DAQP is given when the stage-wise solver does
not finish a step, and the slack problem's (:mod:`planner.constraints.step`); its numpy
twin is :class:`~planner.constraints.reference.ReferenceAssembly`
(``tests/test_constraints_kernels.py``: the same QP).

Layout as in :mod:`planner.constraints.kernels`.
"""

from __future__ import annotations

import numpy as np

from .._jit import njit

__all__ = ["constraint_matrix", "free_parts", "hessian", "predict", "prediction"]


@njit(cache=True)
def prediction(Ad, Bd, umax, P, Gx):
    """Eq. (11) in the scaled moves: ``P[q] = Ad^q`` (q = 0..N) into ``P`` (N+1, 6, 6) and the
    prediction matrix of ``X = free + Gx z`` into ``Gx`` (6N, N m): block ``(i, j)``
    (``j <= i``) is ``Ad^(i-j) Bd diag(umax)``."""
    N = P.shape[0] - 1
    m = Bd.shape[1]
    for a in range(6):
        for c in range(6):
            P[0, a, c] = 1.0 if a == c else 0.0
    for q in range(1, N + 1):
        for a in range(6):
            for c in range(6):
                acc = 0.0
                for t in range(6):
                    acc += Ad[a, t] * P[q - 1, t, c]
                P[q, a, c] = acc
    Bu = np.empty((6, m))
    for a in range(6):
        for lg in range(m):
            Bu[a, lg] = Bd[a, lg] * umax[lg]
    PB = np.empty((N, 6, m))
    for q in range(N):
        for a in range(6):
            for lg in range(m):
                acc = 0.0
                for t in range(6):
                    acc += P[q, a, t] * Bu[t, lg]
                PB[q, a, lg] = acc
    Gx[:, :] = 0.0
    for i in range(N):
        for j in range(i + 1):
            for a in range(6):
                for lg in range(m):
                    Gx[6 * i + a, m * j + lg] += PB[i - j, a, lg]


@njit(cache=True)
def hessian(Ad, Bd, umax, W, du, H):
    """The criterion's Hessian ``H = Gp2' diag(W) Gp2 + diag(du)``, ``Gp2`` the pose rows of
    the prediction matrix ``Gx`` (see :func:`prediction`), scaled so that its largest diagonal
    entry is 1, into ``H`` (N m, N m); returns the scale.

    Without forming ``Gp2' W Gp2``: with ``Q_i = diag(W_i, 0)`` (6, 6) the weight of sample
    ``i`` and ``Pi_j = sum_{i >= j} (Ad^(i-j))' Q_i Ad^(i-j)`` (backward:
    ``Pi_j = Q_j + Ad' Pi_{j+1} Ad``), the block of moves ``j1 <= j2`` is
    ``(Ad^(j2-j1) Bu)' Pi_j2 Bu`` (``Bu = Bd diag(umax)``). O(N^2) small blocks instead of
    the O(N^3) product."""
    N = W.shape[0] // 3
    m = Bd.shape[1]
    nz = H.shape[0]
    Bu = np.empty((6, m))
    for a in range(6):
        for lg in range(m):
            Bu[a, lg] = Bd[a, lg] * umax[lg]
    PB = np.empty((N, 6, m))  # Ad^q Bu
    PB[0] = Bu
    for q in range(1, N):
        for a in range(6):
            for lg in range(m):
                acc = 0.0
                for t in range(6):
                    acc += Ad[a, t] * PB[q - 1, t, lg]
                PB[q, a, lg] = acc
    PiB = np.empty((N, 6, m))  # Pi_j Bu
    Pi = np.zeros((6, 6))
    T = np.empty((6, 6))
    for j in range(N - 1, -1, -1):
        if j < N - 1:  # Pi <- Ad' Pi Ad
            for a in range(6):
                for c in range(6):
                    acc = 0.0
                    for t in range(6):
                        acc += Pi[a, t] * Ad[t, c]
                    T[a, c] = acc
            for a in range(6):
                for c in range(a, 6):
                    acc = 0.0
                    for t in range(6):
                        acc += Ad[t, a] * T[t, c]
                    Pi[a, c] = acc
                    Pi[c, a] = acc
        for a in range(3):
            Pi[a, a] += W[3 * j + a]
        for a in range(6):
            for lg in range(m):
                acc = 0.0
                for t in range(6):
                    acc += Pi[a, t] * Bu[t, lg]
                PiB[j, a, lg] = acc
    H[:, :] = 0.0
    for j2 in range(N):
        c2 = m * j2
        for j1 in range(j2 + 1):
            c1 = m * j1
            q = j2 - j1
            for l1 in range(m):
                for l2 in range(m):
                    acc = 0.0
                    for a in range(6):
                        acc += PB[q, a, l1] * PiB[j2, a, l2]
                    H[c1 + l1, c2 + l2] += acc
                    if j1 != j2:
                        H[c2 + l2, c1 + l1] += acc
    big = 0.0
    for c in range(nz):
        H[c, c] += du[c]
        big = max(big, H[c, c])
    scale = 1.0 / max(big, 1e-300)
    for c1 in range(nz):
        for c2 in range(nz):
            H[c1, c2] *= scale
    return scale


@njit(cache=True)
def free_parts(P, x, d, Gx, W, tgt, col, val, b0l, b0u):
    """The parts of the QP in ``z`` that depend on the free response (the prediction at
    ``z = 0``): ``free = P[1:] x + P[:N] d`` (6N,), the cost's linear term, not yet scaled,
    ``f = Gp2' (W free_pose - tgt)``, and the row bounds ``b0 - Sel free``. Returns
    ``(free, f, bl, bu)``."""
    N = P.shape[0] - 1
    m = Gx.shape[1] // N
    nrow = b0l.shape[0]
    free = np.empty(6 * N)
    f = np.zeros(Gx.shape[1])
    bl = np.empty(nrow)
    bu = np.empty(nrow)
    for i in range(N):
        for a in range(6):
            acc = 0.0
            for t in range(6):
                acc += P[i + 1, a, t] * x[t]
            acc2 = 0.0
            for t in range(6):
                acc2 += P[i, a, t] * d[t]
            free[6 * i + a] = acc + acc2
    for i in range(N):
        nc = m * (i + 1)
        for a in range(3):
            e = W[3 * i + a] * free[6 * i + a] - tgt[3 * i + a]
            if e == 0.0:
                continue
            r = 6 * i + a
            for q in range(nc):
                f[q] += Gx[r, q] * e
    for r in range(col.shape[0]):
        sf = _row_value(col, val, free, r)
        bl[r] = b0l[r] - sf
        bu[r] = b0u[r] - sf
    return free, f, bl, bu


@njit(cache=True)
def predict(Gx, free, z, X):
    """The predicted states ``X = free + Gx z`` (6N,) into ``X`` (sample ``i``'s rows of ``Gx``
    are zero past the moves ``0..i``)."""
    N = Gx.shape[0] // 6
    m = Gx.shape[1] // N
    for i in range(N):
        nc = m * (i + 1)
        for a in range(6):
            r = 6 * i + a
            acc = free[r]
            for q in range(nc):
                acc += Gx[r, q] * z[q]
            X[r] = acc


@njit(cache=True)
def _row_value(col, val, X, r):
    """Row ``r``'s state entries at the states ``X`` (its move entries, ``col >= 6N``, are left
    out: the value at ``z = 0``)."""
    acc = 0.0
    for k in range(col.shape[1]):
        c = col[r, k]
        if c >= 0 and c < X.shape[0]:
            acc += val[r, k] * X[c]
    return acc


@njit(cache=True)
def _matrix_row_into(col, val, Gx, A, r, i):
    """Row ``i`` of ``A`` = row ``r`` of ``Sel_X Gx + Sel_z``."""
    N = Gx.shape[0] // 6
    m = Gx.shape[1] // N
    A[i, :] = 0.0
    for k in range(col.shape[1]):
        c = col[r, k]
        if c < 0:
            continue
        v = val[r, k]
        if c >= 6 * N:  # a move
            A[i, c - 6 * N] += v
            continue
        nc = m * (c // 6 + 1)
        for q in range(nc):
            A[i, q] += v * Gx[c, q]


@njit(cache=True)
def constraint_matrix(col, val, Gx, A):
    """``A = Sel_X Gx + Sel_z`` of every row, into ``A`` (nrow, N m)."""
    for r in range(col.shape[0]):
        _matrix_row_into(col, val, Gx, A, r, r)
