"""Issue 31: plans where users go, at the defaults, certified by the independent checker.

Usage:  OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_fine_ts.py [--seeds 3] [--fine-seeds 1]
        [--users 200 [--users-seed 31]]

Prints three tables (CPU seconds of this process, so that other load matters less):
1. the issue's short [point, box, point] corridors (3-30 mm boxes, start and end at opposite
   corners; 8 a seed) at Ts 2 ms (``--seeds``) and 1 ms (``--fine-seeds``) with the default
   settings: cases, planned, refused, checker problems (tests/certify_support.py), the steps
   done on the Python path (DAQP fallbacks), the least and the largest measured CPU / work
   estimate, and the total time;
2. Table I at Ts 10, 5, 2 and 1 ms with the defaults: N, samples a segment, duration, drive
   energy, the checker's verdict, CPU;
3. Table I with ``fastest`` for four robots (Moving Slide, leg friction 500 and 2000 N s/m, a
   150 kg platform), and for the Moving Slide at the ``--fastest-ts`` sample times (5 and 2
   ms): the plant's RK4 steps a sample, duration found, candidates, CPU,
   estimate and their ratio, and the largest distance of a sample from RK4 with 16 steps a
   sample of the plan's own forces;
4. with ``--users N``: N cases of the generator of where users go
   (:func:`tests.certify_support.user_case`, Ts 1-10 ms) certified in the constrained mode
   (:func:`tests.certify_support.certify_case`): outcomes, problems, the largest measured CPU /
   estimate and how many exceed 1.5x, the total time.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import copy  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from planner import PlannerError, estimate_work, plan  # noqa: E402
from planner.model import load_robot  # noqa: E402
from planner.model.plant import rk4_sample  # noqa: E402
from tests.certify_support import certify_case, check_plan, user_case  # noqa: E402
from tests.test_fine_ts import short_corridor  # noqa: E402

TABLE1 = json.loads((ROOT / "app" / "static" / "examples" / "table1.json").read_text())
SLIDE = json.loads((ROOT / "planner" / "data" / "moving-slide.json").read_text())


def short_table(Ts: float, seeds: int) -> str:
    n = planned = problems = fallbacks = 0
    worst, least = 0.0, float("inf")
    t_all = time.process_time()
    for seed in range(seeds):
        for case in range(8):
            req = {"segments": short_corridor(seed, case), "settings": {"Ts": Ts}}
            est = estimate_work(req).seconds
            n += 1
            t0 = time.process_time()
            try:
                res = plan(req)
            except PlannerError:
                continue
            ratio = (time.process_time() - t0) / est
            worst, least = max(worst, ratio), min(least, ratio)
            planned += 1
            fallbacks += res.metrics.qp_fallbacks or 0
            problems += 0 if check_plan(req, res).ok else 1
    return (f"| {Ts * 1e3:g} ms | {n} | {planned} | {n - planned} | {problems} | {fallbacks} | "
            f"{least:.2f} - {worst:.2f} | {time.process_time() - t_all:.1f} s |")


def table1_row(Ts: float) -> str:
    req = copy.deepcopy(TABLE1)
    req["settings"] = {"Ts": Ts}
    t0 = time.process_time()
    res = plan(req)
    cpu = time.process_time() - t0
    ok = check_plan(req, res).ok
    m = res.metrics
    return (f"| {Ts * 1e3:g} ms | {res.settings.N} | {res.settings.samples_per_segment} | {m.duration_s:.2f} s | "
            f"{m.energy:.1f} | {'certified' if ok else 'PROBLEM'} | {cpu:.2f} s |")


def deviation(res, robot, Ts: float) -> float:
    model = load_robot(robot)
    X = np.hstack((res.pose, res.velocity))
    U = res.drives.force
    return max(float(np.hypot(*(rk4_sample(model, X[k], U[k], Ts, 16)[:2] - X[k + 1][:2])))
               for k in range(len(X) - 1))


def fastest_row(name: str, robot, Ts: float = 0.01) -> str:
    req = copy.deepcopy(TABLE1)
    req["robot"] = robot
    req["settings"] = {"fastest": True} if Ts == 0.01 else {"fastest": True, "Ts": Ts}
    est = estimate_work(req).seconds
    t0 = time.process_time()
    res = plan(req)
    cpu = time.process_time() - t0
    ok = check_plan(req, res).ok
    return (f"| {name} | {res.settings.plant_substeps} | {res.metrics.duration_s:.2f} s | {res.timing.evaluations} | "
            f"{cpu:.2f} s | {est:.2f} s | {cpu / est:.2f} | {deviation(res, robot, Ts) * 1e6:.4f} um | "
            f"{'certified' if ok else 'PROBLEM'} |")


def users_table(n: int, seed: int) -> str:
    outcomes: dict[str, int] = {}
    problems, over, worst = [], 0, 0.0
    t_all = time.process_time()
    for i in range(n):
        case = user_case(np.random.default_rng([seed, i]))
        rec = certify_case(case, modes=("constrained",))["constrained"]
        outcomes[rec["outcome"]] = outcomes.get(rec["outcome"], 0) + 1
        if rec.get("problem"):
            problems.append((i, rec["problem"]))
        if rec.get("estimate"):
            r = rec["seconds"] / rec["estimate"]
            worst = max(worst, r)
            over += r > 1.5
    for i, p in problems[:5]:
        print(f"case {i}: {p}")
    kinds = ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items()))
    return (f"| {n} (seed {seed}) | {kinds} | {len(problems)} | {worst:.2f} | {over} | "
            f"{time.process_time() - t_all:.0f} s |")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=3, help="seeds of 8 short corridors at Ts 2 ms")
    ap.add_argument("--fine-seeds", type=int, default=1, help="seeds of 8 short corridors at Ts 1 ms")
    ap.add_argument("--users", type=int, default=0, help="cases of the where-users-go generator")
    ap.add_argument("--users-seed", type=int, default=31)
    ap.add_argument("--fastest-ts", type=float, nargs="*", default=[0.005, 0.002],
                    help="sample times of further Table I fastest rows (Moving Slide)")
    args = ap.parse_args()
    plan(copy.deepcopy(TABLE1))  # kernels loaded
    print("| Ts | cases | planned | refused | checker problems | DAQP fallback steps | "
          "CPU / estimate (least - largest) | CPU |")
    print("|---|---|---|---|---|---|---|---|")
    print(short_table(0.002, args.seeds))
    if args.fine_seeds:
        print(short_table(0.001, args.fine_seeds))
    print()
    print("| Table I at Ts | N | samples a segment | duration | energy [N^2 s] | checker | CPU |")
    print("|---|---|---|---|---|---|---|")
    for Ts in (0.01, 0.005, 0.002, 0.001):
        print(table1_row(Ts))
    print()
    robots = [("Moving Slide", "moving-slide")]
    for name, key, value in (("leg friction 500", "friction", 500.0), ("leg friction 2000", "friction", 2000.0),
                             ("platform 150 kg", "mass", 150.0)):
        d = copy.deepcopy(SLIDE)
        if key == "friction":
            d["legs"]["friction"] = value
        else:
            d["platform"]["mass"] = value
        robots.append((name, d))
    print("| Table I fastest | RK4 steps a sample | duration | candidates | CPU | estimate | ratio | "
          "from RK4 x16 | checker |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, robot in robots:
        print(fastest_row(name, robot))
    for Ts in args.fastest_ts:
        print(fastest_row(f"Moving Slide, Ts {Ts * 1e3:g} ms", "moving-slide", Ts))
    if args.users:
        print()
        print("| cases | outcomes | checker problems | largest CPU / estimate | over 1.5x | CPU |")
        print("|---|---|---|---|---|---|")
        print(users_table(args.users, args.users_seed))


if __name__ == "__main__":
    main()
