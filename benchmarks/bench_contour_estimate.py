"""The contour estimate against the measured work (issue 35 goal 5) on generated programs
(``tests/contour_programs.py``: many tiny passes, long single passes, many tiny full circles,
arcs, Z ramps and helices, long programs of rapids; 1 to 2000 passes, up to 100 000 lines, Ts
1-10 ms, feeds ``program`` and ``fastest``).

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/bench_contour_estimate.py \
        [--limit 30] [--skip-over 40] [--work-cap 1200] [--small] [--only WORDS] [--feed F] [--shard K/N] \
        [--json rows.jsonl] [--cam [--ts rule,1,2,3,5,10]]

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
constants without planning again. ``--cam [--ts rule,1,2,3,5,10]``: the CAM programs of
``tests/data/cam`` and ``app/static/examples/contour-part.ngc`` (real ramps, helices and seams) in
both feeds at each typed sample time (``rule``: none typed) instead of the generated ones, with
how many parts (cut pieces, free moves) were planned once, twice and three times or more (again
from the forces the part before left, after a release: issue 35's seams) and the cycle time;
``--json`` rows for the refit too. The last
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
    """In the child: read, estimate and plan; send (CPU s, outcome, plans per seamed part).
    Killed by the kernel (SIGXCPU) after ``cpu_cap`` CPU seconds. The plans of each part the
    walk plans (``planner.contour.plan._Walk.seamed``: a cut piece or a free move, planned once,
    or again from the forces the part before left, or a third time after a release) are
    counted by wrapping it (measurement only)."""
    import resource

    resource.setrlimit(resource.RLIMIT_CPU, (cpu_cap, resource.RLIM_INFINITY))
    import planner.contour.plan as contour_plan
    from planner.contour import estimate_contour, plan_contour
    from planner.exchange import read_gcode
    from planner.schema import ContourRequest

    plans: list[int] = []
    seamed = contour_plan._Walk.seamed

    def counted(self, planned, *a, **k):
        n = [0]

        def once(*pa, **pk):
            n[0] += 1
            return planned(*pa, **pk)

        try:
            return seamed(self, once, *a, **k)
        finally:
            plans.append(n[0])

    contour_plan._Walk.seamed = counted  # type: ignore[method-assign]
    t0 = time.process_time()
    try:
        r = ContourRequest.model_validate(req)
        program = read_gcode(r.program, cut_below=r.cut_below_m, z_rapid_m_s=r.z_rapid_m_s)
        estimate_contour(r, program)
        res = plan_contour(r, program=program)
        out = "ok"
        cycle = res.contour.cycle_time_s if res.contour is not None else None
    except Exception as exc:  # the outcome is printed
        out = getattr(exc, "code", type(exc).__name__)
        cycle = None
    conn.send((time.process_time() - t0, out, plans, cycle))


def measure(req: dict, est: float, detail: bool = False) -> tuple:
    """CPU seconds and outcome of ``req`` in a forked child (``detail``: also the plans per
    seamed part and the cycle time)."""
    parent, child = mp.get_context("fork").Pipe(duplex=False)
    cap = int(math.ceil(3 * est + 10))
    p = mp.get_context("fork").Process(target=_work, args=(req, child, cap))
    p.start()
    child.close()
    try:
        cpu, out, plans, cycle = parent.recv()
    except EOFError:  # the child was killed at its CPU cap
        cpu, out, plans, cycle = None, f"stopped at {cap} CPU s", [], None
    p.join()
    return (cpu, out, plans, cycle) if detail else (cpu, out)


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
                    help="the CAM programs of tests/data/cam and app/static/examples/contour-part.ngc (origin "
                         "'fit') in both feeds at the typed sample times of --ts instead")
    ap.add_argument("--ts", default="rule,1,2,3,5,10",
                    help="--cam: the sample times [ms] typed in settings.Ts ('rule': none typed, the contour's own)")
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
        print(f"| program | feed | Ts ms | est s | CPU s | CPU/est | parts planned 1/2/3+ times | cycle s | "
              f"{args.limit:g} s | outcome |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        cam(args.limit, [None if t == "rule" else float(t) * 1e-3 for t in args.ts.split(",")], args.json,
            args.only, args.feed, (shard_k, shard_n))
        return
    print(f"| program | feed | Ts ms | lines | passes | moves | est s | CPU s | CPU/est | parts planned 1/2/3+ times | "
          f"{args.limit:g} s | outcome |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    ratios: list[float] = []
    rows: list[tuple[str, float, float]] = []  # feed, Ts, CPU / estimate
    spent = 0.0

    def record(index: int, req: dict, est: float | None, cpu: float | None, out: str,
               Ts_used: float | None = None, plans: list[int] | None = None) -> None:
        if args.json:
            with open(args.json, "a") as fh:
                fh.write(json.dumps({"seed": args.seed, "large": not args.small, "index": index, "feed": req["feed"],
                                     "Ts": (req.get("settings") or {}).get("Ts", 0.01), "Ts_used": Ts_used,
                                     "est": est, "cpu": cpu, "outcome": out, "plans": plans}) + "\n")

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
                  f"- | - | - | - | refused | {exc.code} up front |", flush=True)
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
            print(f"{head} - | - | - | {admitted} | {why} |", flush=True)
            record(index, req, est, None, why, Ts)
            continue
        spent += est
        cpu, out, plans, _ = measure(req, est, detail=True)
        counts = f"{plans.count(1)}/{plans.count(2)}/{sum(n >= 3 for n in plans)}"
        if cpu is None:
            print(f"{head} > {3 * est + 10:.3g} | - | {counts} | {admitted} | {out} |", flush=True)
            record(index, req, est, None, out, Ts, plans)
            continue
        ratios.append(cpu / est)
        rows.append((req["feed"], Ts, cpu / est))
        record(index, req, est, cpu, out, Ts, plans)
        print(f"{head} {cpu:.3g} | {cpu / est:.2f} | {counts} | {admitted} | {out} |", flush=True)
    summary(rows)


#: the real CAM programs of ``--cam``: tests/data/cam and the example part
CAM_PROGRAMS = [*sorted((Path(__file__).resolve().parents[1] / "tests" / "data" / "cam").iterdir()),
                Path(__file__).resolve().parents[1] / "app" / "static" / "examples" / "contour-part.ngc"]


def cam_request(name: str, feed: str, Ts: float | None) -> dict:
    """The request of ``--cam``'s program ``name`` (a file of :data:`CAM_PROGRAMS`), origin
    ``fit``, at the typed sample time ``Ts`` [s] (None: the contour's own)."""
    path = next(p for p in CAM_PROGRAMS if p.name == name)
    return {"program": path.read_text(), "feed": feed, "origin": "fit",
            "settings": {} if Ts is None else {"Ts": Ts}}


def cam(limit: float, sample_times: list[float | None], json_path: str = "", only: str = "", feed_only: str = "",
        shard: tuple[int, int] = (0, 1)) -> None:
    """The CAM programs (:data:`CAM_PROGRAMS`) in both feeds at each typed sample time (None:
    the contour's own, ``rule``): real ramps, helices and seams beside the generated programs.
    Per row also how many parts (cut pieces and free moves) were planned once, twice (again from
    the forces the part before left) and three times or more (after a release), and the cycle
    time."""
    from app.jobs import ESTIMATE_MARGIN as margin
    from planner.contour import estimate_contour

    rows: list[tuple[str, float, float]] = []
    k = -1
    for path in CAM_PROGRAMS:
        if only and only not in path.name:
            continue
        for feed in ("program", "fastest"):
            if feed_only and feed != feed_only:
                continue
            for Ts_typed in sample_times:
                k += 1
                if k % shard[1] != shard[0]:
                    continue
                req = cam_request(path.name, feed, Ts_typed)
                est, detail = estimate_contour(req)
                used = re.search(r"at Ts = ([0-9.e-]+) s", detail)
                Ts = float(used.group(1)) if used else 0.01
                cpu, out, plans, cycle = measure(req, est, detail=True)
                admitted = "admitted" if est * margin <= limit else "refused"
                ts_txt = f"{Ts * 1e3:g}" + (" (rule)" if Ts_typed is None else "")
                counts = f"{plans.count(1)}/{plans.count(2)}/{sum(n >= 3 for n in plans)}"
                if json_path:
                    with open(json_path, "a") as fh:
                        fh.write(json.dumps({"cam": path.name, "feed": feed, "Ts": Ts_typed, "Ts_used": Ts,
                                             "est": est, "cpu": cpu, "outcome": out, "plans": plans,
                                             "cycle": cycle}) + "\n")
                if cpu is None:
                    print(f"| {path.name} | {feed} | {ts_txt} | {est:.3g} | - | - | {counts} | - | {admitted} | "
                          f"{out} |", flush=True)
                    continue
                rows.append((feed, Ts, cpu / est))
                cyc = "-" if cycle is None else f"{cycle:.3f}"
                print(f"| {path.name} | {feed} | {ts_txt} | {est:.3g} | {cpu:.3g} | {cpu / est:.2f} | {counts} | "
                      f"{cyc} | {admitted} | {out} |", flush=True)
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
