"""The compiled twin (numba) of :func:`planner.constraints.stagewise.dual_solve`: the dual
active-set method of Goldfarb and Idnani on the factorised stage-wise problem of
:mod:`planner.constraints.stagewise_kernels`, each ``H^-1 n`` a Riccati substitution.

Constraint ``i`` is row ``i`` of the rows (``i < n_hard``; skipped if eliminated) or the
force bound of move ``i - n_hard``; ``Y = (X, z)`` as in :mod:`planner.constraints.kernels`.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import njit
from .stagewise_kernels import affine, substitute, substitute_many

__all__ = ["INFEASIBLE", "ITERATION_LIMIT", "SOLVED", "dual_solve", "dual_solve_active"]

#: status of a solve (as :mod:`planner.constraints.stagewise`)
SOLVED, INFEASIBLE, ITERATION_LIMIT = 1, -1, -2


@njit(cache=True, inline="always")
def _value(i, col, val, n_hard, nx, Y):
    """Constraint ``i`` at ``Y``: row ``i``, or (``i >= n_hard``) the move ``i - n_hard``."""
    if i >= n_hard:
        return Y[nx + i - n_hard]
    acc = 0.0
    for t in range(col.shape[1]):
        cc = col[i, t]
        if cc >= 0:
            acc += val[i, t] * Y[cc]
    return acc


@njit(cache=True, inline="always")
def _normal_terms(i, sign, col, val, n_hard, nx, L, Z, q, r):
    """The linear terms whose substitution is ``H^-1 n`` for constraint ``i`` with ``sign``
    (``stagewise._normal_terms``), added into the zeroed ``q``, ``r``; returns the highest
    stage they touch."""
    m = Z.shape[1]
    smax = 0
    nent = 1 if i >= n_hard else col.shape[1]
    for t in range(nent):
        if i >= n_hard:
            cc, v = nx + i - n_hard, 1.0
        else:
            cc, v = col[i, t], val[i, t]
            if cc < 0:
                continue
        if cc < nx:
            s = cc // 6
            q[s, cc % 6] -= sign * v
            smax = max(smax, s)
        else:
            s = (cc - nx) // m
            lg = cc - nx - m * s
            for j in range(m):
                r[s, j] -= sign * v * Z[s, lg, j]
            if s > 0:
                for b in range(6):
                    q[s - 1, b] -= sign * v * L[s, lg, b]
            smax = max(smax, s)
    return smax


@njit(cache=True)
def _most_violated(col, val, lower, upper, zmax, n_hard, elim, nx, Y, tol):
    """The constraint violated most beyond ``tol`` at ``Y``: ``(i, side, violation)``, ``i = -1``
    if none (then ``violation`` is the largest one, possibly negative). Rows (not eliminated),
    then the force bounds ``|z| <= zmax``."""
    best, p, side = tol, -1, 1
    largest = -np.inf
    for i in range(n_hard):
        if elim[i]:
            continue
        v = 0.0
        for t in range(col.shape[1]):
            cc = col[i, t]
            if cc >= 0:
                v += val[i, t] * Y[cc]
        e_lo, e_hi = lower[i] - v, v - upper[i]
        e = max(e_lo, e_hi)
        largest = max(largest, e)
        if e > best:
            best, p, side = e, i, (1 if e_lo >= e_hi else -1)
    for q in range(nx, Y.shape[0]):
        e_lo, e_hi = -zmax[q - nx] - Y[q], Y[q] - zmax[q - nx]
        e = max(e_lo, e_hi)
        largest = max(largest, e)
        if e > best:
            best, p, side = e, n_hard + q - nx, (1 if e_lo >= e_hi else -1)
    return p, side, (best if p >= 0 else largest)


@njit(cache=True)
def dual_solve(ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu, du, x, d, tgt, col, val, lower, upper, zmax,
               n_hard, tol, dep_tol, warm_tol, max_iter, warm, V, Lm, Y):
    """:func:`dual_solve_active` with its own work space for the active set: ``(status,
    iterations, n_active, worst)``."""
    qmax = V.shape[0]
    status, iterations, n_act, worst, p, side = dual_solve_active(
        ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu, du, x, d, tgt, col, val, lower, upper, zmax, n_hard, tol,
        dep_tol, warm_tol, max_iter, warm, V, Lm, Y, np.empty(qmax, np.int64), np.empty(qmax))
    return status, iterations, n_act, worst


@njit(cache=True)
def dual_solve_active(ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu, du, x, d, tgt, col, val, lower, upper,
                      zmax, n_hard, tol, dep_tol, warm_tol, max_iter, warm, V, Lm, Y, act, sgn):
    """``stagewise.dual_solve``: the step's QP by the dual active-set method on the
    factorised stage-wise problem, force bounds ``|z| <= zmax`` (N m,); the solution
    ``Y = (X, z)`` into ``Y``; ``warm`` the
    previous solution shifted (``stagewise.shifted``; empty: no warm start); ``V`` (N m + 1,
    6N + N m) and ``Lm`` (N m + 1, N m + 1) are work space (allocated once per plan). Returns
    ``(status, iterations, n_active, worst)`` (status 1 solved, -1 infeasible, -2 iteration
    limit; ``worst`` the largest violation of a constraint at ``Y``), and ``(p, side)``: where
    the status is infeasible, the violated constraint that proved it (its normal a combination
    of the active ones' that no multiplier can pay for), else -1 and 0. The active constraints
    (``n_active`` of them) and their sides are left in the work space ``act``, ``sgn`` (N m + 1,):
    with ``p`` they are the rows of the proof (a QP of those rows alone is infeasible too)."""
    N = ecnt.shape[0]
    m = Bu.shape[1]
    nx = 6 * N
    nY = nx + N * m
    ncons = n_hard + N * m
    c = np.empty((N, 6))
    k0 = np.empty((N, m))
    q = np.empty((N, 6))
    r = np.empty((N, m))
    affine(x, d, tgt, ecnt, eax, ceq, Kp, Z, L, S, Bu, du, c, k0, q, r)
    substitute(A, B, P, K, C, L, Z, ecnt, q, r, c, k0, x, N - 1, True, Y)
    Y0 = Y.copy()
    qmax = V.shape[0]
    u = np.empty(qmax)
    cvec = np.empty(qmax)
    lvec = np.empty(qmax)
    rvec = np.empty(qmax)
    Yv = np.empty(nY)
    Yz = np.empty(nY)
    n_act = 0
    iterations = 0
    status = SOLVED
    zero6 = np.zeros(6)
    if warm.shape[0] == nY:
        # the first working set: constraints at a bound of the warm start, their responses
        # substituted in one batch, kept where linearly independent of those before them
        cand = np.empty(ncons, np.int64)
        cside = np.empty(ncons)
        nc = 0
        for i in range(ncons):
            if i < n_hard and elim[i]:
                continue
            v = _value(i, col, val, n_hard, nx, warm)
            lo, hi = (-zmax[i - n_hard], zmax[i - n_hard]) if i >= n_hard else (lower[i], upper[i])
            side = 0
            if abs(v - lo) <= warm_tol:
                side = 1
            elif abs(hi - v) <= warm_tol:
                side = -1
            if side != 0 and nc < qmax:
                cand[nc] = i
                cside[nc] = side
                nc += 1
        if nc > 0:
            qb = np.zeros((nc, N, 6))
            rb = np.zeros((nc, N, m))
            for jc in range(nc):
                _normal_terms(cand[jc], cside[jc], col, val, n_hard, nx, L, Z, qb[jc], rb[jc])
            Vb = np.empty((nc, nY))
            substitute_many(A, B, P, K, C, L, Z, ecnt, qb, rb, Vb)
            iterations += nc
            for jc in range(nc):
                i, side = cand[jc], cside[jc]
                ll = 0.0
                for j in range(n_act):
                    acc = sgn[j] * _value(act[j], col, val, n_hard, nx, Vb[jc])
                    for t in range(j):
                        acc -= Lm[j, t] * lvec[t]
                    lvec[j] = acc / Lm[j, j]
                    ll += lvec[j] * lvec[j]
                Mpp = side * _value(i, col, val, n_hard, nx, Vb[jc])
                delta2 = Mpp - ll
                if not delta2 > dep_tol * Mpp:
                    continue
                act[n_act] = i
                sgn[n_act] = side
                for a in range(nY):
                    V[n_act, a] = Vb[jc, a]
                for t in range(n_act):
                    Lm[n_act, t] = lvec[t]
                Lm[n_act, n_act] = math.sqrt(delta2)
                n_act += 1
        # multipliers of the working set as equalities, M lam = -s(Y0); drop the most negative
        while n_act > 0:
            _on_working_set(n_act, act, sgn, u, V, Lm, lvec, col, val, lower, upper, zmax, n_hard, nx, Y0, Y)
            worst = 0
            for j in range(1, n_act):
                if u[j] < u[worst]:
                    worst = j
            if u[worst] >= 0.0:
                break
            for a in range(nY):
                Y[a] = Y0[a]
            _drop(worst, n_act, act, sgn, u, V, Lm)
            n_act -= 1
    while True:
        p, sp_, best = _most_violated(col, val, lower, upper, zmax, n_hard, elim, nx, Y, tol)
        if p < 0:
            break
        if p >= n_hard:
            bound = -zmax[p - n_hard]  # -zmax <= z (side +1) and -z >= -zmax (side -1)
        else:
            bound = lower[p] if sp_ == 1 else -upper[p]
        u_plus = 0.0
        added = False
        while not added:
            iterations += 1
            if iterations > max_iter:
                status = ITERATION_LIMIT
                break
            q[:, :] = 0.0
            r[:, :] = 0.0
            smax = _normal_terms(p, float(sp_), col, val, n_hard, nx, L, Z, q, r)
            substitute(A, B, P, K, C, L, Z, ecnt, q, r, c, k0, zero6, smax, False, Yv)
            # c = N_A' H^-1 n, l = Lm^-1 c, r = Lm^-T l
            for j in range(n_act):
                cvec[j] = sgn[j] * _value(act[j], col, val, n_hard, nx, Yv)
            ll = 0.0
            for j in range(n_act):
                acc = cvec[j]
                for t in range(j):
                    acc -= Lm[j, t] * lvec[t]
                lvec[j] = acc / Lm[j, j]
                ll += lvec[j] * lvec[j]
            for j in range(n_act - 1, -1, -1):
                acc = lvec[j]
                for t in range(j + 1, n_act):
                    acc -= Lm[t, j] * rvec[t]
                rvec[j] = acc / Lm[j, j]
            for a in range(nY):
                Yz[a] = Yv[a]
            for j in range(n_act):
                rj = rvec[j]
                if rj != 0.0:
                    for a in range(nY):
                        Yz[a] -= rj * V[j, a]
            Mpp = sp_ * _value(p, col, val, n_hard, nx, Yv)
            d2 = sp_ * _value(p, col, val, n_hard, nx, Yz)
            delta2 = Mpp - ll
            t1 = np.inf
            kdrop = -1
            for j in range(n_act):
                if rvec[j] > 0.0 and u[j] / rvec[j] < t1:
                    t1 = u[j] / rvec[j]
                    kdrop = j
            slack = sp_ * _value(p, col, val, n_hard, nx, Y) - bound
            dependent = not (d2 > dep_tol * Mpp and delta2 > dep_tol * Mpp)
            t2 = np.inf if dependent else -slack / d2
            t = min(t1, t2)
            if t == np.inf:
                status = INFEASIBLE
                break
            for j in range(n_act):
                u[j] -= t * rvec[j]
            u_plus += t
            if not dependent:
                for a in range(nY):
                    Y[a] += t * Yz[a]
            if t == t2:
                if n_act == qmax:
                    status = ITERATION_LIMIT
                    break
                act[n_act] = p
                sgn[n_act] = sp_
                u[n_act] = u_plus
                for a in range(nY):
                    V[n_act, a] = Yv[a]
                for t_ in range(n_act):
                    Lm[n_act, t_] = lvec[t_]
                Lm[n_act, n_act] = math.sqrt(delta2)
                n_act += 1
                added = True
            else:
                _drop(kdrop, n_act, act, sgn, u, V, Lm)
                n_act -= 1
        if status != SOLVED:
            break
    if status == SOLVED and n_act > 0:
        # polish: the minimiser on the final working set afresh from Y0 (``stagewise.dual_solve``)
        _on_working_set(n_act, act, sgn, u, V, Lm, lvec, col, val, lower, upper, zmax, n_hard, nx, Y0, Y)
    proof = -1
    proof_side = 0
    if status == INFEASIBLE:
        proof = p
        proof_side = sp_
    p, sp_, worst = _most_violated(col, val, lower, upper, zmax, n_hard, elim, nx, Y, 0.0)
    return status, iterations, n_act, max(worst, 0.0), proof, proof_side


@njit(cache=True)
def _on_working_set(n, act, sgn, u, V, Lm, lvec, col, val, lower, upper, zmax, n_hard, nx, Y0, Y):
    """The minimiser with the ``n`` active constraints as equalities, ``Y = Y0 + V lam`` with
    ``M lam = -s(Y0)`` (``M = Lm Lm'``, ``s`` their slacks at the unconstrained minimiser
    ``Y0``); the multipliers ``lam`` into ``u``."""
    nY = Y.shape[0]
    for j in range(n):
        i = act[j]
        if i >= n_hard:
            b = -zmax[i - n_hard]
        else:
            b = lower[i] if sgn[j] > 0 else -upper[i]
        acc = -(sgn[j] * _value(i, col, val, n_hard, nx, Y0) - b)
        for t in range(j):
            acc -= Lm[j, t] * lvec[t]
        lvec[j] = acc / Lm[j, j]
    for j in range(n - 1, -1, -1):
        acc = lvec[j]
        for t in range(j + 1, n):
            acc -= Lm[t, j] * u[t]
        u[j] = acc / Lm[j, j]
    for a in range(nY):
        acc = Y0[a]
        for j in range(n):
            acc += u[j] * V[j, a]
        Y[a] = acc


@njit(cache=True)
def _drop(k, n, act, sgn, u, V, Lm):
    """Remove active constraint ``k`` of ``n``: shift the lists, and downdate the Cholesky
    factor ``Lm`` of ``M`` (row ``k`` removed, the rows below re-triangularised by Givens
    rotations of neighbouring columns)."""
    nY = V.shape[1]
    for j in range(k, n - 1):
        act[j] = act[j + 1]
        sgn[j] = sgn[j + 1]
        u[j] = u[j + 1]
        for a in range(nY):
            V[j, a] = V[j + 1, a]
        for t in range(j + 2):
            Lm[j, t] = Lm[j + 1, t]
    for t in range(n):
        Lm[n - 1, t] = 0.0
    # rows k..n-2 now have one entry above the diagonal (column j+1 of row j)
    for j in range(k, n - 1):
        a_, b_ = Lm[j, j], Lm[j, j + 1]
        rr = math.hypot(a_, b_)
        if rr == 0.0:
            continue
        cs, sn = a_ / rr, b_ / rr
        for i in range(j, n - 1):
            x1, x2 = Lm[i, j], Lm[i, j + 1]
            Lm[i, j] = cs * x1 + sn * x2
            Lm[i, j + 1] = -sn * x1 + cs * x2
        Lm[j, j + 1] = 0.0
    for j in range(k, n - 1):
        if Lm[j, j] < 0.0:
            for i in range(j, n - 1):
                Lm[i, j] = -Lm[i, j]
