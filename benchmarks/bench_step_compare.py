"""The compiled constrained step against another git revision, interleaved in one run (issue 34
goal 4: the registry's fused assembly within 5 % of the 36-argument one).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_step_compare.py --base main [--rounds 7]

The base revision is checked out in a temporary git worktree (its kernels compile there on the
first call unless cached). Each round runs one child process per tree, alternating base and
head: the child plans Table I (constrained, compiled) once recording the controller's state at
every step (the Python path, as ``tests/test_constraints_kernels.py`` records it), then times on
those states the compiled assembly of a step's rows and criterion
(``CompiledAssembly.inputs.assemble``) and the whole compiled step (``CompiledAssembly.step``:
rows, offset, stage-wise solve, refinement), each state ``--repeat`` times, both called from
Python (each call unboxes its arguments: the dispatch is part of the time), and the step within
the compiled loop of a whole plan (``metrics.qp_time_ms / steps``, one dispatch a plan) and the
plan's ``compute_ms`` (``2 repeat + 1`` plans); it reports the medians. The table gives the
median over rounds and head / base (with the median of each round's ratio).
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

CHILD = r"""
import json, statistics, sys, time
import numpy as np
from planner import plan
from planner.constraints import ConstrainedController
from planner.constraints.controller import REFINE_MAX, REFINE_TOL_M, REFINE_TOL_RAD
req = json.load(open(sys.argv[1]))
req = {**req, "settings": {**req.get("settings", {}), "mode": "constrained"}}
repeat = int(sys.argv[2])
states = []
orig = ConstrainedController.__call__
def spy(self, k, x, Ad, Bd):
    warm = self.memory.warm.copy() if self.memory.flags[1] else None
    y_nom = None if self.y_nom is None else self.y_nom.copy()
    states.append((self, k, x.copy(), Ad.copy(), Bd.copy(), y_nom, self.u_prev.copy(), self.guess(), warm))
    return orig(self, k, x, Ad, Bd)
ConstrainedController.__call__ = spy
ConstrainedController.compiled_loop = False
plan(req)
plan(req)
states = states[len(states) // 2:]  # the second plan's (everything warm)
asm_t, step_t = [], []
for c, k, x, Ad, Bd, y_nom, u_prev, u0, warm in states:
    a = c.assembly
    yp = y_nom if y_nom is not None else np.zeros((0, 3))
    a.inputs.assemble(k, x, yp, u_prev)
    a.step(k, x, Ad, Bd, y_nom, u_prev, u0, warm, (REFINE_TOL_M, REFINE_TOL_RAD), REFINE_MAX)
    for _ in range(repeat):
        t = time.perf_counter()
        a.inputs.assemble(k, x, yp, u_prev)
        asm_t.append(time.perf_counter() - t)
        t = time.perf_counter()
        a.step(k, x, Ad, Bd, y_nom, u_prev, u0, warm, (REFINE_TOL_M, REFINE_TOL_RAD), REFINE_MAX)
        step_t.append(time.perf_counter() - t)
ConstrainedController.__call__ = orig
ConstrainedController.compiled_loop = True
loop_t, comp = [], []
for _ in range(2 * repeat + 1):
    m = plan(req).metrics
    loop_t.append(m.qp_time_ms * 1e3 / m.steps)
    comp.append(m.compute_ms)
print(json.dumps({"assemble_us": statistics.median(asm_t) * 1e6, "step_us": statistics.median(step_t) * 1e6,
                  "loop_us": statistics.median(loop_t), "compute_ms": statistics.median(comp),
                  "steps": len(states)}))
"""


def run_child(tree: Path, table1: Path, repeat: int) -> dict:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    env.pop("PYTHONPATH", None)
    out = subprocess.run([sys.executable, "-c", CHILD, str(table1), str(repeat)], cwd=tree, env=env,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description="The compiled constrained step against another revision.")
    ap.add_argument("--base", required=True)
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    table1 = ROOT / "app" / "static" / "examples" / "table1.json"
    head_rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        base_tree = Path(tmp) / "base"
        subprocess.run(["git", "worktree", "add", "--detach", str(base_tree), args.base], cwd=ROOT, check=True,
                       capture_output=True)
        try:
            run_child(base_tree, table1, 1)  # compile or load the base's kernels
            run_child(ROOT, table1, 1)
            res: dict[str, list[dict]] = {"base": [], "head": []}
            for _ in range(args.rounds):
                res["base"].append(run_child(base_tree, table1, args.repeat))
                res["head"].append(run_child(ROOT, table1, args.repeat))
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(base_tree)], cwd=ROOT, check=False,
                           capture_output=True)
    print(f"## Table I compiled constrained step: {args.base} (base) against {head_rev} + working tree (head)\n")
    print(f"Median over {args.rounds} interleaved rounds of each child's median per call ({res['head'][0]['steps']} "
          f"recorded steps x {args.repeat}); load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores.\n")
    print("| call | base [us] | head [us] | head / base (medians) | head / base (median of rounds) |")
    print("|---|---:|---:|---:|---:|")
    for key, label in (("assemble_us", "rows and criterion (assemble), called from Python"),
                       ("step_us", "whole compiled step, called from Python"),
                       ("loop_us", "step in the compiled loop (qp_time_ms / steps)"),
                       ("compute_ms", "Table I plan (compute_ms, ms)")):
        b = statistics.median(r[key] for r in res["base"])
        h = statistics.median(r[key] for r in res["head"])
        per = statistics.median(hr[key] / br[key] for hr, br in zip(res["head"], res["base"]))
        print(f"| {label} | {b:.1f} | {h:.1f} | {h / b:.3f} | {per:.3f} |")


if __name__ == "__main__":
    main()
