"""Contouring against the exact path's optima (issue 35): the second-order optimum (TOPP-RA, no
force-rate limit), the third-order optimum (CasADi + IPOPT, the default force-rate limit) and
the third-order optimum with the tool speed capped at each move's F, per pass and per program,
next to the planner's ``fastest`` and ``program`` feeds at the defaults.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/bench_contour_optimum.py \
        [--grids 10,20,40] [--programs bench,freecad_linuxcnc.ngc,fusion360.nc] [--compare-ts 0.01] [--elements] \
        [--fastest-only]

``--compare-ts``: ``fastest`` also at that typed sample time, beside the defaults (before/after
the defaults' choice of Ts in one run); ``--elements``: per element of each distinct pass, the
third-order optimum's time and top speed beside ``fastest``'s (where a plan loses its time);
``--fastest-only``: no ``program`` feed and no optimum at F. Both third-order ratios are
printed: against the peer under the Z axis's speed and acceleration (``3rd order``, the fair
one) and against the earlier peer under its speed only (``3rd order, Z speed only``; the same
where a pass keeps its Z).

**The third-order exact-path optimum** (an independent peer of :mod:`planner.contour.timing`,
written here from the equations of motion, not from the planner's code):

* the path: a pass's lines and arcs exactly as ``planner.exchange.read_gcode`` reads them, in
  the robot frame at the plan's origin, the platform angle ``psi`` fixed at 0 (as the planner
  contours), parameterised by arc length ``s``: ``q(s)``, ``q'(s)`` (unit tangent),
  ``q''(s)`` (curvature), analytic per element;
* the motion ``s(t)`` in the time domain, per element ``N`` time steps in three blocks
  (speeding up, cruising, slowing down: ``N / 3`` equal steps each, each block's step a
  decision variable, so the transients are resolved on a long move at F); at every node the
  path speed ``v = s_dot >= 0``, the path acceleration ``a = s_dd`` and the four drive forces
  ``f``; ``a`` piecewise linear in time (``v`` and ``s`` integrated exactly from it), ``f``
  piecewise linear in time;
* the robot's full rigid-body dynamics (the 4RPR model ``moving-slide``: platform, rods,
  viscous leg friction) in CasADi symbols, inverse form ``J_l^T f = M_r(q) y_dd - h_r(q,
  y_dot)`` with ``y_dot = q' v``, ``y_dd = q' a + q'' v^2``, at every node (checked against
  ``planner.model.dynamics.generalised_forces`` and against the forward dynamics of
  ``benchmarks/bench_optimality.py`` at random states before solving);
* the limits: ``|f_k| <= force_max``, the leg speeds ``|J_l q' v| <= speed_max`` at every
  node, the drive-force rate ``|f_{k+1} - f_k| <= rate h_e`` (rate = force_max / 50 ms, the
  default ``force_rate_n_s``), and for the capped peer ``v <= F`` of the element's move;
* the Z axis: where a pass moves Z (a ramp, a helix; a vertical arc as ``read_gcode`` reads
  it, a line with Z linear along it) the exact path is the 3-D path, ``Z(s) = Z_0 + g s`` along
  each move of slope ``g = dZ / L``, so ``Z_dot = g v`` and ``Z_dd = g a``: ``|g| v <= z_max``
  (the Z axis speed, the request's ``z_rapid_m_s``, 0.05 m/s by default) and ``|g a| <= z_acc``
  at every node (``a`` is linear between them: the nodes bound it; the Z axis acceleration,
  ``z_accel_m_s2``, 1 m/s^2 by default), the limits the planner holds in both feeds
  (``planner.contour.zaxis``); ``--z-speed-only``: the earlier peer, the Z speed alone;
* junctions: the forces are continuous everywhere (a rate limit allows no jump), so is the
  velocity; where the tangent jumps (a corner) the path must stop; where the curvature jumps
  (a line into an arc, even tangentially) it must stop as well: the generalised acceleration
  ``y_dd = q' a + q'' v^2`` is continuous with the forces, and its normal part ``q'' v^2``
  jumps unless ``v = 0``; where Z's slope changes (a ramp's start and end) with a Z acceleration
  limit: Z's velocity ``g v`` is continuous, so ``v = 0`` there. Only where tangent, curvature
  and slope all continue (collinear lines, arcs of one circle) does the tool pass through;
* the pass starts and ends at rest, with a zero generalised acceleration (it holds its pose
  before and after: the forces are a preload in the null space of ``J_l^T``, free); with
  ``--from-zero`` the forces start and end at 0 instead;
* minimise the sum of the steps; IPOPT (MUMPS) from a minimum-jerk guess per
  element, each finer grid from the coarser solution; each solve bounded (1000 iterations,
  120 CPU s: its status is in the grid table).

Grid refinement: each optimum at ``N`` in ``--grids`` (steps per element); the table gives the
finest, the convergence table all of them (the relative change from the previous grid). The
dynamics hold at the nodes (forces and ``a`` linear between them), so the time converges as
the grid is refined; with free blocks it converges from below (the finer grid is slower), with
one uniform step per element (``--blocks 1``) from above: on the benchmark pass the two
bracket the optimum.

**The second-order optimum**: TOPP-RA on the same exact path, drive forces and leg speeds, no
force-rate limit (``bench_contour.topp_time``: stops only at corners).

**The planner**: ``planner.contour.plan_contour`` at the defaults (``fastest``: Ts and N chosen
from the program's arcs, ``planner.contour.defaults``; ``program``: Ts 10 ms; the default
force-rate limit and Z axis), ``feed`` ``fastest`` and ``program``; per pass ``contour.passes[i].time_s``,
per program ``cut_time_s``; compute: CPU seconds of the whole plan (after one untimed plan that
loads the compiled kernels).

Passes with the same XY geometry and feeds (depth passes) share their optima (solved once).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np

from planner.contour import plan_contour
from planner.exchange import read_gcode
from planner.model import RobotModel, load_robot
from planner.model.dynamics import generalised_forces
from planner.schema import ContourRequest, PathElement
from planner.schema.limits import DEFAULT_FORCE_RISE_S

CAM = Path(__file__).resolve().parent.parent / "tests" / "data" / "cam"
ROBOT = "moving-slide"
#: the Z axis speed [m/s] and acceleration [m/s^2] (``ContourRequest``'s defaults ``z_rapid_m_s``,
#: ``z_accel_m_s2``): a move of slope ``g = dZ / L`` runs at most ``z_max / |g|`` in XY and speeds
#: up at most at ``z_acc / |g|`` in the planner (``planner.contour.zaxis``) and here
Z_MAX_M_S = float(ContourRequest.model_fields["z_rapid_m_s"].default)
Z_ACC_M_S2 = float(ContourRequest.model_fields["z_accel_m_s2"].default)


# ------------------------------------------------------------------ the dynamics, CasADi
def casadi_inverse_dynamics(robot: RobotModel):
    """``(M_r, h_r, J_l)`` of the nRPR robot at pose ``y`` and velocity ``y_dot`` in CasADi
    symbols, so that ``M_r y_dd = h_r + J_l^T f``: the platform (mass at its centre, offset
    from the tool point, inertia), per leg a rod (mass ``m_r`` at ``a`` from the base joint,
    inertia) sliding along the leg, viscous friction on the leg's speed."""
    import casadi as ca

    y = ca.SX.sym("y", 3)
    yd = ca.SX.sym("yd", 3)
    px, py, psi = y[0], y[1], y[2]
    w = yd[2]
    c, s = ca.cos(psi), ca.sin(psi)
    M = ca.SX.zeros(3, 3)
    h = ca.SX.zeros(3)
    rows = []
    for i in range(robot.n_legs):
        r0x, r0y = robot.r0[i]
        rx, ry = c * r0x - s * r0y, s * r0x + c * r0y  # platform joint from the tool point
        dx, dy = px + rx - robot.base[i, 0], py + ry - robot.base[i, 1]
        length = ca.sqrt(dx * dx + dy * dy)
        ex, ey = dx / length, dy / length  # leg direction
        cross, dot = rx * ey - ry * ex, rx * ex + ry * ey
        g_l = ca.vertcat(ex, ey, cross)  # d(length)/dy
        g_phi = ca.vertcat(-ey, ex, dot) / length  # d(leg angle)/dy
        l_dot = ca.dot(g_l, yd)
        phi_dot = ca.dot(g_phi, yd)
        m_r, a_r = robot.rod_mass[i], robot.rod_com[i]
        J_leg = robot.leg_inertia_const[i] + m_r * (length - a_r) ** 2  # about the base joint
        M += m_r * (g_l @ g_l.T) + J_leg * (g_phi @ g_phi.T)
        # velocity products in the leg's coordinates (length, angle), and friction
        q_l = m_r * (dot * w * w - a_r * phi_dot * phi_dot) - robot.friction[i] * l_dot
        q_phi = 2.0 * (J_leg / length - m_r * (length - a_r)) * l_dot * phi_dot - J_leg * cross * w * w / length
        h += g_l * q_l + g_phi * q_phi
        rows.append(g_l.T)
    tx, ty = robot.tool
    rcx, rcy = -(c * tx - s * ty), -(s * tx + c * ty)  # platform centre from the tool point
    mp = robot.platform_mass
    M[0, 0] += mp
    M[1, 1] += mp
    M[2, 2] += mp * (rcx * rcx + rcy * rcy) + robot.platform_inertia
    M[0, 2] -= mp * rcy
    M[2, 0] -= mp * rcy
    M[1, 2] += mp * rcx
    M[2, 1] += mp * rcx
    h[0] += mp * w * w * rcx
    h[1] += mp * w * w * rcy
    return ca.Function("inv", [y, yd], [M, h, ca.vertcat(*rows)])


def check_dynamics(robot: RobotModel, inv, trials: int = 200) -> float:
    """Largest relative difference of ``inv`` against ``planner.model.dynamics.generalised_forces``
    and (forward: ``y_dd`` of random forces) against ``bench_optimality.casadi_dynamics``."""
    from bench_optimality import casadi_dynamics

    fwd = casadi_dynamics(robot)
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(trials):
        y = np.concatenate((rng.uniform(-0.03, 0.03, 2), rng.uniform(-0.3, 0.3, 1)))
        yd = np.concatenate((rng.uniform(-0.5, 0.5, 2), rng.uniform(-2, 2, 1)))
        f = rng.uniform(-1, 1, robot.n_legs) * robot.force_max
        M, h, J = (np.array(v) for v in inv(y, yd))
        Mr, hr, Jr = generalised_forces(robot, y, yd)
        for a, b in ((M, Mr), (h.ravel(), hr), (J, Jr)):
            worst = max(worst, float(np.max(np.abs(a - b)) / max(float(np.max(np.abs(b))), 1e-12)))
        ydd = np.linalg.solve(M, h.ravel() + J.T @ f)
        ref = np.array(fwd(np.concatenate((y, yd)), f)).ravel()[3:]
        worst = max(worst, float(np.max(np.abs(ydd - ref)) / max(float(np.max(np.abs(ref))), 1e-12)))
    return worst


# ------------------------------------------------------------------ the path
def _tangent(e: PathElement, at_end: bool) -> np.ndarray:
    if e.kind == "line":
        d = np.asarray(e.end, float) - np.asarray(e.start, float)
        return d / float(np.hypot(*d))
    assert e.start_angle_rad is not None and e.sweep_rad is not None
    a = e.start_angle_rad + (e.sweep_rad if at_end else 0.0)
    return math.copysign(1.0, e.sweep_rad) * np.array([-math.sin(a), math.cos(a)])


def _curvature(e: PathElement) -> float:
    if e.kind == "line":
        return 0.0
    assert e.radius_m is not None and e.sweep_rad is not None
    return math.copysign(1.0 / e.radius_m, e.sweep_rad)


def _slope(e: PathElement) -> float:
    return (e.z_end_m - e.z_start_m) / e.length_m if e.length_m > 0 else 0.0


def smooth_junction(a: PathElement, b: PathElement, z_slope: bool = True) -> bool:
    """True where the tool may pass ``a``'s end into ``b`` without stopping: tangent and
    (signed) curvature continuous, and (``z_slope``: with a Z acceleration limit) Z's slope
    (module docstring)."""
    t = float(_tangent(a, True) @ _tangent(b, False))
    ka, kb = _curvature(a), _curvature(b)
    same_slope = not z_slope or abs(_slope(a) - _slope(b)) <= 1e-9
    return t > 1 - 1e-9 and abs(ka - kb) <= 1e-6 * max(abs(ka), abs(kb), 1.0) and same_slope


@dataclass
class Optimum:
    time_s: float
    status: str
    cpu_s: float
    nodes: int
    max_residual: float  #: largest equation-of-motion residual at the nodes, N (generalised)
    element_time_s: np.ndarray | None = None  #: per element (of positive length) its time, s
    element_speed_m_s: np.ndarray | None = None  #: per element its top path speed, m/s


def third_order_optimum(robot: RobotModel, elements: list[PathElement], origin: np.ndarray, N: int,
                        rate: np.ndarray | None, feed_cap: bool = False, from_zero: bool = False,
                        z_max: float | None = None, z_acc: float | None = None,
                        guess: dict | None = None, verbose: bool = False, B: int = 3) -> tuple[Optimum, dict]:
    """The minimum time of one pass (module docstring) with ``N`` time steps per element.
    ``rate``: the force-rate limit per drive [N/s] (None: none); ``feed_cap``: ``v <= F``;
    ``z_max``, ``z_acc``: the Z axis speed and acceleration (None: none).
    ``guess``: a previous solution (per element times) to start from. Returns the optimum and
    the per-element times (a guess for a finer grid)."""
    import casadi as ca

    els = [e for e in elements if e.length_m > 1e-12]
    E, n = len(els), robot.n_legs
    nn = N + 1
    Nn = E * nn
    fmax = np.asarray(robot.force_max, float)
    vmax = np.asarray(robot.speed_max, float)
    # per-node geometry: line: p0 + s t; arc: c + R (cos, sin)(th0 + sg s / R)
    isarc = np.array([1.0 if e.kind == "arc" else 0.0 for e in els])
    P0 = np.array([np.asarray(e.start, float) + origin for e in els])
    T0 = np.array([_tangent(e, False) for e in els])
    C = np.array([(np.asarray(e.centre, float) + origin) if e.kind == "arc" else np.zeros(2) for e in els])
    R = np.array([e.radius_m if e.kind == "arc" else 1.0 for e in els], float)
    TH = np.array([e.start_angle_rad if e.kind == "arc" else 0.0 for e in els], float)
    SG = np.array([math.copysign(1.0, e.sweep_rad) if e.kind == "arc" else 1.0 for e in els], float)  # type: ignore[arg-type]
    L = np.array([e.length_m for e in els])
    Fe = np.array([e.feed_m_s for e in els])
    # the Z axis speed's bound on the XY speed of a move whose Z changes (as the planner's z_caps)
    dZ = np.array([abs(e.z_end_m - e.z_start_m) for e in els])
    Zc = np.where((dZ > 0) & (z_max is not None), (z_max or 0.0) * L / np.maximum(dZ, 1e-300), np.inf)
    # and the Z axis acceleration's on the path acceleration: |g a| <= z_acc
    Za = np.where((dZ > 0) & (z_acc is not None), (z_acc or 0.0) * L / np.maximum(dZ, 1e-300), np.inf)

    inv = casadi_inverse_dynamics(robot)
    # one node: residual of the equations of motion (3, scaled by force_max) and leg speeds (n)
    s_, v_, a_ = ca.SX.sym("s"), ca.SX.sym("v"), ca.SX.sym("a")
    f_ = ca.SX.sym("f", n)
    g_ = ca.SX.sym("g", 9)  # isarc, p0 (2), t0 (2), c (2), R, th0 ... sg folded into R's sign below
    sg_ = ca.SX.sym("sg")
    arc, p0, t0, cc, rr, th0 = g_[0], g_[1:3], g_[3:5], g_[5:7], g_[7], g_[8]
    th = th0 + sg_ * s_ / rr
    cs, sn = ca.cos(th), ca.sin(th)
    q_arc = cc + rr * ca.vertcat(cs, sn)
    dq_arc = sg_ * ca.vertcat(-sn, cs)
    ddq_arc = -ca.vertcat(cs, sn) / rr
    q_xy = arc * q_arc + (1 - arc) * (p0 + s_ * t0)
    dq_xy = arc * dq_arc + (1 - arc) * t0
    ddq_xy = arc * ddq_arc
    q = ca.vertcat(q_xy, 0.0)
    dq = ca.vertcat(dq_xy, 0.0)
    ddq = ca.vertcat(ddq_xy, 0.0)
    Msx, hsx, Jsx = inv(q, dq * v_)
    res = (Msx @ (dq * a_ + ddq * v_ * v_) - hsx - Jsx.T @ f_) / float(fmax.max())
    legs = (Jsx @ dq) * v_ / vmax
    node = ca.Function("node", [s_, v_, a_, f_, g_, sg_], [res, legs]).map(Nn)

    geo = np.zeros((9, Nn))
    sgn = np.zeros((1, Nn))
    for e in range(E):
        sl = slice(e * nn, (e + 1) * nn)
        geo[:, sl] = np.concatenate(([isarc[e]], P0[e], T0[e], C[e], [R[e], TH[e]]))[:, None]
        sgn[0, sl] = SG[e]

    opti = ca.Opti()
    # scaled decision variables: s [mm], v [0.1 m/s], a [10 m/s^2], f [force_max], h [ms]
    S = opti.variable(1, Nn)
    V = opti.variable(1, Nn)
    A = opti.variable(1, Nn)
    U = opti.variable(n, Nn)
    H = opti.variable(1, E * B)  # the time step of each block of each element
    s, v, a = 1e-3 * S, 0.1 * V, 10.0 * A
    f = ca.diag(ca.DM(fmax)) @ U
    h = 1e-3 * H
    res, legs = node(s, v, a, f, geo, sgn)
    opti.subject_to(ca.vec(res) == 0)
    opti.subject_to(opti.bounded(-1, ca.vec(legs), 1))
    opti.subject_to(opti.bounded(-1, ca.vec(U), 1))
    opti.subject_to(V >= 0)
    opti.subject_to(opti.bounded(1e-3, H, 1e3))
    if feed_cap:
        cap = np.repeat(Fe, nn) / 0.1
        opti.subject_to(V <= cap.reshape(1, -1))
    for e in np.flatnonzero(np.isfinite(Zc)):  # a ramp's Z within the axis speed
        opti.subject_to(V[0, e * nn:(e + 1) * nn] <= Zc[e] / 0.1)
    for e in np.flatnonzero(np.isfinite(Za)):  # and its acceleration (a is linear between the nodes)
        opti.subject_to(opti.bounded(-Za[e] / 10.0, A[0, e * nn:(e + 1) * nn], Za[e] / 10.0))
    # within an element: a linear in time, s and v integrated exactly
    i0 = np.concatenate([np.arange(e * nn, e * nn + N) for e in range(E)])
    i1 = i0 + 1
    blk = np.minimum(np.arange(N) * B // N, B - 1)  # block of each step within an element
    step_block = np.concatenate([e * B + blk for e in range(E)])
    hk = h[0, step_block]  # (1, N E): element e's N steps together
    opti.subject_to(v[0, i1] - v[0, i0] - hk * (a[0, i0] + a[0, i1]) / 2 == 0)
    opti.subject_to(1e3 * (s[0, i1] - s[0, i0] - v[0, i0] * hk - hk * hk * (2 * a[0, i0] + a[0, i1]) / 6) == 0)
    first = np.arange(E) * nn
    last = first + N
    opti.subject_to(S[0, first] == 0)
    opti.subject_to(S[0, last] == (L * 1e3).reshape(1, -1))
    if rate is not None:
        step = ca.DM(np.asarray(rate, float) / fmax) @ hk  # (n, N E) allowed change of U per step
        dU = U[:, i1] - U[:, i0]
        opti.subject_to(ca.vec(dU - step) <= 0)
        opti.subject_to(ca.vec(-dU - step) <= 0)
    # junctions: forces and speed continuous; a stop where tangent or curvature jumps
    for e in range(E - 1):
        opti.subject_to(U[:, last[e]] == U[:, first[e + 1]])
        if smooth_junction(els[e], els[e + 1], z_acc is not None):
            opti.subject_to(V[0, last[e]] == V[0, first[e + 1]])
        else:
            opti.subject_to(V[0, last[e]] == 0)
            opti.subject_to(V[0, first[e + 1]] == 0)
    # rest at both ends, holding the pose (zero generalised acceleration)
    for k in (first[0], last[-1]):
        opti.subject_to(V[0, k] == 0)
        opti.subject_to(A[0, k] == 0)
        if from_zero:
            opti.subject_to(U[:, k] == 0)
    opti.minimize(ca.sum2(1e3 * hk))  # the time [ms]

    # guess: per element a minimum-jerk rest-to-rest motion in T_e
    Tg = np.asarray(guess["T"]) if guess else np.maximum(2.5 * np.sqrt(L / 5.0), 0.01)
    if feed_cap and not guess:
        Tg = np.maximum(Tg, 1.9 * L / Fe)  # the minimum-jerk guess's top speed 1.875 L / T within F
    if not guess:
        Tg = np.maximum(Tg, 1.9 * L / Zc)  # and within the Z axis' bound
        Tg = np.maximum(Tg, np.sqrt(5.8 * L / Za))  # the minimum-jerk guess's top acceleration 5.77 L / T^2
    if guess and guess.get("N") is not None:  # the previous solution's block durations
        Db = np.asarray(guess["D"]).reshape(E, B)
    else:
        Db = np.repeat(Tg[:, None] / B, B, axis=1)
    counts = np.bincount(blk, minlength=B)
    hb = Db / counts  # (E, B) step per block
    tnode = [np.concatenate(([0.0], np.cumsum(hb[e][blk]))) for e in range(E)]
    taus = [tnode[e] / tnode[e][-1] for e in range(E)]
    Sg = np.concatenate([L[e] * (10 * x ** 3 - 15 * x ** 4 + 6 * x ** 5) for e, x in enumerate(taus)])
    Vg = np.concatenate([L[e] / Tg[e] * (30 * x ** 2 - 60 * x ** 3 + 30 * x ** 4) for e, x in enumerate(taus)])
    Ag = np.concatenate([L[e] / Tg[e] ** 2 * (60 * x - 180 * x ** 2 + 120 * x ** 3) for e, x in enumerate(taus)])
    if guess and guess.get("N") is not None:  # interpolate the previous solution in normalised time
        to = guess["t"]
        Sg = np.concatenate([np.interp(tnode[e], to[e], guess["s"][e]) for e in range(E)])
        Vg = np.concatenate([np.interp(tnode[e], to[e], guess["v"][e]) for e in range(E)])
        Ag = np.concatenate([np.interp(tnode[e], to[e], guess["a"][e]) for e in range(E)])
        Ug = np.concatenate([np.stack([np.interp(tnode[e], to[e], guess["u"][e][j]) for j in range(n)])
                             for e in range(E)], axis=1)
    else:
        # forces from the guessed motion: least-norm solution of J^T f = M y_dd - h
        node1 = ca.Function("n1", [s_, v_, a_, f_, g_, sg_], [Msx @ (dq * a_ + ddq * v_ * v_) - hsx, Jsx])
        Ug = np.zeros((n, Nn))
        for k in range(Nn):
            rhs, Jk = node1(Sg[k], Vg[k], Ag[k], np.zeros(n), geo[:, k], sgn[0, k])
            Ug[:, k] = np.clip(np.linalg.lstsq(np.array(Jk).T, np.array(rhs).ravel(), rcond=None)[0] / fmax, -1, 1)
    opti.set_initial(S, 1e3 * Sg.reshape(1, -1))
    opti.set_initial(V, 10 * Vg.reshape(1, -1))
    opti.set_initial(A, 0.1 * Ag.reshape(1, -1))
    opti.set_initial(U, Ug)
    opti.set_initial(H, 1e3 * hb.reshape(1, -1))
    opti.solver("ipopt", {"print_time": False},
                {"print_level": 5 if verbose else 0, "sb": "yes", "max_iter": 1000, "max_cpu_time": 120.0, "tol": 1e-9,
                 "acceptable_tol": 1e-7, "mu_strategy": "adaptive", "linear_solver": "mumps"})
    c0 = time.process_time()
    try:
        sol = opti.solve()
        status = "ok"
        val = sol.value
    except RuntimeError:
        status = opti.stats().get("return_status", "failed")
        val = opti.debug.value
    cpu = time.process_time() - c0
    hs = np.atleast_1d(np.asarray(val(H), float)).ravel().reshape(E, B) * 1e-3
    D = hs * counts  # block durations
    T_e = D.sum(axis=1)
    resid = float(np.max(np.abs(np.asarray(val(res))))) * float(fmax.max())
    Sv, Vv, Av, Uv = (np.asarray(val(x), float).reshape(-1, Nn) for x in (S, V, A, U))
    out = {"T": T_e, "N": N, "D": D, "t": [np.concatenate(([0.0], np.cumsum(hs[e][blk]))) for e in range(E)],
           "s": [Sv[0, e * nn:(e + 1) * nn] * 1e-3 for e in range(E)],
           "v": [Vv[0, e * nn:(e + 1) * nn] * 0.1 for e in range(E)],
           "a": [Av[0, e * nn:(e + 1) * nn] * 10 for e in range(E)],
           "u": [Uv[:, e * nn:(e + 1) * nn] for e in range(E)]}
    return Optimum(float(T_e.sum()), status, cpu, Nn, resid, T_e,
                   np.array([float(np.max(x)) for x in out["v"]])), out


def converged_optimum(robot: RobotModel, elements: list[PathElement], origin: np.ndarray, grids: list[int],
                      rate: np.ndarray | None, feed_cap: bool, from_zero: bool = False, blocks: int = 3,
                      tol: float = 1e-3, finest: int = 192, z_max: float | None = None,
                      z_acc: float | None = None) -> list[Optimum]:
    """The optimum at each grid (coarse to fine, each started from the previous), then on
    doubled grids until the last two agree within ``tol`` (relative) or ``finest`` is passed."""
    out, guess = [], None
    grids = list(grids)
    k = 0
    while k < len(grids):
        opt, guess = third_order_optimum(robot, elements, origin, grids[k], rate, feed_cap, from_zero, z_max, z_acc,
                                         guess, B=blocks)
        out.append(opt)
        k += 1
        if (k == len(grids) and len(out) > 1 and abs(out[-1].time_s / out[-2].time_s - 1) > tol
                and 2 * grids[-1] <= finest):
            grids.append(2 * grids[-1])
    return out


# ------------------------------------------------------------------ programs
def load_program(name: str) -> tuple[str, str, object]:
    """(label, G-code, origin) of ``bench`` (bench_contour's 15-pass part at its origin) or
    a program in tests/data/cam (origin ``fit``)."""
    if name == "bench":
        import bench_contour

        return "bench_contour part (15 passes)", bench_contour.program(), list(bench_contour.ORIGIN)
    return name, (CAM / name).read_text(), "fit"


def plan(text: str, origin, feed: str, settings: dict | None = None) -> tuple[object, float]:
    c0 = time.process_time()
    res = plan_contour({"program": text, "origin": origin, "feed": feed, "settings": settings or {}})
    return res, time.process_time() - c0


def element_table(label: str, i: int, els: list[PathElement], opt: Optimum, res, k: int) -> list[str]:
    """Per element of pass ``i``: the optimum's time and top speed next to the plan's (its
    samples whose ``program_line`` is the element's line in the ``k``-th cutting run; the top
    speed sample to sample): where a plan loses its time (``--elements``)."""
    c = res.contour
    Ts = res.settings.Ts
    cut = np.asarray(c.cutting, int)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], cut, [0]))))
    if len(edges) != 2 * len(c.passes):  # a pass cut in pieces (tabs, exact stops): no one run per pass
        return [f"\n{label} pass {i}: {len(edges) // 2} cutting runs for {len(c.passes)} passes, no element table"]
    a, b = edges[2 * k], edges[2 * k + 1]
    lines = np.array([-1 if x is None else x for x in c.program_line[a:b]])
    step = np.hypot(*np.diff(res.pose[a:b, :2], axis=0).T) / Ts
    els = [e for e in els if e.length_m > 1e-12]
    out = [f"\n{label} pass {i} (fastest at Ts {Ts:g} s): per element, the third-order optimum (stops where "
           "tangent or curvature jump) against the plan\n",
           "| element | line | kind | mm | R mm | 3rd order s | its top m/s | fastest s | its top m/s |",
           "|---|---|---|---|---|---|---|---|---|"]
    assert opt.element_time_s is not None and opt.element_speed_m_s is not None
    for j, e in enumerate(els):
        m = lines == e.line
        top = float(step[m[:-1]].max()) if m[:-1].any() else 0.0
        out.append(f"| {j} | {e.line} | {e.kind} | {e.length_m * 1e3:.2f} | "
                   f"{(e.radius_m or 0.0) * 1e3:.2f} | {opt.element_time_s[j]:.4f} | {opt.element_speed_m_s[j]:.3f} | "
                   f"{m.sum() * Ts:.4f} | {top:.3f} |")
    return out


def limit_rows(label: str, res, third: list[float]) -> list[str]:
    """Per pass of a ``fastest`` plan: its time over the third-order peer's (``third``, per pass),
    the two-sided tolerance (the largest distance of the cut from the path and of the path from
    the cut, each over the tolerance planned to: at most 1), and per program the largest drive
    force over its limit and the largest force change per sample over ``force_rate_n_s`` x Ts
    (each at most 1, as ``metrics.within_limits`` says)."""
    c = res.contour
    m = res.metrics
    tol = c.tolerance_m
    held = res.settings.force_rate_n_s  # the limit the plan held, N/s per drive (None: the default)
    rate = (np.asarray(load_robot(ROBOT).force_max, float) / DEFAULT_FORCE_RISE_S if held is None
            else np.asarray(held, float))
    f = np.asarray(res.drives.force, float)
    # the force change per sample from zero before the start, over its allowed change (as the metric)
    df = np.abs(np.diff(np.vstack([np.zeros((1, f.shape[1])), f]), axis=0)) / res.settings.Ts
    rate_ratio = float((df / rate).max())
    out: list[str] = []
    first, prev = 0, ""
    for i, p in enumerate(c.passes):  # passes alike in a row (depth passes): one line
        row = (f"| {p.time_s:.3f} | {third[i]:.4f} | {p.time_s / third[i]:.3f}x | {p.max_deviation_m / tol:.3f} | "
               f"{p.max_path_deviation_m / tol:.3f} | {res.settings.Ts * 1e3:g} |")
        if out and row == prev:
            out[-1] = f"| {label} | {first}-{i} {row}"
            continue
        first, prev = i, row
        out.append(f"| {label} | {i} {row}")
    out.append(f"| {label} | all | {c.cut_time_s:.3f} | {sum(third):.4f} | {c.cut_time_s / sum(third):.3f}x | "
               f"{c.max_deviation_m / tol:.3f} | {c.max_path_deviation_m / tol:.3f} | force {m.max_force_ratio:.3f}, "
               f"rate {rate_ratio:.3f} of the limits; within_limits {m.within_limits} |")
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--grids", default="24,48,96",
                    help="time steps per element, coarse to fine (three time blocks each)")
    ap.add_argument("--programs",
                    default="bench,freecad_linuxcnc.ngc,fusion360.nc",
                    help="'bench' (bench_contour's part) and/or files in tests/data/cam")
    ap.add_argument("--from-zero", action="store_true", help="forces 0 at each pass's start and end")
    ap.add_argument("--no-planner", action="store_true", help="the optima only")
    ap.add_argument("--blocks", type=int, default=3, help="time blocks per element (1: uniform steps)")
    ap.add_argument("--compare-ts", type=float, default=None,
                    help="also plan fastest at this typed Ts (e.g. 0.01, the default before issue 35 goal 3) "
                    "and print it beside the defaults")
    ap.add_argument("--elements", action="store_true",
                    help="per element of each distinct pass: the optimum's time and top speed beside fastest's")
    ap.add_argument("--fastest-only", action="store_true",
                    help="fastest and its optima only (no program feed, no optimum at F)")
    args = ap.parse_args()
    grids = [int(g) for g in args.grids.split(",")]
    robot = load_robot(ROBOT)
    rate = np.asarray(robot.force_max, float) / DEFAULT_FORCE_RISE_S
    print(f"load: {os.getloadavg()[0]:.1f} (1-min average) on {os.cpu_count()} cores")
    from importlib.metadata import version

    print(f"CasADi {version('casadi')} + IPOPT (MUMPS), TOPP-RA {version('toppra')}; robot {ROBOT}; "
          f"force rate {rate[0]:g} N/s per drive; grids {grids} nodes per element")
    err = check_dynamics(robot, casadi_inverse_dynamics(robot))
    print(f"CasADi dynamics against planner.model.dynamics and bench_optimality: largest relative "
          f"difference {err:.1e}\n")
    assert err < 1e-9, "the CasADi dynamics differ from the planner's"
    from bench_contour import topp_time

    if not args.no_planner:
        import bench_contour

        plan_contour({"program": bench_contour.program(1), "origin": bench_contour.ORIGIN})  # load the kernels
    memo: dict = {}
    conv_rows: list[str] = []
    summary: list[str] = []
    typed_rows: list[tuple[str, int, int, str]] = []  # program, first and last pass, the row
    element_rows: list[str] = []
    check_rows: list[str] = []
    for name in args.programs.split(","):
        label, text, origin = load_program(name)
        prog = read_gcode(text)
        res = {}
        if not args.no_planner:
            for feed in ("fastest",) if args.fastest_only else ("fastest", "program"):
                res[feed] = plan(text, origin, feed)
            if args.compare_ts:
                res["typed"] = plan(text, origin, "fastest", {"Ts": args.compare_ts})
            for feed, (r, cpu) in res.items():
                print(f"{label}: {feed} at Ts {r.settings.Ts:g} s, N {r.settings.N}: cut {r.contour.cut_time_s:.3f} s, "  # type: ignore[attr-defined]
                      f"{cpu:.1f} CPU s")
            c = res["fastest"][0].contour  # type: ignore[attr-defined]
        else:
            c = plan_contour({"program": text, "origin": origin, "feed": "program"}).contour  # type: ignore[attr-defined]
        assert c is not None
        org = np.asarray(c.origin, float)
        print(f"### {label}: {len(prog.passes)} passes, origin {[float(x) for x in np.round(org, 5)]} m\n")
        print("| pass | elements | mm | F mm/min | L / F s | fastest s | program s | TOPP-RA s (2nd order) | "
              "3rd order s | 3rd order, Z speed only s | 3rd order at F s | fastest / 3rd | fastest / 3rd, Z speed "
              "only | program / 3rd at F | fastest / TOPP-RA |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        tot = np.zeros(8)
        rows: list[tuple[int, str]] = []
        pass_keys: list = []
        for i, b in enumerate(prog.passes):
            els = b.elements
            key = (tuple((e.kind, *np.round(e.start, 9), *np.round(e.end, 9), round(e.sweep_rad or 0.0, 9),
                          round(e.feed_m_s, 9)) for e in els), tuple(np.round(org, 9)))
            pass_keys.append(key)
            if key not in memo:
                topp = topp_time(els, org, leg_speed=True)
                third = converged_optimum(robot, els, org, grids, rate, False, args.from_zero, args.blocks,
                                          z_max=Z_MAX_M_S, z_acc=Z_ACC_M_S2)
                # the earlier peer (the Z speed alone) where the pass moves Z; else the same problem
                moves_z = any(e.z_end_m != e.z_start_m and e.length_m > 1e-12 for e in els)
                zspeed = converged_optimum(robot, els, org, grids, rate, False, args.from_zero, args.blocks,
                                           z_max=Z_MAX_M_S) if moves_z else third
                capped = third if args.fastest_only else converged_optimum(
                    robot, els, org, grids, rate, True, args.from_zero, args.blocks, z_max=Z_MAX_M_S, z_acc=Z_ACC_M_S2)
                memo[key] = (topp, third, capped, zspeed)
                if args.elements and res:
                    element_rows += element_table(label, i, els, third[-1], res["fastest"][0], i)
                for lab, runs in (("3rd order", third), ("3rd order, Z speed only", zspeed),
                                  ("3rd order at F", capped)):
                    if (lab != "3rd order" and runs is third):
                        continue
                    times = " / ".join(f"{r.time_s:.5f}" for r in runs)
                    change = " / ".join(f"{abs(r.time_s / p.time_s - 1) * 100:.3f}" for p, r in zip(runs, runs[1:]))
                    conv_rows.append(f"| {label} pass {i} | {lab} | {', '.join(str(r.nodes) for r in runs)} | "
                                     f"{times} | {change} | {', '.join(r.status for r in runs)} | "
                                     f"{runs[-1].max_residual:.1e} | {sum(r.cpu_s for r in runs):.1f} |")
            topp, third, capped, zspeed = memo[key]
            t3, t3f, t3z = third[-1].time_s, capped[-1].time_s, zspeed[-1].time_s
            L = sum(e.length_m for e in els)
            nominal = sum(e.length_m / e.feed_m_s for e in els)
            # the optima's order: each adds a limit to the one before
            # (TOPP-RA knows no Z limit: the Z speed-only peer bounds it; the Z acceleration adds to that)
            assert topp <= t3z * (1 + 1e-3) and t3z <= t3 * (1 + 1e-3), (topp, t3z, t3)
            assert args.fastest_only or (t3 <= t3f * (1 + 1e-3) and nominal <= t3f * (1 + 1e-3)), (t3, t3f, nominal)
            feeds = sorted({round(e.feed_m_s * 60000) for e in els})
            fast = res["fastest"][0].contour.passes[i].time_s if res else math.nan  # type: ignore[attr-defined]
            prg = res["program"][0].contour.passes[i].time_s if "program" in res else math.nan  # type: ignore[attr-defined]
            if "typed" in res:
                typed = res["typed"][0].contour.passes[i].time_s  # type: ignore[attr-defined]
                row = (f"| {typed:.3f} | {typed / third[-1].time_s:.3f}x | {fast:.3f} | "
                       f"{fast / third[-1].time_s:.3f}x |")
                if typed_rows and typed_rows[-1][0] == label and typed_rows[-1][3] == row:  # depth passes alike
                    typed_rows[-1] = (label, typed_rows[-1][1], i, row)
                else:
                    typed_rows.append((label, i, i, row))
            tot += (fast, prg, topp, t3, t3f, L, nominal, t3z)
            row = (f"| {len(els)} | {L * 1e3:.1f} | {', '.join(map(str, feeds))} | {nominal:.3f} | {fast:.3f} | "
                   f"{prg:.3f} | {topp:.4f} | {t3:.4f} | {t3z:.4f} | {t3f:.4f} | {fast / t3:.3f}x | "
                   f"{fast / t3z:.3f}x | {prg / t3f:.3f}x | {fast / topp:.3f}x |")
            rows.append((i, row))
        k = 0
        while k < len(rows):  # passes alike in a row: one line
            j = k
            while j + 1 < len(rows) and rows[j + 1][1] == rows[k][1]:
                j += 1
            print(f"| {rows[k][0]}{'' if j == k else f'-{rows[j][0]}'} {rows[k][1]}")
            k = j + 1
        if res:
            check_rows += limit_rows(label, res["fastest"][0], [memo[k][1][-1].time_s for k in pass_keys])
        fast, prg, topp, t3, t3f, L, nominal, t3z = tot
        cf = res["fastest"][1] if res else math.nan
        cp = res["program"][1] if "program" in res else math.nan
        print(f"| all | | {L * 1e3:.1f} | | {nominal:.3f} | {fast:.3f} | {prg:.3f} | {topp:.4f} | {t3:.4f} | "
              f"{t3z:.4f} | {t3f:.4f} | {fast / t3:.3f}x | {fast / t3z:.3f}x | {prg / t3f:.3f}x | "
              f"{fast / topp:.3f}x |\n")
        summary.append(f"| {label} | {len(prog.passes)} | {L * 1e3:.0f} | {nominal:.2f} | {fast:.2f} | {cf:.1f} | "
                       f"{prg:.2f} | {cp:.1f} | {topp:.3f} | {t3:.3f} | {t3z:.3f} | {t3f:.3f} | {fast / t3:.3f}x | "
                       f"{fast / t3z:.3f}x | {prg / t3f:.3f}x |")
    if element_rows:
        print("\n".join(element_rows) + "\n")
    print("### per program (cutting time; compute: CPU s of the whole plan at the defaults)\n")
    print("| program | passes | mm | L / F s | fastest s | CPU s | program s | CPU s | TOPP-RA s | 3rd order s | "
          "3rd order, Z speed only s | 3rd order at F s | fastest / 3rd | fastest / 3rd, Z speed only | "
          "program / 3rd at F |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(summary))
    if check_rows:
        print("\n### fastest per pass: against the third-order optimum (goal 1: <= 1.0x), the two-sided "
              "tolerance (cut from path, path from cut, over the tolerance: <= 1), the drive limits\n")
        print("| program | pass | fastest s | 3rd order s | / 3rd | cut->path / tol | path->cut / tol | Ts ms |")
        print("|---|---|---|---|---|---|---|---|")
        print("\n".join(check_rows))
    if typed_rows:
        print(f"\n### fastest at the typed Ts {args.compare_ts:g} s against the defaults (per pass, against the "
              "3rd order)\n")
        print("| program | pass | typed Ts s | / 3rd | defaults s | / 3rd |")
        print("|---|---|---|---|---|---|")
        print("\n".join(f"| {lab} | {a}{'' if a == b else f'-{b}'} {row}" for lab, a, b, row in typed_rows))
    print(f"\n### grid refinement (steps per element {grids}, doubled until two agree within 0.1 %; "
          "change: from the previous grid, %)\n")
    print("| pass | optimum | nodes | time s per grid | change % | IPOPT | max residual N | IPOPT CPU s |")
    print("|---|---|---|---|---|---|---|---|")
    print("\n".join(conv_rows))


if __name__ == "__main__":
    main()
