"""What the synchronous lane's estimate of ``POST /v1/contour`` costs at the program size cap,
and whether to ship the read program to the job's worker or read it again there (issues 33
goal 2, 35 goal 6; app/routers/jobs.py).

For each program family at (close to) ``MAX_PROGRAM_BYTES`` (2 MB): the CPU seconds of reading
it (:func:`planner.exchange.read_gcode`) and of estimating it
(:func:`planner.contour.estimate_contour`), the two steps a synchronous worker runs before the
contour is planned or queued (bounded by the synchronous limit, ``RANGEPLAN_PLAN_TIMEOUT_S``:
30 s by default), and what shipping the read program would cost instead of a second read: its
pickle's size and the CPU seconds to pickle and unpickle it (once each way through the server:
worker -> server -> job worker, so twice this). Medians of ``--repeat`` runs, in one process.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/bench_contour_lanes.py
"""

from __future__ import annotations

import argparse
import math
import pickle
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from planner.contour import estimate_contour
from planner.errors import PlannerError
from planner.exchange import read_gcode
from planner.schema import ContourRequest
from planner.schema.contour import MAX_PROGRAM_BYTES


def many_lines(n: int) -> str:
    """One pass of ``n`` short cutting lines around a 10 mm circle (tests/test_edges_stream.py)."""
    out = ["G21 G90 G17", "G64 P0.05", "G0 X10 Y0 Z2", "G1 Z-1 F300", "F1200"]
    out += [f"G1 X{10 * math.cos(i * 0.01):.3f} Y{10 * math.sin(i * 0.01):.3f}" for i in range(n)]
    return "\n".join([*out, "G0 Z2", "M2"]) + "\n"


def programs() -> list[tuple[str, str]]:
    from tests.contour_programs import circles, rapids

    rng = np.random.default_rng(0)
    return [("rapids, 100 000 lines", rapids(rng, 100_000).text),
            ("rapids, 135 000 lines", rapids(rng, 135_000).text),
            ("one pass, 80 000 lines", many_lines(80_000)),
            ("tiny circles, 30 passes of 1000", circles(rng, 30_000, per_pass=1000).text)]


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print("| program | bytes | lines | read [CPU s] | estimate [CPU s] | read + estimate | estimated work [s] | "
          "pickle [MB] | pickle + unpickle [CPU s] | shipping / reading again |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, text in programs():
        size = len(text.encode())
        if size > MAX_PROGRAM_BYTES:
            print(f"| {name} | {size} | over the cap: skipped |")
            continue
        req = ContourRequest.model_validate({"program": text, "feed": "program"})
        reads, ests, ships = [], [], []
        work = "?"
        size_mb = float("nan")
        for _ in range(args.repeat):
            t0 = time.process_time()
            program = read_gcode(req.program, cut_below=req.cut_below_m, z_rapid_m_s=req.z_rapid_m_s)
            t1 = time.process_time()
            try:
                work = f"{estimate_contour(req, program)[0]:.3g}"
            except PlannerError as exc:  # refused (a pass too large for any tube): the estimate step's answer
                work = f"refused: {exc.code}"
            t2 = time.process_time()
            blob = pickle.dumps(program, protocol=pickle.HIGHEST_PROTOCOL)
            t3 = time.process_time()
            pickle.loads(blob)
            t4 = time.process_time()
            size_mb = len(blob) / 1e6
            reads.append(t1 - t0)
            ests.append(t2 - t1)
            ships.append(2 * ((t3 - t2) + (t4 - t3)))  # worker -> server -> job worker
            del program, blob
        r, e, s = statistics.median(reads), statistics.median(ests), statistics.median(ships)
        print(f"| {name} | {size} | {text.count(chr(10))} | {r:.2f} | {e:.2f} | {r + e:.2f} | {work} | "
              f"{size_mb:.1f} | {s:.2f} | {s / r:.2f} |", flush=True)


if __name__ == "__main__":
    main()
