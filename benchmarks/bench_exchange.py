"""Drawing import and machine output timings (issue 13): each real LibreCAD drawing of
tests/data/drawings imported at 1:10 (default tolerances and 0.1 um flattening), and
Table I's plan written as G-code, a leg-length stream and DXF. Prints markdown tables.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_exchange.py [--repeat 7]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from planner import plan  # noqa: E402
from planner.exchange import export, import_drawing  # noqa: E402


def median_ms(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    import_drawing((ROOT / "tests/data/drawings/Table-coffee-E.dxf").read_bytes())  # imports ezdxf once
    print("### Drawing import (1:10; median of", args.repeat, "runs)\n")
    print("| drawing | bytes | obstacles | holes | vertices (0.1 mm) | import [ms] | vertices (0.1 um) | import [ms] |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for path in sorted((ROOT / "tests/data/drawings").glob("*.dxf")):
        data = path.read_bytes()
        row = [path.name, str(len(data))]
        for tol in (1e-4, 1e-7):
            opts = {"scale": 0.1, "flatten_tolerance": tol}
            res = import_drawing(data, opts)
            if tol == 1e-4:
                row += [str(len(res.layout.obstacles)), str(res.report.holes)]
            row += [str(sum(s.vertices for s in res.report.shapes)),
                    f"{median_ms(lambda d=data, o=opts: import_drawing(d, o), args.repeat):.1f}"]
        print("| " + " | ".join(row) + " |")
    result = plan(json.loads((ROOT / "app/static/examples/table1.json").read_text()))
    print(f"\n### Table I ({len(result.pose)} samples) to machine formats (median of {args.repeat} runs)\n")
    print("| format | bytes | write [ms] |")
    print("|---|---:|---:|")
    for fmt in ("gcode", "joints", "dxf"):
        text = export(result, fmt)  # type: ignore[arg-type]
        ms = median_ms(lambda f=fmt: export(result, f), args.repeat)  # type: ignore[arg-type]
        print(f"| {fmt} | {len(text.encode())} | {ms:.1f} |")


if __name__ == "__main__":
    main()
