"""The tool-speed limit (settings.tool_speed_max_m_s, issue 34 goal 4): what it costs a plan.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_tool_speed.py [--rounds 7]

Table I in the constrained mode (compiled backend; default timing and ``fastest``), without a
limit and with the tool speed limited to 0.8 (default timing) / 0.6 (``fastest``) of the
unlimited plan's peak, planned in interleaved rounds in this process (kernels warm). Prints per
case the median ``metrics.compute_ms``, the median controller time per step
(``qp_time_ms / steps``), the plan's peak tool speed over the limit, the duration, and the work
estimate (:func:`planner.estimate_work`) against the measured compute (the estimate is to bound
the work: measured <= 1.5x the estimate), and the ratios limited / unlimited.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from planner import estimate_work, plan  # noqa: E402

TABLE1 = json.loads((ROOT / "app" / "static" / "examples" / "table1.json").read_text())


def request(**settings: object) -> dict:
    return {**TABLE1, "settings": {**TABLE1.get("settings", {}), "mode": "constrained", **settings}}


def peak(res) -> float:
    v = np.asarray(res.velocity)
    return float(np.hypot(v[:, 0], v[:, 1]).max())


def main() -> None:
    ap = argparse.ArgumentParser(description="What the tool-speed limit costs a Table I plan.")
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()
    free = peak(plan(request()))
    cases = {
        "default timing, no limit": request(),
        "default timing, limit 0.8 x peak": request(tool_speed_max_m_s=0.8 * free),
        "fastest, no limit": request(fastest=True),
        "fastest, limit 0.6 x peak": request(fastest=True, tool_speed_max_m_s=0.6 * free),
    }
    rows: dict[str, dict[str, list[float]]] = {k: {"compute": [], "step": []} for k in cases}
    last = {}
    for _ in range(2):  # warm up every case (kernels, caches)
        for req in cases.values():
            plan(req)
    for _ in range(args.rounds):
        for name, req in cases.items():
            res = plan(req)
            m = res.metrics
            rows[name]["compute"].append(m.compute_ms)
            rows[name]["step"].append((m.qp_time_ms or 0.0) / max(m.steps, 1))
            last[name] = res
    print(f"Table I, constrained, compiled; unlimited peak tool speed {free * 1e3:.1f} mm/s; "
          f"{args.rounds} interleaved rounds, medians; load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores\n")
    print("| case | compute ms | controller ms/step | peak / limit | duration s | estimate s | measured / estimate |")
    print("|---|---|---|---|---|---|---|")
    med = {}
    for name, req in cases.items():
        res = last[name]
        comp = statistics.median(rows[name]["compute"])
        step = statistics.median(rows[name]["step"])
        med[name] = (comp, step)
        lim = req["settings"].get("tool_speed_max_m_s")
        est = estimate_work(req).seconds
        ratio = f"{peak(res) / lim:.5f}" if lim else "-"
        print(f"| {name} | {comp:.1f} | {step:.4f} | {ratio} | {res.metrics.duration_s:.2f} | {est:.3f} | "
              f"{comp / 1e3 / est:.2f} |")
    for a, b in (("default timing, limit 0.8 x peak", "default timing, no limit"),
                 ("fastest, limit 0.6 x peak", "fastest, no limit")):
        print(f"\n{a} / {b}: compute {med[a][0] / med[b][0]:.2f}x, controller per step {med[a][1] / med[b][1]:.2f}x")


if __name__ == "__main__":
    main()
