"""The compiled twin (numba) of :mod:`planner.constraints.stagewise`, first part: the step's
QP in stage-wise form (equalities eliminated), its Riccati factorisation, the affine terms
and the substitution; the dual active-set method on it is in
:mod:`planner.constraints.dual_kernels`. The same arithmetic as the numpy reference
(``tests/test_stagewise.py`` checks they agree, and that both give DAQP's minimiser).

Layout as in :mod:`planner.constraints.kernels`: ``Y = (X, z)``, states ``X[6 s + a]`` of
``x_{s+1}``, then the scaled moves ``z[m s + l]`` at ``Y[6 N + m s + l]``; row ``r`` is
``sum_k val[r, k] Y[col[r, k]]`` (``col`` -1: unused). Constraint ``i`` of the dual method is
row ``i`` (``i < n_hard``; skipped if eliminated) or the force bound of move ``i - n_hard``.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import njit

__all__ = ["affine", "stage_setup", "substitute", "substitute_many"]


@njit(cache=True)
def stage_setup(Ad, Bd, umax, du, W, col, val, lower, upper, n_hard):
    """The stage-wise problem and its Riccati factorisation (``stagewise.stage_problem``).
    Returns ``(ok, ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu)``; ``ok`` False where
    an equality cannot be eliminated."""
    N = W.shape[0] // 3
    m = Bd.shape[1]
    nrow = col.shape[0]
    Bu = np.empty((6, m))
    bnorm = 0.0
    for a in range(6):
        for lg in range(m):
            Bu[a, lg] = Bd[a, lg] * umax[lg]
            bnorm = max(bnorm, abs(Bu[a, lg]))
    ecnt = np.zeros(N, np.int64)
    eax = np.zeros((N, 3), np.int64)
    ceq = np.zeros((N, 3))
    elim = np.zeros(nrow, np.bool_)
    for r in range(n_hard):
        c = col[r, 0]
        if col[r, 1] < 0 and c >= 0 and c < 6 * N and c % 6 < 3 and upper[r] - lower[r] <= 0.0 and val[r, 0] != 0.0:
            s = c // 6
            dup = False
            for t in range(ecnt[s]):
                if eax[s, t] == c % 6:
                    dup = True
            if dup:
                continue
            eax[s, ecnt[s]] = c % 6
            ceq[s, ecnt[s]] = lower[r] / val[r, 0]
            ecnt[s] += 1
            elim[r] = True
    Kp = np.zeros((N, m, 3))
    Z = np.zeros((N, m, m))
    L = np.zeros((N, m, 6))
    A = np.empty((N, 6, 6))
    B = np.empty((N, 6, m))
    R = np.zeros((N, m, m))
    S = np.zeros((N, m, 6))
    P = np.zeros((N, 6, 6))
    K = np.zeros((N, m, 6))
    C = np.zeros((N, m, m))
    ok = True
    for s in range(N):
        e = ecnt[s]
        if e == 0:
            for lg in range(m):
                Z[s, lg, lg] = 1.0
            A[s] = Ad
            B[s] = Bu
            for lg in range(m):
                R[s, lg, lg] = du[lg]
            continue
        if e > m:
            ok = False
            break
        same = -1
        for h in range(s):
            if ecnt[h] == e:
                match = True
                for t in range(e):
                    if eax[h, t] != eax[s, t]:
                        match = False
                if match:
                    same = h
                    break
        if same >= 0:
            Kp[s] = Kp[same]
            Z[s] = Z[same]
            L[s] = L[same]
            A[s] = A[same]
            B[s] = B[same]
            R[s] = R[same]
            S[s] = S[same]
            continue
        if not _eliminate(Bu, eax[s], e, bnorm, Kp[s], Z[s]):
            ok = False
            break
        for lg in range(m):
            for b in range(6):
                acc = 0.0
                for t in range(e):
                    acc -= Kp[s, lg, t] * Ad[eax[s, t], b]
                L[s, lg, b] = acc
        for a in range(6):
            for b in range(6):
                acc = Ad[a, b]
                for lg in range(m):
                    acc += Bu[a, lg] * L[s, lg, b]
                A[s, a, b] = acc
            for j in range(m):
                acc = 0.0
                for lg in range(m):
                    acc += Bu[a, lg] * Z[s, lg, j]
                B[s, a, j] = acc
        for i in range(m):
            for j in range(m):
                acc = 0.0
                for lg in range(m):
                    acc += Z[s, lg, i] * du[lg] * Z[s, lg, j]
                R[s, i, j] = acc
            if i >= m - e:
                R[s, i, i] = 1.0
            for b in range(6):
                acc = 0.0
                for lg in range(m):
                    acc += Z[s, lg, i] * du[lg] * L[s, lg, b]
                S[s, i, b] = acc
    if not ok:
        return ok, ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu
    # backward Riccati: P[s] is the value matrix of x_{s+1}
    for a in range(3):
        P[N - 1, a, a] = W[3 * (N - 1) + a]
    PB = np.empty((6, m))
    PA = np.empty((6, 6))
    Lam = np.empty((m, m))
    G = np.empty((m, 6))
    for s in range(N - 1, -1, -1):
        Pn = P[s]
        As = A[s]
        Bs = B[s]
        for a in range(6):
            for j in range(m):
                acc = 0.0
                for t in range(6):
                    acc += Pn[a, t] * Bs[t, j]
                PB[a, j] = acc
            for b in range(6):
                acc = 0.0
                for t in range(6):
                    acc += Pn[a, t] * As[t, b]
                PA[a, b] = acc
        for i in range(m):
            for j in range(m):
                acc = R[s, i, j]
                for t in range(6):
                    acc += Bs[t, i] * PB[t, j]
                Lam[i, j] = acc
            for b in range(6):
                acc = S[s, i, b]
                for t in range(6):
                    acc += Bs[t, i] * PA[t, b]
                G[i, b] = acc
        # Cholesky Lam = C C'
        for i in range(m):
            for j in range(i + 1):
                acc = Lam[i, j]
                for t in range(j):
                    acc -= C[s, i, t] * C[s, j, t]
                if i == j:
                    if not acc > 0.0:
                        return False, ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu
                    C[s, i, i] = math.sqrt(acc)
                else:
                    C[s, i, j] = acc / C[s, j, j]
        # K = Lam^-1 G
        for b in range(6):
            for i in range(m):
                acc = G[i, b]
                for t in range(i):
                    acc -= C[s, i, t] * K[s, t, b]
                K[s, i, b] = acc / C[s, i, i]
            for i in range(m - 1, -1, -1):
                acc = K[s, i, b]
                for t in range(i + 1, m):
                    acc -= C[s, t, i] * K[s, t, b]
                K[s, i, b] = acc / C[s, i, i]
        if s > 0:
            # P[s-1] = Q[s-1] + A' P A - G' K ; Q[s-1] = diag(W_{s-1}, 0) + L_s' Du L_s
            for a in range(6):
                for b in range(a, 6):
                    acc = 0.0
                    for t in range(6):
                        acc += As[t, a] * PA[t, b]
                    for i in range(m):
                        acc -= G[i, a] * K[s, i, b]
                        acc += L[s, i, a] * du[i] * L[s, i, b]
                    P[s - 1, a, b] = acc
                    P[s - 1, b, a] = acc
            for a in range(3):
                P[s - 1, a, a] += W[3 * (s - 1) + a]
    return ok, ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu


@njit(cache=True)
def _eliminate(Bu, axes, e, bnorm, Kp, Z):
    """``Kp = (C Bu)^+`` (m, e) and ``Z`` (m, m-e, padded) a null-space basis of ``C Bu`` (``C``
    selects the pose coordinates ``axes[:e]``) from a Householder QR ``(C Bu)' = Q [R; 0]``:
    ``Z = Q[:, e:]``, ``Kp = Q[:, :e] R^-T``. False if ``C Bu`` is rank deficient."""
    m = Bu.shape[1]
    M = np.empty((m, e))
    for t in range(e):
        for lg in range(m):
            M[lg, t] = Bu[axes[t], lg]
    Q = np.zeros((m, m))
    for i in range(m):
        Q[i, i] = 1.0
    v = np.empty(m)
    for j in range(e):
        nrm = 0.0
        for i in range(j, m):
            nrm += M[i, j] * M[i, j]
        nrm = math.sqrt(nrm)
        if nrm == 0.0:
            return False
        alpha = -nrm if M[j, j] >= 0.0 else nrm
        vv = 0.0
        for i in range(m):
            v[i] = M[i, j] if i >= j else 0.0
        v[j] -= alpha
        for i in range(j, m):
            vv += v[i] * v[i]
        if vv == 0.0:
            continue
        for c in range(j, e):  # M <- (I - 2 v v'/vv) M
            acc = 0.0
            for i in range(j, m):
                acc += v[i] * M[i, c]
            f = 2.0 * acc / vv
            for i in range(j, m):
                M[i, c] -= f * v[i]
        for i in range(m):  # Q <- Q (I - 2 v v'/vv)
            acc = 0.0
            for t in range(j, m):
                acc += Q[i, t] * v[t]
            f = 2.0 * acc / vv
            for t in range(j, m):
                Q[i, t] -= f * v[t]
    for j in range(e):
        if not abs(M[j, j]) > 1e-9 * bnorm:
            return False
    # Kp' = R^-1 Q1' (R = M[:e, :e] upper triangular)
    for i in range(m):
        for j in range(e - 1, -1, -1):
            acc = Q[i, j]
            for t in range(j + 1, e):
                acc -= M[j, t] * Kp[i, t]
            Kp[i, j] = acc / M[j, j]
        for j in range(m - e):
            Z[i, j] = Q[i, e + j]
    return True


@njit(cache=True)
def affine(x, d, tgt, ecnt, eax, ceq, Kp, Z, L, S, Bu, du, c, k0, q, r):
    """``stagewise.affine_terms`` into ``c`` (N, 6), ``k0`` (N, m), ``q`` (N, 6), ``r`` (N, m)."""
    N = ecnt.shape[0]
    m = Bu.shape[1]
    c[:, :] = 0.0
    k0[:, :] = 0.0
    q[:, :] = 0.0
    r[:, :] = 0.0
    for a in range(6):
        c[0, a] = d[a]
    for s in range(N):
        e = ecnt[s]
        if e > 0:
            for lg in range(m):
                acc = 0.0
                for t in range(e):
                    acc += Kp[s, lg, t] * (ceq[s, t] - c[s, eax[s, t]])
                k0[s, lg] = acc
    for s in range(N):
        if ecnt[s] > 0:
            for a in range(6):
                acc = 0.0
                for lg in range(m):
                    acc += Bu[a, lg] * k0[s, lg]
                c[s, a] += acc
            for j in range(m):
                acc = 0.0
                for lg in range(m):
                    acc += Z[s, lg, j] * du[lg] * k0[s, lg]
                r[s, j] = acc
    for s in range(N):
        for a in range(3):
            q[s, a] = -tgt[3 * s + a]
        if s + 1 < N and ecnt[s + 1] > 0:
            for b in range(6):
                acc = 0.0
                for lg in range(m):
                    acc += L[s + 1, lg, b] * du[lg] * k0[s + 1, lg]
                q[s, b] += acc


@njit(cache=True)
def substitute(A, B, P, K, C, L, Z, ecnt, q, r, c, k0, x0, smax, affine, Y):
    """``stagewise.substitute`` into ``Y``: backward from stage ``smax`` (the linear terms above
    it are zero), forward over all stages; ``affine`` False: ``c``, ``k0``, ``x0`` are zero.
    A stage without equalities (``ecnt`` 0) has ``z = w`` (``L = 0``, ``Z = I``)."""
    N = A.shape[0]
    m = B.shape[2]
    k = np.zeros((N, m))
    p = np.empty(6)
    h = np.empty(6)
    g = np.empty(m)
    for a in range(6):
        p[a] = q[smax, a]
    for s in range(smax, -1, -1):
        for a in range(6):
            acc = p[a]
            if affine:
                for t in range(6):
                    acc += P[s, a, t] * c[s, t]
            h[a] = acc
        for j in range(m):
            acc = r[s, j]
            for t in range(6):
                acc += B[s, t, j] * h[t]
            g[j] = acc
        for j in range(m):  # k = C^-T C^-1 g
            acc = g[j]
            for t in range(j):
                acc -= C[s, j, t] * k[s, t]
            k[s, j] = acc / C[s, j, j]
        for j in range(m - 1, -1, -1):
            acc = k[s, j]
            for t in range(j + 1, m):
                acc -= C[s, t, j] * k[s, t]
            k[s, j] = acc / C[s, j, j]
        if s > 0:
            for a in range(6):
                acc = q[s - 1, a]
                for t in range(6):
                    acc += A[s, t, a] * h[t]
                for j in range(m):
                    acc -= K[s, j, a] * g[j]
                p[a] = acc
    xs = np.zeros(6)
    if affine:
        for a in range(6):
            xs[a] = x0[a]
    xn = np.empty(6)
    w = np.empty(m)
    nx = 6 * N
    for s in range(N):
        for j in range(m):
            acc = -k[s, j]
            for t in range(6):
                acc -= K[s, j, t] * xs[t]
            w[j] = acc
        if ecnt[s] == 0:
            for lg in range(m):
                Y[nx + m * s + lg] = w[lg]
        else:
            for lg in range(m):
                acc = k0[s, lg] if affine else 0.0
                for t in range(6):
                    acc += L[s, lg, t] * xs[t]
                for j in range(m):
                    acc += Z[s, lg, j] * w[j]
                Y[nx + m * s + lg] = acc
        for a in range(6):
            acc = c[s, a] if affine else 0.0
            for t in range(6):
                acc += A[s, a, t] * xs[t]
            for j in range(m):
                acc += B[s, a, j] * w[j]
            xn[a] = acc
        for a in range(6):
            xs[a] = xn[a]
            Y[6 * s + a] = xn[a]


@njit(cache=True)
def substitute_many(A, B, P, K, C, L, Z, ecnt, q, r, Yout):
    """:func:`substitute` of the homogeneous problem for ``nc`` sets of linear terms at once
    (``q`` (nc, N, 6), ``r`` (nc, N, m)), the responses into ``Yout`` (nc, 6N + N m): the same
    arithmetic per right-hand side, with the right-hand sides innermost so that the loops
    vectorise (the warm start substitutes every constraint of its working set)."""
    nc = q.shape[0]
    N = A.shape[0]
    m = B.shape[2]
    nx = 6 * N
    k = np.zeros((N, m, nc))
    p = np.empty((6, nc))
    pn = np.empty((6, nc))
    g = np.empty((m, nc))
    for a in range(6):
        for c in range(nc):
            p[a, c] = q[c, N - 1, a]
    for s in range(N - 1, -1, -1):
        for j in range(m):
            for c in range(nc):
                g[j, c] = r[c, s, j]
        for t in range(6):
            for j in range(m):
                btj = B[s, t, j]
                for c in range(nc):
                    g[j, c] += btj * p[t, c]
        for j in range(m):  # k = C^-T C^-1 g
            for c in range(nc):
                k[s, j, c] = g[j, c]
            for t in range(j):
                cjt = C[s, j, t]
                for c in range(nc):
                    k[s, j, c] -= cjt * k[s, t, c]
            inv = 1.0 / C[s, j, j]
            for c in range(nc):
                k[s, j, c] *= inv
        for j in range(m - 1, -1, -1):
            for t in range(j + 1, m):
                ctj = C[s, t, j]
                for c in range(nc):
                    k[s, j, c] -= ctj * k[s, t, c]
            inv = 1.0 / C[s, j, j]
            for c in range(nc):
                k[s, j, c] *= inv
        if s > 0:
            for a in range(6):
                for c in range(nc):
                    pn[a, c] = q[c, s - 1, a]
            for t in range(6):
                for a in range(6):
                    ata = A[s, t, a]
                    for c in range(nc):
                        pn[a, c] += ata * p[t, c]
            for j in range(m):
                for a in range(6):
                    kja = K[s, j, a]
                    for c in range(nc):
                        pn[a, c] -= kja * g[j, c]
            for a in range(6):
                for c in range(nc):
                    p[a, c] = pn[a, c]
    xs = np.zeros((6, nc))
    xn = np.empty((6, nc))
    w = np.empty((m, nc))
    zz = np.empty((m, nc))
    for s in range(N):
        for j in range(m):
            for c in range(nc):
                w[j, c] = -k[s, j, c]
            for t in range(6):
                kjt = K[s, j, t]
                for c in range(nc):
                    w[j, c] -= kjt * xs[t, c]
        if ecnt[s] == 0:
            for lg in range(m):
                for c in range(nc):
                    zz[lg, c] = w[lg, c]
        else:
            for lg in range(m):
                for c in range(nc):
                    zz[lg, c] = 0.0
                for t in range(6):
                    lt = L[s, lg, t]
                    for c in range(nc):
                        zz[lg, c] += lt * xs[t, c]
                for j in range(m):
                    zj = Z[s, lg, j]
                    for c in range(nc):
                        zz[lg, c] += zj * w[j, c]
        for a in range(6):
            for c in range(nc):
                xn[a, c] = 0.0
            for t in range(6):
                at = A[s, a, t]
                for c in range(nc):
                    xn[a, c] += at * xs[t, c]
            for j in range(m):
                bj = B[s, a, j]
                for c in range(nc):
                    xn[a, c] += bj * w[j, c]
        for a in range(6):
            for c in range(nc):
                xs[a, c] = xn[a, c]
                Yout[c, 6 * s + a] = xn[a, c]
        for lg in range(m):
            for c in range(nc):
                Yout[c, nx + m * s + lg] = zz[lg, c]
