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
step data (:mod:`~planner.constraints.rows`, :mod:`~planner.constraints.step`), of the
compiled assembly (:mod:`~planner.constraints.compiled`), which name what they pass, and from
the fused ``assemble`` of :mod:`planner.constraints.registry`, which calls each row
constraint's count and fill in row order.

Layout: states are stacked per sample, ``X[6 i + a]`` (``a`` = x, y, psi, x_dot, y_dot,
psi_dot of sample ``i + 1``); the scaled moves ``z = u / force_max`` per sample,
``z[m i + l]`` (``m`` legs), after the states in ``Y = (X, z)``. Rows are a sparse selection
of ``Y``: row ``r`` is ``sum_k val[r, k] Y[col[r, k]]`` (``col`` -1: unused) with bounds
``b0l <= . <= b0u``, all in row units (``unit`` = :data:`~planner.constraints.rows.ROW_UNIT_M`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .._jit import njit
from ..model.kernels import leg_jacobians, rk4, state_derivative

__all__ = ["KIND_CORRIDOR", "KIND_RATE", "KIND_SPEED", "KIND_STROKE", "ApproachArgs", "ArrivalArgs", "CorridorArgs",
           "LegSpeedArgs", "RateArgs", "RowStep", "StrokeArgs", "ToolSpeedArgs", "approach_count", "approach_fill",
           "arrival_count", "arrival_fill", "corridor_count", "corridor_fill", "criterion", "finish", "first_legs",
           "legs_count", "offset", "one_step_error", "plant_step", "rate_count", "rate_fill", "speed_fill",
           "step_context", "stroke_fill", "tool_speed_count", "tool_speed_fill"]

#: kinds of rows (the slack variable that softens each in the slack problem; rate rows are
#: never softened); the values of :class:`planner.constraints.rows.RowKind`
KIND_CORRIDOR, KIND_STROKE, KIND_SPEED, KIND_RATE = 0, 1, 2, 3


# ---- the rows of each constraint (compiled twins of the constraint objects' ``rows``) -------
# Each row constraint has a typed tuple of its arrays (``*Args``, what its
# ``RowConstraint.kernel_args`` gives), a count and a fill, all with the same signature:
# ``*_count(step, a)`` its number of rows in the step :class:`RowStep`, ``*_fill(step, a, col,
# val, b0l, b0u, kinds, r)`` writes them from row ``r`` on and returns the next free row. The
# registry (:mod:`planner.constraints.registry`) lists them in row order and its fused
# ``assemble`` calls them.


class RowStep(NamedTuple):
    """What every constraint's rows of one step read (``N`` samples, ``m`` legs)."""

    idx: np.ndarray  #: (N,) int64 sequence index of each sample (``min(k + j, K - 1)``)
    unit: float  #: the row unit (:data:`~planner.constraints.rows.ROW_UNIT_M`)
    u_prev: np.ndarray  #: (m,) the drive forces applied over the previous sample [N]
    J: np.ndarray  #: (N, m, 3) leg Jacobians at the nominal poses
    L: np.ndarray  #: (N, m) leg lengths there [m]
    y_nom: np.ndarray  #: (N, 3) the nominal poses [m, m, rad]


class CorridorArgs(NamedTuple):
    """:class:`~planner.constraints.corridor.CorridorConstraint`'s arrays."""

    lo: np.ndarray  #: (K, 3) the shrunk box of the horizon's first sample
    hi: np.ndarray
    lo_deep: np.ndarray  #: (K, 3) the box of the later samples
    hi_deep: np.ndarray
    has_hp: np.ndarray  #: (K,) bool: half-planes replace the x/y box rows
    hp_ptr: np.ndarray  #: (K + 1,) int64: those of sequence index s are hp_A[hp_ptr[s]:hp_ptr[s + 1]]
    hp_A: np.ndarray  #: (h, 2)
    hp_b: np.ndarray  #: (h,)
    recourse: float  #: the later samples' half-planes are this much tighter [m]


@njit(cache=True)
def corridor_count(step, a):
    """Rows of :class:`~planner.constraints.corridor.CorridorConstraint`: one per sample and
    box axis (x and y only where the sample has no half-planes), and its half-planes."""
    idx = step.idx
    N = idx.shape[0]
    n = 0
    for ax in range(3):
        for j in range(N):
            if ax == 2 or not a.has_hp[idx[j]]:
                n += 1
    for j in range(N):
        s = idx[j]
        if a.has_hp[s]:
            n += a.hp_ptr[s + 1] - a.hp_ptr[s]
    return n


@njit(cache=True)
def corridor_fill(step, a, col, val, b0l, b0u, kinds, r):
    """The corridor rows: ``lo <= pose_j <= hi`` per axis (sorted by axis, then sample; the
    horizon's first sample with ``lo, hi``, the later with ``lo_deep, hi_deep``), then the
    half-planes ``A (x, y)_j <= b`` (``b - recourse`` after the first sample) of the samples
    that have them."""
    idx, unit = step.idx, step.unit
    N = idx.shape[0]
    for ax in range(3):
        for j in range(N):
            s = idx[j]
            if ax == 2 or not a.has_hp[s]:
                col[r, 0] = 6 * j + ax
                val[r, 0] = 1.0 / unit
                b0l[r] = (a.lo[s, ax] if j == 0 else a.lo_deep[s, ax]) / unit
                b0u[r] = (a.hi[s, ax] if j == 0 else a.hi_deep[s, ax]) / unit
                kinds[r] = KIND_CORRIDOR
                r += 1
    for j in range(N):
        s = idx[j]
        if a.has_hp[s]:
            for h in range(a.hp_ptr[s], a.hp_ptr[s + 1]):
                col[r, 0], col[r, 1] = 6 * j, 6 * j + 1
                val[r, 0], val[r, 1] = a.hp_A[h, 0] / unit, a.hp_A[h, 1] / unit
                b0l[r] = -np.inf
                b0u[r] = (a.hp_b[h] - (a.recourse if j > 0 else 0.0)) / unit
                kinds[r] = KIND_CORRIDOR
                r += 1
    return r


class ApproachArgs(NamedTuple):
    """:class:`~planner.constraints.corridor.EndApproachConstraint`'s arrays."""

    on: bool  #: the corridor has the half-plane
    d: np.ndarray  #: (2,) the approach direction
    b: float  #: the bound ``d . end`` [m]
    start: int  #: first sequence index with the row
    recourse: float  #: the later samples' rows are this much tighter [m]


@njit(cache=True)
def approach_count(step, a):
    """Rows of :class:`~planner.constraints.corridor.EndApproachConstraint`: one per sample
    from sequence index ``a.start`` on."""
    n = 0
    if a.on:
        for j in range(step.idx.shape[0]):
            if step.idx[j] >= a.start:
                n += 1
    return n


@njit(cache=True)
def approach_fill(step, a, col, val, b0l, b0u, kinds, r):
    """The no-overshoot rows ``d . (x, y)_j <= b`` (``b - recourse`` after the first sample)."""
    unit = step.unit
    if a.on:
        for j in range(step.idx.shape[0]):
            if step.idx[j] >= a.start:
                col[r, 0], col[r, 1] = 6 * j, 6 * j + 1
                val[r, 0], val[r, 1] = a.d[0] / unit, a.d[1] / unit
                b0l[r] = -np.inf
                b0u[r] = (a.b - (a.recourse if j > 0 else 0.0)) / unit
                kinds[r] = KIND_CORRIDOR
                r += 1
    return r


class ArrivalArgs(NamedTuple):
    """:class:`~planner.constraints.corridor.ArrivalConstraint`'s arrays."""

    start: int  #: first sequence index with the rows
    limit: np.ndarray  #: (3,) [m/s, m/s, rad/s]


@njit(cache=True)
def arrival_count(step, a):
    """Rows of :class:`~planner.constraints.corridor.ArrivalConstraint`: three per sample from
    sequence index ``a.start`` on."""
    n = 0
    for j in range(step.idx.shape[0]):
        if step.idx[j] >= a.start:
            n += 3
    return n


@njit(cache=True)
def arrival_fill(step, a, col, val, b0l, b0u, kinds, r):
    """The arrival rows ``|velocity_j| <= limit`` (x, y, psi rates)."""
    unit = step.unit
    for j in range(step.idx.shape[0]):
        if step.idx[j] >= a.start:
            for ax in range(3):
                col[r, 0] = 6 * j + 3 + ax
                val[r, 0] = 1.0 / unit
                b0l[r] = -a.limit[ax] / unit
                b0u[r] = a.limit[ax] / unit
                kinds[r] = KIND_SPEED
                r += 1
    return r


class LegSpeedArgs(NamedTuple):
    """:class:`~planner.constraints.drives.LegSpeedConstraint`'s arrays."""

    vmax: np.ndarray  #: (m,) [m/s]


@njit(cache=True)
def legs_count(step, a):
    """Rows of the leg constraints (speed, stroke): one per sample and leg."""
    return step.J.shape[0] * step.J.shape[1]


@njit(cache=True)
def speed_fill(step, a, col, val, b0l, b0u, kinds, r):
    """:class:`~planner.constraints.drives.LegSpeedConstraint`: ``|J_l(y0_j) y_dot_j| <= vmax``
    per sample and leg (``J`` (N, m, 3) at the nominal poses)."""
    J, unit = step.J, step.unit
    for j in range(J.shape[0]):
        for i in range(J.shape[1]):
            for ax in range(3):
                col[r, ax] = 6 * j + 3 + ax
                val[r, ax] = J[j, i, ax] / unit
            b0l[r] = -a.vmax[i] / unit
            b0u[r] = a.vmax[i] / unit
            kinds[r] = KIND_SPEED
            r += 1
    return r


class RateArgs(NamedTuple):
    """:class:`~planner.constraints.drives.DriveForceRateConstraint`'s arrays."""

    on: bool  #: a force-rate limit is set
    umax: np.ndarray  #: (m,) force_max [N]
    step: np.ndarray  #: (m,) largest force change over one sample [N]
    recourse: float  #: the moves after the first: this fraction less


@njit(cache=True)
def rate_count(step, a):
    """Rows of :class:`~planner.constraints.drives.DriveForceRateConstraint`: one per move
    and drive (none without a limit)."""
    return step.idx.shape[0] * a.umax.shape[0] if a.on else 0


@njit(cache=True)
def rate_fill(step, a, col, val, b0l, b0u, kinds, r):
    """:class:`~planner.constraints.drives.DriveForceRateConstraint`: ``|u(j) - u(j-1)| <=
    step`` (``(1 - recourse) step`` for ``j >= 1``) per move and drive, on the moves
    (``Y[6N + m j + i]``; ``u(-1) = u_prev``), in the scaled moves' unit (divided by
    ``umax``; the row unit is not used)."""
    if not a.on:
        return r
    N = step.idx.shape[0]
    umax, rs = a.umax, a.step
    m = umax.shape[0]
    for j in range(N):
        for i in range(m):
            col[r, 0] = 6 * N + m * j + i
            val[r, 0] = 1.0
            if j > 0:
                col[r, 1] = 6 * N + m * (j - 1) + i
                val[r, 1] = -1.0
                b0l[r] = -(1.0 - a.recourse) * rs[i] / umax[i]
                b0u[r] = (1.0 - a.recourse) * rs[i] / umax[i]
            else:
                b0l[r] = (step.u_prev[i] - rs[i]) / umax[i]
                b0u[r] = (step.u_prev[i] + rs[i]) / umax[i]
            kinds[r] = KIND_RATE
            r += 1
    return r


class ToolSpeedArgs(NamedTuple):
    """:class:`~planner.constraints.motion.ToolSpeedConstraint`'s arrays."""

    on: bool  #: a tool-speed limit is set
    normals: np.ndarray  #: (n, 2) unit directions of the polygon's sides (half of them: rows are two-sided)
    limit: float  #: ``|normal . (x_dot, y_dot)| <=`` this [m/s]


@njit(cache=True)
def tool_speed_count(step, a):
    """Rows of :class:`~planner.constraints.motion.ToolSpeedConstraint`: one per sample and
    direction (none without a limit)."""
    return step.idx.shape[0] * a.normals.shape[0] if a.on else 0


@njit(cache=True)
def tool_speed_fill(step, a, col, val, b0l, b0u, kinds, r):
    """:class:`~planner.constraints.motion.ToolSpeedConstraint`: ``|n_h . (x_dot, y_dot)_j| <=
    limit`` per sample ``j`` and direction ``h`` (sample by sample)."""
    if not a.on:
        return r
    unit = step.unit
    for j in range(step.idx.shape[0]):
        for h in range(a.normals.shape[0]):
            col[r, 0], col[r, 1] = 6 * j + 3, 6 * j + 4
            val[r, 0], val[r, 1] = a.normals[h, 0] / unit, a.normals[h, 1] / unit
            b0l[r] = -a.limit / unit
            b0u[r] = a.limit / unit
            kinds[r] = KIND_SPEED
            r += 1
    return r


class StrokeArgs(NamedTuple):
    """:class:`~planner.constraints.drives.LegStrokeConstraint`'s arrays."""

    lmin: np.ndarray  #: (m,) [m]
    lmax: np.ndarray  #: (m,) [m]


@njit(cache=True)
def stroke_fill(step, a, col, val, b0l, b0u, kinds, r):
    """:class:`~planner.constraints.drives.LegStrokeConstraint`: ``lmin <= l(y0_j) + J_l(y0_j)
    (y_j - y0_j) <= lmax`` per sample and leg (``L`` (N, m) leg lengths at ``y_nom``)."""
    J, L, y_nom, unit = step.J, step.L, step.y_nom, step.unit
    for j in range(J.shape[0]):
        for i in range(J.shape[1]):
            off = L[j, i] - (J[j, i, 0] * y_nom[j, 0] + J[j, i, 1] * y_nom[j, 1] + J[j, i, 2] * y_nom[j, 2])
            for ax in range(3):
                col[r, ax] = 6 * j + ax
                val[r, ax] = J[j, i, ax] / unit
            b0l[r] = (a.lmin[i] - off) / unit
            b0u[r] = (a.lmax[i] - off) / unit
            kinds[r] = KIND_STROKE
            r += 1
    return r


@njit(cache=True)
def step_context(k, N, x, y_prev, u_prev, unit, K, r0, base):
    """The :class:`RowStep` of step ``k``: the samples' sequence indices, the legs linearised
    at ``y_prev`` (N, 3), or at ``x`` where ``y_prev`` is empty."""
    m = r0.shape[0]
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
    return RowStep(idx, unit, u_prev, J, L, y_nom)


@njit(cache=True)
def criterion(k, N, K, lower, upper, qa, qb):
    """The criterion's weights ``W = qa^2 + qb^2`` and targets ``tgt = qa^2 r_a + qb^2 r_b``
    of samples ``k+1..k+N`` (3N,) (the range sequence padded with ``N`` copies of its last
    sample: ``K + N`` rows)."""
    kw = min(k, K)
    W = np.empty(3 * N)
    tgt = np.empty(3 * N)
    for i in range(N):
        for a in range(3):
            ca, cb = qa[kw + i, a] * qa[kw + i, a], qb[kw + i, a] * qb[kw + i, a]
            W[3 * i + a] = ca + cb
            tgt[3 * i + a] = ca * lower[kw + i, a] + cb * upper[kw + i, a]
    return W, tgt


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
