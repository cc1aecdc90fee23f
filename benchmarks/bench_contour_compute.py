"""Contour compute (issue 35 goal 4): CPU seconds and peak memory of the 15-pass benchmark
program (``bench_contour.program``) at the defaults, ``feed`` ``program`` and ``fastest``, and
CPU against the program's length (1 to 60 passes), for one or more checkouts side by side.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/bench_contour_compute.py \
        [--root /tmp/base --root .] [--rounds 3] [--lengths 1,2,4,8,15,30,60] [--feeds program,fastest] \
        [--length-feeds program,fastest]

Each measurement is one fresh process (``--one``: its peak RSS is the plan's, after one
untimed plan of one pass that loads the compiled kernels) run with ``PYTHONPATH`` on the
checkout; the checkouts alternate within each round (the machine's load falls on all of them
alike); the table prints the median CPU seconds of the rounds and the ratio to the first root.
Goals: <= 5 CPU s (``program``), <= 10 CPU s (``fastest``), <= 500 MB; cost linear in length
(CPU s per pass about constant).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def one(passes: int, feed: str) -> None:
    """Plan ``passes`` passes of the benchmark part in this process; print CPU s, RSS, cut time."""
    import resource
    import time

    from planner.contour import plan_contour  # first: bench_contour puts its own checkout first on sys.path

    sys.path.insert(0, str(HERE))
    from bench_contour import ORIGIN, TOL, program  # type: ignore[import-not-found]

    plan_contour({"program": program(1), "origin": ORIGIN, "tolerance_m": TOL, "feed": feed})  # kernels loaded
    c0 = time.process_time()
    res = plan_contour({"program": program(passes), "origin": ORIGIN, "feed": feed, "tolerance_m": TOL})
    cpu = time.process_time() - c0
    c = res.contour
    assert c is not None
    where = str(Path(sys.modules["planner"].__file__ or "").parent.parent)
    print(json.dumps({"cpu": cpu, "planner": where, "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      "cut_s": c.cut_time_s, "max_dev_m": c.max_deviation_m, "samples": len(res.time)}))


def measure(root: str, passes: int, feed: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(Path(root).resolve()), OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, __file__, "--one", str(passes), feed], env=env, capture_output=True,
                         text=True, check=True)
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert Path(got["planner"]) == Path(root).resolve(), (got["planner"], root)  # the checkout measured
    return got


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--root", action="append", help="checkouts to compare (default: this one)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--feeds", default="program,fastest")
    ap.add_argument("--lengths", default="1,2,4,8,15,30,60", help="passes of the length table")
    ap.add_argument("--length-feeds", default="program", help="the feeds of the length table (e.g. program,fastest)")
    ap.add_argument("--one", nargs=2, metavar=("PASSES", "FEED"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        one(int(args.one[0]), args.one[1])
        return
    roots = args.root or [str(HERE.parent)]
    print(f"load: {os.getloadavg()[0]:.1f} (1-min average) on {os.cpu_count()} cores; {args.rounds} rounds, medians")
    print("\n15 passes at the defaults (tolerance 0.02 mm; Ts and N as the planner chooses them):\n")
    print("| checkout | feed | CPU s (median) | CPU s (rounds) | vs first | peak RSS MB | cut time s "
          "| max deviation mm |")
    print("|---|---|---|---|---|---|---|---|")
    for feed in args.feeds.split(","):
        runs: dict[str, list[dict]] = {r: [] for r in roots}
        for _ in range(args.rounds):
            for r in roots:
                runs[r].append(measure(r, 15, feed))
        base = statistics.median(x["cpu"] for x in runs[roots[0]])
        for r in roots:
            cpus = [x["cpu"] for x in runs[r]]
            med = statistics.median(cpus)
            last = runs[r][-1]
            print(f"| {r} | {feed} | {med:.2f} | {', '.join(f'{c:.2f}' for c in cpus)} | {med / base:.3f}x | "
                  f"{max(x['rss_mb'] for x in runs[r]):.0f} | {last['cut_s']:.2f} | {last['max_dev_m'] * 1e3:.6f} |",
                  flush=True)
    lengths = [int(x) for x in args.lengths.split(",") if x]
    if not lengths:
        return
    print("\nCPU against the program's length (one round):\n")
    print("| checkout | feed | passes | samples | CPU s | CPU s / pass | peak RSS MB |")
    print("|---|---|---|---|---|---|---|")
    for feed in args.length_feeds.split(","):
        for n in lengths:
            for r in roots:
                m = measure(r, n, feed)
                print(f"| {r} | {feed} | {n} | {m['samples']} | {m['cpu']:.2f} | {m['cpu'] / n:.3f} | "
                      f"{m['rss_mb']:.0f} |", flush=True)

if __name__ == "__main__":
    main()
