"""The settling tail of a corridor ending in an x/y point with a psi range, against the work
estimate (issue 20).

Such a plan settles at the middle of the end point's angle range, at most at the arrival rate
(1e-3 rad/s): up to the whole tail (``tail_max_s``), each step with ~2N rows active (the
no-overshoot half-plane and the arrival's psi rate) that the compiled stage-wise solver's warm
start substitutes and factors again (seed 22 case 4731: 59 rows a step over 193 settling
steps, 2.8x its estimate before the term ``tail_row_b N + tail_row_c N^2`` per row and
settling step of ``planner.schema.WORK_COSTS``).

``--calibrate``: corridors of :func:`tests.certify_support.slow_corridor` ending in such a
point, planned at horizons N = 20, 30, 60 (least CPU time of 3): the cost of one row through
one settling step, ``(CPU - the estimate's cost of the steps actually run) / (settling steps x
(2N - 1))``, against the term (the calibration table of ``benchmarks/README.md``).

``--cases M`` (default): M random slow corridors of millimetre boxes (``slow_corridor``),
planned in the constrained mode and certified (``tests.certify_support.certify_case``), the
measured CPU time (on the reference machine: over the machine's speed now, Table I's CPU time
over its quiet time, as ``benchmarks/certify.py``; a case over 1.5x timed twice more and kept
at its least) against the estimate without the term (as before it) and with it, side by side
in one run.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_tail.py [--cases 400] [--seed 1] [--calibrate]
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import certify  # noqa: E402

from planner import PlannerError, estimate_work, plan, warm_up  # noqa: E402
from planner.orchestrator import work  # noqa: E402
from planner.schema import WORK_COSTS, parse_request  # noqa: E402
from tests.certify_support import _with, certify_case, slow_corridor  # noqa: E402


def _cpu(req: dict) -> float:
    t0 = time.process_time()
    try:
        plan(req)
    except PlannerError:
        pass
    return time.process_time() - t0


def _speed() -> float:
    """The machine's speed now against the reference machine: the least of 3 calibrations
    (``certify._calibrate``; one taken while another process runs reads up to 2x slow)."""
    speeds = []
    for _ in range(3):
        certify._calibrate()
        speeds.append(certify._SPEED["constrained"])
    return min(speeds)


def _without_term(req: dict) -> float:
    """The estimate as it was before the settling rows' term (the term's costs set to zero)."""
    saved = WORK_COSTS["tail_row_b"], WORK_COSTS["tail_row_c"]
    WORK_COSTS["tail_row_b"] = WORK_COSTS["tail_row_c"] = 0.0
    try:
        return estimate_work(req).seconds
    finally:
        WORK_COSTS["tail_row_b"], WORK_COSTS["tail_row_c"] = saved


def _psi_end(case: dict) -> bool:
    lo, hi = case["segments"][-1]["lower"], case["segments"][-1]["upper"]
    return lo[0] == hi[0] and lo[1] == hi[1] and hi[2] > lo[2]


def calibrate(seed: int, count: int) -> None:
    rng = np.random.default_rng(seed)
    cases = []
    while len(cases) < count:
        c = slow_corridor(rng)
        if _psi_end(c):
            cases.append(c)
    print("machine speed (Table I CPU now / quiet, the least of 3 calibrations before each horizon):", end=" ")
    c = WORK_COSTS
    table = []
    for N in (20, 30, 60):
        speed = _speed()
        print(f"{speed:.2f}", end=" ", flush=True)
        per_row, tails = [], []
        for case in cases:
            req = _with(dict(case, settings={**case["settings"], "N": N}), mode="constrained")
            try:
                res = plan(req)
            except PlannerError:
                continue
            cpu = min(_cpu(req) for _ in range(3)) / speed
            st = parse_request(req).settings
            K = round(res.timing.sequence_time_s / st.Ts)
            steps = res.metrics.steps
            tail = steps - K
            if tail < 20:
                continue
            step_s = work._step_cost("constrained", "compiled", st.solver, N, st.plant_substeps)
            base = c["fixed"] + steps * (step_s + c["sample"])
            per_row.append((cpu - base) / (tail * (2 * N - 1)))
            tails.append(tail)
        if per_row:
            a = np.array(per_row) * 1e6
            table.append(f"| {N} | {len(a)} | {np.median(tails):.0f} | {np.median(a):.2f} | "
                         f"{np.percentile(a, 90):.2f} | {a.max():.2f} | {work.tail_row_cost(N) * 1e6:.2f} |")
    print("\n\n| N | plans with >= 20 settling steps | settling steps (median) | row cost median [us] | p90 [us] | "
          "largest [us] | term b N + c N^2 [us] |\n|---:|---:|---:|---:|---:|---:|---:|")
    print("\n".join(table))


def sample(seed: int, count: int) -> None:
    rng = np.random.default_rng(seed)
    cases = [slow_corridor(rng) for _ in range(count)]
    certify._calibrate()
    since = 0
    rows: list[tuple[float, float, bool]] = []
    problems, outcomes = [], {}
    t0 = time.perf_counter()
    for case in cases:
        if since >= certify.CALIBRATE:
            certify._calibrate()
            since = 0
        since += 1
        rec = certify_case(case, modes=("constrained",))["constrained"]
        outcomes[rec["outcome"]] = outcomes.get(rec["outcome"], 0) + 1
        if rec.get("problem"):
            problems.append((rec["outcome"], rec["problem"]))
        if rec["outcome"] != "ok":
            continue
        req = _with(case, mode="constrained")
        speed = certify._SPEED["constrained"]
        sec, after, before = rec["seconds"], rec["estimate"], _without_term(req)
        if sec / speed / min(before, after) > 1.5:  # timed twice more at a new calibration, as certify.py
            certify._calibrate()
            speed = certify._SPEED["constrained"]
            sec = min(_cpu(req) for _ in range(2))
        rows.append((sec / speed / before, sec / speed / after, _psi_end(case)))
    wall = time.perf_counter() - t0
    print(f"{count} slow corridors of millimetre boxes (seed {seed}), {wall / 60:.1f} min; outcomes {outcomes}; "
          f"problems {len(problems)}")
    for code, what in problems[:10]:
        print(f"  {code}: {what[:200]}")
    print("\nmeasured CPU time / work estimate on the reference machine, constrained plans\n")
    print("| plans | estimate | count | median | 99th percentile | largest | over 1.5 |\n"
          "|---|---|---:|---:|---:|---:|---:|")
    for what, sel in (("all", lambda r: True), ("end with a psi range", lambda r: r[2]),
                      ("other ends", lambda r: not r[2])):
        for k, name in ((0, "before (no settling-row term)"), (1, "after")):
            a = sorted(r[k] for r in rows if sel(r))
            if a:
                print(f"| {what} | {name} | {len(a)} | {a[len(a) // 2]:.2f} | "
                      f"{a[min(len(a) - 1, int(0.99 * len(a)))]:.2f} | {a[-1]:.2f} | {sum(x > 1.5 for x in a)} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=400)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--calibrate", action="store_true", help="the row cost per horizon (calibration table)")
    args = ap.parse_args()
    warm_up()
    if args.calibrate:
        calibrate(args.seed, min(args.cases, 40))
    else:
        sample(args.seed, args.cases)


if __name__ == "__main__":
    main()
