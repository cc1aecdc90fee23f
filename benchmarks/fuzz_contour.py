"""Generated CAM programs through :func:`planner.contour.plan_contour`, both feeds, checked
against LinuxCNC's interpreter (issue 22 follow-up: contouring must not fail needlessly).

    .venv/bin/python benchmarks/fuzz_contour.py [SEED0 [COUNT]] [--out DIR] [-v]

Each seed makes one program (:func:`program`): mm or inch, G64 P 0.01-0.1 mm (or none: the
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
import traceback
from collections import defaultdict
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np

from planner.contour import plan_contour
from planner.errors import PlannerError

ORIGIN = [-0.015, -0.015]
FEEDS = ("program", "fastest")


def program(rng: np.random.Generator) -> str:
    """One generated program (module docstring)."""
    inch = rng.random() < 0.15
    u = 25.4 if inch else 1.0
    out = ["G20 G90 G17" if inch else "G21 G90 G17"]
    tol_mm = float(rng.choice([0.01, 0.02, 0.05, 0.1]))
    if rng.random() < 0.8:
        out.append(f"G64 P{tol_mm / u:.5f}")
    passes = int(rng.integers(1, 4))

    def feed() -> float:
        return float(rng.choice([200, 500, 1000, 1500, 3000]))

    x, y = rng.uniform(2, 28, 2)
    for _ in range(passes):
        out += [f"G0 Z{2 / u:.4f}", f"G0 X{x / u:.4f} Y{y / u:.4f}", f"G1 Z{-1 / u:.4f} F{300 / u:.1f}",
                f"F{feed() / u:.1f}"]
        for _ in range(int(rng.integers(1, 9))):
            kind = rng.choice(["line", "arcij", "arcr", "circle", "tiny"])
            if kind in ("line", "tiny"):
                step = 0.05 if kind == "tiny" else 8
                nx, ny = np.clip(np.array([x, y]) + rng.uniform(-step, step, 2), 1, 29)
                out.append(f"G1 X{nx / u:.4f} Y{ny / u:.4f}" + (f" F{feed() / u:.1f}" if rng.random() < 0.3 else ""))
                x, y = nx, ny
                continue
            r = float(rng.uniform(0.5, 8))
            a0 = rng.uniform(0, 2 * np.pi)
            cx, cy = x - r * np.cos(a0), y - r * np.sin(a0)
            if kind == "circle":
                nx, ny = x, y
            else:
                a1 = a0 + rng.uniform(-np.pi * 0.95, np.pi * 0.95)
                nx, ny = cx + r * np.cos(a1), cy + r * np.sin(a1)
            if min(cx - r, cy - r) < 0.5 or max(cx + r, cy + r) > 29.5:
                continue
            g = rng.choice(["G2", "G3"])
            if kind == "arcr":  # the sign of R picks the short or the long arc
                cross = (x - cx) * (ny - cy) - (y - cy) * (nx - cx)
                short = (g == "G3") == (cross > 0)
                if np.hypot(nx - x, ny - y) < 0.01:
                    continue
                out.append(f"{g} X{nx / u:.4f} Y{ny / u:.4f} R{(r if short else -r) / u:.4f}")
            else:
                out.append(f"{g} X{nx / u:.4f} Y{ny / u:.4f} I{(cx - x) / u:.4f} J{(cy - y) / u:.4f}")
            x, y = nx, ny
        out.append(f"G0 Z{2 / u:.4f}")
        x, y = rng.uniform(2, 28, 2)
    out.append("M2")
    return "\n".join(out) + "\n"


def check(prog: str, feed: str) -> dict:
    """Plan ``prog`` with ``feed`` and check it (module docstring): ``{"code": "ok" | error code
    | "crash", "problems": [...], "cpu_s", "message"}``."""
    from tests.test_contour import chord_deviation, feed_excess, rs274_cut_path

    t = time.process_time()
    try:
        res = plan_contour({"program": prog, "origin": ORIGIN, "feed": feed})
    except PlannerError as err:
        return {"code": err.code, "problems": [], "cpu_s": time.process_time() - t, "message": str(err)}
    except Exception:
        return {"code": "crash", "problems": [traceback.format_exc()[-600:]], "cpu_s": time.process_time() - t,
                "message": ""}
    cpu = time.process_time() - t
    c, mt = res.contour, res.metrics
    assert c is not None
    probs = []
    if not np.all(np.isfinite(res.pose)):
        probs.append("NaN in the poses")
    path = rs274_cut_path(prog, ORIGIN)
    dev = chord_deviation(res, path, c.tolerance_m / 50)
    if dev > c.tolerance_m * (1 + 1e-7):
        probs.append(f"deviation {dev * 1e6:.2f} um > tolerance {c.tolerance_m * 1e6:.1f} um")
    if abs(c.max_deviation_m - dev) > c.tolerance_m / 20:
        probs.append(f"reported deviation {c.max_deviation_m * 1e6:.2f} um vs measured {dev * 1e6:.2f} um")
    if not (mt.within_limits and mt.max_force_ratio <= 1 + 1e-9):
        probs.append(f"drive limits: force ratio {mt.max_force_ratio:.4f}")
    if feed == "program":
        over = feed_excess(res, prog)
        if over > 1e-9:
            probs.append(f"programmed feed exceeded by {over * 1e3:.4f} mm/s")
    return {"code": "ok", "problems": probs, "cpu_s": cpu, "message": f"dev {dev * 1e6:.2f} um, T {res.time[-1]:.2f} s"}


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
