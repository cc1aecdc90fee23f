"""The contour estimate against the measured work (issue 35 goal 5) on generated programs
(``tests/contour_programs.py``: many tiny passes, long single passes, many tiny full circles,
arcs, Z ramps and helices, long programs of rapids; 1 to 2000 passes, up to 100 000 lines, Ts
1-10 ms, feeds ``program`` and ``fastest``).

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/bench_contour_estimate.py \
        [--limit 30] [--skip-over 40] [--small] [--only WORDS]

One row a program: its lines, passes, moves, the estimate [s]
(:func:`planner.contour.estimate_contour`, after the program is read, as the service's worker
does), the measured CPU seconds of the work the estimate stands for (reading the program,
estimating it and planning it, ``time.process_time`` of a forked child: the machine may be
loaded, wall time is not the figure), their ratio (goal <= 1.5, and not far below 1: an
estimate too high refuses programs that would finish), and whether ``--limit`` admits it. A
program estimated over ``--skip-over`` seconds is not planned (``-``); a child still running
after ``3 x estimate + 10`` CPU seconds is stopped (``stopped``: the estimate is far too
low). The last lines: the ratios' range and median over the programs planned.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import math  # noqa: E402
import multiprocessing as mp  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

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
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    from bench_contour import ORIGIN, TOL, program  # type: ignore[import-not-found]

    from planner import PlannerError
    from planner.contour import estimate_contour, plan_contour
    from planner.exchange import read_gcode
    from planner.schema import ContourRequest

    for feed in ("program", "fastest"):  # the kernels loaded (the forked children inherit them)
        plan_contour({"program": program(1), "origin": ORIGIN, "tolerance_m": TOL, "feed": feed})
    print(f"load: {os.getloadavg()[0]:.1f} (1-min average) on {os.cpu_count()} cores; limit {args.limit:g} s")
    print(f"| program | feed | Ts ms | lines | passes | moves | est s | CPU s | CPU/est | {args.limit:g} s | outcome |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    ratios: list[float] = []
    for made, req in cases(args.seed, large=not args.small):
        if args.only and args.only not in made.name:
            continue
        r = ContourRequest.model_validate(req)
        program_ = read_gcode(r.program, cut_below=r.cut_below_m, z_rapid_m_s=r.z_rapid_m_s)
        try:
            est = estimate_contour(r, program_)[0]
        except PlannerError as exc:  # refused before any work (a pass no tube fits: too_large)
            print(f"| {made.name} | {req['feed']} | - | {made.text.count(chr(10))} | {made.passes} | {made.moves} | "
                  f"- | - | - | refused | {exc.code} up front |", flush=True)
            continue
        del program_
        Ts = (req.get("settings") or {}).get("Ts", 0.01)
        head = (f"| {made.name} | {req['feed']} | {Ts * 1e3:g} | {made.text.count(chr(10))} | {made.passes} | "
                f"{made.moves} | {est:.3g} |")
        admitted = "admitted" if est <= args.limit else "refused"
        if est > args.skip_over:
            print(f"{head} - | - | {admitted} | not run |", flush=True)
            continue
        cpu, out = measure(req, est)
        if cpu is None:
            print(f"{head} > {3 * est + 10:.3g} | - | {admitted} | {out} |", flush=True)
            continue
        ratios.append(cpu / est)
        print(f"{head} {cpu:.3g} | {cpu / est:.2f} | {admitted} | {out} |", flush=True)
    if ratios:
        print(f"\nCPU / estimate over {len(ratios)} programs planned: {min(ratios):.2f}-{max(ratios):.2f}, median "
              f"{statistics.median(ratios):.2f}; over 1.5: {sum(x > 1.5 for x in ratios)}")


if __name__ == "__main__":
    main()
