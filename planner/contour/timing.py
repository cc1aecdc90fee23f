"""The time-optimal speed profile along a pass's programmed path under the drive limits (issue
22): the ``fastest`` feed's timing of the tube.

**Path.** The pass's lines and arcs (robot frame, the platform angle ``psi`` fixed) sampled
every ``h`` along the path length ``s``: ``q(s)``, ``q'(s)``, ``q''(s)`` (3-vectors ``x, y,
psi``). Every element boundary is a grid point twice, once with each element's derivatives
(a step of length 0: the speed there satisfies both sides, where the curvature jumps).

**Constraints** (second order, as in TOPP-RA, Pham and Pham 2018): along the path
``y_dot = q' s_dot``, ``y_dd = q' s_dd + q'' s_dot^2``, and the reduced equations of motion
(:func:`planner.model.generalised_forces`, eq. 6) ``M_r y_dd - h_r = J_l^T f`` with the four
drive forces ``f`` in the box ``|f_k| <= f_max``. The set of generalised forces the box gives is a
zonotope; its facets (normals ``n = g_i x g_j`` of two leg rows ``g`` of ``J_l``, offsets
``sum_k |n . g_k| f_max``) make 12 linear inequalities in ``u = s_dd`` and ``w = s_dot^2``:
``A u + B w <= R`` with ``A = n . M_r q'``, ``B = n . (M_r q'' - h_r(q, q'))`` (the
velocity-product terms and viscous friction evaluated at ``s_dot = 1``, friction scaled by
``w`` as TOPP-RA does: a slight underestimate of friction below 1 m/s, which the planning of the
profile absorbs). The legs' speeds bound ``w <= (v_max / |J_l q'|)^2``; ``cap`` bounds ``w``
further (the tube's cells, the corners).

**Profile** (:func:`speed_profile`): the discrete time-optimal parametrisation on the grid,
``w_{i+1} = w_i + 2 (s_{i+1} - s_i) u_i`` with ``u_i`` feasible at grid point ``i``, by TOPP-RA's
reachability analysis: the controllable sets backwards from rest at the end, then greedily
forwards from rest at the start (``benchmarks/bench_contour.py`` compares the time with
TOPP-RA's own).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..model import RobotModel
from ..model.dynamics import generalised_forces
from ..schema import PathElement

__all__ = ["PathSamples", "constraint_rows", "path_samples", "profile_time", "speed_profile", "tangent", "time_optimal",
           "turn"]


class PathSamples:
    """A pass's path on a grid of path length (module docstring), robot frame."""

    def __init__(self, s: np.ndarray, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, element: np.ndarray,
                 corner: np.ndarray):
        self.s = s  #: (N,) path length [m], non-decreasing (boundaries twice)
        self.q, self.dq, self.ddq = q, dq, ddq  #: (N, 3) pose, d/ds, d2/ds2
        self.element = element  #: (N,) index of the element of the point
        #: (N,) turn angle where the tangent jumps (at both copies of the boundary; 0 elsewhere) [rad]
        self.corner = corner


def tangent(e: PathElement, at_end: bool) -> np.ndarray:
    """The unit tangent of a move at its start or end (``at_end``), in its direction of travel."""
    if e.kind == "line":
        d = np.asarray(e.end, float) - np.asarray(e.start, float)
        return d / max(float(np.hypot(*d)), 1e-300)
    assert e.start_angle_rad is not None and e.sweep_rad is not None
    a = e.start_angle_rad + (e.sweep_rad if at_end else 0.0)
    return math.copysign(1.0, e.sweep_rad) * np.array([-math.sin(a), math.cos(a)])


def turn(a: PathElement, b: PathElement) -> float:
    """The tangent's jump from the end of ``a`` to the start of ``b`` [rad]."""
    t0, t1 = tangent(a, True), tangent(b, False)
    return abs(math.atan2(t0[0] * t1[1] - t0[1] * t1[0], float(t0 @ t1)))


def path_samples(elements: list[PathElement], origin: np.ndarray, psi: float, h: float) -> PathSamples:
    """The pass on a grid of spacing at most ``h`` [m] (module docstring). Elements of length 0
    are skipped."""
    els = [e for e in elements if e.length_m > 1e-12]
    S, Q, D, DD, E = [], [], [], [], []
    s0 = 0.0
    for i, e in enumerate(els):
        n = max(1, math.ceil(e.length_m / h))
        u = e.length_m * np.arange(n + 1) / n
        if e.kind == "line":
            d = (np.asarray(e.end, float) - np.asarray(e.start, float)) / e.length_m
            p = np.asarray(e.start, float) + origin + u[:, None] * d
            dp = np.broadcast_to(d, p.shape)
            ddp = np.zeros_like(p)
        else:
            assert e.centre is not None and e.radius_m is not None and e.start_angle_rad is not None
            assert e.sweep_rad is not None
            r, sg = e.radius_m, math.copysign(1.0, e.sweep_rad)
            a = e.start_angle_rad + sg * u / r
            cs = np.stack((np.cos(a), np.sin(a)), axis=1)
            p = np.asarray(e.centre, float) + origin + r * cs
            dp = sg * np.stack((-cs[:, 1], cs[:, 0]), axis=1)
            ddp = -cs / r
        q = np.column_stack((p, np.full(n + 1, psi)))
        S.append(s0 + u)
        Q.append(q)
        D.append(np.column_stack((dp, np.zeros(n + 1))))
        DD.append(np.column_stack((ddp, np.zeros(n + 1))))
        E.append(np.full(n + 1, i))
        s0 += e.length_m
    s = np.concatenate(S)
    corner = np.zeros(len(s))
    k = 0
    for i in range(len(els) - 1):
        k += len(S[i])
        ang = turn(els[i], els[i + 1])
        if ang > 1e-9:
            corner[k - 1] = corner[k] = ang
    elem = np.concatenate(E)
    idx = np.array([elements.index(e) for e in els])
    return PathSamples(s, np.concatenate(Q), np.concatenate(D), np.concatenate(DD), idx[elem], corner)


def _facets(J: np.ndarray, f_max: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (N, m, 3) and offsets (N, m) of the zonotopes ``J^T [-f_max, f_max]`` of the
    leg Jacobians ``J`` (N, n, 3), both signs of every facet; a pair of parallel leg rows
    (no facet) gets the normal 0 and the offset 1 (the row ``0 <= 1``)."""
    n = J.shape[1]
    i, j = np.triu_indices(n, 1)
    Nv = np.cross(J[:, i], J[:, j])  # (N, pairs, 3)
    norm = np.linalg.norm(Nv, axis=2, keepdims=True)
    good = norm > 1e-12
    Nv = np.where(good, Nv / np.where(good, norm, 1.0), 0.0)
    r = np.where(good[..., 0], np.abs(np.einsum("npk,nlk->npl", Nv, J)) @ f_max, 1.0)
    return np.concatenate((Nv, -Nv), axis=1), np.concatenate((r, r), axis=1)


def constraint_rows(model: RobotModel, path: PathSamples
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``A, B, R`` (N, m) of ``A u + B w <= R`` at every grid point, the legs' speed bound on
    ``w`` (N,) (module docstring) and the acceleration the drives give the tool in every
    direction of the plane from rest (N,) [m/s^2] (the radius of the largest disk about 0 of
    accelerations ``a`` with ``M_r (a, 0)`` in the zonotope: ``min R / |(M_r^T n)_xy|``)."""
    f_max = np.asarray(model.force_max, float) * np.ones(model.n_legs)
    N = len(path.s)
    M = np.empty((N, 3, 3))
    H = np.empty((N, 3))
    J = np.empty((N, model.n_legs, 3))
    for i in range(N):
        M[i], H[i], J[i] = generalised_forces(model, path.q[i], path.dq[i])
    F, R = _facets(J, f_max)
    A = np.einsum("nmk,nk->nm", F, np.einsum("nkl,nl->nk", M, path.dq))
    B = np.einsum("nmk,nk->nm", F, np.einsum("nkl,nl->nk", M, path.ddq) - H)
    leg = np.abs(np.einsum("nkl,nl->nk", J, path.dq))
    w_leg = np.min((np.asarray(model.speed_max, float) / np.maximum(leg, 1e-300)) ** 2, axis=1)
    reach = np.linalg.norm(np.einsum("nmk,nkl->nml", F, M)[:, :, :2], axis=2)
    a_all = np.min(R / np.maximum(reach, 1e-300), axis=1)
    return A, B, R, w_leg, a_all


def _largest_w(C: np.ndarray, d: np.ndarray) -> float:
    """The largest ``w`` of the polygon ``C [u, w] <= d`` (a 2-variable LP by its vertices: every
    two rows' intersection that meets all rows); -inf when it is empty."""
    i, j = np.triu_indices(len(d), 1)
    a, b, c, e = C[i, 0], C[i, 1], C[j, 0], C[j, 1]
    det = a * e - b * c
    ok = np.abs(det) > 1e-12 * (np.abs(a * e) + np.abs(b * c) + 1e-300)
    det = np.where(ok, det, 1.0)
    u = (d[i] * e - b * d[j]) / det
    w = (a * d[j] - d[i] * c) / det
    inside = ok & np.all(C @ np.vstack((u, w)) <= (d + 1e-9 * (np.abs(d) + 1.0))[:, None], axis=0)
    return float(w[inside].max()) if inside.any() else -math.inf


def speed_profile(s: np.ndarray, A: np.ndarray, B: np.ndarray, R: np.ndarray, cap: np.ndarray) -> np.ndarray:
    """``w = s_dot^2`` (N,) of the time-optimal traversal from rest to rest on the grid ``s``
    (module docstring), as TOPP-RA computes it: backwards, the largest ``w_i`` from which some
    feasible ``u_i`` reaches ``[0, K_{i+1}]`` (the controllable sets ``[0, K_i]``, ``K`` = 0 at
    the end: one 2-variable LP per point); forwards from rest, the largest ``u_i`` feasible at
    ``w_i`` that stays within them (greedy: time-optimal, Pham and Pham 2018, Thm. 3)."""
    eps = 1e-12
    N = len(s)
    ds = np.diff(s)
    K = np.empty(N)
    K[-1] = 0.0
    for i in range(N - 2, -1, -1):
        # w_{i+1} = w_i + 2 ds u_i in [0, K_{i+1}] (at a boundary, ds = 0: the same speed on both sides)
        C = np.vstack((np.column_stack((A[i], B[i])), [[2 * ds[i], 1.0], [-2 * ds[i], -1.0], [0.0, 1.0], [0.0, -1.0]]))
        d = np.concatenate((R[i], [K[i + 1], 0.0, cap[i], 0.0]))
        K[i] = max(_largest_w(C, d), 0.0)
    up = A > eps
    with np.errstate(divide="ignore", invalid="ignore"):
        a_r = np.where(up, R / A, 0.0)
        a_b = np.where(up, -B / A, 0.0)
    out = np.empty(N)
    out[0] = 0.0
    for i in range(N - 1):
        w = out[i]
        if ds[i] <= 0.0:
            out[i + 1] = min(w, K[i + 1])
            continue
        u_max = float(np.min(np.where(up[i], a_r[i] + a_b[i] * w, np.inf)))
        out[i + 1] = max(min(w + 2.0 * ds[i] * u_max, K[i + 1]), 0.0)
    return out


def profile_time(s: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The time at every grid point of the profile ``w`` (N,) [s]: constant ``s_dd`` between
    grid points, ``dt = 2 ds / (s_dot_i + s_dot_{i+1})``."""
    v = np.sqrt(np.maximum(w, 0.0))
    ds = np.diff(s)
    dt = np.where(ds > 0, 2.0 * ds / np.maximum(v[:-1] + v[1:], 1e-300), 0.0)
    return np.concatenate(([0.0], np.cumsum(dt)))


def time_optimal(model: RobotModel, elements: list[PathElement], origin: np.ndarray, psi: float, h: float,
                 cap_of: Callable[[PathSamples, np.ndarray], np.ndarray] | None = None
                 ) -> tuple[PathSamples, np.ndarray, np.ndarray]:
    """The time-optimal profile of a pass: its grid (:func:`path_samples`), ``w`` and the time at
    every grid point. ``cap_of(path, a_all) -> (N,)``: further bounds on ``w`` (the tube's, the
    corners'), given the acceleration the drives allow in every direction (:func:`constraint_rows`)."""
    path = path_samples(elements, origin, psi, h)
    A, B, R, w_leg, a_all = constraint_rows(model, path)
    cap = w_leg if cap_of is None else np.minimum(w_leg, cap_of(path, a_all))
    w = speed_profile(path.s, A, B, R, cap)
    return path, w, profile_time(path.s, w)
