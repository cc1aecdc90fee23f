"""Issue 31 goal 1: the independent checker's CPU time per plan (``tests/certify_support.py``,
:func:`check_plan`), reading the result's arrays directly (:func:`result_fields`, now) against
reading the result's whole JSON parsed back (before), on Table I at Ts 10, 2 and 1 ms.

Usage:  OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_certify_checker.py [--rounds 15]

Prints a table of medians of ``--rounds`` checks each (CPU seconds of this process, the two
readings alternated), their ratio and whether both found the same (figures and problems).
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from planner import plan, warm_up  # noqa: E402
from tests.certify_support import check_plan  # noqa: E402
from tests.support import TABLE1, with_settings  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--rounds", type=int, default=15)
    args = ap.parse_args()
    warm_up()
    cases = {"Table I, Ts 10 ms": TABLE1, "Table I, Ts 2 ms, N 60": with_settings(TABLE1, Ts=0.002, N=60),
             "Table I, Ts 1 ms, N 100": with_settings(TABLE1, Ts=0.001, N=100)}
    print("| plan | samples | check via the JSON [ms] | check of the arrays [ms] | ratio | same verdict |\n"
          "|---|---|---|---|---|---|")
    for name, req in cases.items():
        res = plan(req)
        via_json, direct = [], []
        for _ in range(args.rounds):
            t = time.process_time()
            a = check_plan(req, json.loads(res.model_dump_json()), req["segments"])
            via_json.append(time.process_time() - t)
            t = time.process_time()
            b = check_plan(req, res, req["segments"])
            direct.append(time.process_time() - t)
        same = a.figures == b.figures and a.problems == b.problems
        j, d = statistics.median(via_json), statistics.median(direct)
        print(f"| {name} | {len(res.pose)} | {j * 1e3:.2f} | {d * 1e3:.2f} | {j / d:.1f}x | {same} |")


if __name__ == "__main__":
    main()
