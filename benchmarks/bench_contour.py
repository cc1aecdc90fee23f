"""Contouring (issue 22): deviation, cycle time against the exact-path time optimum (TOPP-RA),
planning cost of a 15-pass program and cost against program length.

    .venv/bin/python benchmarks/bench_contour.py [--quick] [--fine-ts 0.002] [--finest-ts 0.001]

Program: a notched rounded rectangle (26 x 15 mm, 3 mm corner arcs, a 10 mm semicircular notch),
cut in 15 depth passes of 0.5 mm at F1200, G64 P0.02 (0.02 mm): 180 lines and arcs, 1358 mm of
cut. Tables:

1. per feed (``program`` at Ts = 0.01 s, ``fastest`` at 0.01 s and at the finer ``--fine-ts``,
   and at ``--finest-ts`` with TOPP-RA's limits: no force-rate limit):
   planning CPU time and wall time, peak memory (RSS of this process), the largest deviation
   of a sample or a chord from the programmed path (the planner's figure, checked against
   shapely on the same path in tests/test_contour.py), the cut time and the whole cycle time;
   then each ``fastest`` cycle against the exact path's (every pass at TOPP-RA's time, the
   plunges, retracts and rapids as planned);
2. one pass's time from rest to rest: the exact path's time optimum under the same drive-force
   limits (TOPP-RA 0.6: the redundant drives' force box mapped through the leg Jacobian is a
   zonotope of generalised forces, whose 12 facet inequalities are the second-order
   constraint; the exact path stops at its two 90-degree corners; viscous friction enters
   TOPP-RA's b(s) term; no force-rate limit: TOPP-RA's constraints are of second order), the
   same with the legs' speed limit, the planner's own exact-path optimum
   (:mod:`planner.contour.timing`, the same limits), and with the chord bound of an output sampled every Ts
   (a controller interpolating linearly between samples runs chords of ``v Ts``, whose
   sagitta on an arc of radius R must stay within the tolerance: ``v <= sqrt(8 R tol) / Ts``);
   ``fastest`` at each Ts, with the default force-rate limit and without it (TOPP-RA's
   limits); the programmed feed's nominal time L / F and the ``program`` plan's;
3. CPU time against program length (1, 2, 4, 8 passes).
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np

from planner.contour import plan_contour
from planner.contour.timing import time_optimal
from planner.exchange import read_gcode
from planner.model import load_robot
from planner.model.dynamics import generalised_forces
from planner.schema import PathElement

ORIGIN = [-0.013, -0.0075]
TOL = 2e-5


def program(passes: int = 15, step: float = 0.5, feed: float = 1200.0, tol_mm: float = 0.02) -> str:
    """The benchmark part (module docstring) in ``passes`` depth passes."""
    w, h, r = 26.0, 15.0, 3.0
    out = ["(benchmark part: a notched rounded rectangle in depth passes)", "G21 G90 G17", f"G64 P{tol_mm}",
           "T1 M6", "S18000 M3", "G0 Z3"]
    for i in range(passes):
        z = -(i + 1) * step
        out += [f"G0 X{r:.4f} Y0", f"G1 Z{z:.3f} F300", f"F{feed:g}",
                f"G1 X{w - r:.4f}", f"G3 X{w:.4f} Y{r:.4f} I0 J{r:.4f}", f"G1 Y{h - r:.4f}",
                f"G3 X{w - r:.4f} Y{h:.4f} I{-r:.4f} J0",
                f"G1 X{w / 2 + 5:.4f}", f"G1 Y{h - 4:.4f}", f"G2 X{w / 2 - 5:.4f} Y{h - 4:.4f} R5", f"G1 Y{h:.4f}",
                f"G1 X{r:.4f}", f"G3 X0 Y{h - r:.4f} I0 J{-r:.4f}", "G1 Y3", f"G3 X{r:.4f} Y0 I{r:.4f} J0", "G0 Z3"]
    out += ["M5", "M2"]
    return "\n".join(out) + "\n"


def run(text: str, feed: str, settings: dict | None = None) -> tuple[object, float, float]:
    c0, w0 = time.process_time(), time.perf_counter()
    res = plan_contour({"program": text, "origin": ORIGIN, "feed": feed, "tolerance_m": TOL,
                        "settings": settings or {}})
    return res, time.process_time() - c0, time.perf_counter() - w0


# ------------------------------------------------------------------ TOPP-RA on the exact path
def _smooth_pieces(elements: list[PathElement]) -> list[list[PathElement]]:
    """Split a pass where the tangent jumps (the exact path must stop there)."""
    def tangent(e: PathElement, at_end: bool) -> np.ndarray:
        if e.kind == "line":
            d = e.end - e.start
            return d / np.hypot(*d)
        assert e.start_angle_rad is not None and e.sweep_rad is not None
        a = e.start_angle_rad + (e.sweep_rad if at_end else 0.0)
        s = math.copysign(1.0, e.sweep_rad)
        return s * np.array([-math.sin(a), math.cos(a)])

    out = [[elements[0]]]
    for prev, e in zip(elements, elements[1:]):
        if float(tangent(prev, True) @ tangent(e, False)) < 1 - 1e-9:
            out.append([])
        out[-1].append(e)
    return out


def topp_time(elements: list[PathElement], origin: np.ndarray, leg_speed: bool = False, Ts: float | None = None,
              tol: float = TOL, feed: bool = False, step: float = 2e-4) -> float:
    """Time-optimal traversal of the exact path (rest at both ends and at every corner) under
    the drive-force box, by TOPP-RA. ``leg_speed``: the legs' speed limit too (``|J_l q'(s)| sdot
    <= speed_max``, a bound on ``sdot^2``); ``Ts``: the output's chord bound too: a controller
    that interpolates linearly between samples ``Ts`` apart runs a chord of length ``sdot Ts``
    whose sagitta on an arc of radius R, ``(sdot Ts)^2 / (8 R)``, must stay within the tolerance:
    ``sdot <= sqrt(8 R tol) / Ts`` (a bound for an exact tracker; any tracking error takes from it);
    ``feed``: the tool speed capped at each move's F (a move's end point takes the smaller F of
    the two moves meeting there). Grid points ``step`` [m] apart (at least 60 a piece)."""
    import toppra as ta
    import toppra.algorithm as algo
    import toppra.constraint as constraint
    from toppra.interpolator import AbstractGeometricPath

    model = load_robot("moving-slide")
    umax = np.array(model.force_max, float) * np.ones(model.n_legs)

    class Piecewise(AbstractGeometricPath):
        def __init__(self, els: list[PathElement]):
            self.els = els
            self.cum = np.concatenate(([0.0], np.cumsum([e.length_m for e in els])))

        @property
        def dof(self) -> int:
            return 3

        @property
        def path_interval(self) -> np.ndarray:
            return np.array([0.0, self.cum[-1]])

        @property
        def waypoints(self):  # pragma: no cover - not used by TOPPRA
            return None

        def __call__(self, ss, order=0):
            ss = np.atleast_1d(np.asarray(ss, float))
            out = np.zeros((len(ss), 3))
            for k, s in enumerate(ss):
                i = int(np.clip(np.searchsorted(self.cum, s, side="right") - 1, 0, len(self.els) - 1))
                e, u = self.els[i], s - self.cum[i]
                if e.kind == "line":
                    d = (e.end - e.start) / e.length_m
                    val = [e.start + origin + u * d, d, np.zeros(2)][order]
                else:
                    assert e.centre is not None and e.radius_m is not None and e.start_angle_rad is not None
                    assert e.sweep_rad is not None
                    sg = math.copysign(1.0, e.sweep_rad)
                    a = e.start_angle_rad + sg * u / e.radius_m
                    c, sn = math.cos(a), math.sin(a)
                    val = [e.centre + origin + e.radius_m * np.array([c, sn]), sg * np.array([-sn, c]),
                           -np.array([c, sn]) / e.radius_m][order]
                out[k, :2] = val
            return out

    def inv_dyn(q, qd, qdd):
        M_r, h_r, _ = generalised_forces(model, q, qd)
        return M_r @ qdd - h_r

    def facets(q):
        _, _, J = generalised_forces(model, q, np.zeros(3))
        A = J.T  # generalised forces of the drive forces: tau = J^T u, u in the box
        rows = []
        n = A.shape[1]
        for i in range(n):
            for j in range(i + 1, n):
                nv = np.cross(A[:, i], A[:, j])
                if np.linalg.norm(nv) > 1e-12:
                    rows.append(nv / np.linalg.norm(nv))
        F = np.array(rows)
        h = np.abs(F @ A) @ umax
        return np.vstack((F, -F)), np.concatenate((h, h))

    def cF(q):
        return facets(q)[0]

    def cg(q):
        return facets(q)[1]

    class PathSpeed(constraint.LinearConstraint):
        """An upper bound on sdot^2 along the path (leg speeds, the chord bound)."""

        def __init__(self, els: list[PathElement]):
            super().__init__()
            self.els = els

        def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
            x_max = np.full(len(gridpoints), np.inf)
            if leg_speed:
                q, dq = path(gridpoints), path(gridpoints, 1)
                for k in range(len(gridpoints)):
                    _, _, J = generalised_forces(model, q[k], np.zeros(3))
                    x_max[k] = float(np.min(model.speed_max / np.maximum(np.abs(J @ dq[k]), 1e-12))) ** 2
            if Ts is not None or feed:
                for k, s in enumerate(gridpoints):
                    i = int(np.clip(np.searchsorted(path.cum, s, side="right") - 1, 0, len(self.els) - 1))
                    for e in {i, max(i - 1, 0)} if abs(s - path.cum[i]) < 1e-12 else {i}:
                        if feed:
                            x_max[k] = min(x_max[k], self.els[e].feed_m_s ** 2)
                        if Ts is not None and self.els[e].kind == "arc":
                            assert self.els[e].radius_m is not None
                            x_max[k] = min(x_max[k], 8 * self.els[e].radius_m * tol / Ts ** 2)
            xbound = np.column_stack((np.zeros(len(gridpoints)), x_max))
            return None, None, None, None, None, None, xbound

    total = 0.0
    for piece in _smooth_pieces(elements):
        path = Piecewise(piece)
        L = path.cum[-1]
        grid = np.unique(np.concatenate((np.linspace(0, L, max(60, int(L / step))), path.cum)))
        pc = constraint.SecondOrderConstraint(inv_dyn, cF, cg, dof=3,
                                              discretization_scheme=constraint.DiscretizationType.Interpolation)
        cons = [pc] + ([PathSpeed(piece)] if leg_speed or Ts is not None or feed else [])
        inst = algo.TOPPRA(cons, path, gridpoints=grid, parametrizer="ParametrizeConstAccel")
        traj = inst.compute_trajectory(0, 0)
        assert traj is not None, "TOPP-RA found no parametrisation"
        total += float(traj.duration)
    del ta
    return total


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="1x and 2x only in the length table")
    ap.add_argument("--fine-ts", type=float, default=0.002,
                    help="the finer output sample time the tables compare with the default 0.01 s")
    ap.add_argument("--finest-ts", type=float, default=0.001,
                    help="the sample time of the run with TOPP-RA's limits (no force-rate limit)")
    args = ap.parse_args()
    print(f"load: {os.getloadavg()[0]:.1f} (1-min average) on {os.cpu_count()} cores")
    text = program()
    prog = read_gcode(text)
    n_el = sum(len(b.elements) for b in prog.passes)
    L = sum(e.length_m for b in prog.passes for e in b.elements)
    print(f"program: {len(prog.passes)} passes, {n_el} lines and arcs, {L * 1e3:.0f} mm of cut, tolerance "
          f"{TOL * 1e3:g} mm\n")
    plan_contour({"program": program(1), "origin": ORIGIN, "tolerance_m": TOL})  # load the kernels
    results = {}
    print("| feed | Ts s | CPU s | wall s | peak RSS MB | max deviation mm | within tolerance | cut time s | cycle s |")
    print("|---|---|---|---|---|---|---|---|---|")
    p0 = prog.passes[0].elements
    origin = np.array(ORIGIN)
    topp = topp_time(p0, origin)
    t_leg = topp_time(p0, origin, leg_speed=True)
    runs = [("program", 0.01, None), ("fastest", 0.01, None), ("fastest", args.fine_ts, None),
            ("fastest", args.finest_ts, "off")]
    for feed, Ts, rate in runs:
        res, cpu, wall = run(text, feed, {"Ts": Ts} | ({} if rate is None else {"force_rate_n_s": rate}))
        c = res.contour  # type: ignore[attr-defined]
        results[feed, Ts] = res
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        label = feed if rate is None else f"{feed}, force rates {rate}"
        print(f"| {label} | {Ts:g} | {cpu:.1f} | {wall:.1f} | {rss:.0f} | {c.max_deviation_m * 1e3:.4f} | "
              f"{c.max_deviation_m <= c.tolerance_m} | {c.cut_time_s:.2f} | {c.cycle_time_s:.2f} |")
    # the whole cycle against the exact path's: every cut pass at TOPP-RA's time (the passes are
    # alike), the rest of the cycle (plunges, retracts, rapids) as planned
    print("\nthe cycle against the exact path's (every pass at TOPP-RA's time, the plunges, retracts and "
          "rapids as planned):\n")
    print("| feed | Ts s | force rates | cycle s | exact-path cycle s, drive forces | ratio | "
          "exact-path cycle s, drive forces and leg speeds | ratio |")
    print("|---|---|---|---|---|---|---|---|")
    for feed, Ts, rate in runs[1:]:
        c = results[feed, Ts].contour  # type: ignore[attr-defined]
        rest = c.cycle_time_s - sum(p.time_s for p in c.passes)
        exact, exact_leg = rest + topp * len(c.passes), rest + t_leg * len(c.passes)
        print(f"| {feed} | {Ts:g} | {rate or 'default'} | {c.cycle_time_s:.2f} | {exact:.2f} | "
              f"{c.cycle_time_s / exact:.4f}x | {exact_leg:.2f} | {c.cycle_time_s / exact_leg:.4f}x |")
    one = program(1)
    nominal = sum(e.length_m / e.feed_m_s for e in p0)
    print(f"\none pass ({sum(e.length_m for e in p0) * 1e3:.1f} mm), from rest to rest; 'vs same Ts': against "
          "TOPP-RA with the leg speeds and the chord bound at that output sample time:\n")
    print("| | Ts s | time s | vs TOPP-RA | vs TOPP-RA + leg speeds | vs same Ts |")
    print("|---|---|---|---|---|---|")
    print(f"| TOPP-RA 0.6, exact path, drive-force zonotope | - | {topp:.4f} | 1.00x | | |")
    print(f"| TOPP-RA + leg speeds | - | {t_leg:.4f} | {t_leg / topp:.4f}x | 1.00x | |")
    model = load_robot("moving-slide")
    _, _, T_own = time_optimal(model, p0, origin, 0.0, 1e-4, lambda p, a: np.where(p.corner > 0, 0.0, np.inf))
    print(f"| planner.contour.timing, drive forces and leg speeds, 0.1 mm grid | - | {T_own[-1]:.4f} | "
          f"{T_own[-1] / topp:.4f}x | {T_own[-1] / t_leg:.4f}x | |")
    for Ts in (0.01, 0.005, args.fine_ts, args.finest_ts):
        bound = topp_time(p0, origin, leg_speed=True, Ts=Ts)
        print(f"| TOPP-RA + leg speeds + chord bound (sagitta <= tolerance) | {Ts:g} | {bound:.4f} | "
              f"{bound / topp:.2f}x | {bound / t_leg:.2f}x | 1.00x |")
        for rate, label in ((None, "fastest (tube, drive forces, force rates 3000 N/s, leg speeds)"),
                            ("off", "fastest, force rates off (TOPP-RA's limits)")):
            st: dict = {"Ts": Ts} if rate is None else {"Ts": Ts, "force_rate_n_s": rate}
            res, cpu, _ = run(one, "fastest", st)
            t = res.contour.passes[0].time_s  # type: ignore[attr-defined]
            print(f"| {label} | {Ts:g} | {t:.4f} | {t / topp:.4f}x | {t / t_leg:.4f}x | {t / bound:.2f}x |")
    progp = results["program", 0.01].contour.passes[0].time_s  # type: ignore[attr-defined]
    print(f"| programmed feed L / F | - | {nominal:.3f} | {nominal / topp:.2f}x | | |")
    print(f"| program feed plan | 0.01 | {progp:.3f} | {progp / topp:.2f}x | | |")
    print("\ncost against program length (feed program):\n")
    print("| passes | cut mm | samples | CPU s | CPU ms per sample | CPU s / pass |")
    print("|---|---|---|---|---|---|")
    for k in ((1, 2) if args.quick else (1, 2, 4, 8)):
        res, cpu, _ = run(program(k), "program")
        n = len(res.time)  # type: ignore[attr-defined]
        cut = sum(p.length_m for p in res.contour.passes)  # type: ignore[attr-defined]
        print(f"| {k} | {cut * 1e3:.0f} | {n} | {cpu:.2f} | {cpu / n * 1e3:.3f} | {cpu / k:.2f} |")


if __name__ == "__main__":
    main()
