"""Generated CAM programs through :func:`planner.contour.plan_contour`, both feeds, checked
against LinuxCNC's interpreter (issue 22 follow-up: contouring must not fail needlessly).

    .venv/bin/python benchmarks/fuzz_contour.py [SEED0 [COUNT]] [--out DIR] [-v]

Each seed makes one program (:func:`tests.contour_fuzz.program`): mm or inch, G64 P 0.01-0.1 mm (or none: the
0.05 mm default), 1-3 passes of 1-8 moves each (lines, I/J and R arcs, full circles, moves
of 0.05 mm and less), feeds 200-3000 mm/min, inside a 30 mm square. Each is planned with
``feed: program`` and ``feed: fastest`` and checked independently (tests/test_contour.py:
shapely on rs274's canonical path): the deviation of every cut sample and chord within the
tolerance, the reported ``contour.max_deviation_m`` within tolerance / 20 of that measure,
the programmed feed never exceeded (``program``: speed and chord speed <= F of the line),
the drive limits, no NaN, no crash. A **needless** verdict: one feed answers ``infeasible``
where the other plans the program (the ``program`` feed is a cap on a timing ``fastest``
may use, and ``fastest`` may use every timing ``program`` finds). Prints one line per
problem (every line with ``-v``), then the table of outcomes by feed and code with the CPU
time (median, max); failing programs are written to ``--out``. Exit 1 on any problem.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections import defaultdict
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np

from tests.contour_fuzz import FEEDS, check, program


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("seed0", type=int, nargs="?", default=0)
    ap.add_argument("count", type=int, nargs="?", default=200)
    ap.add_argument("--out", default="/tmp/fuzz_contour", help="folder for failing programs")
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args(argv)
    out = Path(args.out)
    table: dict[tuple[str, str], list[float]] = defaultdict(list)
    problems = needless = 0
    wall = time.perf_counter()
    for seed in range(args.seed0, args.seed0 + args.count):
        prog = program(np.random.default_rng(seed))
        runs = {feed: check(prog, feed) for feed in FEEDS}
        codes = {feed: r["code"] for feed, r in runs.items()}
        for feed, r in runs.items():
            table[(feed, r["code"])].append(r["cpu_s"])
            bad = bool(r["problems"]) or r["code"] == "crash"
            other = FEEDS[1 - FEEDS.index(feed)]
            pointless = r["code"] == "infeasible" and codes[other] == "ok"
            problems += bad
            needless += pointless
            if bad or pointless or args.verbose:
                tag = "PROBLEM" if bad else "NEEDLESS" if pointless else ""
                print(f"{seed:4d} {feed:8s} {r['code']:12s} {r['cpu_s']:6.2f} s {tag} "
                      f"{'; '.join(r['problems']) or r['message'][:160]}", flush=True)
            if bad or pointless:
                out.mkdir(parents=True, exist_ok=True)
                (out / f"seed{seed}_{feed}.ngc").write_text(prog)
    print(f"\n{args.count} programs (seeds {args.seed0}..{args.seed0 + args.count - 1}), "
          f"{time.perf_counter() - wall:.0f} s wall\n")
    print("| feed | outcome | programs | CPU median s | CPU max s |")
    print("|---|---|---:|---:|---:|")
    for (feed, code), cpu in sorted(table.items()):
        print(f"| {feed} | {code} | {len(cpu)} | {statistics.median(cpu):.2f} | {max(cpu):.2f} |")
    print(f"\nproblems (deviation, reported deviation, feed, limits, NaN, crash): {problems}; "
          f"needless infeasible verdicts: {needless}")
    return 1 if problems or needless else 0


if __name__ == "__main__":
    sys.exit(main())
