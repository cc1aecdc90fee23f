"""The drive-force rate across a contour plan's seams (issue 35, branch seamforce): per program,
feed and sample time, the largest force change per sample over the force-rate limit at the
seams between the plan's parts (a cut piece, a free move, a rest) and elsewhere, and what the
result says (``within_limits``); one or more checkouts side by side.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/bench_contour_seams.py \
        [--root /tmp/base --root .] [--programs fusion360.nc,...] [--feeds program,fastest] \
        [--ts default,1,2,3,5,10]

Each (root, program, feed, Ts) is planned in a fresh process with ``PYTHONPATH`` on the root
(origin ``fit``, everything else at the defaults but ``settings.Ts``: ``default`` leaves the
sample time to the contour's rule). The parts are taken where the planner joins them
(``planner.contour.plan.join_parts``, wrapped): a seam is the first force a part holds after
the part before. The rate is the joined forces' change per sample over ``Ts`` (from zero
before the start; the last row, the plan's end, not a force applied), against the limit of
each drive (``planner.constraints.force_rate``), computed here from the result's forces, not
from its metrics. Columns per root: the largest ratio at the seams (with the kinds of parts
of the worst one), elsewhere, the number of seams over the limit (1e-9 relative, what
``within_limits`` allows), ``within_limits`` as the result reports it, the cycle time [s] and
the CPU seconds of the plan.
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
CAM = HERE.parent / "tests" / "data" / "cam"
EXAMPLE = HERE.parent / "app" / "static" / "examples" / "contour-part.ngc"
PROGRAMS = "freecad_linuxcnc.ngc,fusion360.nc,estlcam.nc,dxf2gcode.ngc,pcb_gcode.ngc,contour-part.ngc"
#: what ``within_limits`` tolerates of a rate (planner.orchestrator.result.RATE_TOL_REL)
RATE_TOL_REL = 1e-9


def program_text(name: str) -> str:
    return (EXAMPLE if name == "contour-part.ngc" else CAM / name).read_text()


def _kind(part) -> str:
    if part.result.metrics is None:
        return "rest"
    return "cut" if bool(part.cutting.any()) else "move"


def one(name: str, feed: str, ts: str) -> None:
    """Plan ``name`` in this process; print one JSON line."""
    import numpy as np

    import planner.contour.plan as contour_plan
    from planner.constraints import force_rate
    from planner.contour import plan_contour
    from planner.model import load_robot

    seen: dict = {}
    join = contour_plan.join_parts

    def wrapped(parts, *args, **kwargs):
        seen["kinds"] = [_kind(p) for p in parts]
        seen["sizes"] = [len(p.result.pose) for p in parts]
        return join(parts, *args, **kwargs)

    contour_plan.join_parts = wrapped  # type: ignore[assignment]
    text = program_text(name)
    settings = {} if ts == "default" else {"Ts": float(ts) * 1e-3}
    c0 = time.process_time()
    try:
        res = plan_contour({"program": text, "origin": "fit", "feed": feed, "settings": settings})
    except Exception as exc:  # a refusal is a row of the table
        print(json.dumps({"error": f"{type(exc).__name__}: {exc}"[:300]}))
        return
    cpu = time.process_time() - c0
    Ts = res.settings.Ts
    rate = force_rate(load_robot(res.robot), res.settings)
    U = np.asarray(res.drives.force, float)
    dU = np.abs(np.diff(np.vstack((np.zeros((1, U.shape[1])), U[:-1])), axis=0))
    ratio = (dU / (rate * Ts)).max(axis=1) if rate is not None else np.zeros(len(dU))
    # the first force part i holds is row (samples of the parts before, each after the first
    # sharing its first sample with the one before) - 1
    seams, at = [], 0
    for i, n in enumerate(seen["sizes"]):
        at += n - (1 if i else 0)
        if i + 1 < len(seen["sizes"]):
            seams.append(at - 1)
    seams_a = np.asarray(seams, np.int64)
    seams_a = seams_a[seams_a < len(ratio)]
    mask = np.zeros(len(ratio), bool)
    mask[seams_a] = True
    worst = int(seams_a[np.argmax(ratio[seams_a])]) if len(seams_a) else -1
    wi = seams.index(worst) if worst >= 0 else -1
    where = str(Path(sys.modules["planner"].__file__ or "").parent.parent)
    print(json.dumps({
        "planner": where, "Ts": Ts, "cpu": cpu, "cycle": float(res.time[-1]),
        "seam": float(ratio[mask].max(initial=0.0)), "else": float(ratio[~mask].max(initial=0.0)),
        "over": int(np.sum(ratio[mask] > 1 + RATE_TOL_REL)), "over_else": int(np.sum(ratio[~mask] > 1 + RATE_TOL_REL)),
        "worst": f"{seen['kinds'][wi]}>{seen['kinds'][wi + 1]}" if wi >= 0 else "",
        "within": bool(res.metrics.within_limits), "seams": len(seams)}))


def run_root(root: str, name: str, feed: str, ts: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(Path(root).resolve()), OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, __file__, "--one", name, "--feed", feed, "--ts", ts], env=env,
                         capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"{root}: {out.stderr[-2000:]}")
    got = json.loads(out.stdout.strip().splitlines()[-1])
    if "planner" in got:
        assert Path(got["planner"]) == Path(root).resolve(), (got["planner"], root)
    return got


def cells(g: dict) -> str:
    if "error" in g:
        return f"refused: {g['error'][:60]} | | | | | "
    mark = "**" if g["seam"] > 1 + RATE_TOL_REL else ""
    return (f"{mark}{g['seam']:.4f}{mark} {g['worst']} | {g['else']:.4f} | {g['over']}/{g['seams']} | "
            f"{'yes' if g['within'] else 'no'} | {g['cycle']:.3f} | {g['cpu']:.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--one", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--root", action="append", default=None, help="a checkout to plan with (repeatable; default .)")
    ap.add_argument("--programs", default=PROGRAMS)
    ap.add_argument("--feeds", default="program,fastest")
    ap.add_argument("--feed", default="fastest", help=argparse.SUPPRESS)
    ap.add_argument("--ts", default="default,1,2,3,5,10", help="sample times [ms] (default: the contour's rule)")
    args = ap.parse_args()
    if args.one is not None:
        one(args.one, args.feed, args.ts)
        return
    roots = args.root or [str(HERE.parent)]
    print(f"load: {os.getloadavg()[0]:.1f} (1-min average) on {os.cpu_count()} cores; roots: {', '.join(roots)}\n")
    head = " | ".join(f"{Path(r).resolve().name}: seams max | elsewhere max | seams over | within | cycle s | CPU s"
                      for r in roots)
    print(f"| program | feed | Ts ms | {head} |")
    print("|---|---|---|" + "---|---|---|---|---|---|" * len(roots), flush=True)
    for name in args.programs.split(","):
        for feed in args.feeds.split(","):
            for ts in args.ts.split(","):
                got = [run_root(r, name, feed, ts) for r in roots]
                shown = next((f"{g['Ts'] * 1e3:g}" for g in got if "Ts" in g), ts)
                label = f"{shown} (rule)" if ts == "default" else shown
                print(f"| {name} | {feed} | {label} | " + " | ".join(cells(g) for g in got) + " |", flush=True)


if __name__ == "__main__":
    main()
