"""Constrained mode: its own defaults against the paper mode's penalties, on several corridors.

The constrained mode keeps the corridor by constraints, so its penalties only pull the robot
along. ``planner.schema.MODE_DEFAULTS`` gives it a lighter pull and a longer horizon than
the paper mode (``k_r`` 0.1, ``k_u`` 2e-4, ``N`` 30 instead of 1, 1e-3, 20). This script plans
each corridor in constrained mode with both, at the same timing (samples per segment), and
prints drive energy, peak force, containment, settling and compute time side by side.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_constrained_defaults.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from planner import PlannerError, plan, warm_up
from planner.schema import MODE_DEFAULTS, builtin_description

EXAMPLES = Path(__file__).resolve().parents[1] / "app" / "static" / "examples"
TABLE1 = json.loads((EXAMPLES / "table1.json").read_text())
PSI_TURN = json.loads((EXAMPLES / "psi-turn.json").read_text())
BOUNDS = {"lower": [-0.1, -0.05], "upper": [0.1, 0.08]}


def _robot(**legs) -> dict:
    desc = builtin_description("moving-slide").model_dump(mode="json", exclude_none=True)
    desc["legs"] = dict(desc["legs"], **legs)
    return desc


def corridors() -> list[tuple[str, dict]]:
    """(label, request) pairs; ``settings.samples_per_segment`` fixed so both runs share the timing."""
    def layout(shape, obstacle, size, end, psi_range=None):
        lay = {"bounds": BOUNDS, "obstacles": [obstacle], "cell": {"shape": shape, "size": size},
               "start": [-0.08, 0.0, 0.0], "end": end}
        if psi_range:
            lay["psi_range"] = psi_range
        return {"robot": "moving-slide", "layout": lay}

    rect = {"type": "rectangle", "lower": [-0.02, -0.05], "upper": [0.01, 0.03]}
    circle = {"type": "circle", "center": [0.0, 0.0], "radius": 0.02}
    out = [("Table I", TABLE1, 20), ("Table I, S = 10", TABLE1, 10), ("Table I, S = 40", TABLE1, 40),
           ("Table I, speed_max 0.12 m/s", {**TABLE1, "robot": _robot(speed_max=0.12)}, 20),
           ("Table I, force_max 15 N", {**TABLE1, "robot": _robot(force_max=15.0)}, 20),
           ("psi ranges 0..0.12 rad", PSI_TURN, 20),
           ("layout, squares 20 mm", layout("square", rect, 0.02, [0.07, 0.0, 0.0]), 20),
           ("layout, triangles 20 mm", layout("triangle", rect, 0.02, [0.07, 0.0, 0.0]), 20),
           ("layout, triangles 15 mm, end psi 0.1", layout("triangle", circle, 0.015, [0.07, 0.0, 0.1],
                                                           [-0.05, 0.15]), 20)]
    return [(label, _with(req, S)) for label, req, S in out]


def _with(req: dict, S: int) -> dict:
    req = copy.deepcopy(req)
    req["settings"] = {"mode": "constrained", "samples_per_segment": S, "require_settled": False}
    return req


def run(req: dict, extra: dict, repeat: int):
    req = copy.deepcopy(req)
    req["settings"].update(extra)
    times, res = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        try:
            res = plan(req).to_json_dict()
        except PlannerError as exc:
            return None, exc.code
        times.append((time.perf_counter() - t0) * 1e3)
    return res, statistics.median(times)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="plans per corridor and setting (median time)")
    args = ap.parse_args(argv)
    warm_up()
    pp, cd = MODE_DEFAULTS["paper"], MODE_DEFAULTS["constrained"]
    print(f"constrained mode; A = paper penalties (k_r {pp['k_r']:g}, k_u {pp['k_u']:g}, N {pp['N']}), "
          f"B = constrained defaults (k_r {cd['k_r']:g}, k_u {cd['k_u']:g}, N {cd['N']}); same samples per "
          f"segment; median of {args.repeat} runs\n")
    head = ("corridor", "steps", "energy A", "energy B", "B / A", "F max A", "F max B", "kept A", "kept B",
            "ms A", "ms B")
    print("| " + " | ".join(head) + " |")
    print("|---|" + "---:|" * (len(head) - 1))
    for label, req in corridors():
        a, ta = run(req, pp, args.repeat)
        b, tb = run(req, {}, args.repeat)
        if a is None or b is None:
            print(f"| {label} | error: A {ta if a is None else 'ok'}, B {tb if b is None else 'ok'} |")
            continue

        def kept(r):
            m = r["metrics"]
            return "yes" if (m["contained"] and m["settled"] and m["within_limits"]
                             and m["infeasible_steps"] == 0) else "NO"
        ma, mb = a["metrics"], b["metrics"]
        print(f"| {label} | {mb['steps']} | {ma['energy']:.1f} | {mb['energy']:.1f} | "
              f"{mb['energy'] / ma['energy']:.2f} | {ma['max_drive_force_n']:.1f} | {mb['max_drive_force_n']:.1f} | "
              f"{kept(a)} | {kept(b)} | {ta:.0f} | {tb:.0f} |", flush=True)
    print("\nenergy in N^2 s (sum u^2 Ts), F max in N; kept = contained, settled, within limits, no slack")
    return 0


if __name__ == "__main__":
    sys.exit(main())
