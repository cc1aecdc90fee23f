"""One step of the constrained controller in one compiled call (numba): the compiled twin of
:meth:`planner.constraints.controller.ConstrainedController.__call__` on the compiled
assembly with the stage-wise solver (the rows, the one-step offset, the factorisation, the
dual active-set solve and the refinement of the offset).

Why one call: each step is a few dozen small kernels; called one by one from Python their
call overhead (and the wrappers' dataclasses) cost as much as their arithmetic. When the
solve does not succeed (infeasible, iteration limit, an equality that cannot be
eliminated) the kernel says so and the controller does the step on the Python path (DAQP,
then the slack problem), which is also the reference this kernel is tested against.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import njit
from .dual_kernels import INFEASIBLE, SOLVED, dual_solve_active
from .kernels import KIND_RATE, finish, first_legs, offset, plant_step
from .registry import assemble
from .stagewise_kernels import stage_setup

__all__ = ["ACCEPT_TOL", "INACCURATE", "NOT_ELIMINATED", "PROOF_FIELDS", "constrained_step", "prediction_violation",
           "proof_rows", "record_proof"]

#: status of a step whose equalities could not be eliminated (else ``stagewise_kernels``' codes)
NOT_ELIMINATED = -3
#: status of a solve the stage-wise method called solved whose moves, predicted by the model
#: itself, violate a row by more than :data:`ACCEPT_TOL` (an ill-conditioned working set)
INACCURATE = -4
#: a stage-wise solution is accepted only if the states the model predicts from its moves
#: (``x_{s+1} = Ad x_s + Bu z_s``, the offset at the first) keep every hard row, the eliminated
#: equalities included, within this (row units: 1e-9 m or rad, 1e-9 m/s, 1e-6 of force_max for
#: the force rates). The dual method's own states ``X`` are ``Y0 + V lam``: with nearly dependent
#: active rows the multipliers ``lam`` reach 1e6-1e7 and the cancellation leaves ``X`` off the
#: dynamics by 1e-5 (issue 20: a zero-width psi range left by 1.9e-7 rad, on a QP DAQP finds
#: infeasible). 1e3 times the solve's tolerance, 1e-3 of the widening of a relaxed step.
ACCEPT_TOL = 1e-6
#: integers per row of a proof carried to the next step (:func:`record_proof`): kind, first
#: column shifted by one sample, rank among the rows of that kind and first column
PROOF_FIELDS = 3


@njit(cache=True)
def constrained_step(k, x, Ad, Bd, y_prev, u_prev, u0, warm, packed, Ts, substeps, umax, zmax, du, unit, N,
                     refine_tol_m, refine_tol_rad, refine_max, tol, dep_tol, warm_tol, relax, max_iter, V, Lm, proof,
                     inputs):
    """Step ``k`` at state ``x`` with the model ``Ad, Bd`` (eq. 9): the rows and criterion
    (``registry.assemble``; ``inputs``: ``K``, the padded range sequence ``lower, upper, qa, qb``,
    the legs ``r0, base``, their strokes ``lmin, lmax`` and the sections' tuples), the legs linearised at
    ``y_prev`` (or at ``x``: empty), the force bounds ``|z| <= zmax`` (N m,) of the scaled
    moves, the forces applied over the previous sample ``u_prev``
    [N] (the rate rows), the warm start ``warm`` (the previous solution shifted: the rows
    at a bound there start in the working set; empty: none), the offset under the guessed move ``u0`` [N], the
    stage-wise problem factorised and solved, and the offset refined at the solution's first
    move while the plant lands farther than ``refine_tol_m`` / ``refine_tol_rad`` from the
    prediction (at most ``refine_max`` times; each re-solve warm-started from the solution
    before it). A QP found infeasible is solved once more
    with every row widened by ``relax`` (row units; ``relax * unit`` of force_max for the
    force-rate rows): a plan that sat on a vertex of its rows
    can leave the next step's QP infeasible by the prediction error of a re-linearised model,
    a fraction of a nanometre; within ``relax`` that is accepted (``relaxed`` in the return).

    A solve is accepted only if the states the model predicts from its moves keep the rows
    within :data:`ACCEPT_TOL` (:func:`prediction_violation`); otherwise it counts as failed
    (:data:`INACCURATE`: relaxed as an infeasible one, then left to the Python path).

    ``proof`` (int64, in and out; empty: not used) carries the rows that proved the previous
    step's hard QP infeasible to this step (:func:`record_proof`). Where it names rows, the hard
    QP with those rows alone (the force bounds and the eliminated equalities kept) is solved
    first: a subset of the rows that is infeasible proves the whole QP infeasible, so the step
    goes to the relaxed QP without the full hard solve, which on a relaxed stretch runs
    hundreds to thousands of active-set changes to its verdict (issue 31 goal 6: the braking
    onto the end point of a 6-leg robot at Ts 1 ms, N 100). Where the subset has a solution
    (or stops at the iteration limit) the full hard QP is solved as without it. The plan is the
    same either way: the step is relaxed exactly when the hard QP has no solution.

    Returns ``(status, Y, z, X, y_nom, iterations, refinements, worst, relaxed)``: 1 solved (else the
    solver's code, :data:`NOT_ELIMINATED` or :data:`INACCURATE`), the solution ``(X, z)`` as solved
    (6N + N m,), the moves clipped to the force bounds (N m,),
    the predicted states (N, 6), the next step's nominal poses (N, 3), the active-set changes,
    the re-solves and the largest row violation of the predicted states (row units)."""
    m = Bd.shape[1]
    n_seq, lo_seq, hi_seq, qa, qb, r0, base, lmin, lmax, sections = inputs
    W, tgt, col, val, lower, upper, kinds, n_hard, speed0, stroke0 = assemble(
        k, N, x, y_prev, u_prev, unit, n_seq, lo_seq, hi_seq, qa, qb, r0, base, sections)
    x1 = plant_step(packed, x, u0, Ts, substeps)
    d = offset(x1, x, u0, Ad, Bd)
    first_legs(x1, r0, base, lmin, lmax, unit, speed0, stroke0, val, lower, upper)
    ok, ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu = stage_setup(Ad, Bd, umax, du, W, col, val, lower, upper,
                                                                          n_hard)
    Y = np.empty(6 * N + N * m)
    if not ok:
        zc, Xr, y_nom = finish(Y[6 * N:], Y[:6 * N])
        return NOT_ELIMINATED, Y, zc, Xr, y_nom, 0, 0, 0.0, False
    iterations = 0
    refinements = 0
    relaxed = False
    u1 = np.empty(m)
    start = warm
    qmax = V.shape[0]
    act = np.empty(qmax, np.int64)
    sgn = np.empty(qmax)
    nx = 6 * N
    # the previous step's proof: this step's hard QP on those rows alone, solved first
    subset = proof.shape[0] > 0 and proof[0] > 0
    if subset:
        lo_s, hi_s = proof_rows(proof, col, kinds, lower, upper, elim, n_hard)
    else:
        lo_s, hi_s = lower, upper
    if proof.shape[0] > 0:
        proof[0] = 0
    while True:
        status = SOLVED
        worst = 0.0
        proved = False
        if subset:
            subset = False
            status, it, n_act, worst, p, side = dual_solve_active(
                ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu, du, x, d, tgt, col, val, lo_s, hi_s, zmax, n_hard,
                tol, dep_tol, warm_tol, max_iter, start, V, Lm, Y, act, sgn)
            iterations += it
            if status == INFEASIBLE:
                proved = True
                record_proof(proof, act, n_act, p, col, kinds, n_hard, nx, m)
        if not proved:
            status, it, n_act, worst, p, side = dual_solve_active(
                ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu, du, x, d, tgt, col, val, lower, upper, zmax,
                n_hard, tol, dep_tol, warm_tol, max_iter, start, V, Lm, Y, act, sgn)
            iterations += it
            if status == INFEASIBLE and not relaxed and proof.shape[0] > 0:
                record_proof(proof, act, n_act, p, col, kinds, n_hard, nx, m)
        if status == SOLVED:
            worst = prediction_violation(Ad, Bu, x, d, col, val, lower, upper, zmax, n_hard, Y)
            if not worst <= ACCEPT_TOL:
                status = INACCURATE
        if status != SOLVED and not relaxed:
            relaxed = True
            for i in range(n_hard):
                if not elim[i]:  # the rate rows are in force_max, not in row units
                    r_i = relax * unit if kinds[i] == KIND_RATE else relax
                    lower[i] -= r_i
                    upper[i] += r_i
            continue
        if status != SOLVED or refinements >= refine_max:
            break
        for lg in range(m):
            u1[lg] = Y[6 * N + lg] * umax[lg]
        x1 = plant_step(packed, x, u1, Ts, substeps)
        e = offset(x1, x, u1, Ad, Bd)
        if math.hypot(e[0] - d[0], e[1] - d[1]) <= refine_tol_m and abs(e[2] - d[2]) <= refine_tol_rad:
            break
        d = e
        first_legs(x1, r0, base, lmin, lmax, unit, speed0, stroke0, val, lower, upper)
        refinements += 1
        start = Y.copy()  # the re-solve starts from this solution: the offset moved a little
    zc, Xr, y_nom = finish(Y[6 * N:], Y[:6 * N])
    clip_first_rates(zc, col, lower, upper, kinds, elim, n_hard, 6 * N, m, relax * unit if relaxed else 0.0)
    return status, Y, zc, Xr, y_nom, iterations, refinements, worst, relaxed


@njit(cache=True)
def record_proof(proof, act, n_act, p, col, kinds, n_hard, nx, m):
    """The rows of an infeasibility proof (the active constraints ``act[:n_act]`` and the
    violated row ``p`` of ``dual_solve_active``) as the next step will see them, into
    ``proof``: ``proof[0]`` rows, then :data:`PROOF_FIELDS` integers each: the row's kind, its
    first column one sample earlier (the next step's horizon starts a sample later) and its
    rank among the rows of that kind and first column (the half-planes of a sample, the legs).
    Rows of the first sample (they leave the horizon) and the force bounds (always in the
    subset) are left out."""
    cap = (proof.shape[0] - 1) // PROOF_FIELDS
    n = 0
    for j in range(n_act + 1):
        i = act[j] if j < n_act else p
        if i < 0 or i >= n_hard:
            continue
        c = col[i, 0]
        if c < nx:
            if c < 6:
                continue
            shifted = c - 6
        else:
            if c - nx < m:
                continue
            shifted = c - m
        rank = 0
        for r in range(i):
            if kinds[r] == kinds[i] and col[r, 0] == c:
                rank += 1
        if n < cap:
            proof[1 + PROOF_FIELDS * n] = kinds[i]
            proof[2 + PROOF_FIELDS * n] = shifted
            proof[3 + PROOF_FIELDS * n] = rank
            n += 1
    proof[0] = n


@njit(cache=True)
def proof_rows(proof, col, kinds, lower, upper, elim, n_hard):
    """The bounds of the hard QP with only the rows the previous step's proof names
    (:func:`record_proof`): the other hard rows unbounded (the eliminated equalities kept).
    Returns ``(lower, upper)`` (copies)."""
    keep = np.zeros(n_hard, np.bool_)
    for e in range(proof[0]):
        kind = proof[1 + PROOF_FIELDS * e]
        c = proof[2 + PROOF_FIELDS * e]
        rank = proof[3 + PROOF_FIELDS * e]
        seen = 0
        for r in range(n_hard):
            if kinds[r] == kind and col[r, 0] == c:
                if seen == rank:
                    keep[r] = True
                    break
                seen += 1
    lo = lower.copy()
    hi = upper.copy()
    for r in range(n_hard):
        if not keep[r] and not elim[r]:
            lo[r] = -np.inf
            hi[r] = np.inf
    return lo, hi


@njit(cache=True)
def clip_first_rates(zc, col, lower, upper, kinds, elim, n_hard, q0, m, widened):
    """The applied (first) moves ``zc[:m]`` clipped, in place, to their force-rate rows as
    given (before a relaxed step's widening by ``widened``, in force_max): a relaxed solve
    may use the widening (8e-7 of force_max, 6e-4 of a 20 N/s x 0.01 s step), the solve's
    acceptance 1e-6; the plant gets a force within its rate limit (issue 31). The plan's
    prediction keeps the solved move: the next step starts from the actual state."""
    for i in range(n_hard):
        if kinds[i] != KIND_RATE or col[i, 1] >= 0 or col[i, 0] < q0 or col[i, 0] >= q0 + m:
            continue
        r = 0.0 if elim[i] else widened
        q = col[i, 0] - q0
        zc[q] = min(max(zc[q], lower[i] + r), upper[i] - r)


@njit(cache=True)
def prediction_violation(Ad, Bu, x, d, col, val, lower, upper, zmax, n_hard, Y):
    """The largest violation (row units, 0 if none) of the hard rows (equalities included) and
    of the force bounds ``|z| <= zmax`` by the moves ``z = Y[6N:]`` and the states the model
    predicts from them, ``x_{s+1} = Ad x_s + Bu z_s`` (+ ``d`` at ``s = 0``, from ``x_0 = x``):
    eq. (11) in the scaled moves, as the dense QP's ``X = free + Gx z``; ``Y``'s own states are
    not read."""
    m = Bu.shape[1]
    N = (Y.shape[0]) // (6 + m)
    nx = 6 * N
    Yc = np.empty(Y.shape[0])
    for q in range(nx, Y.shape[0]):
        Yc[q] = Y[q]
    for s in range(N):
        for a in range(6):
            acc = d[a] if s == 0 else 0.0
            for b in range(6):
                acc += Ad[a, b] * (x[b] if s == 0 else Yc[6 * (s - 1) + b])
            for lg in range(m):
                acc += Bu[a, lg] * Y[nx + m * s + lg]
            Yc[6 * s + a] = acc
    worst = 0.0
    for i in range(n_hard):
        v = 0.0
        for t in range(col.shape[1]):
            cc = col[i, t]
            if cc >= 0:
                v += val[i, t] * Yc[cc]
        worst = max(worst, lower[i] - v, v - upper[i])
    for q in range(nx, Y.shape[0]):
        worst = max(worst, abs(Y[q]) - zmax[q - nx])
    return worst
