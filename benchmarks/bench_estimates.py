"""Estimated against measured CPU seconds of the work issue 33 found under-estimated: plans
with ``fastest`` (Table I at Ts 10, 5, 2 ms; serpentine corridors of 20, 50, 100 segments),
G-code contours (many lines, many tiny full circles, many short passes) and drawing imports.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_estimates.py [--only fastest|contour|import]
        [--limit 60] [--skip-over 40]

Prints one row a case: the estimate [s], the measured CPU seconds of this process
(``time.process_time``; the machine may be loaded, wall time is not the figure), their ratio
(goal <= 1.5) and whether a 30 s limit admits the case. A case whose estimate is over
``--skip-over`` seconds is not run (``-``). Imports: the CPU seconds of reading a DXF spline
(``too_large``: refused from its point counts). Run it with ``PYTHONPATH`` on the checkout to
measure (e.g. a ``git archive`` of the base for the before figures).
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import copy  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

EXAMPLES = Path(__file__).resolve().parents[1] / "app" / "static" / "examples"
TABLE1 = json.loads((EXAMPLES / "table1.json").read_text())


def with_settings(req: dict, **settings) -> dict:
    out = copy.deepcopy(req)
    out["settings"] = {**out.get("settings", {}), **settings}
    return out


def serpentine(n: int, cell: float = 0.01) -> dict:
    """A corridor of ``n`` segments: a start point, ``n - 2`` square boxes of ``cell`` [m]
    back and forth in rows of 14 across x in [-0.07, 0.07], an end point."""
    boxes = []
    per_row = 14
    for k in range(n - 2):
        row, col = divmod(k, per_row)
        if row % 2:
            col = per_row - 1 - col
        x0, y0 = -0.07 + col * cell, -0.04 + row * cell
        boxes.append({"lower": [x0, y0, 0.0], "upper": [x0 + cell, y0 + cell, 0.0]})
    first, last = boxes[0], boxes[-1]
    start = [first["lower"][0] + cell / 2, first["lower"][1] + cell / 2, 0.0]
    end = [last["lower"][0] + cell / 2, last["lower"][1] + cell / 2, 0.0]
    return {"name": f"serpentine {n}", "segments": [{"lower": start, "upper": start}, *boxes,
                                                    {"lower": end, "upper": end}]}


def fastest_cases() -> list[tuple[str, dict]]:
    cases = [(f"Table I, fastest, Ts {ts * 1e3:g} ms", with_settings(TABLE1, fastest=True, Ts=ts))
             for ts in (0.01, 0.005, 0.002)]
    cases += [(f"serpentine {n} segments, fastest", with_settings(serpentine(n), fastest=True))
              for n in (20, 50, 100)]
    return cases


def gcode_lines(n: int, per_pass: int = 100, step: float = 0.5) -> str:
    """``n`` short G1 moves of ``step`` [mm], ``per_pass`` to a pass, each pass a staircase
    (x, then y) starting 1 mm further along x than the one before (ten starts)."""
    out = ["G21 G90"]
    x = y = 0.0
    for i in range(n):
        p, k = divmod(i, per_pass)
        if k == 0:
            x, y = (p % 10) * 1.0, 0.0
            out += ["G0 Z5", f"G0 X{x:.3f} Y{y:.3f}", "G1 Z-1 F3000"]
        if k % 2:
            y += step
        else:
            x += step
        out.append(f"G1 X{x:.3f} Y{y:.3f}")
    return "\n".join(out) + "\n"


def gcode_circles(n: int, r_mm: float = 0.1, per_pass: int = 100) -> str:
    """``n`` tiny full circles (G2 with I) on a 0.5 mm grid of ten columns, ``per_pass`` to a
    pass (passes 1 mm apart along x, ten starts)."""
    out = ["G21 G90"]
    for i in range(n):
        p, k = divmod(i, per_pass)
        x, y = (p % 10) * 1.0 + (k % 10) * 0.5, (k // 10) * 0.5
        if k == 0:
            out += ["G0 Z5", f"G0 X{x:.3f} Y{y:.3f}", "G1 Z-1 F3000"]
        else:
            out.append(f"G1 X{x:.3f} Y{y:.3f}")
        out.append(f"G2 X{x:.3f} Y{y:.3f} I{r_mm:.3f} J0")
    return "\n".join(out) + "\n"


def gcode_passes(n: int) -> str:
    """``n`` short passes: plunge, a 0.9 mm line, retract, rapid to the next."""
    out = ["G21 G90"]
    for i in range(n):
        x, y = (i % 20) * 1.0, (i // 20) * 1.0
        out += [f"G0 X{x:.3f} Y{y:.3f}", "G1 Z-1 F3000", f"G1 X{x + 0.8:.3f} Y{y + 0.4:.3f}", "G0 Z5"]
    return "\n".join(out) + "\n"


def gcode_arcs(n: int, r_mm: float = 1.5, per_pass: int = 20) -> str:
    """``n`` half circles of radius ``r_mm`` in a wave (G2, G3 alternating), ``per_pass`` to a
    pass (passes 15 mm apart along y, five starts)."""
    out = ["G21 G90"]
    x = y = 0.0
    for i in range(n):
        p, k = divmod(i, per_pass)
        if k == 0:
            x, y = 0.0, (p % 5) * 10 * r_mm
            out += ["G0 Z5", f"G0 X{x:.3f} Y{y:.3f}", "G1 Z-1 F1200"]
        out.append(f"{'G2' if k % 2 else 'G3'} X{x + 2 * r_mm:.3f} Y{y:.3f} R{r_mm:.3f}")
        x += 2 * r_mm
    return "\n".join(out) + "\n"


def gcode_long(n: int) -> str:
    """A long program: ``n`` lines of rapids and comments above the part around 100 lines of 0.5 mm."""
    filler = [f"G0 X{(i % 50) * 0.2:.3f} Y{(i // 50 % 50) * 0.2:.3f} (rapid {i})" for i in range(n)]
    return "G21 G90\nG0 Z5\n" + "\n".join(filler) + "\n" + gcode_lines(100).split("\n", 1)[1]


def contour_cases() -> list[tuple[str, dict]]:
    cases = []
    for n in (200, 1000, 3000):
        cases.append((f"{n} lines of 0.5 mm, program feed", {"program": gcode_lines(n), "feed": "program"}))
    for n in (50, 300, 1000):
        cases.append((f"{n} full circles r 0.1 mm, program feed", {"program": gcode_circles(n), "feed": "program"}))
    for n in (10, 50, 200):
        cases.append((f"{n} passes of 0.9 mm, program feed", {"program": gcode_passes(n), "feed": "program"}))
    for n in (20, 100):
        cases.append((f"{n} half circles r 1.5 mm, program feed", {"program": gcode_arcs(n), "feed": "program"}))
    cases.append(("20 000 rapid lines + 100 cut lines", {"program": gcode_long(20_000), "feed": "program"}))
    cases.append(("6 000 lines of 0.5 mm, program feed", {"program": gcode_lines(6000), "feed": "program"}))
    cases.append(("200 lines, fastest", {"program": gcode_lines(200), "feed": "fastest"}))
    cases += [  # other sample times, and fastest
        ("200 lines, Ts 5 ms", {"program": gcode_lines(200), "settings": {"Ts": 0.005}}),
        ("50 circles, Ts 2 ms", {"program": gcode_circles(50), "settings": {"Ts": 0.002}}),
        ("20 passes, Ts 2 ms", {"program": gcode_passes(20), "settings": {"Ts": 0.002}}),
        ("100 lines, fastest, Ts 5 ms", {"program": gcode_lines(100), "feed": "fastest", "settings": {"Ts": 0.005}}),
        ("30 circles, fastest", {"program": gcode_circles(30), "feed": "fastest"}),
        ("20 passes, fastest", {"program": gcode_passes(20), "feed": "fastest"}),
        ("20 half circles, fastest", {"program": gcode_arcs(20), "feed": "fastest"}),
        ("20 half circles, tolerance 0.01 mm", {"program": gcode_arcs(20), "tolerance_m": 1e-5}),
    ]
    return cases


def _cpu(fn) -> tuple[float, str]:
    t0 = time.process_time()
    try:
        fn()
        out = "ok"
    except Exception as exc:
        out = getattr(exc, "code", type(exc).__name__)
    return time.process_time() - t0, out


def run_fastest(limit: float, skip: float) -> None:
    from planner import estimate_work, plan

    for name, req in fastest_cases():
        est = estimate_work(req).seconds
        _row(name, est, lambda req=req: plan(req), limit, skip)


def run_contour(limit: float, skip: float) -> None:
    from planner.contour import estimate_contour, plan_contour
    from planner.exchange import read_gcode
    from planner.schema import ContourRequest

    for name, raw in contour_cases():
        req = ContourRequest.model_validate(raw)

        def go(req=req) -> None:
            program = read_gcode(req.program, cut_below=req.cut_below_m, z_rapid_m_s=req.z_rapid_m_s)
            plan_contour(req, program=program)

        program = read_gcode(req.program, cut_below=req.cut_below_m, z_rapid_m_s=req.z_rapid_m_s)
        est = estimate_contour(req, program)[0]
        _row(name, est, go, limit, skip)


def spline_dxf(n: int, fit: bool) -> bytes:
    """A DXF of one closed spline through (``fit``) or on ``n`` points of a 50 mm circle."""
    import io

    import ezdxf
    import numpy as np

    doc = ezdxf.new()
    msp = doc.modelspace()
    a = np.linspace(0, 2 * math.pi, n, endpoint=False)
    pts = np.c_[50 * np.cos(a), 50 * np.sin(a)].tolist()
    sp = msp.add_spline(pts) if fit else msp.add_open_spline(pts)
    sp.closed = True
    buf = io.StringIO()
    doc.write(buf)
    return buf.getvalue().encode()


def _dxf(build) -> bytes:
    import io

    import ezdxf

    doc = ezdxf.new()
    doc.header["$INSUNITS"] = 4
    build(doc, doc.modelspace())
    buf = io.StringIO()
    doc.write(buf)
    return buf.getvalue().encode()


def _squares(msp, n: int, size: float = 2.0, pitch: float = 3.0, cols: int = 40) -> None:
    """``n`` squares of four LINEs on a grid."""
    for k in range(n):
        x, y = (k % cols) * pitch, (k // cols) * pitch
        pts = [(x, y), (x + size, y), (x + size, y + size), (x, y + size)]
        for a, b in zip(pts, pts[1:] + pts[:1]):
            msp.add_line(a, b)


def _circles(msp, n: int, r: float, pitch: float, cols: int = 40) -> None:
    for k in range(n):
        msp.add_circle(((k % cols) * pitch, (k // cols) * pitch), r)


def _nested(doc, msp, fan: int, depth: int, copies: int = 1) -> None:
    """Blocks ``depth`` deep, each inserting the one below ``fan`` times (a MINSERT grid of
    ``copies`` cells at the top); the bottom block: one square of four LINEs and a circle."""
    blk = doc.blocks.new("B0")
    for a, b in (((0, 0), (1, 0)), ((1, 0), (1, 1)), ((1, 1), (0, 1)), ((0, 1), (0, 0))):
        blk.add_line(a, b)
    blk.add_circle((0.5, 0.5), 0.3)
    for d in range(1, depth + 1):
        blk = doc.blocks.new(f"B{d}")
        for k in range(fan):
            blk.add_blockref(f"B{d - 1}", ((k % 5) * 2.0 * 5 ** ((d - 1) // 2), (k // 5) * 2.0 * 5 ** ((d - 1) // 2)))
    ref = msp.add_blockref(f"B{depth}", (0, 0))
    if copies > 1:
        ref.grid(size=(copies, 1), spacing=(1000.0, 1000.0))


def _hatches(msp, n: int, edges: int, arcs: bool) -> None:
    """``n`` hatches, each one boundary path of ``edges`` edges around a circle of 2 mm (line
    edges, or arc edges of that circle)."""
    for k in range(n):
        cx, cy = (k % 40) * 5.0, (k // 40) * 5.0
        h = msp.add_hatch()
        path = h.paths.add_edge_path()
        for j in range(edges):
            a0, a1 = 360.0 * j / edges, 360.0 * (j + 1) / edges
            if arcs:
                path.add_arc((cx, cy), 2.0, a0, a1)
            else:
                path.add_line((cx + 2 * math.cos(math.radians(a0)), cy + 2 * math.sin(math.radians(a0))),
                              (cx + 2 * math.cos(math.radians(a1)), cy + 2 * math.sin(math.radians(a1))))


def _bulges(msp, n: int, verts: int) -> None:
    """``n`` closed LWPOLYLINEs of ``verts`` vertices on a 3 mm circle, each side a bulge."""
    for k in range(n):
        cx, cy = (k % 40) * 8.0, (k // 40) * 8.0
        pts = [(cx + 3 * math.cos(2 * math.pi * j / verts), cy + 3 * math.sin(2 * math.pi * j / verts), 0, 0, 0.2)
               for j in range(verts)]
        msp.add_lwpolyline(pts, format="xyseb", close=True)


def _svg(body: str, defs: str = "") -> bytes:
    return (f'<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" width="400mm" '
            f'height="400mm" viewBox="0 0 400 400"><defs>{defs}</defs>{body}</svg>').encode()


def svg_paths(n: int, per: int) -> bytes:
    """``n`` closed paths of ``per`` line segments."""
    out = []
    for k in range(n):
        x, y = (k % 40) * 8.0, (k // 40) * 8.0
        d = f"M{x:.2f},{y:.2f} " + " ".join(f"L{x + 3 + 3 * math.cos(2 * math.pi * j / per):.3f},"
                                            f"{y + 3 + 3 * math.sin(2 * math.pi * j / per):.3f}" for j in range(per))
        out.append(f'<path d="{d} Z"/>')
    return _svg("".join(out))


def svg_arcs(n: int) -> bytes:
    """``n`` circles made of two arc segments each (r 3 mm)."""
    out = []
    for k in range(n):
        x, y = (k % 40) * 8.0, (k // 40) * 8.0
        out.append(f'<path d="M{x:.2f},{y + 3:.2f} A3,3 0 1,0 {x + 6:.2f},{y + 3:.2f} '
                   f'A3,3 0 1,0 {x:.2f},{y + 3:.2f} Z"/>')
    return _svg("".join(out))


def svg_circles(n: int, r: float) -> bytes:
    return _svg("".join(f'<circle cx="{(k % 40) * (2 * r + 1):.2f}" cy="{(k // 40) * (2 * r + 1):.2f}" r="{r}"/>'
                        for k in range(n)))


def svg_uses(n: int, per: int) -> bytes:
    """A group of ``per`` small rects used ``n`` times."""
    group = "".join(f'<rect x="{j * 1.5:.1f}" y="0" width="1" height="1"/>' for j in range(per))
    uses = "".join(f'<use xlink:href="#g" x="0" y="{k * 2.0:.1f}"/>' for k in range(n))
    return _svg(uses, f'<g id="g">{group}</g>')


def import_cases() -> list[tuple[str, bytes, str, dict]]:
    """Drawings at the edges (issue 33): many lines, fine circles, nested block references,
    MINSERT grids, hatches of line and arc edges, bulged polylines, splines, big SVGs."""
    mm = {"units": "mm"}
    cases = [
        ("DXF 2 000 squares (8 000 LINEs)", _dxf(lambda d, m: _squares(m, 2000)), "dxf", mm),
        ("DXF 600 overlapping circles r 50 mm, tol 0.01 mm", _dxf(lambda d, m: _circles(m, 600, 50.0, 1.0)), "dxf",
         {**mm, "flatten_tolerance": 1e-5}),
        ("DXF 1 500 circles r 1 mm", _dxf(lambda d, m: _circles(m, 1500, 1.0, 3.0)), "dxf", mm),
        ("DXF INSERT 5 deep x 4 (1 024 blocks)", _dxf(lambda d, m: _nested(d, m, 4, 5)), "dxf", mm),
        ("DXF INSERT 3 deep x 10 (1 000 blocks)", _dxf(lambda d, m: _nested(d, m, 10, 3)), "dxf", mm),
        ("DXF MINSERT 2 x 300 cells of 5 x 5", _dxf(lambda d, m: _nested(d, m, 5, 2, 300)), "dxf", mm),
        ("DXF 500 hatches of 40 line edges", _dxf(lambda d, m: _hatches(m, 500, 40, False)), "dxf", mm),
        ("DXF 500 hatches of 8 arc edges", _dxf(lambda d, m: _hatches(m, 500, 8, True)), "dxf", mm),
        ("DXF 1 000 LWPOLYLINEs of 24 bulges", _dxf(lambda d, m: _bulges(m, 1000, 24)), "dxf", mm),
        ("SVG 1 500 paths of 30 lines", svg_paths(1500, 30), "svg", {}),
        ("SVG 300 paths of 30 lines", svg_paths(300, 30), "svg", {}),
        ("SVG 1 500 arc circles", svg_arcs(1500), "svg", {}),
        ("SVG 1 500 circles r 3 mm", svg_circles(1500, 3.0), "svg", {}),
        ("SVG 1 500 circles r 3 mm, tol 0.005 mm", svg_circles(1500, 3.0), "svg", {"flatten_tolerance": 5e-6}),
        ("SVG group of 20 rects used 300 times", svg_uses(300, 20), "svg", {}),
    ]
    for n, fit in ((1000, True), (2000, True), (4000, False), (9000, False)):
        cases.append((f"DXF spline, {n} {'fit' if fit else 'control'} points", spline_dxf(n, fit), "dxf", mm))
    return cases


def run_import(limit: float, skip: float) -> None:
    """Estimated against measured CPU seconds of importing edge drawings (the estimate: the
    file parsed and counted, :func:`planner.exchange.estimate_import`; a drawing refused from
    its counts: its code)."""
    from planner.errors import PlannerError
    from planner.exchange import estimate_import, import_drawing

    for name, data, fmt, options in import_cases():
        try:
            est = estimate_import(data, options, format=fmt).seconds
        except PlannerError as exc:
            print(f"{name:45s} {'':>9s} {'':>9s} {'':>7s} {'refused':>9s} {exc.code} (counted)", flush=True)
            continue
        _row(name, est, lambda data=data, fmt=fmt, options=options: import_drawing(data, options, format=fmt),
             limit, skip)


def _row(name: str, est: float, fn, limit: float, skip: float) -> None:
    if est > skip:
        print(f"{name:45s} {est:9.3g} {'-':>9s} {'-':>7s} {'refused' if est > limit else 'admitted':>9s}", flush=True)
        return
    cpu, out = _cpu(fn)
    ratio = cpu / est if est > 0 else math.inf
    print(f"{name:45s} {est:9.3g} {cpu:9.3g} {ratio:7.2f} {'refused' if est > limit else 'admitted':>9s} {out}",
          flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=("fastest", "contour", "import"))
    ap.add_argument("--limit", type=float, default=30.0)
    ap.add_argument("--skip-over", type=float, default=1e9)
    args = ap.parse_args()
    from planner import plan
    plan(with_settings(TABLE1, N=5, tail_max_s=0.05, require_settled=False))  # kernels loaded
    print(f"{'case':45s} {'est s':>9s} {'CPU s':>9s} {'CPU/est':>7s} {'30 s':>9s}")
    if args.only in (None, "fastest"):
        run_fastest(args.limit, args.skip_over)
    if args.only in (None, "contour"):
        run_contour(args.limit, args.skip_over)
    if args.only in (None, "import"):
        run_import(args.limit, args.skip_over)


if __name__ == "__main__":
    main()
