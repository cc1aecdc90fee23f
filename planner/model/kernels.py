"""Compiled twins (numba) of the model's hot functions: dynamics (eqs. 4-8,
:mod:`planner.model.dynamics`), zero-order hold (eq. 9, :mod:`planner.model.discretisation`),
the RK4 plant (:func:`planner.model.plant.rk4_sample`) and the singularity measure
(:func:`planner.model.kinematics.singularity_measure`), and the leg geometry they share
(:func:`leg`, the twin of :func:`planner.model.kinematics.leg_vectors`).

Why compiled: one receding-horizon step works on 3x3 to 6x6 matrices. In numpy each of the
few hundred small operations of a step costs a call (~1 us) whatever its size, so a step
took ~400 us; the same arithmetic compiled takes a few microseconds
(``benchmarks/bench_planner.py``). The numpy implementations stay the readable reference;
``tests/test_kernels.py`` checks that every kernel here equals its reference to rounding.

The model is passed as one float array ``packed`` (:func:`pack`, built once per
:class:`~planner.model.RobotModel`), so that the functions compile once for every robot.
Functions are compiled on first use and cached on disk (``cache=True``), so a new process
loads them in a fraction of a second.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import njit

# layout of the robot array: 7 per-leg rows of n values, then 5 scalars
_R0X, _R0Y, _BX, _BY, _MROD, _ACOM, _FRIC, _JCONST = range(8)
_NROWS = 8


def pack(robot) -> np.ndarray:
    """Pack what the dynamics need of a :class:`~planner.model.RobotModel` into one float array:
    per leg (rows of ``n``): pivot offset from the tool point ``r0`` (x, y) [m], base pivot
    (x, y) [m], rod mass [kg], rod centre distance [m], viscous friction [N s/m], the leg's
    constant inertia about its base pivot [kg m^2]; then platform mass [kg], platform inertia
    [kg m^2] and the tool offset (x, y) [m]."""
    n = robot.n_legs
    rows = np.empty((_NROWS, n))
    rows[_R0X], rows[_R0Y] = robot.r0[:, 0], robot.r0[:, 1]
    rows[_BX], rows[_BY] = robot.base[:, 0], robot.base[:, 1]
    rows[_MROD], rows[_ACOM], rows[_FRIC] = robot.rod_mass, robot.rod_com, robot.friction
    rows[_JCONST] = robot.leg_inertia_const
    tail = np.array([robot.platform_mass, robot.platform_inertia, robot.tool[0], robot.tool[1], float(n)])
    return np.concatenate((rows.ravel(), tail))


@njit(cache=True)
def leg(c, s, r0x, r0y, bx, by, px, py):
    """One leg at a pose (the compiled twin of :func:`planner.model.kinematics.leg_vectors`,
    the loop closure of eq. 2 solved for the leg, and of the leg's entries of ``R``, eq. 4):
    the tool point ``(px, py)`` and ``c, s`` = cos, sin of the platform angle, the leg's pivot
    relative to the tool point, platform frame, ``(r0x, r0y)`` and its base pivot ``(bx, by)``
    [m] -> ``(rx, ry, l, ex, ey, r x e, r . e)``: the pivot relative to the tool point, world
    frame [m], the leg length [m], its unit direction and the two products [m]. The one
    compiled statement of the leg geometry: :func:`leg_jacobians` and the dynamics use it."""
    rx = r0x * c - r0y * s
    ry = r0x * s + r0y * c
    dx = px + rx - bx
    dy = py + ry - by
    length = math.hypot(dx, dy)
    ex, ey = dx / length, dy / length
    return rx, ry, length, ex, ey, rx * ey - ry * ex, rx * ex + ry * ey


@njit(cache=True)
def leg_jacobians(r0, base, poses, J, L):
    """Leg Jacobians ``J_l`` (k, n, 3) and leg lengths (k, n) [m] at the poses (k, 3), into
    ``J`` and ``L`` (``r0``: :attr:`RobotModel.r0`, ``base``: :attr:`RobotModel.base`): the
    compiled twin of :func:`planner.model.kinematics.leg_jacobians` and
    :func:`~planner.model.kinematics.leg_lengths` (the leg rows of ``R``, eq. 4)."""
    for k in range(poses.shape[0]):
        c, s = math.cos(poses[k, 2]), math.sin(poses[k, 2])
        for i in range(r0.shape[0]):
            _, _, li, ex, ey, cr, _ = leg(c, s, r0[i, 0], r0[i, 1], base[i, 0], base[i, 1], poses[k, 0], poses[k, 1])
            J[k, i, 0], J[k, i, 1], J[k, i, 2] = ex, ey, cr
            L[k, i] = li


@njit(cache=True)
def _terms(packed, n, x, W, M):
    """The shared pieces of eqs. (4)-(8) at state ``x = (y, y_dot)`` (as the numpy
    ``planner.model.dynamics._terms``): fills ``W = [J_l; J_phi]`` (2n, 3) and ``M = R^T M R`` (3, 3) and
    returns per-leg ``l, r x e, r . e, l_dot, phi_dot, J_leg`` and the platform centre
    relative to the tool point ``(rcx, rcy)``."""
    c, s = math.cos(x[2]), math.sin(x[2])
    w = x[5]
    l = np.empty(n)
    cross = np.empty(n)
    dot = np.empty(n)
    l_dot = np.empty(n)
    phi_dot = np.empty(n)
    J_leg = np.empty(n)
    for a in range(3):
        for b in range(3):
            M[a, b] = 0.0
    o = _NROWS * n
    mp, ip, tx, ty = packed[o], packed[o + 1], packed[o + 2], packed[o + 3]
    for i in range(n):
        _, _, li, ex, ey, cr, dt = leg(c, s, packed[_R0X * n + i], packed[_R0Y * n + i], packed[_BX * n + i],
                                       packed[_BY * n + i], x[0], x[1])
        ld = ex * x[3] + ey * x[4] + cr * w
        pd = (ex * x[4] - ey * x[3] + dt * w) / li
        arm = li - packed[_ACOM * n + i]
        mr = packed[_MROD * n + i]
        jl = packed[_JCONST * n + i] + mr * arm * arm
        l[i], cross[i], dot[i], l_dot[i], phi_dot[i], J_leg[i] = li, cr, dt, ld, pd, jl
        W[i, 0], W[i, 1], W[i, 2] = ex, ey, cr
        W[n + i, 0], W[n + i, 1], W[n + i, 2] = -ey / li, ex / li, dt / li
        for a in range(3):
            for b in range(3):
                M[a, b] += mr * W[i, a] * W[i, b] + jl * W[n + i, a] * W[n + i, b]
    rcx = -(tx * c - ty * s)
    rcy = -(tx * s + ty * c)
    M[0, 0] += mp
    M[1, 1] += mp
    M[2, 2] += mp * (rcx * rcx + rcy * rcy) + ip
    M[0, 2] -= mp * rcy
    M[2, 0] -= mp * rcy
    M[1, 2] += mp * rcx
    M[2, 1] += mp * rcx
    return l, cross, dot, l_dot, phi_dot, J_leg, rcx, rcy


@njit(cache=True)
def _chol3_solve(M, B):
    """Solve ``M X = B`` in place of ``B`` for the symmetric positive definite 3x3 reduced
    mass matrix (Cholesky); returns False if ``M`` is not positive definite."""
    l00 = M[0, 0]
    if not l00 > 0.0:
        return False
    l00 = math.sqrt(l00)
    l10 = M[1, 0] / l00
    l20 = M[2, 0] / l00
    d1 = M[1, 1] - l10 * l10
    if not d1 > 0.0:
        return False
    l11 = math.sqrt(d1)
    l21 = (M[2, 1] - l20 * l10) / l11
    d2 = M[2, 2] - l20 * l20 - l21 * l21
    if not d2 > 0.0:
        return False
    l22 = math.sqrt(d2)
    for j in range(B.shape[1]):
        z0 = B[0, j] / l00
        z1 = (B[1, j] - l10 * z0) / l11
        z2 = (B[2, j] - l20 * z0 - l21 * z1) / l22
        x2 = z2 / l22
        x1 = (z1 - l21 * x2) / l11
        x0 = (z0 - l10 * x1 - l20 * x2) / l00
        B[0, j], B[1, j], B[2, j] = x0, x1, x2
    return True


@njit(cache=True)
def acceleration(packed, x, u, out):
    """Eq. (6): ``y_dd = M_r^-1 (R^T (g - M R_dot y_dot) + J_l^T u)`` into ``out`` (3,);
    returns False at a singular reduced mass matrix. Same as :meth:`Robot.acceleration`."""
    n = int(packed[-1])
    W = np.empty((2 * n, 3))
    M = np.empty((3, 3))
    l, cross, dot, l_dot, phi_dot, J_leg, rcx, rcy = _terms(packed, n, x, W, M)
    w = x[5]
    h = np.zeros((3, 1))
    for i in range(n):
        mr, a = packed[_MROD * n + i], packed[_ACOM * n + i]
        hl = mr * (dot[i] * w * w - a * phi_dot[i] * phi_dot[i]) - packed[_FRIC * n + i] * l_dot[i] + u[i]
        hp = (2.0 * (J_leg[i] / l[i] - mr * (l[i] - a)) * l_dot[i] * phi_dot[i]
              - J_leg[i] * cross[i] * w * w / l[i])
        for b in range(3):
            h[b, 0] += W[i, b] * hl + W[n + i, b] * hp
    mp = packed[_NROWS * n]
    h[0, 0] += mp * w * w * rcx
    h[1, 0] += mp * w * w * rcy
    ok = _chol3_solve(M, h)
    out[0], out[1], out[2] = h[0, 0], h[1, 0], h[2, 0]
    return ok


@njit(cache=True)
def factorised_blocks(packed, x, A22, B2):
    """Eq. (8): the blocks ``A22`` (3, 3) and ``B2`` (3, n) of the exact factorisation
    ``x_dot = A(x) x + B(x) u`` (as :meth:`Robot.factorised_blocks`), written into the given
    arrays; returns False at a singular reduced mass matrix."""
    n = int(packed[-1])
    W = np.empty((2 * n, 3))
    M = np.empty((3, 3))
    l, cross, dot, l_dot, phi_dot, J_leg, rcx, rcy = _terms(packed, n, x, W, M)
    w = x[5]
    rhs = np.zeros((3, 3 + n))
    for i in range(n):
        mr, a = packed[_MROD * n + i], packed[_ACOM * n + i]
        c1 = J_leg[i] / l[i] - mr * (l[i] - a)
        # rows of K (K v = h): the l row and the phi row of leg i
        kl0 = -mr * a * phi_dot[i] * W[n + i, 0] - packed[_FRIC * n + i] * W[i, 0]
        kl1 = -mr * a * phi_dot[i] * W[n + i, 1] - packed[_FRIC * n + i] * W[i, 1]
        kl2 = -mr * a * phi_dot[i] * W[n + i, 2] - packed[_FRIC * n + i] * W[i, 2] + mr * dot[i] * w
        kp0 = c1 * phi_dot[i] * W[i, 0] + c1 * l_dot[i] * W[n + i, 0]
        kp1 = c1 * phi_dot[i] * W[i, 1] + c1 * l_dot[i] * W[n + i, 1]
        kp2 = c1 * phi_dot[i] * W[i, 2] + c1 * l_dot[i] * W[n + i, 2] - J_leg[i] * cross[i] * w / l[i]
        for b in range(3):
            rhs[b, 0] += W[i, b] * kl0 + W[n + i, b] * kp0
            rhs[b, 1] += W[i, b] * kl1 + W[n + i, b] * kp1
            rhs[b, 2] += W[i, b] * kl2 + W[n + i, b] * kp2
            rhs[b, 3 + i] = W[i, b]
    mp = packed[_NROWS * n]
    rhs[0, 2] += mp * w * rcx
    rhs[1, 2] += mp * w * rcy
    ok = _chol3_solve(M, rhs)
    for a in range(3):
        for b in range(3):
            A22[a, b] = rhs[a, b]
        for b in range(n):
            B2[a, b] = rhs[a, 3 + b]
    return ok


@njit(cache=True)
def _expm(M):
    """``expm(M)`` by scaling and squaring of the Taylor series (truncated where the next
    term is below 1e-17 relative); used for the rare sample whose ``||A22 Ts||`` is large."""
    d = M.shape[0]
    norm = 0.0
    for j in range(d):
        col = 0.0
        for i in range(d):
            col += abs(M[i, j])
        norm = max(norm, col)
    s = 0
    while norm > 0.25:
        norm *= 0.5
        s += 1
    X = M * (0.5 ** s)
    E = np.eye(d)
    T = np.eye(d)
    k = 1
    while k < 40:
        T = (T @ X) / k
        E += T
        tn = 0.0
        for i in range(d):
            for j in range(d):
                tn = max(tn, abs(T[i, j]))
        if tn < 1e-18:
            break
        k += 1
    for _ in range(s):
        E = E @ E
    return E


@njit(cache=True)
def zoh(A22, B2, Ts, Ad, Bd):
    """Eq. (9) for ``A = [[0, I], [0, A22]]``, ``B = [[0], [B2]]`` (as
    :func:`planner.discretisation.zoh_factorised`): ``Ad = [[I, Ts phi_1], [0, phi_0]]``,
    ``Bd = [[Ts^2 phi_2 B2], [Ts phi_1 B2]]`` with the phi-functions of ``X = A22 Ts`` summed
    by Horner's rule; beyond ``||X||_1 = 0.1`` the augmented matrix exponential (Van Loan)."""
    m = B2.shape[1]
    X = A22 * Ts
    norm = 0.0
    for i in range(3):
        for j in range(3):
            norm = max(norm, abs(X[i, j]))
    norm *= 3.0
    if norm > 0.1:
        Mx = np.zeros((6 + m, 6 + m))
        for i in range(3):
            Mx[i, 3 + i] = Ts
            for j in range(3):
                Mx[3 + i, 3 + j] = X[i, j]
            for j in range(m):
                Mx[3 + i, 6 + j] = B2[i, j] * Ts
        E = _expm(Mx)
        Ad[:, :] = E[:6, :6]
        Bd[:, :] = E[:6, 6:]
        return
    d = 1
    term = norm * norm / 6.0
    while term > 1e-17 and d < 35:
        d += 1
        term *= norm / (d + 2)
    fact = 1.0
    for k in range(2, d + 3):
        fact *= k
    phi = np.eye(3) / fact  # I / (d+2)!
    for k in range(d + 1, 1, -1):
        fact /= k + 1  # k!
        phi = X @ phi
        for i in range(3):
            phi[i, i] += 1.0 / fact
    phi2 = phi
    phi1 = X @ phi2
    for i in range(3):
        phi1[i, i] += 1.0
    phi0 = X @ phi1
    for i in range(3):
        phi0[i, i] += 1.0
    P2B = phi2 @ B2
    P1B = phi1 @ B2
    for i in range(6):
        for j in range(6):
            Ad[i, j] = 0.0
    for i in range(3):
        Ad[i, i] = 1.0
        for j in range(3):
            Ad[i, 3 + j] = Ts * phi1[i, j]
            Ad[3 + i, 3 + j] = phi0[i, j]
        for j in range(m):
            Bd[i, j] = Ts * Ts * P2B[i, j]
            Bd[3 + i, j] = Ts * P1B[i, j]


@njit(cache=True)
def blocks_derivative(A22, B2, x, u, out):
    """Eq. (8) with its blocks already factorised: ``x_dot = (y_dot, A22 y_dot + B2 u)`` into
    ``out`` (6,) (the same numbers as :func:`state_derivative` at that state)."""
    for i in range(3):
        out[i] = x[3 + i]
        acc = 0.0
        for j in range(3):
            acc += A22[i, j] * x[3 + j]
        for j in range(B2.shape[1]):
            acc += B2[i, j] * u[j]
        out[3 + i] = acc


@njit(cache=True)
def state_derivative(packed, x, u, out):
    """Eq. (7): ``x_dot = f(x) + G(x) u`` into ``out`` (6,)."""
    out[0], out[1], out[2] = x[3], x[4], x[5]
    acc = np.empty(3)
    ok = acceleration(packed, x, u, acc)
    out[3], out[4], out[5] = acc[0], acc[1], acc[2]
    return ok


@njit(cache=True)
def rk4(packed, x, u, Ts, substeps, f0):
    """The plant (as :func:`planner.model.plant.rk4_sample`): ``substeps`` classical Runge-Kutta
    steps of the nonlinear model (eq. 7) under constant ``u`` over one sample; ``f0`` is
    ``x_dot`` at ``x``. Returns the new state (NaN if the mass matrix turned singular)."""
    h = Ts / substeps
    k1 = np.empty(6)
    k2 = np.empty(6)
    k3 = np.empty(6)
    k4 = np.empty(6)
    xs = np.empty(6)
    x = x.copy()
    ok = True
    for it in range(substeps):
        if it == 0:
            k1[:] = f0
        else:
            ok &= state_derivative(packed, x, u, k1)
        for i in range(6):
            xs[i] = x[i] + 0.5 * h * k1[i]
        ok &= state_derivative(packed, xs, u, k2)
        for i in range(6):
            xs[i] = x[i] + 0.5 * h * k2[i]
        ok &= state_derivative(packed, xs, u, k3)
        for i in range(6):
            xs[i] = x[i] + h * k3[i]
        ok &= state_derivative(packed, xs, u, k4)
        for i in range(6):
            x[i] += (h / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    if not ok:
        x[:] = np.nan
    return x


@njit(cache=True)
def model_step(packed, x, Ts):
    """Eqs. (8)-(9) at state ``x``: ``(A22, B2, Ad, Bd, ok)``."""
    n = int(packed[-1])
    A22 = np.empty((3, 3))
    B2 = np.empty((3, n))
    Ad = np.empty((6, 6))
    Bd = np.empty((6, n))
    ok = factorised_blocks(packed, x, A22, B2)
    zoh(A22, B2, Ts, Ad, Bd)
    return A22, B2, Ad, Bd, ok


@njit(cache=True)
def smallest_singular_values(J):
    """Smallest singular value of each ``(r, 3)`` matrix of the batch ``J`` (k, r, 3), by
    one-sided Jacobi rotations of the columns (accurate to rounding relative to each singular
    value, like LAPACK's ``gesvd`` used by the reference); 0 for a matrix with a non-finite
    entry. Same as ``np.linalg.svd(J, compute_uv=False)[:, -1]``."""
    k, r, c = J.shape
    out = np.empty(k)
    A = np.empty((r, c))
    for b in range(k):
        finite = True
        for i in range(r):
            for j in range(c):
                A[i, j] = J[b, i, j]
                if not math.isfinite(A[i, j]):
                    finite = False
        if not finite:
            out[b] = 0.0
            continue
        for _sweep in range(60):
            rotated = False
            for p in range(c - 1):
                for q in range(p + 1, c):
                    alpha = 0.0
                    beta = 0.0
                    gamma = 0.0
                    for i in range(r):
                        alpha += A[i, p] * A[i, p]
                        beta += A[i, q] * A[i, q]
                        gamma += A[i, p] * A[i, q]
                    if abs(gamma) <= 1e-16 * math.sqrt(alpha * beta) or gamma == 0.0:
                        continue
                    rotated = True
                    zeta = (beta - alpha) / (2.0 * gamma)
                    t = (1.0 if zeta >= 0 else -1.0) / (abs(zeta) + math.sqrt(1.0 + zeta * zeta))
                    cs = 1.0 / math.sqrt(1.0 + t * t)
                    sn = cs * t
                    for i in range(r):
                        ap, aq = A[i, p], A[i, q]
                        A[i, p] = cs * ap - sn * aq
                        A[i, q] = sn * ap + cs * aq
            if not rotated:
                break
        smin = math.inf
        for j in range(c):
            nrm = 0.0
            for i in range(r):
                nrm += A[i, j] * A[i, j]
            smin = min(smin, math.sqrt(nrm))
        out[b] = smin
    return out
