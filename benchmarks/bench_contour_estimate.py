"""The contour estimate against the measured work (issue 35 goal 5) on generated programs
(``tests/contour_programs.py``: many tiny passes, long single passes, many tiny full circles,
arcs, Z ramps and helices, long programs of rapids; 1 to 2000 passes, up to 100 000 lines, Ts
1-10 ms, feeds ``program`` and ``fastest``).

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/bench_contour_estimate.py \
        [--limit 30] [--skip-over 40] [--work-cap 1200] [--small] [--only WORDS] [--feed F] [--shard K/N] \
        [--json rows.jsonl] [--cam]

One row a program: its sample time (the request's, or the one the planner chose for it: ``fastest``
without a ``settings.Ts``), its lines, passes, moves, the estimate [s]
(:func:`planner.contour.estimate_contour`, after the program is read, as the service's worker
does), the measured CPU seconds of the work the estimate stands for (reading the program,
estimating it and planning it, ``time.process_time`` of a child forked after the kernels and the
Z axis's LP are loaded: once-a-process costs, which a service worker pays on its first request;
the machine may be loaded, wall time is not the figure), their ratio (goal <= 1.5, and not far below 1: an
estimate too high refuses programs that would finish), and whether ``--limit`` admits it (as the
service does: estimate x ``app.jobs.ESTIMATE_MARGIN`` <= the limit). A
program estimated over ``--skip-over`` seconds is not planned (``-``); a child still running
after ``3 x estimate + 10`` CPU seconds is stopped (``stopped``: the estimate is far too
low). ``--work-cap``: the programs are run while the sum of their estimates stays under it
(the rest ``not run (work cap)``: the run fits ~20 min of CPU); ``--shard K/N``: every N-th
program from the K-th (two shards side by side on two cores); ``--json``: a line per program
(its index in :func:`tests.contour_programs.cases`, feed, Ts, estimate, CPU, outcome) for
``benchmarks/refit_contour_estimate.py``, which recomputes the ratios with the estimate's current
constants without planning again. ``--cam``: the CAM programs of ``tests/data/cam``
(real ramps and helices) in both feeds at their defaults instead of the generated ones. The last
lines: the ratios' least, median and largest over the programs planned, by feed, by sample time
and by both.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import multiprocessing as mp  # noqa: E402
import re  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from tests.contour_programs import cases  # noqa: E402


def _work(req: dict, conn, cpu_cap: int) -> None:
    """In the child: read, estimate and plan; send (CPU s, outcome). Killed by the kernel
    (SIGXCPU) after ``cpu_cap`` CPU seconds."""
    import resource

    resource.setrlimit(resource.RLIMIT_CPU, (cpu_cap, resource.RLIM_INFINITY))
    from planner.contour import estimate_contour, plan_contour
    from planner.exchange import read_gcode
    from planner.schema import ContourRequest

    t0 = time.process_time()
    try:
        r = ContourRequest.model_validate(req)
        program = read_gcode(r.program, cut_below=r.cut_below_m, z_rapid_m_s=r.z_rapid_m_s)
        estimate_contour(r, program)
        plan_contour(r, program=program)
        out = "ok"
    except Exception as exc:  # the outcome is printed
        out = getattr(exc, "code", type(exc).__name__)
    conn.send((time.process_time() - t0, out))


def measure(req: dict, est: float) -> tuple[float | None, str]:
    parent, child = mp.get_context("fork").Pipe(duplex=False)
    cap = int(math.ceil(3 * est + 10))
    p = mp.get_context("fork").Process(target=_work, args=(req, child, cap))
    p.start()
    child.close()
    try:
        cpu, out = parent.recv()
    except EOFError:  # the child was killed at its CPU cap
        cpu, out = None, f"stopped at {cap} CPU s"
    p.join()
    return cpu, out


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--limit", type=float, default=30.0)
    ap.add_argument("--skip-over", type=float, default=40.0)
    ap.add_argument("--small", action="store_true", help="without the programs of 500+ passes and 10 000+ lines")
    ap.add_argument("--only", default="", help="only programs whose name contains this")
    ap.add_argument("--feed", default="", choices=("", "program", "fastest"), help="only programs of this feed")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--work-cap", type=float, default=1200.0, help="the sum of the estimates run at most [s]")
    ap.add_argument("--shard", default="0/1", help="K/N: every N-th program from the K-th")
    ap.add_argument("--json", default="", help="append a JSON line per program to this file")
    ap.add_argument("--cam", action="store_true",
                    help="the CAM programs of tests/data/cam (origin 'fit') in both feeds at their defaults instead "
                         "(no JSON rows)")
    args = ap.parse_args()
    shard_k, shard_n = (int(x) for x in args.shard.split("/"))
    from bench_contour import ORIGIN, TOL, program  # type: ignore[import-not-found]

    from app.jobs import ESTIMATE_MARGIN as margin  # a job is admitted if estimate x margin <= its limit
    from planner import PlannerError
    from planner.contour import estimate_contour, plan_contour
    from planner.exchange import read_gcode
    from planner.schema import ContourRequest
    from tests.contour_programs import ramps

    for feed in ("program", "fastest"):  # the kernels loaded (the forked children inherit them), and the
        # Z axis's LP (scipy.optimize: ~0.5 CPU s, once a process; the 1-ramp program measured 1.54x without it)
        plan_contour({"program": program(1), "origin": ORIGIN, "tolerance_m": TOL, "feed": feed})
        plan_contour({"program": ramps(np.random.default_rng(0), 1).text, "feed": feed})
    print(f"load: {os.getloadavg()[0]:.1f} (1-min average) on {os.cpu_count()} cores; limit {args.limit:g} s")
    if args.cam:
        print(f"| program | feed | Ts ms | est s | CPU s | CPU/est | {args.limit:g} s | outcome |")
        print("|---|---|---|---|---|---|---|---|")
        cam(args.limit)
        return
    print(f"| program | feed | Ts ms | lines | passes | moves | est s | CPU s | CPU/est | {args.limit:g} s | outcome |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    ratios: list[float] = []
    rows: list[tuple[str, float, float]] = []  # feed, Ts, CPU / estimate
    spent = 0.0

    def record(index: int, req: dict, est: float | None, cpu: float | None, out: str,
               Ts_used: float | None = None) -> None:
        if args.json:
            with open(args.json, "a") as fh:
                fh.write(json.dumps({"seed": args.seed, "large": not args.small, "index": index, "feed": req["feed"],
                                     "Ts": (req.get("settings") or {}).get("Ts", 0.01), "Ts_used": Ts_used,
                                     "est": est, "cpu": cpu, "outcome": out}) + "\n")

    for index, (made, req) in enumerate(cases(args.seed, large=not args.small)):
        if args.only and args.only not in made.name:
            continue
        if args.feed and req["feed"] != args.feed:
            continue
        if index % shard_n != shard_k:
            continue
        r = ContourRequest.model_validate(req)
        program_ = read_gcode(r.program, cut_below=r.cut_below_m, z_rapid_m_s=r.z_rapid_m_s)
        try:
            est, detail = estimate_contour(r, program_)
        except PlannerError as exc:  # refused before any work (a pass no tube fits: too_large)
            print(f"| {made.name} | {req['feed']} | - | {made.text.count(chr(10))} | {made.passes} | {made.moves} | "
                  f"- | - | - | refused | {exc.code} up front |", flush=True)
            record(index, req, None, None, f"{exc.code} up front")
            continue
        del program_
        # the sample time planned: the request's, or the one the planner chose (fastest's defaults)
        used = re.search(r"at Ts = ([0-9.e-]+) s", detail)
        Ts = float(used.group(1)) if used else (req.get("settings") or {}).get("Ts", 0.01)
        head = (f"| {made.name} | {req['feed']} | {Ts * 1e3:g} | {made.text.count(chr(10))} | {made.passes} | "
                f"{made.moves} | {est:.3g} |")
        admitted = "admitted" if est * margin <= args.limit else "refused"
        if est > args.skip_over or spent + est > args.work_cap:
            why = "not run" if est > args.skip_over else "not run (work cap)"
            print(f"{head} - | - | {admitted} | {why} |", flush=True)
            record(index, req, est, None, why, Ts)
            continue
        spent += est
        cpu, out = measure(req, est)
        if cpu is None:
            print(f"{head} > {3 * est + 10:.3g} | - | {admitted} | {out} |", flush=True)
            record(index, req, est, None, out, Ts)
            continue
        ratios.append(cpu / est)
        rows.append((req["feed"], Ts, cpu / est))
        record(index, req, est, cpu, out, Ts)
        print(f"{head} {cpu:.3g} | {cpu / est:.2f} | {admitted} | {out} |", flush=True)
    summary(rows)


def cam(limit: float) -> None:
    """The CAM programs of tests/data/cam in both feeds at their defaults (origin ``fit``):
    real ramps and helices beside the generated ones."""
    from app.jobs import ESTIMATE_MARGIN as margin
    from planner.contour import estimate_contour

    rows: list[tuple[str, float, float]] = []
    for path in sorted((Path(__file__).resolve().parents[1] / "tests" / "data" / "cam").iterdir()):
        for feed in ("program", "fastest"):
            req = {"program": path.read_text(), "feed": feed, "origin": "fit"}
            est, detail = estimate_contour(req)
            used = re.search(r"at Ts = ([0-9.e-]+) s", detail)
            Ts = float(used.group(1)) if used else 0.01
            cpu, out = measure(req, est)
            admitted = "admitted" if est * margin <= limit else "refused"
            if cpu is None:
                print(f"| {path.name} | {feed} | {Ts * 1e3:g} | {est:.3g} | - | - | {admitted} | {out} |", flush=True)
                continue
            rows.append((feed, Ts, cpu / est))
            print(f"| {path.name} | {feed} | {Ts * 1e3:g} | {est:.3g} | {cpu:.3g} | {cpu / est:.2f} | {admitted} | "
                  f"{out} |", flush=True)
    summary(rows)


def summary(rows: list[tuple[str, float, float]]) -> None:
    """The ratios' least, median and largest: over all programs planned, by feed, by Ts, by
    feed and Ts."""
    if not rows:
        return
    groups: dict[str, list[float]] = {"all": [r for _, _, r in rows]}
    for feed, Ts, r in rows:
        groups.setdefault(f"feed {feed}", []).append(r)
        groups.setdefault(f"Ts {Ts * 1e3:g} ms", []).append(r)
    for feed, Ts, r in sorted(rows, key=lambda x: (x[0], -x[1])):  # by feed and sample time
        groups.setdefault(f"{feed}, Ts {Ts * 1e3:g} ms", []).append(r)
    print("\n| programs | planned | least | median | largest | over 1.5 |\n|---|---|---|---|---|---|")
    for name, rs in groups.items():
        print(f"| {name} | {len(rs)} | {min(rs):.2f} | {statistics.median(rs):.2f} | {max(rs):.2f} | "
              f"{sum(x > 1.5 for x in rs)} |")


if __name__ == "__main__":
    main()
