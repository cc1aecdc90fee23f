"""Planner speed: Table I plan time, per-step cost against the horizon N, and the floor.

Usage:  OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_planner.py [--repeat 7]

Prints four tables (medians of --repeat runs):
1. Table I planned end to end with each solver (compute time as the planner reports it, and
   the receding-horizon loop alone): 'riccati' (the compiled loop, default) and the numpy
   reference loop with the 'structured' (banded) and 'qr' (the paper's) solvers.
2. Per-step cost for N = 10, 20, 40, 80: the compiled Riccati solve, the numpy structured
   (banded) solve, the paper's Householder QR route, the bare QR of the stacked matrix alone
   (the floor of the QR route), and a full compiled receding-horizon step (model, ZOH, solve,
   plant) from a Table I run at that N.
3. What one step at N = 20 is made of, compiled and numpy side by side.
4. A cold process: import, load of the cached compiled kernels, and one Table I plan.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from planner import parse_request, plan  # noqa: E402
from planner.corridor import range_sequence  # noqa: E402
from planner.horizon import prediction_matrices, solve_qr, solve_riccati, solve_structured, stacked_system  # noqa: E402
from planner.horizon.kernels import riccati  # noqa: E402
from planner.model import dynamics, kernels, load_robot  # noqa: E402
from planner.model.discretisation import zoh_factorised  # noqa: E402
from planner.model.plant import rk4_sample  # noqa: E402
from planner.orchestrator.simulate import C_POSE, simulate  # noqa: E402

TABLE1 = Path(__file__).resolve().parents[1] / "app" / "static" / "examples" / "table1.json"


def median_time(fn, repeat: int, inner: int = 1) -> float:
    """Median wall time of ``fn`` in seconds over ``repeat`` runs of ``inner`` calls."""
    fn()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        for _ in range(inner):
            fn()
        times.append((time.perf_counter() - t) / inner)
    return statistics.median(times)


def table1_request(**settings) -> dict:
    req = json.loads(TABLE1.read_text())
    req["settings"] = settings
    return req


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    R = args.repeat
    robot = load_robot("moving-slide")

    print("## Table I, end to end (median of", R, "runs)\n")
    print("compute = `metrics.compute_ms` (parse, checks, range sequence, loop, result); loop = "
          "`planner.orchestrator.simulate` alone.\n")
    print("| solver | steps | compute [ms] | loop [ms] | per step [us] | compute / riccati |")
    print("|---|---:|---:|---:|---:|---:|")
    base = None
    for solver in ("riccati", "structured", "qr"):
        req = table1_request(solver=solver)
        ms = statistics.median(plan(req).metrics.compute_ms for _ in range(R))
        steps = plan(req).metrics.steps
        preq = parse_request(req)
        seq = range_sequence(preq.segments, preq.settings, 4)
        loop = median_time(lambda seq=seq, st=preq.settings: simulate(robot, seq, st), R) * 1e3
        base = base or ms
        print(f"| {solver} | {steps} | {ms:.1f} | {loop:.1f} | {loop / steps * 1e3:.0f} | {ms / base:.1f} |")

    x = np.array([-0.03, 0.02, 0.0, 0.1, 0.05, 0.0])
    A22, B2 = dynamics.factorised_blocks(robot, x)
    Ad, Bd = zoh_factorised(A22, B2, 0.01)
    print("\n## Per step against the horizon N (median of", R, "runs)\n")
    print("| N | Riccati solve (compiled) [us] | structured solve (numpy) [us] | paper QR route [us] | "
          "bare QR of stacked matrix [us] | QR route / Riccati | full compiled step [us] | full step / N [us] |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for N in (10, 20, 40, 80):
        req = parse_request(table1_request(N=N))
        seq = range_sequence(req.segments, req.settings, 4)
        lo, hi, qa, qb, qu = seq.window(3 * N, N)
        qa, qb, lo, hi = (np.ascontiguousarray(a) for a in (qa, qb, lo, hi))
        U = np.empty((N, 4))
        quv = np.ascontiguousarray(qu[0])
        inner = max(1, 2000 // (N * N))
        t_ric = median_time(lambda a=(qa, qb, quv, lo, hi, U): riccati(Ad, Bd, x, *a), R, 200)
        t_st = median_time(lambda a=(qa, qb, qu, lo, hi): solve_structured(Ad, Bd, C_POSE, x, *a), R, 50)
        t_qr = median_time(lambda a=(qa, qb, qu, lo, hi): solve_qr(Ad, Bd, C_POSE, x, *a), R, inner)
        F, G = prediction_matrices(Ad, Bd, C_POSE, N)
        A, _ = stacked_system(F, G, x, qa, qb, qu, lo, hi)
        t_bare = median_time(lambda A=A: np.linalg.qr(A, mode="r"), R, inner)
        preq = parse_request(table1_request(N=N, require_settled=False))
        seq = range_sequence(preq.segments, preq.settings, 4)
        steps = simulate(robot, seq, preq.settings).steps
        step = median_time(lambda seq=seq, st=preq.settings: simulate(robot, seq, st), R) / steps * 1e6
        print(f"| {N} | {t_ric * 1e6:.1f} | {t_st * 1e6:.0f} | {t_qr * 1e6:.0f} | {t_bare * 1e6:.0f} | "
              f"{t_qr / t_ric:.0f} | {step:.1f} | {step / N:.2f} |")

    print("\n## One step at N = 20, by stage (median of", R, "x 200 calls; compiled calls include "
          "the ~0.3 us call from Python)\n")
    req = parse_request(table1_request())
    seq = range_sequence(req.segments, req.settings, 4)
    lo, hi, qa, qb, qu = seq.window(60, 20)
    qa, qb, lo, hi = (np.ascontiguousarray(a) for a in (qa, qb, lo, hi))
    u = solve_riccati(Ad, Bd, C_POSE, x, qa, qb, qu, lo, hi)[0]
    xdot = np.concatenate((x[3:], A22 @ x[3:] + B2 @ u))
    packed = robot.packed
    A22c, B2c, Adc, Bdc = np.empty((3, 3)), np.empty((3, 4)), np.empty((6, 6)), np.empty((6, 4))
    U = np.empty((20, 4))
    quv = np.ascontiguousarray(qu[0])

    stages = [
        ("model factorisation A(x), B(x) (eq. 8)", lambda: kernels.factorised_blocks(packed, x, A22c, B2c),
         lambda: dynamics.factorised_blocks(robot, x)),
        ("zero-order hold (eq. 9)", lambda: kernels.zoh(A22, B2, 0.01, Adc, Bdc),
         lambda: zoh_factorised(A22, B2, 0.01)),
        ("horizon solve (eqs. 22-23): Riccati / structured",
         lambda: riccati(Ad, Bd, x, qa, qb, quv, lo, hi, U),
         lambda: solve_structured(Ad, Bd, C_POSE, x, qa, qb, qu, lo, hi)),
        ("plant: one RK4 step of the nonlinear model (3 evaluations)", lambda: kernels.rk4(packed, x, u, 0.01, 1, xdot),
         lambda: rk4_sample(robot, x, u, 0.01, 1, xdot)),
    ]
    print("| stage | compiled [us] | numpy reference [us] | numpy / compiled |")
    print("|---|---:|---:|---:|")
    tc = tn = 0.0
    for name, fc, fnp in stages:
        a = median_time(fc, R, 200) * 1e6
        b = median_time(fnp, R, 200) * 1e6
        tc, tn = tc + a, tn + b
        print(f"| {name} | {a:.1f} | {b:.0f} | {b / a:.0f} |")
    print(f"| sum | {tc:.1f} | {tn:.0f} | {tn / tc:.0f} |")

    print("\n## A cold process (median of 3): `python -c` importing the planner and planning Table I once\n")
    code = ("import json, time; t = time.perf_counter(); from planner import plan; "
            f"t1 = time.perf_counter(); r = plan(json.load(open({str(TABLE1)!r}))); t2 = time.perf_counter(); "
            "print((t1 - t) * 1e3, (t2 - t1) * 1e3, r.metrics.compute_ms)")
    rows = []
    for _ in range(3):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
        rows.append([float(v) for v in out.split()])
    imp, first, comp = (statistics.median(c) for c in zip(*rows))
    print("| import planner [ms] | first plan incl. loading the cached kernels [ms] | its compute_ms |")
    print("|---:|---:|---:|")
    print(f"| {imp:.0f} | {first:.0f} | {comp:.0f} |")


if __name__ == "__main__":
    main()
