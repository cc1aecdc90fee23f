"""What the first contour in a fresh planning worker pays for (issue 33 goal 2): the worker's
start (``app.worker_process.load_planner``) with and without its preload of ``scipy.optimize``
(``PRELOAD``), then the CPU seconds of the first and the second contour of a program with
Z ramps (the Z axis's LP, ``linprog``), each run in a fresh interpreter.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_worker_preload.py [--runs 5]

Prints one table: medians over the runs; ``first / second``: what the first job pays over a
warm one.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

CHILD = r"""
import json, sys, time
import app.worker_process as wp
if sys.argv[1] == "none":
    wp.PRELOAD = ()
t0 = time.process_time()
status = wp.load_planner()
start = time.process_time() - t0
assert status == ("ready", None), status
from planner.contour import plan_contour

from tests.contour_programs import staircase

req = {"program": staircase(150, 50), "feed": "program"}
cpu = []
for _ in range(2):
    t0 = time.process_time()
    plan_contour(req)
    cpu.append(time.process_time() - t0)
print(json.dumps({"start": start, "first": cpu[0], "second": cpu[1],
                  "optimize_at_start": "scipy.optimize" in sys.modules}))
"""


def one(variant: str) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, variant], cwd=ROOT, capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    rows = {}
    for _ in range(args.runs):  # interleaved, so that the machine's load falls on both alike
        for variant in ("none", "scipy.optimize"):
            rows.setdefault(variant, []).append(one(variant))
    print(f"| worker preload | start CPU s | first contour CPU s | second contour CPU s | first / second |"
          f"  (medians of {args.runs} fresh processes)")
    print("|---|---|---|---|---|")
    for variant, runs in rows.items():
        med = {k: statistics.median(r[k] for r in runs) for k in ("start", "first", "second")}
        print(f"| {variant} | {med['start']:.3f} | {med['first']:.3f} | {med['second']:.3f} | "
              f"{med['first'] / med['second']:.2f} |")
    first = {variant: statistics.median(r["first"] for r in runs) for variant, runs in rows.items()}
    print(f"first contour, scipy.optimize preloaded / none: {first['scipy.optimize'] / first['none']:.2f}")


if __name__ == "__main__":
    main()
