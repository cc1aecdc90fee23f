"""Generated G-code programs at the edges of the contour estimate (issue 35 goal 5): many tiny
passes, long single passes, many tiny full circles, arcs, Z ramps and helices, long programs of
rapids; 1 to 2000 passes, up to 100 000 lines. Each generator returns the program's text and
what it made, counted here as it writes the program (passes, feed moves cut, arcs, cut length
and the time at F), independently of the reader and of :func:`planner.contour.estimate_contour`.
Used by ``benchmarks/bench_contour_estimate.py`` (estimate against measured CPU) and
``tests/test_contour_estimate.py`` (the estimate's counts against these).

Every part fits in a 20 mm square about program zero's (10, 10) mm (the default ``origin:
"fit"`` places it in reach)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: the side of the square every generated part fits in [mm]
SIDE_MM = 20.0


@dataclass
class Made:
    """A generated program and what its generator wrote: ``passes`` cut passes, ``moves``
    feed moves cut (lines and arcs; a helix is an arc), ``arcs`` of them arcs, ``cut_mm`` the
    XY length cut, ``time_at_f_s`` the XY length of each move over its F summed."""

    name: str
    text: str
    passes: int = 0
    moves: int = 0
    arcs: int = 0
    cut_mm: float = 0.0
    time_at_f_s: float = 0.0
    lines: list[str] = field(default_factory=list, repr=False)

    def cut(self, line: str, length_mm: float, f_mm_min: float, arc: bool = False) -> None:
        self.lines.append(line)
        self.moves += 1
        self.arcs += int(arc)
        self.cut_mm += length_mm
        self.time_at_f_s += length_mm / (f_mm_min / 60.0)

    def done(self) -> Made:
        self.text = "\n".join(self.lines) + "\n"
        return self


def staircase(n: int, per_pass: int = 100) -> str:
    """``n`` cut lines of 0.5 mm at F3000 (mm), ``per_pass`` a pass: each pass a staircase from
    its own start (1 mm apart in X, ten columns), plunged to Z -1 from Z 5."""
    out, x, y = ["G21 G90"], 0.0, 0.0
    for i in range(n):
        p, k = divmod(i, per_pass)
        if k == 0:
            x, y = (p % 10) * 1.0, 0.0
            out += ["G0 Z5", f"G0 X{x:.3f} Y{y:.3f}", "G1 Z-1 F3000"]
        y, x = (y + 0.5, x) if k % 2 else (y, x + 0.5)
        out.append(f"G1 X{x:.3f} Y{y:.3f}")
    return "\n".join(out) + "\n"


def _start(name: str, tol_mm: float | None = None) -> Made:
    m = Made(name, "")
    m.lines += ["G21 G90 G17"] + ([f"G64 P{tol_mm:g}"] if tol_mm else []) + ["G0 Z2"]
    return m


def _plunge(m: Made, x: float, y: float, f: float, z: float = -0.5) -> None:
    m.lines += [f"G0 X{x:.4f} Y{y:.4f}", f"G1 Z{z:.3f} F300", f"F{f:g}"]
    m.passes += 1


def tiny_passes(rng: np.random.Generator, n: int, f: float = 1200.0) -> Made:
    """``n`` passes of 1-3 short lines (0.2-1 mm) each, on a grid filling the square."""
    m = _start(f"{n} tiny passes")
    cols = max(int(math.ceil(math.sqrt(n))), 1)
    pitch = SIDE_MM / cols
    for i in range(n):
        x, y = round((i % cols + 0.2) * pitch, 4), round((i // cols + 0.2) * pitch, 4)
        _plunge(m, x, y, f)
        for _ in range(int(rng.integers(1, 4))):
            step = float(rng.uniform(0.2, 1.0)) * min(pitch * 0.25, 1.0)
            a = float(rng.uniform(0, 2 * math.pi))
            x2 = round(min(max(x + step * math.cos(a), 0.0), SIDE_MM), 4)  # as written
            y2 = round(min(max(y + step * math.sin(a), 0.0), SIDE_MM), 4)
            m.cut(f"G1 X{x2:.4f} Y{y2:.4f}", math.hypot(x2 - x, y2 - y), f)
            x, y = x2, y2
        m.lines.append("G0 Z2")
    return m.done()


def long_pass(rng: np.random.Generator, n: int, step_mm: float = 0.5, f: float = 1200.0) -> Made:
    """One pass of ``n`` lines: a raster of rows ``step_mm`` apart, each row in moves of
    ``step_mm`` (a line a row change)."""
    m = _start(f"one pass of {n} lines of {step_mm:g} mm")
    per_row = max(int(SIDE_MM / step_mm) - 1, 1)
    x = y = 0.0
    _plunge(m, x, y, f)
    direction = 1
    for i in range(n):
        k = i % (per_row + 1)
        if k == per_row:  # the row change
            y2 = y + step_mm if y + step_mm <= SIDE_MM else 0.0
            m.cut(f"G1 Y{y2:.4f}", abs(y2 - y), f)
            y, direction = y2, -direction
            continue
        x2 = x + direction * step_mm
        m.cut(f"G1 X{x2:.4f}", step_mm, f)
        x = x2
    return m.done()


def circles(rng: np.random.Generator, n: int, r_mm: float = 0.1, per_pass: int = 100, f: float = 1200.0) -> Made:
    """``n`` full circles of radius ``r_mm`` (G2 with I), ``per_pass`` to a pass, on a grid."""
    m = _start(f"{n} full circles r {r_mm:g} mm, {per_pass} a pass")
    cols = max(int(math.ceil(math.sqrt(n))), 1)
    pitch = (SIDE_MM - 2 * r_mm) / cols
    x = y = 0.0
    for i in range(n):
        x2, y2 = round((i % cols) * pitch, 4), round((i // cols) * pitch, 4)
        if i % per_pass == 0:
            m.lines.append("G0 Z2")
            _plunge(m, x2, y2, f)
        else:
            m.cut(f"G1 X{x2:.4f} Y{y2:.4f}", math.hypot(x2 - x, y2 - y), f)
        m.cut(f"G2 X{x2:.4f} Y{y2:.4f} I{r_mm:.4f} J0", 2 * math.pi * r_mm, f, arc=True)
        x, y = x2, y2
    m.lines.append("G0 Z2")
    return m.done()


def arcs(rng: np.random.Generator, n: int, r_mm: float = 1.5, per_pass: int = 20, f: float = 1200.0,
         tol_mm: float | None = None) -> Made:
    """``n`` half circles of radius ``r_mm`` in waves (G2 and G3 alternating, R words),
    ``per_pass`` to a pass; rows ``4 r`` apart."""
    m = _start(f"{n} half circles r {r_mm:g} mm, {per_pass} a pass", tol_mm)
    per_row = max(int(SIDE_MM / (2 * r_mm)), 1)
    row = 0
    x = y = 0.0
    for i in range(n):
        k = i % per_pass
        if k == 0 or (k % per_row == 0):
            if k == 0:
                m.lines.append("G0 Z2")
            x, y = 0.0, (row % max(int(SIDE_MM / (4 * r_mm)), 1)) * 4 * r_mm + r_mm
            row += 1
            if k == 0:
                _plunge(m, x, y, f)
            else:
                m.lines += ["G0 Z2", f"G0 X{x:.4f} Y{y:.4f}", "G1 Z-0.5 F300", f"F{f:g}"]
                m.passes += 1
        m.cut(f"{'G2' if k % 2 else 'G3'} X{x + 2 * r_mm:.4f} Y{y:.4f} R{r_mm:.4f}", math.pi * r_mm, f, arc=True)
        x += 2 * r_mm
    m.lines.append("G0 Z2")
    return m.done()


def ramps(rng: np.random.Generator, n: int, f: float = 600.0) -> Made:
    """``n`` passes, each a ramp down along a 4 mm line (Z from -0.1 to -0.5), back along it at
    depth, and a helix of one turn (r 1 mm) down 0.3 mm more; on a grid."""
    m = _start(f"{n} ramp and helix passes")
    cols = max(int(math.ceil(math.sqrt(n))), 1)
    pitch = SIDE_MM / cols
    L = min(4.0, 0.6 * pitch)
    r = min(1.0, 0.2 * pitch)
    for i in range(n):
        x, y = (i % cols) * pitch + 0.1 * pitch, (i // cols) * pitch + 0.5 * pitch
        m.lines += [f"G0 X{x:.4f} Y{y:.4f}", "G1 Z-0.1 F300", f"F{f:g}"]
        m.passes += 1
        m.cut(f"G1 X{x + L:.4f} Z-0.5", L, f)
        m.cut(f"G1 X{x:.4f}", L, f)
        m.cut(f"G2 X{x:.4f} Y{y:.4f} Z-0.8 I{r:.4f} J0", 2 * math.pi * r, f, arc=True)
        m.lines.append("G0 Z2")
    return m.done()


def rapids(rng: np.random.Generator, n: int) -> Made:
    """A long program: ``n`` lines of rapids (every tenth with a comment) above the part, then 50 lines of a
    long pass."""
    m = long_pass(rng, 50)
    filler = [f"G0 X{(i % 50) * 0.2:.1f} Y{(i // 50 % 50) * 0.2:.1f}" + (f" (rapid {i})" if i % 10 == 0 else "")
              for i in range(n)]  # short lines: 100 000 of them within the 2 MB a program may have
    m.lines[2:2] = filler  # after the first retract, before the pass's first point
    m.name = f"{n} rapid lines + 50 cut lines"
    return m.done()


def depth_passes(rng: np.random.Generator, n: int, f: float = 1200.0) -> Made:
    """``n`` depth passes (0.5 mm apart) of one outline: a 16 x 10 mm rectangle with 2 mm
    corner arcs and a 3 mm notch (lines and arcs; the passes share their time-optimal profiles)."""
    m = _start(f"{n} depth passes of a notched rectangle", 0.02)
    w, h, r = 16.0, 10.0, 2.0
    for i in range(n):
        m.lines.append(f"G0 X{r:.4f} Y0")
        m.lines += [f"G1 Z{-(i + 1) * 0.5:.3f} F300", f"F{f:g}"]
        m.passes += 1
        m.cut(f"G1 X{w - r:.4f}", w - 2 * r, f)
        m.cut(f"G3 X{w:.4f} Y{r:.4f} I0 J{r:.4f}", math.pi * r / 2, f, arc=True)
        m.cut(f"G1 Y{h - r:.4f}", h - 2 * r, f)
        m.cut(f"G3 X{w - r:.4f} Y{h:.4f} I{-r:.4f} J0", math.pi * r / 2, f, arc=True)
        m.cut(f"G1 X{w / 2 + 3:.4f}", w / 2 - 3 - r, f)
        m.cut(f"G2 X{w / 2 - 3:.4f} Y{h:.4f} R3", math.pi * 3, f, arc=True)
        m.cut(f"G1 X{r:.4f}", w / 2 - 3 - r, f)
        m.cut(f"G3 X0 Y{h - r:.4f} I0 J{-r:.4f}", math.pi * r / 2, f, arc=True)
        m.cut(f"G1 Y{r:.4f}", h - 2 * r, f)
        m.cut(f"G3 X{r:.4f} Y0 I{r:.4f} J0", math.pi * r / 2, f, arc=True)
        m.lines.append("G0 Z2")
    return m.done()


def cases(seed: int = 0, large: bool = True) -> list[tuple[Made, dict]]:
    """The benchmark's programs (and settings): each family over its sizes, both feeds, Ts 1-10
    ms. ``large``: also the programs of 500-2000 passes and 10 000-100 000 lines (most are
    refused at a 30 s limit: their estimate is printed, and measured where it is admitted)."""
    rng = np.random.default_rng(seed)
    out: list[tuple[Made, dict]] = []

    def add(made: Made, feed: str = "program", Ts: float | None = None, **extra) -> None:
        req: dict = {"program": made.text, "feed": feed, **extra}
        if Ts is not None:
            req["settings"] = {"Ts": Ts}
        out.append((made, req))

    for n in (1, 10, 100) + ((500, 2000) if large else ()):
        add(tiny_passes(rng, n))
    add(tiny_passes(rng, 50), "fastest")
    add(tiny_passes(rng, 20), Ts=0.002)
    add(tiny_passes(rng, 5), Ts=0.001)
    for n in (50, 500, 3000) + ((20_000,) if large else ()):
        add(long_pass(rng, n))
    add(long_pass(rng, 300, step_mm=0.2))
    add(long_pass(rng, 200), "fastest")
    add(long_pass(rng, 100), "fastest", Ts=0.005)
    add(long_pass(rng, 200), Ts=0.005)
    add(long_pass(rng, 40), Ts=0.001)
    for n, per in ((20, 20), (300, 100), (1000, 1000)):
        add(circles(rng, n, per_pass=per))
    add(circles(rng, 200, r_mm=0.5, per_pass=1))
    add(circles(rng, 30, per_pass=10), "fastest")
    add(circles(rng, 50, per_pass=50), Ts=0.002)
    for n in (20, 200):
        add(arcs(rng, n))
    add(arcs(rng, 40, tol_mm=0.01))
    add(arcs(rng, 20, r_mm=0.5), "fastest")
    add(arcs(rng, 20), Ts=0.001)
    for n in (1, 10, 100):
        add(ramps(rng, n))
    add(ramps(rng, 10), "fastest")
    add(ramps(rng, 10), Ts=0.002)
    for n in (1_000, 20_000) + ((100_000,) if large else ()):
        add(rapids(rng, n))
    for n in (1, 15) + ((60,) if large else ()):
        add(depth_passes(rng, n))
    add(depth_passes(rng, 15), "fastest")
    add(depth_passes(rng, 3), Ts=0.002)
    sweep(rng, add)
    return out


def sweep(rng: np.random.Generator, add) -> None:
    """Small programs of every family at each sample time of the goal (1, 2, 5, 10 ms) in both
    feeds: where a sample's cost and the search's plans change with Ts (kept small: at Ts 1 ms
    a sample costs ~5x one at 10 ms)."""
    for Ts in (0.001, 0.002, 0.005, 0.01):
        for feed in ("program", "fastest"):
            add(tiny_passes(rng, 4), feed, Ts=Ts)
            add(long_pass(rng, 60), feed, Ts=Ts)
            add(circles(rng, 8, per_pass=8), feed, Ts=Ts)
            add(arcs(rng, 6, per_pass=6), feed, Ts=Ts)
            add(ramps(rng, 2), feed, Ts=Ts)
            add(depth_passes(rng, 1), feed, Ts=Ts)
