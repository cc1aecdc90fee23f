"""Table I plan time of this tree against another git revision, interleaved in one run.

    python benchmarks/compare_revisions.py --base f0e9b8a [--rounds 3] [--runs 15]

The base revision is checked out in a temporary git worktree (its numba kernels compile
there on the first call, ~1 minute). Each round runs one child process per tree (the
tree's own directory first on ``sys.path``), alternating base and head, each warming up
and then planning Table I ``--runs`` times in paper mode and in constrained mode; a child
reports the medians of ``metrics.compute_ms`` and of the wall time of ``plan()``. The table
gives the median over rounds, and head / base. BLAS is single-threaded, as in the service.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TABLE1 = ROOT / "app" / "static" / "examples" / "table1.json"

CHILD = r"""
import json, statistics, sys, time
import planner
plan = getattr(planner, "plan", None)
if not callable(plan):  # before the redesign: planner.plan.plan returned a dict
    from planner.plan import plan
req = json.load(open(sys.argv[1]))
runs = int(sys.argv[2])
out = {}
for mode in ("paper", "constrained"):
    r = {**req, "settings": {"mode": mode}}
    for _ in range(3):
        plan(r)
    comp, wall = [], []
    for _ in range(runs):
        t = time.perf_counter()
        res = plan(r)
        wall.append((time.perf_counter() - t) * 1e3)
        m = res["metrics"] if isinstance(res, dict) else res.metrics.model_dump()
        comp.append(m["compute_ms"])
    out[mode] = {"compute_ms": statistics.median(comp), "wall_ms": statistics.median(wall)}
print(json.dumps(out))
"""


def run_child(tree: Path, runs: int) -> dict:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    env.pop("PYTHONPATH", None)
    out = subprocess.run([sys.executable, "-c", CHILD, str(TABLE1), str(runs)], cwd=tree, env=env,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, help="git revision to compare against")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--runs", type=int, default=15)
    args = ap.parse_args()
    head_rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    with tempfile.TemporaryDirectory(prefix="rangeplan-base-") as tmp:
        base_tree = Path(tmp) / "tree"
        subprocess.run(["git", "worktree", "add", "--detach", str(base_tree), args.base], cwd=ROOT, check=True,
                       capture_output=True)
        try:
            run_child(base_tree, 1)  # compile the base tree's kernels once
            run_child(ROOT, 1)
            rounds: dict[str, list[dict]] = {"base": [], "head": []}
            for _ in range(args.rounds):
                rounds["base"].append(run_child(base_tree, args.runs))
                rounds["head"].append(run_child(ROOT, args.runs))
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(base_tree)], cwd=ROOT, check=False,
                           capture_output=True)
    print(f"## Table I: {args.base} (base) against {head_rev} + working tree (head), same run\n")
    print(f"Median over {args.rounds} interleaved rounds of each round's median of {args.runs} plans.\n")
    print("| mode | base compute [ms] | head compute [ms] | head / base | base plan() wall [ms] | "
          "head plan() wall [ms] | head / base |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for mode in ("paper", "constrained"):
        med = {k: {q: statistics.median(r[mode][q] for r in v) for q in ("compute_ms", "wall_ms")}
               for k, v in rounds.items()}
        b, h = med["base"], med["head"]
        print(f"| {mode} | {b['compute_ms']:.1f} | {h['compute_ms']:.1f} | {h['compute_ms'] / b['compute_ms']:.2f} | "
              f"{b['wall_ms']:.1f} | {h['wall_ms']:.1f} | {h['wall_ms'] / b['wall_ms']:.2f} |")


if __name__ == "__main__":
    main()
