"""The cost in cutting time of the Z axis acceleration (issue 32, goal 3) on the shipped
examples: each program planned at each Z acceleration given (``none``: the field omitted, as a
planner before it ran), its cut and cycle time, the ratio to the first column's, and the Z
speed and acceleration measured on the plan's samples while cutting (finite differences of
``contour.z_m``).

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/bench_contour_z.py --accel 100 1 0.5
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from planner.contour import plan_contour

ROOT = Path(__file__).resolve().parent.parent
PROGRAMS = {"contour-part": (ROOT / "app/static/examples/contour-part.ngc", [-0.01, -0.01]),
            **{p.stem: (p, [-0.005, -0.004]) for p in sorted((ROOT / "tests/data/cam").glob("*.n*c"))}}


def measure(text: str, origin: list[float], feed: str, accel: str) -> tuple[float, float, float, float, float]:
    req = {"program": text, "origin": origin, "feed": feed}
    if accel != "none":
        req["z_accel_m_s2"] = float(accel)
    t0 = time.process_time()
    res = plan_contour(req)
    cpu = time.process_time() - t0
    c = res.contour
    assert c is not None
    ts = float(res.settings.Ts)
    z, cut = np.asarray(c.z_m), np.asarray(c.cutting)
    vz = az = 0.0
    for a, b in runs(cut):  # within each run of cutting samples
        zz = z[a:b]
        if len(zz) > 1:
            vz = max(vz, float(np.abs(np.diff(zz)).max()) / ts)
        if len(zz) > 2:
            az = max(az, float(np.abs(np.diff(zz, 2)).max()) / ts ** 2)
    return c.cut_time_s, c.cycle_time_s, vz, az, cpu


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
    return list(zip(edges[::2], edges[1::2]))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--accel", nargs="+", default=["100", "1"], help="Z accelerations [m/s^2] or 'none'")
    ap.add_argument("--feed", nargs="+", default=["program", "fastest"])
    args = ap.parse_args()
    print("| program | feed | z_accel m/s^2 | cut s | cycle s | cut / first | max Z speed m/s | max Z accel m/s^2 "
          "| CPU s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, (path, origin) in PROGRAMS.items():
        text = path.read_text()
        for feed in args.feed:
            first = None
            for accel in args.accel:
                cut, cycle, vz, az, cpu = measure(text, origin, feed, accel)
                first = first or cut
                print(f"| {name} | {feed} | {accel} | {cut:.3f} | {cycle:.3f} | {cut / first:.3f} | {vz:.4f} | "
                      f"{az:.3f} | {cpu:.1f} |", flush=True)


if __name__ == "__main__":
    main()
