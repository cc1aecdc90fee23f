"""The constrained mode's per-step QP, compiled (numba): the rows of the constraints, the
prediction and Hessian, the equality elimination, the screening and checking of rows.

Why compiled: the numpy assembly of one step's QP
(:class:`~planner.constraints.reference.ReferenceAssembly`, the reference) is a few dozen
array operations on small arrays plus the dense products ``Sel Gx`` and ``Gp2' W Gp2``; most
of its cost was call overhead and multiplications by the zeros of the block lower-triangular
prediction matrix. Here products skip those zeros, the Hessian comes from a backward
recursion, and the constraint selection ``Sel`` is kept sparse (at most three entries per
row: a pose coordinate, a half-plane normal, a leg Jacobian row).
``tests/test_constraints_kernels.py`` checks that both assemblies give the same QP, and that
the QP with its equalities eliminated has the same minimiser.

The kernels are positional and internal: they are called only from methods of the typed
step data (:mod:`~planner.constraints.rows`, :mod:`~planner.constraints.step`) and of the
compiled assembly (:mod:`~planner.constraints.compiled`), which name what they pass.

Layout: states are stacked per sample, ``X[6 i + a]`` (``a`` = x, y, psi, x_dot, y_dot,
psi_dot of sample ``i + 1``); the scaled moves ``z = u / force_max`` per sample,
``z[m i + l]`` (``m`` legs). Rows are a sparse selection of predicted states: row ``r`` is
``sum_k val[r, k] X[col[r, k]]`` (``col`` -1: unused) with bounds ``b0l <= . <= b0u``, all in
row units (``unit`` = :data:`~planner.constraints.rows.ROW_UNIT_M` metres).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..model.kernels import rk4, state_derivative

__all__ = ["KIND_CORRIDOR", "KIND_SPEED", "KIND_STROKE", "approach_count", "approach_fill", "assemble",
           "check_rows", "constraint_matrix", "corridor_count", "corridor_fill", "finish", "first_legs", "free_parts",
           "hessian", "leg_rows", "offset", "one_step_error", "plant_step", "predict", "prediction", "reduce_check",
           "reduce_forward", "reduce_free", "reduce_problem", "reduce_screen", "reduce_setup", "reduce_start", "screen",
           "solver_problem", "speed_fill", "stroke_fill"]

#: kinds of rows (the slack variable that softens each in the slack problem); the values of
#: :class:`planner.constraints.rows.RowKind`
KIND_CORRIDOR, KIND_STROKE, KIND_SPEED = 0, 1, 2


@njit(cache=True)
def leg_rows(r0, base, poses, J, L):
    """Leg Jacobians ``J_l`` (k, n, 3) and leg lengths (k, n) [m] at the poses (k, 3), into
    ``J`` and ``L``: the compiled twin of :func:`planner.model.kinematics.leg_jacobians` and
    :func:`~planner.model.kinematics.leg_lengths` (``r0``: :attr:`RobotModel.r0`)."""
    n = r0.shape[0]
    for k in range(poses.shape[0]):
        c, s = math.cos(poses[k, 2]), math.sin(poses[k, 2])
        for i in range(n):
            rx = c * r0[i, 0] - s * r0[i, 1]
            ry = s * r0[i, 0] + c * r0[i, 1]
            dx = poses[k, 0] + rx - base[i, 0]
            dy = poses[k, 1] + ry - base[i, 1]
            li = math.hypot(dx, dy)
            ex, ey = dx / li, dy / li
            J[k, i, 0], J[k, i, 1], J[k, i, 2] = ex, ey, rx * ey - ry * ex
            L[k, i] = li


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


# ---- the rows of each constraint (compiled twins of the constraint objects' ``rows``) -------
# Each constraint has a count and a fill: ``*_count`` gives its number of rows for the
# samples' sequence indices ``idx`` (N,), ``*_fill`` writes them from row ``r`` on and returns
# the next free row. :func:`assemble` calls them in row order.

@njit(cache=True)
def corridor_count(idx, has_hp, hp_ptr):
    """Rows of :class:`~planner.constraints.corridor.CorridorConstraint`: one per sample and
    box axis (x and y only where the sample has no half-planes), and its half-planes."""
    N = idx.shape[0]
    n = 0
    for ax in range(3):
        for j in range(N):
            if ax == 2 or not has_hp[idx[j]]:
                n += 1
    for j in range(N):
        s = idx[j]
        if has_hp[s]:
            n += hp_ptr[s + 1] - hp_ptr[s]
    return n


@njit(cache=True)
def corridor_fill(idx, unit, lo, hi, has_hp, hp_ptr, hp_A, hp_b, col, val, b0l, b0u, kinds, r):
    """The corridor rows: ``lo <= pose_j <= hi`` per axis (sorted by axis, then sample), then
    the half-planes ``A (x, y)_j <= b`` of the samples that have them (the pose sets per
    sequence index; half-planes of sequence index ``s`` are ``hp_A[hp_ptr[s]:hp_ptr[s+1]]``)."""
    N = idx.shape[0]
    for ax in range(3):
        for j in range(N):
            s = idx[j]
            if ax == 2 or not has_hp[s]:
                col[r, 0] = 6 * j + ax
                val[r, 0] = 1.0 / unit
                b0l[r] = lo[s, ax] / unit
                b0u[r] = hi[s, ax] / unit
                kinds[r] = KIND_CORRIDOR
                r += 1
    for j in range(N):
        s = idx[j]
        if has_hp[s]:
            for h in range(hp_ptr[s], hp_ptr[s + 1]):
                col[r, 0], col[r, 1] = 6 * j, 6 * j + 1
                val[r, 0], val[r, 1] = hp_A[h, 0] / unit, hp_A[h, 1] / unit
                b0l[r] = -np.inf
                b0u[r] = hp_b[h] / unit
                kinds[r] = KIND_CORRIDOR
                r += 1
    return r


@njit(cache=True)
def approach_count(idx, app_on, app_from):
    """Rows of :class:`~planner.constraints.corridor.EndApproachConstraint`: one per sample
    from sequence index ``app_from`` on."""
    n = 0
    if app_on:
        for j in range(idx.shape[0]):
            if idx[j] >= app_from:
                n += 1
    return n


@njit(cache=True)
def approach_fill(idx, unit, app_on, app_d, app_b, app_from, col, val, b0l, b0u, kinds, r):
    """The no-overshoot rows ``d . (x, y)_j <= b``."""
    if app_on:
        for j in range(idx.shape[0]):
            if idx[j] >= app_from:
                col[r, 0], col[r, 1] = 6 * j, 6 * j + 1
                val[r, 0], val[r, 1] = app_d[0] / unit, app_d[1] / unit
                b0l[r] = -np.inf
                b0u[r] = app_b / unit
                kinds[r] = KIND_CORRIDOR
                r += 1
    return r


@njit(cache=True)
def speed_fill(J, unit, vmax, col, val, b0l, b0u, kinds, r):
    """:class:`~planner.constraints.drives.LegSpeedConstraint`: ``|J_l(y0_j) y_dot_j| <= vmax``
    per sample and leg (``J`` (N, n, 3) at the nominal poses)."""
    for j in range(J.shape[0]):
        for i in range(J.shape[1]):
            for a in range(3):
                col[r, a] = 6 * j + 3 + a
                val[r, a] = J[j, i, a] / unit
            b0l[r] = -vmax[i] / unit
            b0u[r] = vmax[i] / unit
            kinds[r] = KIND_SPEED
            r += 1
    return r


@njit(cache=True)
def stroke_fill(J, L, y_nom, unit, lmin, lmax, col, val, b0l, b0u, kinds, r):
    """:class:`~planner.constraints.drives.LegStrokeConstraint`: ``lmin <= l(y0_j) + J_l(y0_j)
    (y_j - y0_j) <= lmax`` per sample and leg (``L`` (N, n) leg lengths at ``y_nom``)."""
    for j in range(J.shape[0]):
        for i in range(J.shape[1]):
            off = L[j, i] - (J[j, i, 0] * y_nom[j, 0] + J[j, i, 1] * y_nom[j, 1] + J[j, i, 2] * y_nom[j, 2])
            for a in range(3):
                col[r, a] = 6 * j + a
                val[r, a] = J[j, i, a] / unit
            b0l[r] = (lmin[i] - off) / unit
            b0u[r] = (lmax[i] - off) / unit
            kinds[r] = KIND_STROKE
            r += 1
    return r


@njit(cache=True)
def assemble(k, N, x, y_prev, unit, K, lower, upper, qa, qb, r0, base,
             lo, hi, has_hp, hp_ptr, hp_A, hp_b, app_on, app_d, app_b, app_from, vmax, lmin, lmax):
    """The rows and criterion of step ``k`` in one call (few calls per step: numpy's per-call
    cost dominated these sizes). Inputs: the step (``k``, horizon ``N``, state ``x``, the
    previous step's predicted poses shifted ``y_prev`` (N, 3), empty at the first step: then
    the legs are linearised at ``x``), the row unit, the range sequence padded with ``N``
    copies of its last sample (``K`` samples; ``lower, upper, qa, qb`` as
    ``RangeSequence.window``), the legs (``r0``, ``base``), then each constraint's arrays in row
    order: corridor (``lo .. hp_b``), end approach (``app_*``), leg speed (``vmax``), stroke
    (``lmin``, ``lmax``).

    Returns ``(W, tgt, col, val, b0l, b0u, kinds, n_hard, speed0, stroke0)``: the criterion's
    weights ``W = qa^2 + qb^2`` and targets ``tgt = qa^2 r_a + qb^2 r_b`` of samples
    ``k+1..k+N`` (3N,), the rows, the number of hard rows (the stroke rows after them enter
    only the slack problem) and the first leg-speed and stroke rows (those of sample 0)."""
    m = r0.shape[0]
    kw = min(k, K)
    W = np.empty(3 * N)
    tgt = np.empty(3 * N)
    for i in range(N):
        for a in range(3):
            ca, cb = qa[kw + i, a] * qa[kw + i, a], qb[kw + i, a] * qb[kw + i, a]
            W[3 * i + a] = ca + cb
            tgt[3 * i + a] = ca * lower[kw + i, a] + cb * upper[kw + i, a]
    idx = np.empty(N, np.int64)
    for j in range(N):
        idx[j] = min(k + j, K - 1)
    y_nom = np.empty((N, 3))
    for j in range(N):
        for a in range(3):
            y_nom[j, a] = y_prev[j, a] if y_prev.shape[0] > 0 else x[a]
    J = np.empty((N, m, 3))
    L = np.empty((N, m))
    leg_rows(r0, base, y_nom, J, L)
    nrow = corridor_count(idx, has_hp, hp_ptr) + approach_count(idx, app_on, app_from) + 2 * N * m
    col = np.full((nrow, 3), -1, np.int64)
    val = np.zeros((nrow, 3))
    b0l = np.empty(nrow)
    b0u = np.empty(nrow)
    kinds = np.zeros(nrow, np.int64)
    r = corridor_fill(idx, unit, lo, hi, has_hp, hp_ptr, hp_A, hp_b, col, val, b0l, b0u, kinds, 0)
    r = approach_fill(idx, unit, app_on, app_d, app_b, app_from, col, val, b0l, b0u, kinds, r)
    speed0 = r
    r = speed_fill(J, unit, vmax, col, val, b0l, b0u, kinds, r)
    n_hard = r
    stroke_fill(J, L, y_nom, unit, lmin, lmax, col, val, b0l, b0u, kinds, r)
    return W, tgt, col, val, b0l, b0u, kinds, n_hard, speed0, n_hard


@njit(cache=True)
def first_legs(x1, r0, base, lmin, lmax, unit, speed0, stroke0, val, b0l, b0u):
    """Sample 0's leg rows linearised at the plant's next pose ``x1[:3]`` instead of the
    nominal pose: the leg-speed rows from ``speed0`` and the stroke rows from ``stroke0``
    (their selection and the stroke bounds), in place."""
    m = r0.shape[0]
    y1 = np.empty((1, 3))
    for a in range(3):
        y1[0, a] = x1[a]
    J = np.empty((1, m, 3))
    L = np.empty((1, m))
    leg_rows(r0, base, y1, J, L)
    for i in range(m):
        for a in range(3):
            val[speed0 + i, a] = J[0, i, a] / unit
            val[stroke0 + i, a] = J[0, i, a] / unit
        off = (L[0, i] - (J[0, i, 0] * y1[0, 0] + J[0, i, 1] * y1[0, 1] + J[0, i, 2] * y1[0, 2])) / unit
        b0l[stroke0 + i] = lmin[i] / unit - off
        b0u[stroke0 + i] = lmax[i] / unit - off


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
    acc = 0.0
    for k in range(col.shape[1]):
        c = col[r, k]
        if c >= 0:
            acc += val[r, k] * X[c]
    return acc


@njit(cache=True)
def _matrix_row_into(col, val, Gx, A, r, i):
    """Row ``i`` of ``A`` = row ``r`` of ``Sel Gx``."""
    N = Gx.shape[0] // 6
    m = Gx.shape[1] // N
    A[i, :] = 0.0
    for k in range(col.shape[1]):
        c = col[r, k]
        if c < 0:
            continue
        v = val[r, k]
        nc = m * (c // 6 + 1)
        for q in range(nc):
            A[i, q] += v * Gx[c, q]


@njit(cache=True)
def constraint_matrix(col, val, Gx, A):
    """``A = Sel Gx`` of every row, into ``A`` (nrow, N m)."""
    for r in range(col.shape[0]):
        _matrix_row_into(col, val, Gx, A, r, r)


@njit(cache=True)
def screen(col, val, b0l, b0u, kinds, n_hard, X, delta, keep):
    """Mark in ``keep`` the rows (of the first ``n_hard``) that the solver is given: the
    equalities and every row within ``delta[kind]`` of a bound at the predicted states ``X``
    (the warm start's prediction). Returns how many."""
    count = 0
    for r in range(n_hard):
        v = _row_value(col, val, X, r)
        d = delta[kinds[r]]
        if b0u[r] - b0l[r] <= 0.0 or v - b0l[r] < d or b0u[r] - v < d:
            keep[r] = True
        if keep[r]:
            count += 1
    return count


@njit(cache=True)
def check_rows(col, val, b0l, b0u, n_hard, X, keep, tol):
    """Largest violation of the first ``n_hard`` rows at the predicted states ``X``
    (``b0l <= Sel X <= b0u``, i.e. ``bl <= A z <= bu``; 0 if none); rows not in ``keep``
    violated by more than ``tol`` are added to ``keep``. Returns ``(worst, added)``."""
    worst = 0.0
    added = 0
    for r in range(n_hard):
        v = _row_value(col, val, X, r)
        e = max(b0l[r] - v, v - b0u[r])
        worst = max(worst, e)
        if e > tol and not keep[r]:
            keep[r] = True
            added += 1
    return worst, added


@njit(cache=True)
def solver_problem(keep, col, val, Gx, bl, bu):
    """The rows in ``keep`` as DAQP takes them: ``A`` (k, N m) and the bounds and senses of
    the ``N m`` simple bounds ``-1 <= z <= 1`` (the drive forces) followed by the rows
    (sense 5: equality)."""
    nz = Gx.shape[1]
    k = 0
    for r in range(keep.shape[0]):
        if keep[r]:
            k += 1
    A = np.empty((k, nz))
    BU = np.empty(nz + k)
    BL = np.empty(nz + k)
    sense = np.zeros(nz + k, np.int32)
    for q in range(nz):
        BU[q] = 1.0
        BL[q] = -1.0
    i = 0
    for r in range(keep.shape[0]):
        if keep[r]:
            _matrix_row_into(col, val, Gx, A, r, i)
            BU[nz + i] = bu[r]
            BL[nz + i] = bl[r]
            if bu[r] - bl[r] <= 0.0:
                sense[nz + i] = 5
            i += 1
    return A, BU, BL, sense


# ---- the plant's one-step map and the offset (the refinement, see planner.constraints.controller)

@njit(cache=True)
def plant_step(packed, x, u, Ts, substeps):
    """The plant (:func:`planner.model.kernels.rk4` from ``x`` under ``u``, ``x_dot`` at ``x``
    from :func:`~planner.model.kernels.state_derivative`): the state one sample later."""
    f0 = np.empty(6)
    state_derivative(packed, x, u, f0)
    return rk4(packed, x, u, Ts, substeps, f0)


@njit(cache=True)
def offset(x1, x, u, Ad, Bd):
    """``d = x1 - Ad x - Bd u`` (6,)."""
    d = np.empty(6)
    for a in range(6):
        acc = x1[a]
        for t in range(6):
            acc -= Ad[a, t] * x[t]
        for lg in range(u.shape[0]):
            acc -= Bd[a, lg] * u[lg]
        d[a] = acc
    return d


@njit(cache=True)
def one_step_error(packed, x, u, Ad, Bd, d, Ts, substeps):
    """The plant's next state under ``u`` and how far it lands from the QP's prediction of
    it ``Ad x + Bd u + d``: ``(x1, position error [m], angle error [rad])``."""
    x1 = plant_step(packed, x, u, Ts, substeps)
    e = offset(x1, x, u, Ad, Bd)
    return x1, math.hypot(e[0] - d[0], e[1] - d[1]), abs(e[2] - d[2])


@njit(cache=True)
def finish(z, X):
    """After the solve: ``z`` clipped to the force bounds, the predicted states ``X`` as
    (N, 6) and the nominal poses of the next step (the predicted poses shifted by one
    sample, the last repeated)."""
    nz = z.shape[0]
    zc = np.empty(nz)
    for q in range(nz):
        zc[q] = min(max(z[q], -1.0), 1.0)
    N = X.shape[0] // 6
    Xr = X.reshape(N, 6)
    y_nom = np.empty((N, 3))
    for j in range(N):
        s = min(j + 1, N - 1)
        for a in range(3):
            y_nom[j, a] = Xr[s, a]
    return zc, Xr, y_nom


# ---- equalities eliminated ---------------------------------------------------------------
# A row fixing a pose coordinate of sample i (a point range, e.g. psi = 0 along Table I) is
# an equality. DAQP handles each equality as a constraint that is always active, which
# costs about as much as a third of the whole solve per equality at these sizes; here they
# are eliminated through the dynamics instead. With C_i the fixed coordinates of sample i,
# c_i their values, Bu = Bd diag(umax) and Y_i = Ad X_{i-1} (+ d at i = 0) the state before
# move i acts, move i is parametrised as
#
#     z_i = Z_i w_i + K_i (c_i - C_i Y_i),    K_i = (C_i Bu)^+,  Z_i = basis of null(C_i Bu),
#
# so C_i X_i = C_i (Y_i + Bu z_i) = c_i for every w; the map w -> z is an affine bijection
# onto the moves that meet the equalities, so the QP in w (fewer variables, no equalities,
# force bounds as rows) has the same minimiser. Its prediction is the closed loop
# X_i = F_i Ad X_{i-1} + Bu Z_i w_i + Bu K_i c_i with F_i = I - Bu K_i C_i, and its
# Hessian again a backward recursion (see reduce_setup).


@njit(cache=True)
def reduce_setup(Ad, Bd, umax, W, du, col, val, b0l, b0u, n_hard, N):
    """The equalities of the rows (single-entry rows on a pose coordinate with
    ``b0l == b0u``) and the reduced QP's parts that do not depend on the one-step offset.
    Returns ``(ok, nw, off, ecnt, eax, ceq, K, Z, Acl, L, G, Hw, scale, elim, Bu)``:
    ``off[i]`` the first column of ``w_i`` (``nw = off[N]``), ``ecnt[i]``/``eax[i]``/``ceq[i]``
    the number, coordinates and values of sample ``i``'s equalities, ``K, Z, Acl = F Ad``,
    ``L = -K C Ad`` per sample, ``G`` (6N, nw) the closed-loop prediction ``X = Xf + G w``,
    ``Hw`` the scaled Hessian and its scale, ``elim[r]`` whether row ``r`` is eliminated.
    ``ok`` is False (use the QP in ``z``) where there is no equality or one cannot be
    eliminated (``C_i Bu`` rank deficient, or nothing left to optimise)."""
    m = Bd.shape[1]
    nrow = col.shape[0]
    ecnt = np.zeros(N, np.int64)
    eax = np.zeros((N, 3), np.int64)
    ceq = np.zeros((N, 3))
    elim = np.zeros(nrow, np.bool_)
    K = np.zeros((N, m, 3))
    Z = np.zeros((N, m, m))
    Acl = np.zeros((N, 6, 6))
    L = np.zeros((N, m, 6))
    off = np.zeros(N + 1, np.int64)
    Bu = np.empty((6, m))
    for a in range(6):
        for lg in range(m):
            Bu[a, lg] = Bd[a, lg] * umax[lg]
    bad = (False, 0, off, ecnt, eax, ceq, K, Z, Acl, L, np.zeros((6 * N, 0)), np.zeros((0, 0)), 1.0, elim, Bu)
    neq = 0
    for r in range(n_hard):
        c = col[r, 0]
        if col[r, 1] < 0 and c >= 0 and c % 6 < 3 and b0u[r] - b0l[r] <= 0.0 and val[r, 0] != 0.0:
            i = c // 6
            dup = False
            for t in range(ecnt[i]):
                if eax[i, t] == c % 6:
                    dup = True
            if dup:
                continue
            eax[i, ecnt[i]] = c % 6
            ceq[i, ecnt[i]] = b0l[r] / val[r, 0]
            ecnt[i] += 1
            elim[r] = True
            neq += 1
    if neq == 0:
        return bad
    # per pattern of fixed coordinates (a bit mask): K, Z and the closed-loop matrices
    bnorm = 0.0
    for a in range(6):
        for lg in range(m):
            bnorm = max(bnorm, abs(Bu[a, lg]))
    for i in range(N):
        e = ecnt[i]
        if e > m:
            return bad
        if e == 0:
            for lg in range(m):
                Z[i, lg, lg] = 1.0
            for a in range(6):
                Acl[i, a, :] = Ad[a, :]
            off[i + 1] = off[i] + m
            continue
        same = -1
        for h in range(i):
            if ecnt[h] == e:
                match = True
                for t in range(e):
                    if eax[h, t] != eax[i, t]:
                        match = False
                if match:
                    same = h
                    break
        if same >= 0:
            K[i] = K[same]
            Z[i] = Z[same]
            Acl[i] = Acl[same]
            L[i] = L[same]
        else:
            CB = np.empty((e, m))
            for t in range(e):
                for lg in range(m):
                    CB[t, lg] = Bu[eax[i, t], lg]
            U, s, Vt = np.linalg.svd(CB)
            if not s[e - 1] > 1e-9 * bnorm:
                return bad
            for lg in range(m):
                for t in range(e):
                    acc = 0.0
                    for q in range(e):
                        acc += Vt[q, lg] / s[q] * U[t, q]
                    K[i, lg, t] = acc
                for q in range(m - e):
                    Z[i, lg, q] = Vt[e + q, lg]
            # L = -K C Ad ; Acl = Ad + Bu L
            for lg in range(m):
                for b in range(6):
                    acc = 0.0
                    for t in range(e):
                        acc -= K[i, lg, t] * Ad[eax[i, t], b]
                    L[i, lg, b] = acc
            for a in range(6):
                for b in range(6):
                    acc = Ad[a, b]
                    for lg in range(m):
                        acc += Bu[a, lg] * L[i, lg, b]
                    Acl[i, a, b] = acc
        off[i + 1] = off[i] + m - e
    nw = off[N]
    if nw == 0:
        return bad
    # closed-loop prediction: G[i, j] = Bu Z_j (i = j), Acl_i G[i-1, j] (i > j); row block i
    # is Acl_i times row block i-1 (all earlier columns at once), then Bu Z_i
    G = np.zeros((6 * N, nw))
    for i in range(N):
        if i > 0:
            c_end = off[i]
            for a in range(6):
                for b in range(6):
                    s_ = Acl[i, a, b]
                    if s_ == 0.0:
                        continue
                    for c in range(c_end):
                        G[6 * i + a, c] += s_ * G[6 * (i - 1) + b, c]
        ni = off[i + 1] - off[i]
        for a in range(6):
            for q in range(ni):
                acc = 0.0
                for lg in range(m):
                    acc += Bu[a, lg] * Z[i, lg, q]
                G[6 * i + a, off[i] + q] = acc
    # Hessian (lower triangle, then mirrored): state weights Qt_i = diag(W_i, 0) +
    # L_{i+1}' Du L_{i+1}, backward Pi_j = Qt_j + Acl_{j+1}' Pi_{j+1} Acl_{j+1}; the rows of w_j
    # and columns of w_j1 (j1 <= j) are (G[j, j]' Pi_j) G[j, j1]; plus Z_i' Du Z_i on the
    # diagonal and Z_i' Du L_i G[i-1, j] in the rows of w_i, columns of w_j (j < i)
    Hw = np.zeros((nw, nw))
    Pi = np.zeros((6, 6))
    T = np.empty((6, 6))
    GPi = np.empty((m, 6))
    for j in range(N - 1, -1, -1):
        if j < N - 1:
            for a in range(6):
                for b in range(6):
                    acc = 0.0
                    for t in range(6):
                        acc += Pi[a, t] * Acl[j + 1, t, b]
                    T[a, b] = acc
            for a in range(6):
                for b in range(a, 6):
                    acc = 0.0
                    for t in range(6):
                        acc += Acl[j + 1, t, a] * T[t, b]
                    Pi[a, b] = acc
                    Pi[b, a] = acc
            if ecnt[j + 1] > 0:
                for a in range(6):
                    for b in range(6):
                        acc = 0.0
                        for lg in range(m):
                            acc += L[j + 1, lg, a] * du[lg] * L[j + 1, lg, b]
                        Pi[a, b] += acc
        for a in range(3):
            Pi[a, a] += W[3 * j + a]
        nj = off[j + 1] - off[j]
        for q in range(nj):
            for a in range(6):
                acc = 0.0
                for t in range(6):
                    acc += G[6 * j + t, off[j] + q] * Pi[t, a]
                GPi[q, a] = acc
        c_end = off[j + 1]
        for q in range(nj):
            r = off[j] + q
            for a in range(6):
                g = GPi[q, a]
                if g == 0.0:
                    continue
                for c in range(c_end):
                    Hw[r, c] += g * G[6 * j + a, c]
    Mi = np.empty((m, 6))
    for i in range(N):
        ni = off[i + 1] - off[i]
        for q1 in range(ni):
            for q2 in range(ni):
                acc = 0.0
                for lg in range(m):
                    acc += Z[i, lg, q1] * du[lg] * Z[i, lg, q2]
                Hw[off[i] + q1, off[i] + q2] += acc
        if ecnt[i] > 0 and i > 0:
            for q in range(ni):
                for b in range(6):
                    acc = 0.0
                    for lg in range(m):
                        acc += Z[i, lg, q] * du[lg] * L[i, lg, b]
                    Mi[q, b] = acc
            c_end = off[i]
            for q in range(ni):
                r = off[i] + q
                for b in range(6):
                    g = Mi[q, b]
                    if g == 0.0:
                        continue
                    for c in range(c_end):
                        Hw[r, c] += g * G[6 * (i - 1) + b, c]
    for r in range(nw):  # mirror the lower triangle
        for c in range(r + 1, nw):
            Hw[r, c] = Hw[c, r]
    big = 0.0
    for c in range(nw):
        big = max(big, Hw[c, c])
    scale = 1.0 / max(big, 1e-300)
    for c1 in range(nw):
        for c2 in range(nw):
            Hw[c1, c2] *= scale
    return True, nw, off, ecnt, eax, ceq, K, Z, Acl, L, G, Hw, scale, elim, Bu


@njit(cache=True)
def reduce_forward(x, d, Ad, Bu, ecnt, eax, ceq, K, Z, off, w, z, X):
    """Moves ``z`` (N m) and states ``X`` (6N) of the parametrisation at ``w`` (see
    :func:`reduce_setup`), by running the prediction model forward; ``w = 0`` gives the
    free parts ``zf`` and ``Xf``."""
    N = ecnt.shape[0]
    m = Bu.shape[1]
    Y = np.empty(6)
    for i in range(N):
        for a in range(6):
            acc = 0.0
            for t in range(6):
                acc += Ad[a, t] * (X[6 * (i - 1) + t] if i > 0 else x[t])
            Y[a] = acc + (d[a] if i == 0 else 0.0)
        e = ecnt[i]
        for lg in range(m):
            acc = 0.0
            for q in range(off[i + 1] - off[i]):
                acc += Z[i, lg, q] * w[off[i] + q]
            for t in range(e):
                acc += K[i, lg, t] * (ceq[i, t] - Y[eax[i, t]])
            z[m * i + lg] = acc
        for a in range(6):
            acc = Y[a]
            for lg in range(m):
                acc += Bu[a, lg] * z[m * i + lg]
            X[6 * i + a] = acc


@njit(cache=True)
def reduce_free(x, d, Ad, Bu, ecnt, eax, ceq, K, Z, Acl, L, G, off, W, tgt, du, scale, col, val, b0l, b0u):
    """The reduced QP's parts that depend on the one-step offset ``d``: the free moves and
    states ``zf, Xf`` (``w = 0``), the linear term ``fw`` (scaled; adjoint recursion
    ``lam_j = e_j + Acl_{j+1}' lam_{j+1}``, ``fw_j = G[j, j]' lam_j + Z_j' Du zf_j`` with
    ``e_j = (W_j Xf_j - tgt_j, 0) + L_{j+1}' Du zf_{j+1}``) and the row bounds
    ``b0 - Sel Xf``. Returns ``(zf, Xf, fw, bl, bu)``."""
    N = ecnt.shape[0]
    m = Bu.shape[1]
    nw = off[N]
    zf = np.empty(N * m)
    Xf = np.empty(6 * N)
    reduce_forward(x, d, Ad, Bu, ecnt, eax, ceq, K, Z, off, np.zeros(nw), zf, Xf)
    fw = np.zeros(nw)
    lam = np.zeros(6)
    tmp = np.empty(6)
    for j in range(N - 1, -1, -1):
        if j < N - 1:
            for b in range(6):
                acc = 0.0
                for a in range(6):
                    acc += Acl[j + 1, a, b] * lam[a]
                tmp[b] = acc
            for b in range(6):
                lam[b] = tmp[b]
            if ecnt[j + 1] > 0:
                for b in range(6):
                    acc = 0.0
                    for lg in range(m):
                        acc += L[j + 1, lg, b] * du[lg] * zf[m * (j + 1) + lg]
                    lam[b] += acc
        for a in range(3):
            lam[a] += W[3 * j + a] * Xf[6 * j + a] - tgt[3 * j + a]
        for q in range(off[j + 1] - off[j]):
            acc = 0.0
            for a in range(6):
                acc += G[6 * j + a, off[j] + q] * lam[a]
            for lg in range(m):
                acc += Z[j, lg, q] * du[lg] * zf[m * j + lg]
            fw[off[j] + q] = acc * scale
    nrow = col.shape[0]
    bl = np.empty(nrow)
    bu = np.empty(nrow)
    for r in range(nrow):
        sf = _row_value(col, val, Xf, r)
        bl[r] = b0l[r] - sf
        bu[r] = b0u[r] - sf
    return zf, Xf, fw, bl, bu


@njit(cache=True)
def reduce_start(z, Z, off, m):
    """A warm start in ``w`` from moves ``z``: ``w_i = Z_i' z_i``."""
    N = off.shape[0] - 1
    w = np.empty(off[N])
    for i in range(N):
        for q in range(off[i + 1] - off[i]):
            acc = 0.0
            for lg in range(m):
                acc += Z[i, lg, q] * z[m * i + lg]
            w[off[i] + q] = acc
    return w


@njit(cache=True)
def reduce_screen(col, val, b0l, b0u, kinds, n_hard, elim, X, z, delta, delta_force, keep, keepf):
    """:func:`screen` for the reduced QP: rows (not eliminated) near a bound at ``X``, and
    force rows with ``|z| > 1 - delta_force`` (the moves at the warm start)."""
    for r in range(n_hard):
        if elim[r]:
            continue
        v = _row_value(col, val, X, r)
        dl = delta[kinds[r]]
        if v - b0l[r] < dl or b0u[r] - v < dl:
            keep[r] = True
    for q in range(z.shape[0]):
        if abs(z[q]) > 1.0 - delta_force:
            keepf[q] = True


@njit(cache=True)
def reduce_check(col, val, b0l, b0u, n_hard, elim, X, z, keep, keepf, tol):
    """:func:`check_rows` for the reduced QP at its moves ``z`` and states ``X``: every
    row (the eliminated ones too) and the force bounds ``|z| <= 1``; violated rows not
    given to the solver are added. Returns ``(worst, added)`` (row units; forces scaled)."""
    worst = 0.0
    added = 0
    for r in range(n_hard):
        v = _row_value(col, val, X, r)
        e = max(b0l[r] - v, v - b0u[r])
        worst = max(worst, e)
        if e > tol and not keep[r] and not elim[r]:
            keep[r] = True
            added += 1
    for q in range(z.shape[0]):
        e = abs(z[q]) - 1.0
        if e > tol and not keepf[q]:
            keepf[q] = True
            added += 1
    return worst, added


@njit(cache=True)
def reduce_problem(keep, keepf, col, val, G, off, L, Z, ecnt, zf, bl, bu, m):
    """The reduced QP's rows as DAQP takes them (no simple bounds): the kept rows
    ``Sel G w`` and the kept force rows ``zf + Gz w`` (``Gz[i, i] = Z_i``,
    ``Gz[i, j] = L_i G[i-1, j]``), with bounds and senses."""
    N = ecnt.shape[0]
    nw = off[N]
    k = 0
    for r in range(keep.shape[0]):
        if keep[r]:
            k += 1
    for q in range(keepf.shape[0]):
        if keepf[q]:
            k += 1
    A = np.zeros((k, nw))
    BU = np.empty(k)
    BL = np.empty(k)
    sense = np.zeros(k, np.int32)
    i = 0
    for r in range(keep.shape[0]):
        if not keep[r]:
            continue
        for t in range(col.shape[1]):
            c = col[r, t]
            if c < 0:
                continue
            v = val[r, t]
            nc = off[c // 6 + 1]
            for q in range(nc):
                A[i, q] += v * G[c, q]
        BU[i] = bu[r]
        BL[i] = bl[r]
        i += 1
    for q in range(keepf.shape[0]):
        if not keepf[q]:
            continue
        s = q // m
        lg = q - s * m
        if s > 0 and ecnt[s] > 0:
            for b in range(6):
                lv = L[s, lg, b]
                if lv == 0.0:
                    continue
                for c in range(off[s]):
                    A[i, c] += lv * G[6 * (s - 1) + b, c]
        for t in range(off[s + 1] - off[s]):
            A[i, off[s] + t] = Z[s, lg, t]
        BU[i] = 1.0 - zf[q]
        BL[i] = -1.0 - zf[q]
        i += 1
    return A, BU, BL, sense
