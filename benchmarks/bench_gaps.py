"""Issue 31 goal 2: layouts with narrow gaps plan at the defaults, or with the advice, or are
proved to have no plan at any cell shape and size.

Usage:  OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/bench_gaps.py [--n 100] [--seed 31]
        [--proof-ratio 1.1] [--jsonl out.jsonl]

For each of ``--n`` layouts of :func:`tests.gap_layouts.gap_layout` (0.5-3 mm passages after
the clearance: walls, slanted walls, slots, holed obstacles; clearances 0-1.5 mm; cell size
and shape left to the planner) it plans the request at the defaults; a refusal's first remedy
(:func:`tests.advice_support.apply_advice`) is applied and planned. A layout neither plans is
swept for the proof: every size from the default down to the smallest within MAX_CELLS cells,
a factor ``--proof-ratio`` apart, in both shapes, segmented, and each that gives a path
planned; the independent fine-grid search of the free space (``grid_path_exists``, 0.25 mm)
says whether any path exists at all. Every plan is checked by the independent checker
(:func:`tests.certify_support.check_plan`).

Prints a table: kind, layouts, planned at the defaults, with the advice, neither (with its
proof), checker problems, the cells the defaults used, CPU seconds.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import copy  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import Counter, defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from planner import PlannerError, plan  # noqa: E402
from planner import segment as segment_request  # noqa: E402
from planner.corridor import segment  # noqa: E402
from planner.model import load_robot  # noqa: E402
from planner.schema import MAX_CELLS, cell_count  # noqa: E402
from tests.advice_support import apply_advice  # noqa: E402
from tests.certify_support import check_plan, grid_path_exists, robot_of  # noqa: E402
from tests.gap_layouts import KINDS, gap_layout  # noqa: E402


def _checked(req: dict, res) -> list[str]:
    segs = [{"lower": s.lower.tolist(), "upper": s.upper.tolist(),
             "polygon": None if s.polygon is None else s.polygon.tolist()} for s in res.corridor.segments]
    v = check_plan(req, res, segs)
    return [] if v.ok else list(v.problems)


def proof(req: dict, ratio: float) -> dict:
    """Every shape and size from the default down to MAX_CELLS cells (``ratio`` apart):
    segmented, and planned where they give a path; the fine free-space search."""
    lay = req["layout"]
    lo, hi = lay["bounds"]["lower"], lay["bounds"]["upper"]
    s0 = 0.02
    robot = load_robot(req.get("robot") or "moving-slide")
    out = {"sizes": 0, "paths": 0, "plans": 0, "smallest": {}, "free_space_path": None}
    for shape in ("square", "triangle"):
        size = s0
        while cell_count(lo, hi, shape, size)[0] <= MAX_CELLS:
            trial = copy.deepcopy(req)
            trial["layout"]["cell"] = {"shape": shape, "size": size}
            out["sizes"] += 1
            out["smallest"][shape] = size
            try:
                segment(trial["layout"], robot, advise=False)  # the bare answer, no remedy search
                out["paths"] += 1
                plan(trial)
                out["plans"] += 1
                out.setdefault("planned_with", (shape, size))
            except PlannerError:
                pass
            size /= ratio
    out["free_space_path"] = grid_path_exists(lay, robot_of(req.get("robot")), 2.5e-4)
    return out


def run_case(req: dict, ratio: float | None) -> dict:
    rec: dict = {"name": req["name"]}
    t0 = time.process_time()
    try:
        res = plan(req)
        rec["outcome"] = "defaults"
        seg = segment_request(req)
        rec["cells"] = (seg.shape, seg.size)
        rec["problems"] = _checked(req, res)
    except PlannerError as exc:
        rec["refusal"] = f"{exc.code}: {exc.message}"
        fixed = apply_advice(req, exc.message)
        rec["advice"] = None if fixed is None else {"layout": fixed["layout"].get("cell"),
                                                    "clearance": fixed["layout"].get("clearance"),
                                                    "settings": fixed.get("settings")}
        ok = False
        if fixed is not None:
            try:
                res = plan(fixed)
                ok = True
                rec["problems"] = _checked(fixed, res)
            except PlannerError as again:
                rec["advice_fails"] = f"{again.code}: {again.message}"
        if ok:
            rec["outcome"] = "advice"
        else:
            rec["outcome"] = "neither"
            rec["proof"] = proof(req, ratio) if ratio else {"plans": -1, "free_space_path": None}
    rec["cpu_s"] = time.process_time() - t0
    return rec


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--seed", type=int, default=31)
    ap.add_argument("--proof-ratio", type=float, default=1.1)
    ap.add_argument("--jsonl", type=Path)
    ap.add_argument("--no-proof", action="store_true", help="skip the sweep of a layout neither plans")
    args = ap.parse_args()
    rows: dict[str, Counter] = defaultdict(Counter)
    cells: Counter = Counter()
    cpu: dict[str, float] = defaultdict(float)
    out = args.jsonl.open("w") if args.jsonl else None
    t_all = time.process_time()
    for i in range(args.n):
        req = gap_layout(args.seed, i)
        kind = KINDS[i % len(KINDS)]
        rec = run_case(req, None if args.no_proof else args.proof_ratio)
        rows[kind][rec["outcome"]] += 1
        rows[kind]["problems"] += bool(rec.get("problems"))
        cpu[kind] += rec["cpu_s"]
        if rec["outcome"] == "defaults":
            cells[rec["cells"][0]] += 1
        if rec["outcome"] == "neither":
            p = rec["proof"]
            rows[kind]["proved"] += p["plans"] == 0
            rows[kind]["no_free_path"] += p["free_space_path"] is False
        if out:
            out.write(json.dumps(rec, default=str) + "\n")
            out.flush()
        print(f"{i:4d} {rec['outcome']:9s} {rec['cpu_s']:6.2f} s  {req['name']}"
              + (f"  [{rec.get('refusal', '')[:160]}]" if rec["outcome"] != "defaults" else ""),
              file=sys.stderr, flush=True)
    print(f"\n{args.n} layouts, seed {args.seed}: passages 0.5-3 mm after clearances 0-1.5 mm "
          f"(cells at the defaults: {dict(cells)})\n")
    print("| kind | layouts | defaults | advice | neither | neither: no shape or size plans | neither: no "
          "free-space path (0.25 mm grid) | checker problems | CPU s |")
    print("|---|---|---|---|---|---|---|---|---|")
    total: Counter = Counter()
    for kind in KINDS:
        r = rows[kind]
        n = r["defaults"] + r["advice"] + r["neither"]
        total.update(r)
        print(f"| {kind} | {n} | {r['defaults']} | {r['advice']} | {r['neither']} | {r['proved']} | "
              f"{r['no_free_path']} | {r['problems']} | {cpu[kind]:.1f} |")
    n = total["defaults"] + total["advice"] + total["neither"]
    print(f"| all | {n} | {total['defaults']} | {total['advice']} | {total['neither']} | {total['proved']} | "
          f"{total['no_free_path']} | {total['problems']} | {time.process_time() - t_all:.1f} |")


if __name__ == "__main__":
    main()
