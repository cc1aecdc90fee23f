"""Optimality benchmark (issue 6): paper mode, constrained mode and the whole-horizon optimum.

The optimum: the same corridor, model, limits and duration solved over the whole horizon
with CasADi + IPOPT by direct multiple shooting:

* states ``X_k`` (6) and drive forces ``U_k`` (n) for ``k = 0..K`` (``K`` = the constrained
  plan's number of steps, so the same duration);
* ``X_{k+1} = RK4(X_k, U_k)`` with the *full nonlinear* nRPR dynamics (eq. 6), written in
  CasADi symbols from ``planner/model/dynamics.py``'s equations and checked here against
  ``dynamics.state_derivative`` at random states before solving; one RK4 step per sample with
  ``plant_substeps`` substeps, as the planner's plant;
* the same pose sets per sample as the constrained mode (the time-indexed ranges, shrunk by
  the same 1 um margin, the end point's micrometre box, polygon half-planes), the same
  ``|u| <= force_max``, leg speeds ``|J_l(y) y_dot| <= speed_max`` (exact, not linearised);
* start at rest at the start point (equality), end at rest (velocity zero) with the pose in
  the constrained mode's stop box at the end point (a few micrometres inside the last cell);
* minimise the drive energy ``sum u^2 Ts`` (the metric ``energy`` the planner reports),
  plus ``1e-9 sum |X_{k+1} - X_k|^2`` as a tiny regulariser.

Planner times: median of ``--repeat`` plans after one untimed plan per mode (loading the
compiled kernels is a one-off per process; the HTTP workers do it before serving). IPOPT:
median of ``--ipopt-repeat`` solves, NLP construction included.

Initial guess: poses at the centres of the per-sample ranges, velocities from their
differences, forces 0 (the planner's solution is not used). One table:
mode | compute time | energy | max violation | end error (and more).

Minimum time (issue 17): the planner's ``fastest`` plan against IPOPT over the same samples
(its per-segment counts, so the same per-sample boxes) with the sample time ``h`` a decision
variable, minimising ``K h``: the same force, leg-speed and force-rate limits (the rate limit
``rate h`` per sample), start at rest, end at rest in the stop box; started from the plan
(feasible for ``h = Ts``).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_optimality.py [--repeat 3] [--samples 20]

Needs the bench extra: ``pip install -e '.[bench]'`` (casadi).
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from planner import plan
from planner.constraints import ArrivalConstraint, CorridorConstraint, EndApproachConstraint
from planner.constraints.composed import force_rate
from planner.corridor import range_sequence
from planner.corridor.geometry import approach_direction, corridor_violation
from planner.model import dynamics, load_robot
from planner.model.plant import rk4_sample
from planner.orchestrator.result import overshoot
from planner.schema import MODE_DEFAULTS, parse_request

TABLE1 = Path(__file__).resolve().parents[1] / "app" / "static" / "examples" / "table1.json"
#: the paper mode's penalties and horizon, run in constrained mode for comparison with the
#: constrained mode's own defaults (planner.schema.MODE_DEFAULTS)
PAPER_PENALTIES = MODE_DEFAULTS["paper"]


def casadi_dynamics(robot):
    """``x_dot = f(x, u)`` of the nRPR robot in CasADi symbols (same equations as
    ``planner.model.dynamics``: reduced mass matrix ``R^T M R``, velocity products,
    viscous leg friction, ``J_l^T u``)."""
    import casadi as ca

    x = ca.SX.sym("x", 6)
    u = ca.SX.sym("u", robot.n_legs)
    px, py, psi, vx, vy, w = (x[i] for i in range(6))
    c, s = ca.cos(psi), ca.sin(psi)
    mp, m_r, a = robot.platform_mass, robot.rod_mass, robot.rod_com
    Jc = robot.leg_inertia_const
    M = ca.SX.zeros(3, 3)
    h = ca.SX.zeros(3)
    for i in range(robot.n_legs):
        r0x, r0y = robot.r0[i]
        rx, ry = c * r0x - s * r0y, s * r0x + c * r0y
        dx, dy = px + rx - robot.base[i, 0], py + ry - robot.base[i, 1]
        l = ca.sqrt(dx * dx + dy * dy)
        ex, ey = dx / l, dy / l
        cross = rx * ey - ry * ex
        dot = rx * ex + ry * ey
        Jl = ca.vertcat(ex, ey, cross)
        Jphi = ca.vertcat(-ey, ex, dot) / l
        l_dot = ex * vx + ey * vy + cross * w
        phi_dot = (ex * vy - ey * vx + dot * w) / l
        J_leg = Jc[i] + m_r[i] * (l - a[i]) ** 2
        M += m_r[i] * (Jl @ Jl.T) + J_leg * (Jphi @ Jphi.T)
        h_l = m_r[i] * (dot * w * w - a[i] * phi_dot * phi_dot) - robot.friction[i] * l_dot + u[i]
        h_phi = 2.0 * (J_leg / l - m_r[i] * (l - a[i])) * l_dot * phi_dot - J_leg * cross * w * w / l
        h += Jl * h_l + Jphi * h_phi
    tx, ty = robot.tool
    rcx, rcy = -(c * tx - s * ty), -(s * tx + c * ty)  # platform centre relative to the tool point
    M[0, 0] += mp
    M[1, 1] += mp
    M[2, 2] += mp * (rcx * rcx + rcy * rcy) + robot.platform_inertia
    M[0, 2] -= mp * rcy
    M[2, 0] -= mp * rcy
    M[1, 2] += mp * rcx
    M[2, 1] += mp * rcx
    h[0] += mp * w * w * rcx
    h[1] += mp * w * w * rcy
    acc = ca.solve(M, h)
    return ca.Function("f", [x, u], [ca.vertcat(vx, vy, w, acc)])


def check_dynamics(robot, f, trials: int = 200) -> float:
    """Largest relative difference between the CasADi dynamics and ``dynamics.state_derivative``."""
    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(trials):
        x = np.concatenate((rng.uniform(-0.06, 0.06, 2), rng.uniform(-0.3, 0.3, 1),
                            rng.uniform(-0.5, 0.5, 2), rng.uniform(-2, 2, 1)))
        u = rng.uniform(-1, 1, robot.n_legs) * robot.force_max
        a = np.array(f(x, u)).ravel()
        b = dynamics.state_derivative(robot, x, u)
        worst = max(worst, float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-12)))
    return worst


def solve_optimum(req: dict, K: int, robot, verbose=False, minimum_time: bool = False,
                  guess: tuple[np.ndarray, np.ndarray] | None = None) -> dict:
    """The whole-horizon optimum (module docstring) over ``K`` samples: minimum energy at the
    request's sample time, or (``minimum_time``) the minimum time ``K h`` with the sample time
    ``h`` a decision variable (the same samples, so the same per-sample boxes; the force-rate
    limit then ``rate h`` per sample). ``guess``: initial states (K+1, 6) and forces (K, m)
    instead of the range centres and zero forces."""
    import casadi as ca

    pr = parse_request(req)
    st = pr.settings
    segs = pr.segments
    seq = range_sequence(segs, st, robot.n_legs)
    sets = CorridorConstraint(seq, segs)
    approach = EndApproachConstraint(seq, segs)
    arrival = ArrivalConstraint(seq, segs)
    rate = force_rate(robot, st) if st.mode == "constrained" else None
    f = casadi_dynamics(robot)
    Ts, sub, m = st.Ts, st.plant_substeps, robot.n_legs
    xs, us, hs = ca.SX.sym("x", 6), ca.SX.sym("u", m), ca.SX.sym("h")
    xk, h = xs, hs / sub
    for _ in range(sub):
        k1 = f(xk, us)
        k2 = f(xk + 0.5 * h * k1, us)
        k3 = f(xk + 0.5 * h * k2, us)
        k4 = f(xk + h * k3, us)
        xk = xk + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    F = ca.Function("F", [xs, us, hs], [xk])

    opti = ca.Opti()
    X = opti.variable(6, K + 1)
    U = opti.variable(m, K)
    hT = opti.variable() if minimum_time else Ts
    if minimum_time:
        opti.subject_to(opti.bounded(0.2 * Ts, hT, 2.0 * Ts))
    opti.subject_to(X[:, 1:] == F.map(K)(X[:, :-1], U, ca.repmat(hT, 1, K)))
    start = np.concatenate((seq.start, np.zeros(3)))
    opti.subject_to(X[:, 0] == start)
    # at rest at the end: velocity zero, and the pose in the same end box as the constrained
    # mode (the end point's micrometre box inside the last cell; the sample set of K below)
    opti.subject_to(X[3:, K] == 0)
    fmax = robot.force_max.reshape(-1, 1)
    opti.subject_to(opti.bounded(-fmax, U, fmax))
    idx = np.minimum(np.arange(K), seq.K - 1)  # sample j = 1..K -> sequence index j-1
    lo, hi = sets.lo[idx], sets.hi[idx]
    hp_rows = [q for q in range(K) if sets.hp[idx[q]] is not None]
    box_rows = [q for q in range(K) if sets.hp[idx[q]] is None]
    P = X[:3, 1:]
    if box_rows:
        br = np.array(box_rows)
        opti.subject_to(opti.bounded(lo[br, :2].T, P[:2, br], hi[br, :2].T))
    opti.subject_to(opti.bounded(lo[:, 2].reshape(1, -1), P[2, :], hi[:, 2].reshape(1, -1)))
    for q in hp_rows:
        A_, b_ = sets.hp[idx[q]]
        opti.subject_to(A_ @ P[:2, q] <= b_)
    if approach.half_plane is not None:
        d, b = approach.half_plane
        sel = [q for q in range(K) if idx[q] >= approach.start_index]
        if sel:
            opti.subject_to(d[0] * P[0, sel] + d[1] * P[1, sel] <= b)
    rest = [q for q in range(K) if idx[q] >= arrival.start_index]  # at rest from the arrival on
    if rest:
        lim = arrival.limit.reshape(-1, 1)
        opti.subject_to(opti.bounded(-lim, X[3:, 1:][:, rest], lim))
    if rate is not None:  # force rates, from zero before the start
        dU = ca.horzcat(U[:, :1], U[:, 1:] - U[:, :-1])
        step = ca.repmat(ca.DM(rate.reshape(-1, 1)) * hT, 1, K)
        opti.subject_to(ca.vec(dU - step) <= 0)
        opti.subject_to(ca.vec(-dU - step) <= 0)
    # leg speeds, exact
    y, v = ca.SX.sym("y", 3), ca.SX.sym("v", 3)
    c_, s_ = ca.cos(y[2]), ca.sin(y[2])
    ld = []
    for i in range(m):
        r0x, r0y = robot.r0[i]
        rx, ry = c_ * r0x - s_ * r0y, s_ * r0x + c_ * r0y
        dx, dy = y[0] + rx - robot.base[i, 0], y[1] + ry - robot.base[i, 1]
        l = ca.sqrt(dx * dx + dy * dy)
        ld.append((dx * v[0] + dy * v[1]) / l + (rx * dy - ry * dx) / l * v[2])
    LD = ca.Function("ld", [y, v], [ca.vertcat(*ld)]).map(K)
    vmax = robot.speed_max.reshape(-1, 1)
    opti.subject_to(opti.bounded(-vmax, LD(X[:3, 1:], X[3:, 1:]), vmax))
    energy = ca.sumsqr(U) * hT
    if minimum_time:
        opti.minimize(K * hT + 1e-7 * energy)
        opti.set_initial(hT, Ts)
    else:
        opti.minimize(energy + 1e-9 * ca.sumsqr(X[:, 1:] - X[:, :-1]))
    if guess is not None:
        opti.set_initial(X, guess[0].T)
        opti.set_initial(U, guess[1].T)
    else:  # centres of the per-sample ranges
        cen = np.vstack((seq.start, 0.5 * (seq.lower[idx] + seq.upper[idx])))
        vel = np.vstack((np.diff(cen, axis=0) / Ts, np.zeros((1, 3))))
        opti.set_initial(X, np.hstack((cen, vel)).T)
        opti.set_initial(U, 0.0)
    opti.solver("ipopt", {"print_time": False, "ipopt.print_level": 5 if verbose else 0, "ipopt.sb": "yes",
                          "ipopt.tol": 1e-8, "ipopt.constr_viol_tol": 1e-10, "ipopt.max_iter": 3000,
                          "ipopt.acceptable_iter": 0, "ipopt.linear_solver": "mumps"})
    t0 = time.perf_counter()
    sol = opti.solve()
    dt = time.perf_counter() - t0
    Xs, Us = np.array(sol.value(X)).T, np.array(sol.value(U)).T
    stats = sol.stats()
    return {"X": Xs, "U": Us, "time_s": dt, "iterations": stats.get("iter_count"),
            "status": stats.get("return_status"), "segments": segs, "seq": seq, "F": F,
            "h": float(sol.value(hT)) if minimum_time else Ts}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs of each planner mode (median time)")
    ap.add_argument("--ipopt-repeat", type=int, default=1, help="runs of IPOPT (median time)")
    ap.add_argument("--samples", type=int, default=None, help="samples_per_segment (default 20)")
    ap.add_argument("--input", default=str(TABLE1), help="plan request JSON with segments")
    ap.add_argument("--verbose", action="store_true")
    args = ap.parse_args(argv)
    base = json.loads(Path(args.input).read_text())
    base.setdefault("settings", {})
    if args.samples:
        base["settings"]["samples_per_segment"] = args.samples
    robot = load_robot(base.get("robot", "moving-slide"))
    f = casadi_dynamics(robot)
    err = check_dynamics(robot, f)
    print(f"CasADi dynamics vs dynamics.state_derivative at 200 random states: max relative difference {err:.1e}")
    if err > 1e-10:
        print("dynamics differ: not the same model; stopping")
        return 1

    rows = []
    results = {}
    S = base["settings"].get("samples_per_segment", base["settings"].get("N", 20))
    pp = PAPER_PENALTIES
    configs = [("paper", {"mode": "paper", "samples_per_segment": S}),
               ("constrained", {"mode": "constrained", "samples_per_segment": S}),
               (f"constr. k_r={pp['k_r']:g} k_u={pp['k_u']:g} N={pp['N']}",
                {"mode": "constrained", **pp, "samples_per_segment": S})]
    for label, extra in configs:
        req = copy.deepcopy(base)
        req["settings"].update(extra)
        req["settings"]["require_settled"] = False
        plan(req)  # untimed: loads the compiled kernels this mode uses (once per process, as a server's warm-up)
        times = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            res = plan(req)
            times.append(time.perf_counter() - t0)
        results[label] = res
        mt = res.metrics
        rows.append((label, statistics.median(times), mt.energy, mt.max_corridor_violation_m,
                     mt.end_error_m, mt.overshoot_m, mt.max_force_ratio, mt.duration_s))
    K = results["constrained"].metrics.steps
    req = copy.deepcopy(base)
    req["settings"]["mode"] = "constrained"
    times, opt = [], None
    for _ in range(args.ipopt_repeat):
        opt = solve_optimum(req, K, robot, args.verbose)
        times.append(opt["time_s"])
    X, U = opt["X"], opt["U"]
    Ts = parse_request(req).settings.Ts
    viol = float(corridor_violation(X[:, :3], opt["segments"]).max())
    end_err = float(np.hypot(*(X[-1, :2] - opt["seq"].end[:2])))
    # replay IPOPT's forces through the planner's own plant (open loop)
    st = parse_request(req).settings
    x = X[0].copy()
    replay = 0.0
    for k in range(K):
        x = rk4_sample(robot, x, U[k], Ts, st.plant_substeps)
        replay = max(replay, float(np.max(np.abs(x[:3] - X[k + 1, :3]))))
    over = overshoot(X[:, :3], approach_direction(opt["segments"]), opt["seq"].end,
                     int(np.argmax(opt["seq"].segment >= len(opt["segments"]) - 2)) + 1)
    rows.append(("IPOPT optimum", statistics.median(times), float(np.sum(U * U) * Ts), viol, end_err, over,
                 float(np.max(np.abs(U) / robot.force_max)), K * Ts))
    print(f"IPOPT: {opt['status']}, {opt['iterations']} iterations, {K} intervals, {X.size + U.size} variables; "
          f"replaying its forces through the planner's plant: pose differs by {replay:.1e} (m/rad)")
    print()
    hdr = (f"{'mode':22s} {'compute ms':>11s} {'energy N^2 s':>13s} {'max viol m':>11s} {'end err m':>10s} "
           f"{'overshoot m':>11s} {'F/Fmax':>7s} {'duration s':>10s}")
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        print(f"{r[0]:22s} {r[1] * 1e3:11.1f} {r[2]:13.2f} {r[3]:11.1e} {r[4]:10.1e} {r[5]:11.1e} {r[6]:7.3f} "
              f"{r[7]:10.2f}")
    print()
    for r in rows[1:3]:
        print(f"{r[0]}: energy / IPOPT's {r[2] / rows[3][2]:.3f} (goal <= 1.15); "
              f"IPOPT time / its time {rows[3][1] / r[1]:.1f}x (goal >= 50x)")
    # minimum time: the planner's fastest timing against IPOPT over the same samples (the
    # same per-sample boxes) with the sample time a decision variable
    req = copy.deepcopy(base)
    req["settings"] = {"mode": "constrained", "fastest": True}
    t0 = time.perf_counter()
    fast = plan(req)
    search_s = time.perf_counter() - t0
    st_fast = fast.settings.model_dump(mode="json", exclude_none=True)
    st_fast.pop("fastest", None)
    st_fast.pop("samples_per_segment", None)
    req = {**base, "settings": st_fast}
    guess = (np.hstack((fast.pose, fast.velocity)), fast.drives.force[:-1])
    opt = solve_optimum(req, fast.metrics.steps, robot, args.verbose, minimum_time=True, guess=guess)
    t_min = opt["h"] * fast.metrics.steps
    print()
    print(f"{'minimum time':22s} {'compute s':>11s} {'duration s':>11s} {'sample time ms':>15s}")
    print(f"{'planner fastest':22s} {search_s:11.2f} {fast.metrics.duration_s:11.3f} {fast.settings.Ts * 1e3:15.2f}")
    print(f"{'IPOPT minimum time':22s} {opt['time_s']:11.2f} {t_min:11.3f} {opt['h'] * 1e3:15.2f}")
    print(f"fastest / IPOPT minimum time over the same {fast.metrics.steps} samples: "
          f"{fast.metrics.duration_s / t_min:.3f} (goal <= 1.05); IPOPT {opt['status']}, {opt['iterations']} "
          f"iterations; timing {fast.timing.segment_samples}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
