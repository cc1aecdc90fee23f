"""The work estimate against the measured planning time (issue 15).

A server rejects a request whose estimated compute time
(:func:`planner.estimate_work`) exceeds its time limit. Since issue 20 the estimate bounds the
work (the whole settling tail counted, a layout estimated again once segmented):
measured / estimated should be <= 1.5 (the random cases of ``benchmarks/certify.py`` check it
on thousands of requests) and not far below it (or requests that could finish are refused). For each request
of a suite (modes, backends, horizons, long corridors, layouts, the fastest-timing search,
reference tracking) this prints the estimate, the measured wall time of ``planner.plan``
(median of ``--repeat`` runs; one run for those over a second) and their ratio, and the
time the estimate itself takes.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_work.py [--repeat 3] [--quick] \
        [--slack] [--cpu] [--no-advice]

``--slack``: only constrained plans with ``require_settled: false`` that need slack (issue 20).
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import copy  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_segmentation import layout as obstacle_layout  # noqa: E402

from planner import PlannerError, estimate_work, plan  # noqa: E402

EXAMPLES = Path(__file__).resolve().parents[1] / "app" / "static" / "examples"
TABLE1 = json.loads((EXAMPLES / "table1.json").read_text())
PSI = json.loads((EXAMPLES / "psi-turn.json").read_text())


def with_settings(req: dict, **settings) -> dict:
    out = copy.deepcopy(req)
    out["settings"] = {**out.get("settings", {}), **settings}
    return out


def walk(n: int, seed: int = 0) -> dict:
    """``n`` point segments on a random walk of 1 mm steps (the issue's 1 999-segment request)."""
    pts = np.cumsum(np.random.default_rng(seed).uniform(-0.001, 0.001, (n, 2)), axis=0)
    return {"segments": [{"lower": [float(x), float(y), 0.0], "upper": [float(x), float(y), 0.0]} for x, y in pts],
            "settings": {"require_settled": False}}


def suite(quick: bool) -> list[tuple[str, dict]]:
    lay = obstacle_layout("square")
    tri = obstacle_layout("triangle")
    paper = with_settings(TABLE1, mode="paper")  # the default mode is the constrained one
    cases = [
        ("Table I, paper", paper),
        ("Table I, paper, N = 80", with_settings(paper, N=80)),
        ("Table I, paper, 5 RK4 substeps", with_settings(paper, plant_substeps=5)),
        ("Table I, paper, reference backend", with_settings(paper, backend="reference")),
        ("Table I, paper, structured solver", with_settings(paper, backend="reference", solver="structured")),
        ("Table I, paper, QR solver", with_settings(paper, backend="reference", solver="qr")),
        ("Table I, constrained N = 10", with_settings(TABLE1, mode="constrained", N=10)),
        ("Table I, constrained", with_settings(TABLE1, mode="constrained")),
        ("Table I, constrained N = 60", with_settings(TABLE1, mode="constrained", N=60)),
        ("Table I, constrained, reference", with_settings(TABLE1, mode="constrained", backend="reference")),
        ("Table I, constrained, fastest", with_settings(TABLE1, mode="constrained", fastest=True)),
        ("psi-turn, constrained", with_settings(PSI, mode="constrained")),
        ("Table I, paper, speed 0.02 m/s", with_settings(paper, speed_m_s=0.02)),
        ("Table I, constrained, speed 0.02 m/s", with_settings(TABLE1, mode="constrained", speed_m_s=0.02)),
        ("reference tracking, 500 poses", {"reference": {"pose": [[-0.08 + 0.14 * i / 499, 0.04 * i / 499, 0.0]
                                                                  for i in range(500)]},
                                           "settings": {"mode": "paper"}}),
        ("layout 0.3 m, 5 mm squares, 20 obstacles, paper", {"layout": lay, "settings": {"mode": "paper"}}),
        ("layout, triangles, paper", {"layout": tri, "settings": {"mode": "paper"}}),
        ("layout, constrained (default tool speed)", {"layout": lay}),
        ("layout, triangles, constrained (default tool speed)", {"layout": tri}),
        ("200 point segments, paper", with_settings(walk(200), mode="paper")),
        ("1 999 point segments, paper", with_settings(walk(1999), mode="paper")),
    ]
    if not quick:
        cases += [
            ("1 999 point segments x 100 samples, paper", with_settings(walk(1999), mode="paper",
                                                                        samples_per_segment=100)),
            ("200 point segments, constrained", with_settings(walk(200), mode="constrained")),
            ("Table I, constrained N = 120", with_settings(TABLE1, mode="constrained", N=120)),
        ]
    return cases


def corner(sps: int, psi: float, **settings) -> dict:
    """Issue 20's tiny corridor: the box x, y in [0, 1 mm] and its corner as the end point, psi
    in [0, psi]; with ``samples_per_segment`` 1 or 2 every step of it (or the first few) needs
    slack."""
    return {"segments": [{"lower": [0, 0, 0], "upper": [0.001, 0.001, psi]},
                         {"lower": [0.001, 0.001, 0], "upper": [0.001, 0.001, psi]}],
            "settings": {"samples_per_segment": sps, "require_settled": False, **settings}}


def slack_suite() -> list[tuple[str, dict]]:
    """Constrained plans with ``require_settled: false`` that need slack (issue 20: their
    infeasible steps are bounded by the estimate, ``planner.orchestrator.work.slack_steps_allowed``)."""
    cases = []
    for robot in ("moving-slide", "tri-slide"):
        for N in (10, 30, 60):
            for sps, psi in ((1, 0.0), (1, 0.01), (2, 0.0)):
                cases.append((f"corner, {robot}, N = {N}, S = {sps}, psi [0, {psi:g}]",
                              {**corner(sps, psi, N=N), "robot": robot}))
    cases += [("Table I, constrained, 3 samples per segment (336 of 336 steps infeasible, 42 s unbounded)",
               with_settings(TABLE1, mode="constrained", samples_per_segment=3, require_settled=False)),
              ("Table I, constrained, 8 samples per segment (13 steps infeasible)",
               with_settings(TABLE1, mode="constrained", samples_per_segment=8, require_settled=False)),
              ("Table I, constrained, speed 0.5 m/s", with_settings(TABLE1, mode="constrained", speed_m_s=0.5,
                                                                   require_settled=False)),
              ("Table I, constrained, speed 0.5 m/s, reference",
               with_settings(TABLE1, mode="constrained", speed_m_s=0.5, require_settled=False, backend="reference"))]
    return cases


def measure(req: dict, repeat: int, clock=time.perf_counter) -> tuple[float, str]:
    times, outcome = [], "ok"
    for _ in range(repeat):
        t = clock()
        try:
            plan(req)
        except PlannerError as exc:
            outcome = exc.code
        times.append(clock() - t)
        if times[-1] > 1.0:
            break
    return statistics.median(times), outcome


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="leave out the three slowest requests")
    ap.add_argument("--slack", action="store_true", help="only the plans with require_settled false that need "
                    "slack (issue 20)")
    ap.add_argument("--cpu", action="store_true", help="measure the process's CPU time (robust to other load) "
                    "instead of the wall time")
    ap.add_argument("--no-advice", action="store_true", help="an infeasible plan's error without its checked advice "
                    "(the advice is estimated apart, advice_seconds): the plan's own work")
    args = ap.parse_args()
    if args.no_advice:
        import planner.orchestrator.plan as plan_module

        plan_module._more_time_advice = lambda exc, *a, **k: exc  # type: ignore[assignment]
    clock = time.process_time if args.cpu else time.perf_counter
    plan(TABLE1)  # load the kernels
    print("| request | steps (est.) | estimate [s] | measured [s] | measured / estimate | outcome "
          "| estimate took [us] |")
    print("|---|---:|---:|---:|---:|---|---:|")
    ratios = []
    for name, req in (slack_suite() if args.slack else suite(args.quick)):
        t = time.perf_counter()
        est = estimate_work(req)
        est_us = (time.perf_counter() - t) * 1e6
        took, outcome = measure(req, args.repeat, clock)
        ratios.append(took / est.seconds)
        print(f"| {name} | {est.steps} | {est.seconds:.3g} | {took:.3g} | {took / est.seconds:.2f} | {outcome} | "
              f"{est_us:.0f} |", flush=True)
    print(f"\nmeasured / estimate: min {min(ratios):.2f}, median {statistics.median(ratios):.2f}, "
          f"max {max(ratios):.2f}")


if __name__ == "__main__":
    main()
