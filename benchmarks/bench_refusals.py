"""Issue 31 goal 2: the issue's refusals, each with the limit that makes it impossible as
asked (where one does) and the setting its advice names, planned and checked.

Usage:  OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/bench_refusals.py [--skip-slow]

Table I (app/static/examples/table1.json) with: a speed of 5 m/s; total_time_s 0.05; a force
rate of 20 N/s; legs of 0.01 m/s (``--skip-slow`` leaves it out: its advice plans N 200);
leg friction 2000 N s/m with plant_substeps 1. For each: the bound the message states, the
advice, whether the advised request plans and passes the independent checker
(tests/certify_support.check_plan), and the CPU seconds of the refusal (the plan and its
advice checks) and of the advised plan.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import copy  # noqa: E402
import json  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from planner import PlannerError, plan  # noqa: E402
from tests.advice_support import apply_advice  # noqa: E402
from tests.certify_support import check_plan  # noqa: E402

TABLE1 = json.loads((ROOT / "app" / "static" / "examples" / "table1.json").read_text())
SLIDE = json.loads((ROOT / "planner" / "data" / "moving-slide.json").read_text())


def _robot(**legs) -> dict:
    d = copy.deepcopy(SLIDE)
    d["legs"].update(legs)
    return d


def cases(slow: bool) -> list[tuple[str, dict]]:
    out = [("speed_m_s 5", {"settings": {"speed_m_s": 5.0}}),
           ("total_time_s 0.05", {"settings": {"total_time_s": 0.05}}),
           ("force_rate_n_s 20", {"settings": {"force_rate_n_s": 20.0}}),
           ("friction 2000 N s/m, plant_substeps 1, 240 samples",
            {"robot": _robot(friction=2000.0), "settings": {"plant_substeps": 1, "samples_per_segment": 240}})]
    if slow:
        out.insert(3, ("leg speed_max 0.01 m/s", {"robot": _robot(speed_max=0.01), "settings": {}}))
    return [(name, {**copy.deepcopy(TABLE1), **extra}) for name, extra in out]


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--skip-slow", action="store_true")
    args = ap.parse_args()
    rows = []
    for name, req in cases(not args.skip_slow):
        t0 = time.process_time()
        try:
            plan(req)
            rows.append((name, "plans", "-", "-", "-", time.process_time() - t0, 0.0))
            continue
        except PlannerError as exc:
            err = exc
        t_refusal = time.process_time() - t0
        m = re.search(r"impossible as asked: with (.+?), the robot needs at least ([0-9.]+) s from the start to the "
                      r"end, its timing gives ([0-9.]+) s", err.message)
        bound = f"{m.group(2)} s needed, {m.group(3)} s given ({m.group(1)[:40]}...)" if m else "-"
        advice = next((c for c in err.message.split("; ") if re.search(r"\bplans\b", c) and "do not plan" not in c),
                      "none")
        fixed = apply_advice(req, err.message)
        verdict, t_fix = "no advice", 0.0
        if fixed is not None:
            t1 = time.process_time()
            try:
                res = plan(fixed)
                v = check_plan(fixed, res, fixed["segments"])
                verdict = f"plans, duration {res.metrics.duration_s:.3g} s, checker " + ("ok" if v.ok else
                                                                                          str(v.problems[:1]))
            except PlannerError as again:
                verdict = f"FAILS: {again.code}"
            t_fix = time.process_time() - t1
        rows.append((name, err.code, bound, advice, verdict, t_refusal, t_fix))
        print(name, "done", file=sys.stderr, flush=True)
    print("| request (Table I) | refusal | bound stated | advice | advice planned | CPU s refusal | CPU s advised |")
    print("|---|---|---|---|---|---|---|")
    for name, code, bound, advice, verdict, t_r, t_f in rows:
        print(f"| {name} | {code} | {bound} | {advice} | {verdict} | {t_r:.1f} | {t_f:.1f} |")


if __name__ == "__main__":
    main()
