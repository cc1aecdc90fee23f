"""Planner speed: Table I plan time, per-step cost against the horizon N, and the floor.

Usage:  OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_planner.py [--repeat 7]

Prints three tables (medians of --repeat runs):
1. Table I planned end to end with each solver (compute time as the planner reports it).
2. Per-step cost for N = 10, 20, 40, 80: the structured (banded) solve, the paper's
   Householder QR route, the bare QR of the stacked matrix alone (the floor of the QR route),
   and a full receding-horizon step (model, ZOH, solve, plant) from a Table I run at that N.
3. What one step at N = 20 is made of.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from planner.discretisation import zoh_factorised  # noqa: E402
from planner.plan import C_POSE, plan, rk4_sample  # noqa: E402
from planner.prediction import prediction_matrices  # noqa: E402
from planner.ranges import range_sequence  # noqa: E402
from planner.request import parse_request  # noqa: E402
from planner.robot import load_robot  # noqa: E402
from planner.solver import solve_qr, solve_structured, stacked_system  # noqa: E402

TABLE1 = Path(__file__).resolve().parents[1] / "tests" / "data" / "table1-corridor.json"


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

    print("## Table I, end to end (compute_ms as reported by the planner; median of", R, "runs)\n")
    print("| solver | steps | compute [ms] | per step [us] |")
    print("|---|---:|---:|---:|")
    for solver in ("structured", "qr"):
        req = table1_request(solver=solver)
        ms = statistics.median(plan(req)["metrics"]["compute_ms"] for _ in range(R))
        steps = plan(req)["metrics"]["steps"]
        print(f"| {solver} | {steps} | {ms:.1f} | {ms / steps * 1e3:.0f} |")

    robot = load_robot("moving-slide")
    x = np.array([-0.03, 0.02, 0.0, 0.1, 0.05, 0.0])
    A22, B2 = robot.factorised_blocks(x)
    Ad, Bd = zoh_factorised(A22, B2, 0.01)
    print("\n## Per step against the horizon N (median of", R, "runs)\n")
    print("| N | structured solve [us] | paper QR route [us] | bare QR of stacked matrix [us] | "
          "QR route / structured | full step, structured [us] | full step / N [us] |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for N in (10, 20, 40, 80):
        req = parse_request(table1_request(N=N))
        seq = range_sequence(req.segments, req.settings, 4)
        lo, hi, qa, qb, qu = seq.window(3 * N, N)
        inner = max(1, 2000 // (N * N))
        t_st = median_time(lambda: solve_structured(Ad, Bd, C_POSE, x, qa, qb, qu, lo, hi), R, 50)
        t_qr = median_time(lambda: solve_qr(Ad, Bd, C_POSE, x, qa, qb, qu, lo, hi), R, inner)
        F, G = prediction_matrices(Ad, Bd, C_POSE, N)
        A, _ = stacked_system(F, G, x, qa, qb, qu, lo, hi)
        t_bare = median_time(lambda: np.linalg.qr(A, mode="r"), R, inner)
        runs = [plan(table1_request(N=N, require_settled=False)) for _ in range(3)]
        step = statistics.median(r["metrics"]["compute_ms"] / r["metrics"]["steps"] for r in runs) * 1e3
        print(f"| {N} | {t_st * 1e6:.0f} | {t_qr * 1e6:.0f} | {t_bare * 1e6:.0f} | {t_qr / t_st:.1f} | "
              f"{step:.0f} | {step / N:.1f} |")

    print("\n## One step at N = 20, by stage (median of", R, "x 200 calls)\n")
    req = parse_request(table1_request())
    seq = range_sequence(req.segments, req.settings, 4)
    lo, hi, qa, qb, qu = seq.window(60, 20)
    u = solve_structured(Ad, Bd, C_POSE, x, qa, qb, qu, lo, hi)[0]
    xdot = np.concatenate((x[3:], A22 @ x[3:] + B2 @ u))

    def window_and_solve():
        w_lo, w_hi, w_qa, w_qb, w_qu = seq.window(60, 20)
        return solve_structured(Ad, Bd, C_POSE, x, w_qa, w_qb, w_qu, w_lo, w_hi)

    stages = {
        "model factorisation A(x), B(x) (eq. 8)": lambda: robot.factorised_blocks(x),
        "zero-order hold (eq. 9)": lambda: zoh_factorised(A22, B2, 0.01),
        "range window + structured solve (eqs. 22-23)": window_and_solve,
        "plant: one RK4 step of the nonlinear model (3 evaluations)": lambda: rk4_sample(robot, x, u, 0.01, 1, xdot),
    }
    print("| stage | time [us] |")
    print("|---|---:|")
    total = 0.0
    for name, fn in stages.items():
        t = median_time(fn, R, 200) * 1e6
        total += t
        print(f"| {name} | {t:.0f} |")
    print(f"| sum | {total:.0f} |")


if __name__ == "__main__":
    main()
