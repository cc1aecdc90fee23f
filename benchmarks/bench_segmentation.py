"""Benchmark: free-space segmentation (issue 3).

Goal: a 0.3 m x 0.3 m workspace at 5 mm cells with 20 obstacles segments in <= 50 ms.
Prints a table: median (and min/max) wall time of ``planner.corridor.segment`` over
several runs, per cell shape and psi range, with the cell counts and the path found; and
the time of ``reachable_region`` (the editor's reachable-workspace outline).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_segmentation.py [--runs 15]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from planner.corridor import reachable_region, segment
from planner.model import load_robot


def layout(shape: str, psi_range=None, n_obstacles: int = 20, seed: int = 3) -> dict:
    """0.3 m x 0.3 m about the home pose, 20 obstacles (rectangles, circles, polygons of
    10-30 mm), 2 mm clearance, 5 mm cells; start and end kept clear of the obstacles."""
    rng = np.random.default_rng(seed)
    start, end = [-0.08, -0.05, 0.0], [0.08, 0.06, 0.0]
    obstacles = []
    while len(obstacles) < n_obstacles:
        c = rng.uniform(-0.13, 0.13, 2)
        if min(np.hypot(*(c - start[:2])), np.hypot(*(c - end[:2]))) < 0.04:
            continue
        r = rng.uniform(0.005, 0.015)
        kind = ("rectangle", "circle", "polygon")[len(obstacles) % 3]
        if kind == "rectangle":
            obstacles.append({"type": "rectangle", "lower": (c - r).tolist(), "upper": (c + r).tolist()})
        elif kind == "circle":
            obstacles.append({"type": "circle", "center": c.tolist(), "radius": r})
        else:
            a = np.sort(rng.uniform(0, 2 * np.pi, 6))
            obstacles.append({"type": "polygon", "points": (c + r * np.column_stack((np.cos(a), np.sin(a)))).tolist()})
    return {"bounds": {"lower": [-0.15, -0.15], "upper": [0.15, 0.15]}, "obstacles": obstacles,
            "clearance": 0.002, "cell": {"shape": shape, "size": 0.005}, "start": start, "end": end,
            "psi_range": psi_range}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=15)
    args = ap.parse_args()
    robot = load_robot("moving-slide")
    rows = []
    for shape in ("square", "triangle"):
        for psi in (None, [-0.1, 0.1]):
            lay = layout(shape, psi)
            segment(lay, robot)  # warm-up
            times = []
            for _ in range(args.runs):
                t0 = time.perf_counter()
                seg = segment(lay, robot)
                times.append((time.perf_counter() - t0) * 1e3)
            c = seg.counts
            rows.append((shape, "0" if psi is None else f"{psi[0]:g}..{psi[1]:g}", len(seg.state), c["free"],
                         c["blocked"], c["unreachable"], len(seg.path), seg.turns,
                         statistics.median(times), min(times), max(times)))
    print(f"segmentation, 0.3 m x 0.3 m, 5 mm cells, 20 obstacles, {args.runs} runs (goal: median <= 50 ms)")
    print("| shape | psi range [rad] | cells | free | blocked | unreachable | path cells | turns | median ms "
          "| min ms | max ms |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(str(v) if not isinstance(v, float) else f"{v:.1f}" for v in r) + " |")
    print()
    print("reachable_region (the editor's reachable-workspace outline), 0.4 m x 0.4 m")
    print("| resolution [mm] | psi range [rad] | polygons | median ms | min ms | max ms |")
    print("|---|---|---|---|---|---|")
    bounds = {"lower": [-0.2, -0.2], "upper": [0.2, 0.2]}
    for res in (0.005, 0.002):
        for psi in ((0.0, 0.0), (-0.1, 0.1)):
            times = []
            for _ in range(args.runs):
                t0 = time.perf_counter()
                region = reachable_region(robot, bounds, psi, res)
                times.append((time.perf_counter() - t0) * 1e3)
            print(f"| {res * 1e3:g} | {psi[0]:g}..{psi[1]:g} | {len(region)} | {statistics.median(times):.1f} | "
                  f"{min(times):.1f} | {max(times):.1f} |")


if __name__ == "__main__":
    main()
