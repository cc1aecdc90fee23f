"""The constrained mode's per-step rows and plant step, compiled (numba): the rows of every
constraint (the twins of the constraint objects' ``rows``), the criterion's weights and
targets, the plant's one-step map and the offset. The dense QP in ``z`` is in
:mod:`planner.constraints.dense_kernels`, the stage-wise solver in
:mod:`planner.constraints.stagewise_kernels` and :mod:`planner.constraints.dual_kernels`.

Why compiled: the numpy assembly of one step
(:class:`~planner.constraints.reference.ReferenceAssembly`, the reference) is a few dozen
array operations on small arrays; most of its cost was call overhead. The constraint
selection ``Sel`` is kept sparse (at most three entries per row: a pose coordinate, a
half-plane normal, a leg Jacobian row, a move and its predecessor).
``tests/test_constraints_kernels.py`` checks that both assemblies give the same rows and QP.

The kernels are positional and internal: they are called only from methods of the typed
step data (:mod:`~planner.constraints.rows`, :mod:`~planner.constraints.step`) and of the
compiled assembly (:mod:`~planner.constraints.compiled`), which name what they pass.

Layout: states are stacked per sample, ``X[6 i + a]`` (``a`` = x, y, psi, x_dot, y_dot,
psi_dot of sample ``i + 1``); the scaled moves ``z = u / force_max`` per sample,
``z[m i + l]`` (``m`` legs), after the states in ``Y = (X, z)``. Rows are a sparse selection
of ``Y``: row ``r`` is ``sum_k val[r, k] Y[col[r, k]]`` (``col`` -1: unused) with bounds
``b0l <= . <= b0u``, all in row units (``unit`` = :data:`~planner.constraints.rows.ROW_UNIT_M`).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import njit
from ..model.kernels import leg_jacobians, rk4, state_derivative

__all__ = ["KIND_CORRIDOR", "KIND_RATE", "KIND_SPEED", "KIND_STROKE", "approach_count", "approach_fill",
           "arrival_count", "arrival_fill", "assemble", "corridor_count", "corridor_fill", "finish", "first_legs",
           "offset", "one_step_error", "plant_step", "rate_fill", "speed_fill", "stroke_fill"]

#: kinds of rows (the slack variable that softens each in the slack problem; rate rows are
#: never softened); the values of :class:`planner.constraints.rows.RowKind`
KIND_CORRIDOR, KIND_STROKE, KIND_SPEED, KIND_RATE = 0, 1, 2, 3


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
def corridor_fill(idx, unit, lo, hi, lo_deep, hi_deep, has_hp, hp_ptr, hp_A, hp_b, recourse, col, val, b0l, b0u, kinds,
                  r):
    """The corridor rows: ``lo <= pose_j <= hi`` per axis (sorted by axis, then sample; the
    horizon's first sample with ``lo, hi``, the later with ``lo_deep, hi_deep``), then the
    half-planes ``A (x, y)_j <= b`` (``b - recourse`` after the first sample) of the samples
    that have them (the pose sets per sequence index; half-planes of sequence index ``s`` are
    ``hp_A[hp_ptr[s]:hp_ptr[s+1]]``)."""
    N = idx.shape[0]
    for ax in range(3):
        for j in range(N):
            s = idx[j]
            if ax == 2 or not has_hp[s]:
                col[r, 0] = 6 * j + ax
                val[r, 0] = 1.0 / unit
                b0l[r] = (lo[s, ax] if j == 0 else lo_deep[s, ax]) / unit
                b0u[r] = (hi[s, ax] if j == 0 else hi_deep[s, ax]) / unit
                kinds[r] = KIND_CORRIDOR
                r += 1
    for j in range(N):
        s = idx[j]
        if has_hp[s]:
            for h in range(hp_ptr[s], hp_ptr[s + 1]):
                col[r, 0], col[r, 1] = 6 * j, 6 * j + 1
                val[r, 0], val[r, 1] = hp_A[h, 0] / unit, hp_A[h, 1] / unit
                b0l[r] = -np.inf
                b0u[r] = (hp_b[h] - (recourse if j > 0 else 0.0)) / unit
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
def approach_fill(idx, unit, app_on, app_d, app_b, app_from, recourse, col, val, b0l, b0u, kinds, r):
    """The no-overshoot rows ``d . (x, y)_j <= b`` (``b - recourse`` after the first sample)."""
    if app_on:
        for j in range(idx.shape[0]):
            if idx[j] >= app_from:
                col[r, 0], col[r, 1] = 6 * j, 6 * j + 1
                val[r, 0], val[r, 1] = app_d[0] / unit, app_d[1] / unit
                b0l[r] = -np.inf
                b0u[r] = (app_b - (recourse if j > 0 else 0.0)) / unit
                kinds[r] = KIND_CORRIDOR
                r += 1
    return r


@njit(cache=True)
def arrival_count(idx, arr_from):
    """Rows of :class:`~planner.constraints.corridor.ArrivalConstraint`: three per sample from
    sequence index ``arr_from`` on."""
    n = 0
    for j in range(idx.shape[0]):
        if idx[j] >= arr_from:
            n += 3
    return n


@njit(cache=True)
def arrival_fill(idx, unit, arr_from, arr_lim, col, val, b0l, b0u, kinds, r):
    """The arrival rows ``|velocity_j| <= arr_lim`` (x, y, psi rates)."""
    for j in range(idx.shape[0]):
        if idx[j] >= arr_from:
            for a in range(3):
                col[r, 0] = 6 * j + 3 + a
                val[r, 0] = 1.0 / unit
                b0l[r] = -arr_lim[a] / unit
                b0u[r] = arr_lim[a] / unit
                kinds[r] = KIND_SPEED
                r += 1
    return r


@njit(cache=True)
def rate_fill(N, u_prev, unit, rate_on, umax, rate_step, recourse, col, val, b0l, b0u, kinds, r):
    """:class:`~planner.constraints.drives.DriveForceRateConstraint`: ``|u(j) - u(j-1)| <=
    rate_step`` (``(1 - recourse) rate_step`` for ``j >= 1``) per move and drive, on the
    moves (``Y[6N + m j + i]``; ``u(-1) = u_prev``), in the scaled moves' unit (divided by
    ``umax``; ``unit`` is not used)."""
    if not rate_on:
        return r
    m = umax.shape[0]
    for j in range(N):
        for i in range(m):
            col[r, 0] = 6 * N + m * j + i
            val[r, 0] = 1.0
            if j > 0:
                col[r, 1] = 6 * N + m * (j - 1) + i
                val[r, 1] = -1.0
                b0l[r] = -(1.0 - recourse) * rate_step[i] / umax[i]
                b0u[r] = (1.0 - recourse) * rate_step[i] / umax[i]
            else:
                b0l[r] = (u_prev[i] - rate_step[i]) / umax[i]
                b0u[r] = (u_prev[i] + rate_step[i]) / umax[i]
            kinds[r] = KIND_RATE
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
def assemble(k, N, x, y_prev, u_prev, unit, K, lower, upper, qa, qb, r0, base,
             lo, hi, lo_deep, hi_deep, has_hp, hp_ptr, hp_A, hp_b, recourse, app_on, app_d, app_b, app_from, arr_from,
             arr_lim, vmax,
             rate_on, umax, rate_step, rate_recourse, lmin, lmax):
    """The rows and criterion of step ``k`` in one call (few calls per step: numpy's per-call
    cost dominated these sizes). Inputs: the step (``k``, horizon ``N``, state ``x``, the
    previous step's predicted poses shifted ``y_prev`` (N, 3), empty at the first step: then
    the legs are linearised at ``x``; the forces applied over the previous sample ``u_prev``),
    the row unit, the range sequence padded with ``N`` copies of its last sample (``K``
    samples; ``lower, upper, qa, qb`` as ``RangeSequence.window``), the legs (``r0``,
    ``base``), then each constraint's arrays in row order: corridor (``lo .. recourse``), end
    approach (``app_*``), arrival (``arr_*``), leg speed (``vmax``), force rate (``rate_on``,
    ``umax``, ``rate_step``, ``rate_recourse``), stroke (``lmin``, ``lmax``).

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
    leg_jacobians(r0, base, y_nom, J, L)
    nrow = (corridor_count(idx, has_hp, hp_ptr) + approach_count(idx, app_on, app_from) + arrival_count(idx, arr_from)
            + (3 if rate_on else 2) * N * m)
    col = np.full((nrow, 3), -1, np.int64)
    val = np.zeros((nrow, 3))
    b0l = np.empty(nrow)
    b0u = np.empty(nrow)
    kinds = np.zeros(nrow, np.int64)
    r = corridor_fill(idx, unit, lo, hi, lo_deep, hi_deep, has_hp, hp_ptr, hp_A, hp_b, recourse, col, val, b0l, b0u,
                      kinds, 0)
    r = approach_fill(idx, unit, app_on, app_d, app_b, app_from, recourse, col, val, b0l, b0u, kinds, r)
    r = arrival_fill(idx, unit, arr_from, arr_lim, col, val, b0l, b0u, kinds, r)
    speed0 = r
    r = speed_fill(J, unit, vmax, col, val, b0l, b0u, kinds, r)
    r = rate_fill(N, u_prev, unit, rate_on, umax, rate_step, rate_recourse, col, val, b0l, b0u, kinds, r)
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
    leg_jacobians(r0, base, y1, J, L)
    for i in range(m):
        for a in range(3):
            val[speed0 + i, a] = J[0, i, a] / unit
            val[stroke0 + i, a] = J[0, i, a] / unit
        off = (L[0, i] - (J[0, i, 0] * y1[0, 0] + J[0, i, 1] * y1[0, 1] + J[0, i, 2] * y1[0, 2])) / unit
        b0l[stroke0 + i] = lmin[i] / unit - off
        b0u[stroke0 + i] = lmax[i] / unit - off


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
