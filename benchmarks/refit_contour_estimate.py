"""Re-check the contour estimate against CPU seconds measured before, without planning again
(issue 35 goal 5): after a change of the estimate's constants (``planner/contour/estimate.py``,
all at the top of the module) or of the planner's costs, the rows that
``benchmarks/bench_contour_estimate.py --json rows.jsonl`` wrote (the program's index in
:func:`tests.contour_programs.cases`, its seed, the measured CPU) are estimated again with the
current code and their CPU / estimate printed with the least, median and largest by feed and
by sample time (a program measured in several files: its last measurement). Rows of
``--cam`` (the CAM programs at typed sample times) are re-estimated from their files.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/refit_contour_estimate.py rows.jsonl [more.jsonl]

The CPU figures are those of the code measured: after a change of the planner's costs (the
search, the timing, the kernels) measure again with ``bench_contour_estimate.py --json``.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_contour_estimate import cam_request, summary

from planner import PlannerError
from planner.contour import estimate_contour
from tests.contour_programs import cases


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("rows", nargs="+", help="JSON lines of bench_contour_estimate.py --json")
    args = ap.parse_args()
    by_case: dict[tuple, dict] = {}  # a program measured in several files: the last measurement
    for f in args.rows:
        for line in Path(f).read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                # a CAM program's row (--cam): by its file, feed and typed sample time
                key = ("cam", r["cam"], r["feed"], r["Ts"]) if "cam" in r else (r["seed"], r["large"], r["index"])
                if r["cpu"] is not None or key not in by_case or by_case[key]["cpu"] is None:
                    by_case[key] = r
    rows = list(by_case.values())
    made: dict[tuple[int, bool], list] = {}
    print("| program | feed | Ts ms | est s (then) | est s (now) | CPU s | CPU/est | outcome |")
    print("|---|---|---|---|---|---|---|---|")
    out: list[tuple[str, float, float]] = []
    for r in sorted(rows, key=lambda r: (r.get("cam", ""), r.get("seed", 0), r.get("index", 0), r["feed"],
                                         r["Ts"] or 0.0)):
        if "cam" in r:  # a CAM program at a typed sample time (None: the contour's own)
            req = cam_request(r["cam"], r["feed"], r["Ts"])
            name = r["cam"] + ("" if r["Ts"] is not None else " (rule)")
        else:
            key = (r["seed"], r["large"])
            if key not in made:
                made[key] = cases(r["seed"], large=r["large"])
            program, req = made[key][r["index"]]
            name = program.name
        try:
            est, detail = estimate_contour(req)
        except PlannerError as exc:
            print(f"| {name} | {r['feed']} | {(r['Ts'] or 0.01) * 1e3:g} | {r['est']} | refused ({exc.code}) | "
                  f"{r['cpu']} | - | {r['outcome']} |")
            continue
        then = "-" if r["est"] is None else f"{r['est']:.3g}"
        used = re.search(r"at Ts = ([0-9.e-]+) s", detail)  # the sample time planned (fastest chooses its own)
        r["Ts"] = float(used.group(1)) if used else (r["Ts"] or 0.01)
        if r["cpu"] is None:
            print(f"| {name} | {r['feed']} | {r['Ts'] * 1e3:g} | {then} | {est:.3g} | - | - | {r['outcome']} |")
            continue
        out.append((r["feed"], r["Ts"], r["cpu"] / est))
        print(f"| {name} | {r['feed']} | {r['Ts'] * 1e3:g} | {then} | {est:.3g} | {r['cpu']:.3g} | "
              f"{r['cpu'] / est:.2f} | {r['outcome']} |")
    summary(out)


if __name__ == "__main__":
    main()
