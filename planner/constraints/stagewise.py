"""The step's QP as a stage-wise problem, solved by a dual active-set method whose linear
systems are Riccati substitutions (numpy reference; compiled twin:
:mod:`planner.constraints.stagewise_kernels`).

Why. The QP of a step (:mod:`planner.constraints.step`) is an optimal-control problem:
``N`` stages, 6 states, ``m`` drive forces, every row bounding one sample's state (or a
move). Its Hessian in the moves is the condensed one (``N m`` square, dense), but solving
with it needs only the stage-wise structure: ``H^-1 g`` is the backward Riccati recursion
the paper mode already uses, ``O(N)`` once the recursion's matrices are factorised. So the
dual active-set method of Goldfarb and Idnani (the method DAQP implements on the dense
problem) is run here with every ``H^-1 n`` formed by a Riccati substitution: the
factorisation once per step, then per change of the active set one substitution
(``O(N)``) and a Cholesky update of the small matrix ``M = N_A' H^-1 N_A`` of the active
rows. The unconstrained minimiser is its starting point, so a step whose unconstrained
solution already meets every row costs one factorisation and one substitution.
(``benchmarks/bench_qp.py`` compares it with DAQP, OSQP, ProxSuite and Clarabel, and says
why not an interior point method as HPIPM, or a primal online active set as qpOASES.)

The problem, in the scaled moves ``z = u / force_max`` (:class:`~planner.constraints.step.FullQP`)::

    min sum_s 0.5 y_s' W_s y_s - tgt_s' y_s + 0.5 z_s' Du z_s
    s.t. x_{s+1} = Ad x_s + Bu z_s + c_s     (c_0 = d, the one-step offset; else 0)
         lower <= Sel Y <= upper,  -1 <= z <= 1          (Y = (X, z): states 1..N, moves)

with ``y_s`` the pose of ``x_{s+1}``. Rows are sparse selections of ``Y`` (``Rows.col``: an
index below ``6N`` is a state, from ``6N`` on a move). **Equalities** (a pose coordinate of a
sample fixed: psi = 0 along Table I) are eliminated stage by stage, as the dense path did
(``kernels.reduce_setup``): with ``C_s`` the fixed coordinates of ``x_{s+1}`` and ``c`` their
values, ``z_s = L_s x_s + Z_s w_s + k0_s`` (``K = (C Bu)^+``, ``Z`` a null-space basis of
``C Bu``, both from a QR factorisation of ``(C Bu)'``, ``L = -K C Ad``, ``k0 = K (c - C
c_s)``), which leaves a problem in ``w`` of the same stage-wise form with a cross term between ``w_s`` and ``x_s``::

    x_{s+1} = A_s x_s + B_s w_s + c'_s,     A_s = Ad + Bu L_s, B_s = Bu Z_s, c'_s = c_s + Bu k0_s
    cost    0.5 w_s' R_s w_s + w_s' S_s x_s + r_s' w_s  (R = Z' Du Z, S = Z' Du L, r = Z' Du k0)
            + 0.5 x_s' (L' Du L) x_s + (L' Du k0)' x_s   (added to the weights of x_s)

``w_s`` is padded to ``m`` entries (the padding has unit weight and no effect), so every
stage has the same shapes.

The Riccati recursion (value ``0.5 x' P x + p' x`` of ``x_{s+1}``): ``Lam_s = R_s + B_s' P B_s``
(Cholesky), ``K_s = Lam_s^-1 (S_s + B_s' P A_s)``, ``P <- Q + A_s' P A_s - (S_s + B_s' P A_s)'
K_s``; a substitution with linear terms ``q`` (states), ``r`` (inputs) and offsets ``c``:
``h = p + P c_s``, ``g = r_s + B_s' h``, ``k_s = Lam_s^-1 g``, ``p <- q + A_s' h - K_s' g``, then
forward ``w_s = -K_s x_s - k_s``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .rows import Rows

__all__ = ["DEPENDENT_TOL", "SOLVE_TOL", "WARM_TOL", "DualResult", "StageProblem", "dual_solve", "shifted",
           "stage_problem"]

#: a row counts as violated beyond this (row units; force bounds in force / force_max)
SOLVE_TOL = 1e-9
#: a row whose direction is this close (relative, squared sine in the H^-1 metric) to the span
#: of the active rows is linearly dependent on them
DEPENDENT_TOL = 1e-12
#: a row within this of a bound at the warm start (row units) starts in the working set
WARM_TOL = 1e-6
#: status of a solve
SOLVED, INFEASIBLE, ITERATION_LIMIT = 1, -1, -2


@dataclass(slots=True, eq=False)
class StageProblem:
    """A step's QP in stage-wise form, equalities eliminated, Riccati matrices factorised
    (module docstring). Stage ``s`` = 0..N-1 maps ``x_s`` to ``x_{s+1}``; the weights and
    value matrices are those of ``x_{s+1}``."""

    N: int
    m: int
    Ad: np.ndarray  #: (6, 6)
    Bu: np.ndarray  #: (6, m) ``Bd diag(force_max)``
    du: np.ndarray  #: (m,) move weights
    ecnt: np.ndarray  #: (N,) equalities of stage s (on x_{s+1})
    eax: np.ndarray  #: (N, 3) their pose coordinates
    ceq: np.ndarray  #: (N, 3) their values (m, rad)
    elim: np.ndarray  #: (nrow,) rows replaced by the elimination
    Kp: np.ndarray  #: (N, m, 3) ``(C_s Bu)^+``
    Z: np.ndarray  #: (N, m, m) null-space basis, padded with zero columns
    L: np.ndarray  #: (N, m, 6) ``-K C Ad``
    A: np.ndarray  #: (N, 6, 6) ``Ad + Bu L``
    B: np.ndarray  #: (N, 6, m) ``Bu Z``
    R: np.ndarray  #: (N, m, m)
    S: np.ndarray  #: (N, m, 6)
    Q: np.ndarray  #: (N, 6, 6) weight of ``x_{s+1}``
    P: np.ndarray  #: (N, 6, 6) value matrix of ``x_{s+1}``
    K: np.ndarray  #: (N, m, 6) feedback
    C: np.ndarray  #: (N, m, m) lower Cholesky factor of ``Lam_s``


def stage_problem(Ad: np.ndarray, Bd: np.ndarray, umax: np.ndarray, du: np.ndarray, W: np.ndarray,
                  rows: Rows) -> StageProblem | None:
    """The stage-wise problem of a step (model ``Ad, Bd``, force limits ``umax`` [N], move
    weights ``du`` (m,), pose weights ``W`` (3N,), the hard rows of ``rows``), factorised; None
    where an equality cannot be eliminated (``C_s Bu`` rank deficient)."""
    N, m = len(W) // 3, Bd.shape[1]
    Bu = Bd * umax
    nrow = rows.n_rows
    ecnt = np.zeros(N, np.int64)
    eax = np.zeros((N, 3), np.int64)
    ceq = np.zeros((N, 3))
    elim = np.zeros(nrow, bool)
    for r in range(rows.n_hard):
        c = int(rows.col[r, 0])
        if (rows.col[r, 1] < 0 and 0 <= c < 6 * N and c % 6 < 3 and rows.upper[r] - rows.lower[r] <= 0.0
                and rows.val[r, 0] != 0.0):
            s = c // 6
            if c % 6 in eax[s, :ecnt[s]]:
                continue
            eax[s, ecnt[s]] = c % 6
            ceq[s, ecnt[s]] = rows.lower[r] / rows.val[r, 0]
            ecnt[s] += 1
            elim[r] = True
    Kp, Z, L = np.zeros((N, m, 3)), np.zeros((N, m, m)), np.zeros((N, m, 6))
    bnorm = float(np.abs(Bu).max())
    for s in range(N):
        e = int(ecnt[s])
        if e == 0:
            Z[s] = np.eye(m)
            continue
        if e > m:
            return None
        # QR of (C Bu)' = Q [R; 0]: the null space is Q[:, e:], the pseudo-inverse Q[:, :e] R^-T
        Qf, Rf = np.linalg.qr(Bu[eax[s, :e]].T, mode="complete")
        if not np.all(np.abs(np.diag(Rf[:e])) > 1e-9 * bnorm):
            return None
        Kp[s, :, :e] = Qf[:, :e] @ np.linalg.inv(Rf[:e].T)
        Z[s, :, :m - e] = Qf[:, e:]
        L[s] = -Kp[s, :, :e] @ Ad[eax[s, :e]]
    A = Ad + np.einsum("am,smb->sab", Bu, L)
    B = np.einsum("am,smn->san", Bu, Z)
    R = np.einsum("sla,l,slb->sab", Z, du, Z) + np.array([np.diag((ecnt[s] > np.arange(m)[::-1]).astype(float))
                                                          for s in range(N)])
    S = np.einsum("sla,l,slb->sab", Z, du, L)
    Q = np.zeros((N, 6, 6))
    for s in range(N):
        Q[s, :3, :3] = np.diag(W[3 * s:3 * s + 3])
        if s + 1 < N:
            Q[s] += L[s + 1].T @ (du[:, None] * L[s + 1])
    P, K, C = np.zeros((N, 6, 6)), np.zeros((N, m, 6)), np.zeros((N, m, m))
    P[N - 1] = Q[N - 1]
    for s in range(N - 1, -1, -1):
        Lam = R[s] + B[s].T @ P[s] @ B[s]
        G = S[s] + B[s].T @ P[s] @ A[s]
        C[s] = np.linalg.cholesky(Lam)
        K[s] = np.linalg.solve(Lam, G)
        if s > 0:
            Pn = Q[s - 1] + A[s].T @ P[s] @ A[s] - G.T @ K[s]
            P[s - 1] = 0.5 * (Pn + Pn.T)
    return StageProblem(N, m, Ad, Bu, du, ecnt, eax, ceq, elim, Kp, Z, L, A, B, R, S, Q, P, K, C)


def affine_terms(sp: StageProblem, x: np.ndarray, d: np.ndarray,
                 tgt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The parts of the step's problem that depend on the state ``x``, the offset ``d`` and the
    targets ``tgt`` (3N,): offsets ``c'`` (N, 6), ``k0`` (N, m), linear terms of the states
    ``q`` (N, 6; of ``x_{s+1}``) and of the inputs ``r`` (N, m)."""
    N, m = sp.N, sp.m
    c0 = np.zeros((N, 6))
    c0[0] = d
    k0 = np.zeros((N, m))
    for s in range(N):
        e = int(sp.ecnt[s])
        if e:
            k0[s] = sp.Kp[s, :, :e] @ (sp.ceq[s, :e] - c0[s, sp.eax[s, :e]])
    c = c0 + k0 @ sp.Bu.T
    r = np.einsum("slw,l,sl->sw", sp.Z, sp.du, k0)
    q = np.zeros((N, 6))
    q[:, :3] = -tgt.reshape(N, 3)
    q[:N - 1] += np.einsum("sla,l,sl->sa", sp.L[1:], sp.du, k0[1:])
    return c, k0, q, r


def substitute(sp: StageProblem, q: np.ndarray, r: np.ndarray, c: np.ndarray | None = None,
               k0: np.ndarray | None = None, x0: np.ndarray | None = None) -> np.ndarray:
    """The minimiser of the problem with linear terms ``q`` (N, 6) and ``r`` (N, m), offsets
    ``c`` and ``k0`` and start ``x0`` (None: zero, the homogeneous problem), as ``Y = (X, z)``
    (6N + N m,): one backward and one forward pass."""
    N, m = sp.N, sp.m
    c = np.zeros((N, 6)) if c is None else c
    k0 = np.zeros((N, m)) if k0 is None else k0
    k = np.zeros((N, m))
    p = q[N - 1].copy()
    for s in range(N - 1, -1, -1):
        h = p + sp.P[s] @ c[s]
        g = r[s] + sp.B[s].T @ h
        k[s] = np.linalg.solve(sp.C[s].T, np.linalg.solve(sp.C[s], g))
        if s > 0:
            p = q[s - 1] + sp.A[s].T @ h - sp.K[s].T @ g
    X, z = np.zeros((N, 6)), np.zeros((N, m))
    xs = np.zeros(6) if x0 is None else np.asarray(x0, float)
    for s in range(N):
        w = -sp.K[s] @ xs - k[s]
        z[s] = sp.L[s] @ xs + sp.Z[s] @ w + k0[s]
        xs = sp.A[s] @ xs + sp.B[s] @ w + c[s]
        X[s] = xs
    return np.concatenate((X.ravel(), z.ravel()))


@dataclass(slots=True, eq=False)
class DualResult:
    """A solve of the step's QP by :func:`dual_solve`."""

    status: int  #: 1 solved, -1 infeasible, -2 iteration limit
    Y: np.ndarray  #: (6N + N m,) states and moves at the solution (or where it stopped)
    iterations: int  #: substitutions of a constraint's normal (warm start and active-set changes)
    active: list[tuple[int, int]]  #: active constraints ``(id, side)`` (side +1: lower bound, -1: upper)
    multipliers: np.ndarray  #: their multipliers (>= 0)
    violation: float  #: largest violation of a row at ``Y`` (row units)


def _constraints(sp: StageProblem, rows: Rows,
                 zmax: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray, np.ndarray]:
    """The inequality constraints the dual method sees, as index lists into ``Y``, values and
    bounds: the hard rows not eliminated, then the force bounds ``-zmax <= z <= zmax``."""
    nx = 6 * sp.N
    cols, vals, lo, hi = [], [], [], []
    for r in range(rows.n_hard):
        if sp.elim[r]:
            continue
        used = rows.col[r] >= 0
        cols.append(rows.col[r, used])
        vals.append(rows.val[r, used])
        lo.append(rows.lower[r])
        hi.append(rows.upper[r])
    for q in range(sp.N * sp.m):
        cols.append(np.array([nx + q]))
        vals.append(np.array([1.0]))
        lo.append(-zmax[q])
        hi.append(zmax[q])
    return cols, vals, np.array(lo), np.array(hi)


def _normal_terms(sp: StageProblem, cols: np.ndarray, vals: np.ndarray, sign: float) -> tuple[np.ndarray, np.ndarray]:
    """Linear terms ``(q, r)`` whose substitution gives ``H^-1 n`` for the normal ``n`` of the
    constraint ``sign * vals . Y[cols]`` (the linear term is ``-n``)."""
    N, m = sp.N, sp.m
    q, r = np.zeros((N, 6)), np.zeros((N, m))
    for c, v in zip(cols, vals):
        c = int(c)
        if c < 6 * N:
            q[c // 6, c % 6] -= sign * v
        else:
            s, lg = divmod(c - 6 * N, m)
            r[s] -= sign * v * sp.Z[s, lg]
            if s > 0:
                q[s - 1] -= sign * v * sp.L[s, lg]
    return q, r


def shifted(Y: np.ndarray, N: int, m: int) -> np.ndarray:
    """A solution ``Y = (X, z)`` of the previous step, one sample on: states and moves of
    samples 2..N as those of 1..N-1, the last repeated (the warm start of the next step)."""
    X, z = Y[:6 * N].reshape(N, 6), Y[6 * N:].reshape(N, m)
    return np.concatenate((np.vstack((X[1:], X[-1:])).ravel(), np.vstack((z[1:], z[-1:])).ravel()))


def dual_solve(sp: StageProblem, rows: Rows, zmax: np.ndarray, x: np.ndarray, d: np.ndarray, tgt: np.ndarray,
               warm: np.ndarray | None = None, tol: float = SOLVE_TOL, max_iter: int = 1000) -> DualResult:
    """The step's QP by the dual active-set method of Goldfarb and Idnani (module docstring):
    from the unconstrained minimiser, add the most violated constraint; the step direction
    ``H^-1 n - V r`` (``V`` the substitutions of the active rows, ``r = M^-1 N_A' H^-1 n``)
    moves to the constraint or, first, drops an active constraint whose multiplier reaches
    zero. Exact: it ends on the active rows (as DAQP). ``zmax`` (N m,): the force bounds of
    the scaled moves.

    Warm start (``warm``: the previous step's solution :func:`shifted`): the constraints within
    :data:`WARM_TOL` of a bound there form the first working set (the linearly independent
    ones, in order); the minimiser with them as equalities is ``Y0 + V lam``, ``M lam = -s(Y0)``
    (``s`` their slacks at the unconstrained minimiser ``Y0``); while a multiplier is negative
    the most negative one is dropped. That point is optimal for its working set with
    multipliers >= 0, which is all the method needs to start from."""
    cols, vals, lo, hi = _constraints(sp, rows, zmax)
    c, k0, q, r = affine_terms(sp, x, d, tgt)
    Y0 = substitute(sp, q, r, c, k0, x)
    Y = Y0

    def value(i: int, y: np.ndarray) -> float:
        return float(vals[i] @ y[cols[i]])

    def bound(i: int, side: int) -> float:
        return float(lo[i] if side == 1 else -hi[i])

    def on_working_set() -> tuple[np.ndarray, np.ndarray]:  # minimiser with the active rows as equalities
        lam = np.linalg.solve(M, -np.array([sj * value(j, Y0) - bound(j, sj) for j, sj in active]))
        return Y0 + np.array(V).T @ lam, lam

    active: list[tuple[int, int]] = []
    u: list[float] = []
    V: list[np.ndarray] = []
    M = np.zeros((0, 0))
    iterations = 0
    if warm is not None:
        for i in range(len(cols)):
            v = value(i, warm)
            for side, gap in ((1, v - lo[i]), (-1, hi[i] - v)):
                if abs(gap) <= WARM_TOL:
                    iterations += 1
                    Yv = substitute(sp, *_normal_terms(sp, cols[i], vals[i], side))
                    cvec = np.array([sj * value(j, Yv) for j, sj in active])
                    Mpp = side * value(i, Yv)
                    delta2 = Mpp - float(cvec @ np.linalg.solve(M, cvec)) if active else Mpp
                    if delta2 > DEPENDENT_TOL * Mpp:
                        active.append((i, side))
                        V.append(Yv)
                        M = np.block([[M, cvec[:, None]], [cvec[None, :], np.array([[Mpp]])]])
                    break
        while active:
            Yw, lam = on_working_set()
            worst = int(np.argmin(lam))
            if lam[worst] >= 0.0:
                Y = Yw
                u = list(lam)
                break
            del active[worst], V[worst]
            M = np.delete(np.delete(M, worst, 0), worst, 1)
    status = SOLVED
    while True:
        v_all = np.array([value(i, Y) for i in range(len(cols))])
        viol = np.maximum(lo - v_all, v_all - hi)
        p = int(np.argmax(viol))
        if viol[p] <= tol:
            break
        sp_ = 1 if lo[p] - v_all[p] >= v_all[p] - hi[p] else -1
        u_plus = 0.0
        added = False
        while not added:
            iterations += 1
            if iterations > max_iter:
                status = ITERATION_LIMIT
                break
            Yv = substitute(sp, *_normal_terms(sp, cols[p], vals[p], sp_))
            cvec = np.array([si * value(i, Yv) for i, si in active])
            rvec = np.linalg.solve(M, cvec) if active else np.zeros(0)
            Yz = Yv - (np.array(V).T @ rvec if active else 0.0)
            Mpp = sp_ * value(p, Yv)
            d2 = sp_ * value(p, Yz)
            t1, kdrop = np.inf, -1
            for j, rj in enumerate(rvec):
                if rj > 0 and u[j] / rj < t1:
                    t1, kdrop = u[j] / rj, j
            slack = sp_ * value(p, Y) - bound(p, sp_)
            delta2 = Mpp - float(cvec @ rvec)  # the new diagonal of M's Cholesky factor, squared
            dependent = not (d2 > DEPENDENT_TOL * Mpp and delta2 > DEPENDENT_TOL * Mpp)
            t2 = np.inf if dependent else -slack / d2
            t = min(t1, t2)
            if not np.isfinite(t):
                status = INFEASIBLE
                break
            u = [uj - t * rj for uj, rj in zip(u, rvec)]
            u_plus += t
            if np.isfinite(t2):
                Y = Y + t * Yz
            if t == t2:
                active.append((p, sp_))
                u.append(u_plus)
                V.append(Yv)
                M = np.block([[M, cvec[:, None]], [cvec[None, :], np.array([[Mpp]])]])
                added = True
            else:
                del active[kdrop], u[kdrop], V[kdrop]
                M = np.delete(np.delete(M, kdrop, 0), kdrop, 1)
        if status != SOLVED:
            break
    if status == SOLVED and active:
        # polish: the minimiser on the final working set computed afresh from Y0, free of the
        # rounding the steps accumulated along the QP's flat directions (the drives' internal
        # force, weighted only by the small force penalty)
        Y, lam = on_working_set()
        u = list(lam)
    v_all = np.array([value(i, Y) for i in range(len(cols))])
    worst_v = float(max(np.maximum(lo - v_all, v_all - hi).max(initial=0.0), 0.0))
    return DualResult(status, Y, iterations, active, np.array(u), worst_v)
