"""A pass that goes back over its own path, before/after (issue 35, the ``fastest`` ramp
regression): ``tests.contour_programs.ramps`` (each pass a ramp down a 4 mm line, back along it
at depth, a helix of one turn that ends where it starts) in ``fastest`` and ``program`` at typed
sample times and at the one the planner chooses, one or more checkouts side by side.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/bench_contour_retrace.py \
        [--root /tmp/base --root .] [--passes 2] [--ts none,0.01,0.005] [--feeds fastest,program]

Each root plans in a fresh process with ``PYTHONPATH`` on it, after two untimed plans that load
the compiled kernels and the Z axis's LP (as ``bench_contour_estimate.py`` measures): per case
the outcome, the cutting time (the passes' ``time_s``), the CPU seconds of the plan, the work
estimate (``planner.contour.estimate_contour``) and their ratio (goal <= 1.5), and the two-sided
deviation measured independently of the planner on rs274's path (``tests.test_contour.two_sided``:
the cut from the path, the path from the cut, the largest over the passes; the tolerance 0.05 mm).
A case still running after ``--cap`` CPU seconds is stopped.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
HERE = Path(__file__).resolve().parent


def one(passes: int, feed: str, ts: str, cap: int) -> None:
    """In the child: plan one case, print one JSON line."""
    import resource

    import numpy as np

    from planner import PlannerError
    from planner.contour import estimate_contour, plan_contour
    from tests.contour_programs import long_pass, ramps
    from tests.test_contour import two_sided

    plan_contour({"program": ramps(np.random.default_rng(0), 1).text})  # kernels and the Z LP loaded
    plan_contour({"program": long_pass(np.random.default_rng(0), 5).text, "feed": "fastest"})
    text = ramps(np.random.default_rng(0), passes).text
    req: dict = {"program": text, "feed": feed}
    if ts != "none":
        req["settings"] = {"Ts": float(ts)}
    est = estimate_contour(req)[0]
    used = resource.getrusage(resource.RUSAGE_SELF)
    resource.setrlimit(resource.RLIMIT_CPU, (int(used.ru_utime + used.ru_stime) + cap, resource.RLIM_INFINITY))
    c0 = time.process_time()
    where = str(Path(sys.modules["planner"].__file__ or "").parent.parent)
    try:
        res = plan_contour(req)
    except PlannerError as err:
        print(json.dumps({"planner": where, "outcome": f"{err.code}", "cpu": time.process_time() - c0, "est": est}))
        return
    cpu = time.process_time() - c0
    c = res.contour
    assert c is not None
    sides = two_sided(res, text + "M2\n", np.asarray(c.origin, float), 1e-7)
    print(json.dumps({"planner": where, "outcome": "ok", "cpu": cpu, "est": est, "Ts": res.settings.Ts,
                      "cut": sum(p.time_s for p in c.passes), "cut_d": max(s[0] for s in sides),
                      "path_d": max(s[1] for s in sides), "tol": c.tolerance_m}))


def run_root(root: str, passes: int, feed: str, ts: str, cap: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(Path(root).resolve()), OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, __file__, "--one", str(passes), feed, ts, str(cap)], env=env,
                         capture_output=True, text=True)
    lines = out.stdout.strip().splitlines()
    if out.returncode != 0 or not lines:
        return {"outcome": f"stopped (exit {out.returncode})" if out.returncode < 0 or "CPU" in out.stderr
                else f"error: {out.stderr.strip().splitlines()[-1:]}", "cpu": None, "est": None}
    got = json.loads(lines[-1])
    assert Path(got["planner"]) == Path(root).resolve(), (got["planner"], root)
    return got


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--one", nargs=4, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--root", action="append", default=None, help="a checkout to plan with (repeatable; default .)")
    ap.add_argument("--passes", type=int, default=2)
    ap.add_argument("--ts", default="none,0.01,0.005", help="sample times [s]; none: the one the planner chooses")
    ap.add_argument("--feeds", default="fastest,program")
    ap.add_argument("--cap", type=int, default=120, help="CPU seconds a case may take")
    args = ap.parse_args()
    if args.one is not None:
        p, feed, ts, cap = args.one
        one(int(p), feed, ts, int(cap))
        return
    roots = args.root or [str(HERE.parent)]
    print(f"load: {os.getloadavg()[0]:.1f} (1-min average) on {os.cpu_count()} cores; roots: {', '.join(roots)}; "
          f"{args.passes} ramp-and-helix passes\n")
    print("| feed | Ts asked | root | outcome | Ts ms | cut s | CPU s | estimate s | CPU / est | cut->path mm | "
          "path->cut mm |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for feed in args.feeds.split(","):
        for ts in args.ts.split(","):
            for root in roots:
                g = run_root(root, args.passes, feed, ts, args.cap)
                name = Path(root).resolve().name
                if g["outcome"] != "ok":
                    cpu = f"{g['cpu']:.2f}" if g.get("cpu") is not None else "-"
                    est = f"{g['est']:.3g}" if g.get("est") is not None else "-"
                    print(f"| {feed} | {ts} | {name} | {g['outcome']} | | | {cpu} | {est} | | | |")
                    continue
                dev = f"{g['cut_d'] * 1e3:.4f} | {g['path_d'] * 1e3:.4f}"
                print(f"| {feed} | {ts} | {name} | ok | {g['Ts'] * 1e3:g} | {g['cut']:.3f} | {g['cpu']:.2f} | "
                      f"{g['est']:.3g} | {g['cpu'] / g['est']:.2f} | {dev} |")


if __name__ == "__main__":
    main()
