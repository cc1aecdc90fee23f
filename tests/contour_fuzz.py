"""Generated CAM programs for the contour planner and their independent check (issue 22):
used by tests/test_contour_fuzz.py and benchmarks/fuzz_contour.py (which describes both)."""

from __future__ import annotations

import time
import traceback

import numpy as np

from planner.contour import plan_contour
from planner.errors import PlannerError
from tests.test_contour import chord_deviation, feed_excess, rs274_cut_path, two_sided

ORIGIN = [-0.015, -0.015]
FEEDS = ("program", "fastest")


def program(rng: np.random.Generator, max_passes: int = 3, max_moves: int = 8) -> str:
    """One generated program: mm or inch, G64 P 0.01-0.1 mm (or none: the 0.05 mm default),
    1-``max_passes`` passes of 1-``max_moves`` moves each (lines, I/J and R arcs, full circles,
    moves of 0.05 mm and less), feeds 200-3000 mm/min, inside a 30 mm square."""
    inch = rng.random() < 0.15
    u = 25.4 if inch else 1.0
    out = ["G20 G90 G17" if inch else "G21 G90 G17"]
    tol_mm = float(rng.choice([0.01, 0.02, 0.05, 0.1]))
    if rng.random() < 0.8:
        out.append(f"G64 P{tol_mm / u:.5f}")
    passes = int(rng.integers(1, max_passes + 1))

    def feed() -> float:
        return float(rng.choice([200, 500, 1000, 1500, 3000]))

    x, y = rng.uniform(2, 28, 2)
    for _ in range(passes):
        out += [f"G0 Z{2 / u:.4f}", f"G0 X{x / u:.4f} Y{y / u:.4f}", f"G1 Z{-1 / u:.4f} F{300 / u:.1f}",
                f"F{feed() / u:.1f}"]
        for _ in range(int(rng.integers(1, max_moves + 1))):
            kind = rng.choice(["line", "arcij", "arcr", "circle", "tiny"])
            if kind in ("line", "tiny"):
                step = 0.05 if kind == "tiny" else 8
                nx, ny = np.clip(np.array([x, y]) + rng.uniform(-step, step, 2), 1, 29)
                out.append(f"G1 X{nx / u:.4f} Y{ny / u:.4f}" + (f" F{feed() / u:.1f}" if rng.random() < 0.3 else ""))
                x, y = nx, ny
                continue
            r = float(rng.uniform(0.5, 8))
            a0 = rng.uniform(0, 2 * np.pi)
            cx, cy = x - r * np.cos(a0), y - r * np.sin(a0)
            if kind == "circle":
                nx, ny = x, y
            else:
                a1 = a0 + rng.uniform(-np.pi * 0.95, np.pi * 0.95)
                nx, ny = cx + r * np.cos(a1), cy + r * np.sin(a1)
            if min(cx - r, cy - r) < 0.5 or max(cx + r, cy + r) > 29.5:
                continue
            g = rng.choice(["G2", "G3"])
            if kind == "arcr":  # the sign of R picks the short or the long arc
                cross = (x - cx) * (ny - cy) - (y - cy) * (nx - cx)
                short = (g == "G3") == (cross > 0)
                if np.hypot(nx - x, ny - y) < 0.01:
                    continue
                out.append(f"{g} X{nx / u:.4f} Y{ny / u:.4f} R{(r if short else -r) / u:.4f}")
            else:
                out.append(f"{g} X{nx / u:.4f} Y{ny / u:.4f} I{(cx - x) / u:.4f} J{(cy - y) / u:.4f}")
            x, y = nx, ny
        out.append(f"G0 Z{2 / u:.4f}")
        x, y = rng.uniform(2, 28, 2)
    out.append("M2")
    return "\n".join(out) + "\n"


def check(prog: str, feed: str) -> dict:
    """Plan ``prog`` with ``feed`` and check it (module docstring): ``{"code": "ok" | error code
    | "crash", "problems": [...], "cpu_s", "message"}``."""
    t = time.process_time()
    try:
        res = plan_contour({"program": prog, "origin": ORIGIN, "feed": feed})
    except PlannerError as err:
        return {"code": err.code, "problems": [], "cpu_s": time.process_time() - t, "message": str(err)}
    except Exception:
        return {"code": "crash", "problems": [traceback.format_exc()[-600:]], "cpu_s": time.process_time() - t,
                "message": ""}
    cpu = time.process_time() - t
    c, mt = res.contour, res.metrics
    assert c is not None
    probs = []
    if not np.all(np.isfinite(res.pose)):
        probs.append("NaN in the poses")
    path = rs274_cut_path(prog, ORIGIN)
    dev = chord_deviation(res, path, c.tolerance_m / 50)
    if dev > c.tolerance_m * (1 + 1e-7):
        probs.append(f"deviation {dev * 1e6:.2f} um > tolerance {c.tolerance_m * 1e6:.1f} um")
    # the other direction (issue 32): every point of the programmed path within P of the cut
    path_dev = max(s[1] for s in two_sided(res, prog, ORIGIN, c.tolerance_m / 500))
    if path_dev > c.tolerance_m:
        probs.append(f"path-to-cut {path_dev * 1e6:.2f} um > tolerance {c.tolerance_m * 1e6:.1f} um")
    if abs(c.max_path_deviation_m - path_dev) > c.tolerance_m / 200:
        probs.append(f"reported path-to-cut {c.max_path_deviation_m * 1e6:.2f} um vs measured {path_dev * 1e6:.2f} um")
    dev = max(dev, path_dev)
    if abs(c.max_deviation_m - dev) > c.tolerance_m / 20:
        probs.append(f"reported deviation {c.max_deviation_m * 1e6:.2f} um vs measured {dev * 1e6:.2f} um")
    if not (mt.within_limits and mt.max_force_ratio <= 1 + 1e-9):
        probs.append(f"drive limits: force ratio {mt.max_force_ratio:.4f}")
    if feed == "program":
        over = feed_excess(res, prog)
        if over > 1e-9:
            probs.append(f"programmed feed exceeded by {over * 1e3:.4f} mm/s")
    return {"code": "ok", "problems": probs, "cpu_s": cpu, "message": f"dev {dev * 1e6:.2f} um, T {res.time[-1]:.2f} s"}
