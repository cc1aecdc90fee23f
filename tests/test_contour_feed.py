"""``program`` feed: F is the process limit (issue 35 goal 2).

On generated passes with a different F on every move: the tool never runs faster than the
programmed F of the move being cut (the samples, and the straight moves between samples as the
exported inverse-time program runs them, each against the smaller F of its two ends: F read
here from the G-code text, not from the planner's parser), and the result's
``max_feed_ratio`` says so; the cutting time is within the goal of an independent lower bound:
TOPP-RA (the ``toppra`` package, not the planner's own ``timing.py``) on the exact programmed
path under the drive forces and leg speeds, the tool speed capped at each move's F, stopping
at corners. That bound has no force-rate limit (second order); the goal is stated against the
third-order optimum, which lies above it (``benchmarks/bench_contour_optimum.py`` measures it):
here the plan must be at least 0.98x the bound (the tube may round what the exact path stops
at) and at most :data:`UPPER` times it. ``fastest`` reports how far it went over F.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from planner.contour import plan_contour
from planner.exchange import read_gcode
from planner.exchange.gcode import to_gcode
from planner.model import load_robot
from planner.model.dynamics import generalised_forces
from planner.schema import PathElement

#: the relative tolerance on "never faster than F" (float rounding of the plan's own samples)
F_TOL = 1e-6
#: the exported program (positions printed to 1e-4 mm, inverse-time F to its printed digits)
EXPORT_TOL = 5e-3
#: the plan's cutting time over the second-order F-capped bound: at least LOWER (the tube may
#: round a corner the exact path stops at), at most UPPER. The third-order optimum at F, whose
#: force-rate limit slows every start, stop and change of F, lies between; the goal is 1.02x
#: that, measured by benchmarks/bench_contour_optimum.py, not here: on these four programs the
#: plans measured 1.09-1.26x this bound (issue 35), so UPPER catches a regression to the pass
#: scaled by its slowest move (1.3-1.8x), not the goal itself
LOWER, UPPER = 0.98, 1.3
ORIGIN = [-0.015, -0.015]
FEEDS_MM_MIN = (300, 500, 800, 1200, 1800)


def mixed_feed_program(rng: np.random.Generator) -> str:
    """One pass of 4-7 moves (mm, G64 P0.02) from (15, 15): lines of 2-7 mm and arcs (radius
    4-8 mm, 30-150 degrees, G2/G3, tangent or not), corners of 30-170 degrees, each move with
    its own F from :data:`FEEDS_MM_MIN` on its line. The arcs are wide enough for one tube
    chord per sample at F (a chord of sagitta 0.18 P, docs/contouring.md "Sample time and
    speed": at Ts 10 ms and 1800 mm/min a radius of 3.1 mm)."""
    pos = np.array([15.0, 15.0])
    heading = rng.uniform(0, 2 * math.pi)
    out = ["G21 G90 G17", "G64 P0.02", f"G0 X{pos[0]:.4f} Y{pos[1]:.4f} Z2", "G1 Z-1 F300"]
    for k in range(int(rng.integers(4, 8))):
        f = int(rng.choice(FEEDS_MM_MIN))
        kind = rng.choice(["line", "line", "arc", "tangent"])
        if k > 0 and kind != "tangent":
            heading += (math.pi - math.radians(rng.uniform(30, 170))) * rng.choice([-1, 1])
        d = np.array([math.cos(heading), math.sin(heading)])
        if kind == "line":
            pos = pos + d * rng.uniform(2, 7)
            out.append(f"G1 X{pos[0]:.4f} Y{pos[1]:.4f} F{f}")
            continue
        r, sweep, ccw = rng.uniform(4, 8), math.radians(rng.uniform(30, 150)), bool(rng.random() < 0.5)
        c = pos + r * np.array([-d[1], d[0]]) * (1 if ccw else -1)
        a1 = math.atan2(pos[1] - c[1], pos[0] - c[0]) + (sweep if ccw else -sweep)
        end = c + r * np.array([math.cos(a1), math.sin(a1)])
        out.append(f"{'G3' if ccw else 'G2'} X{end[0]:.4f} Y{end[1]:.4f} I{c[0] - pos[0]:.4f} "
                   f"J{c[1] - pos[1]:.4f} F{f}")
        pos, heading = end, heading + (sweep if ccw else -sweep)
    return "\n".join(out + ["G0 Z2", "M2"]) + "\n"


def feed_by_line(program: str) -> dict[int, float]:
    """The modal F [m/s] in effect on each source line, read from the text (mm/min, G21)."""
    f, out = 0.0, {}
    for n, text in enumerate(program.splitlines(), start=1):
        m = re.search(r"F\s*([-+0-9.]+)", text.split("(")[0].upper())
        if m:
            f = float(m.group(1)) * 1e-3 / 60
        out[n] = f
    return out


def feed_ratio(result, program: str) -> float:
    """Largest tool speed / F while cutting: each cut sample's speed against its line's F, each
    straight move between two cut samples (length over its time) against the smaller F of the
    lines at its ends."""
    c = result.contour
    feed = feed_by_line(program)
    cut = np.asarray(c.cutting)
    F = np.array([feed[x] if x is not None else np.inf for x in c.program_line])
    speed = np.hypot(*result.velocity[:, :2].T)
    ratio = np.where(cut, speed / F, 0.0)
    chord = np.hypot(*np.diff(result.pose[:, :2], axis=0).T) / np.diff(result.time)
    both = cut[:-1] & cut[1:]
    ratio2 = np.where(both, chord / np.minimum(F[:-1], F[1:]), 0.0)
    return float(max(ratio.max(), ratio2.max()))


def toppra_at_feed(elements: list[PathElement], origin) -> float:
    """The exact path's second-order time optimum with the tool speed capped at each move's F:
    TOPP-RA (``toppra``) under the drive-force box (its generalised forces' zonotope facets) and
    the leg speeds, from rest to rest, stopping where the tangent jumps; a move's end point
    takes the smaller F of the two moves meeting there."""
    ta = pytest.importorskip("toppra")
    import toppra.algorithm as algo  # pyright: ignore[reportMissingImports]
    import toppra.constraint as constraint  # pyright: ignore[reportMissingImports]
    from toppra.interpolator import AbstractGeometricPath  # pyright: ignore[reportMissingImports]

    model = load_robot("moving-slide")
    umax = np.array(model.force_max, float) * np.ones(model.n_legs)
    org = np.asarray(origin, float)

    def tangent(e: PathElement, at_end: bool) -> np.ndarray:
        if e.kind == "line":
            return (e.end - e.start) / e.length_m
        a0, sweep = float(e.start_angle_rad or 0.0), float(e.sweep_rad or 0.0)
        a = a0 + (sweep if at_end else 0.0)
        return math.copysign(1.0, sweep) * np.array([-math.sin(a), math.cos(a)])

    pieces: list[list[PathElement]] = [[elements[0]]]
    for a, b in zip(elements, elements[1:]):
        if float(np.dot(tangent(a, True), tangent(b, False))) < 1 - 1e-9:
            pieces.append([])
        pieces[-1].append(b)

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
        def waypoints(self):  # pragma: no cover - not used by TOPP-RA
            return None

        def __call__(self, ss, order=0):
            ss = np.atleast_1d(np.asarray(ss, float))
            out = np.zeros((len(ss), 3))
            for k, s in enumerate(ss):
                i = int(np.clip(np.searchsorted(self.cum, s, side="right") - 1, 0, len(self.els) - 1))
                e, u = self.els[i], s - self.cum[i]
                if e.kind == "line":
                    d = (e.end - e.start) / e.length_m
                    val = [e.start + org + u * d, d, np.zeros(2)][order]
                else:
                    assert e.centre is not None and e.radius_m is not None
                    assert e.start_angle_rad is not None and e.sweep_rad is not None
                    sg = math.copysign(1.0, e.sweep_rad)
                    a = e.start_angle_rad + sg * u / e.radius_m
                    c, sn = math.cos(a), math.sin(a)
                    val = [e.centre + org + e.radius_m * np.array([c, sn]), sg * np.array([-sn, c]),
                           -np.array([c, sn]) / e.radius_m][order]
                out[k, :2] = val
            return out

    def facets(q):
        _, _, J = generalised_forces(model, q, np.zeros(3))
        A = J.T
        rows = [np.cross(A[:, i], A[:, j]) for i in range(A.shape[1]) for j in range(i + 1, A.shape[1])]
        F = np.array([r / np.linalg.norm(r) for r in rows if np.linalg.norm(r) > 1e-12])
        h = np.abs(F @ A) @ umax
        return np.vstack((F, -F)), np.concatenate((h, h))

    def inv_dyn(q, qd, qdd):
        M_r, h_r, _ = generalised_forces(model, q, qd)
        return M_r @ qdd - h_r

    class SpeedCap(constraint.LinearConstraint):
        """sdot^2 at most the leg speeds' bound and the move's F squared (the smaller of two
        moves at their common point)."""

        def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
            q, dq = path(gridpoints), path(gridpoints, 1)
            x_max = np.empty(len(gridpoints))
            for k, s in enumerate(gridpoints):
                _, _, J = generalised_forces(model, q[k], np.zeros(3))
                x_max[k] = float(np.min(model.speed_max / np.maximum(np.abs(J @ dq[k]), 1e-12))) ** 2
                i = int(np.clip(np.searchsorted(path.cum, s, side="right") - 1, 0, len(path.els) - 1))
                near = {i, max(i - 1, 0)} if abs(s - path.cum[i]) < 1e-12 else {i}
                x_max[k] = min(x_max[k], min(path.els[j].feed_m_s for j in near) ** 2)
            return None, None, None, None, None, None, np.column_stack((np.zeros(len(gridpoints)), x_max))

    total = 0.0
    for piece in pieces:
        path = Piecewise(piece)
        L = path.cum[-1]
        grid = np.unique(np.concatenate((np.linspace(0, L, max(60, int(L / 1e-4))), path.cum)))
        pc = constraint.SecondOrderConstraint(inv_dyn, lambda q: facets(q)[0], lambda q: facets(q)[1], dof=3,
                                              discretization_scheme=constraint.DiscretizationType.Interpolation)
        inst = algo.TOPPRA([pc, SpeedCap()], path, gridpoints=grid, parametrizer="ParametrizeConstAccel")
        traj = inst.compute_trajectory(0, 0)
        assert traj is not None, "TOPP-RA found no parametrisation"
        total += float(traj.duration)
    del ta
    return total


@pytest.fixture(scope="module", params=range(4))
def planned(request):
    prog = mixed_feed_program(np.random.default_rng(3500 + request.param))
    return prog, plan_contour({"program": prog, "origin": ORIGIN, "feed": "program"})


def test_program_feed_never_faster_than_the_move_s_F(planned):
    prog, res = planned
    ratio = feed_ratio(res, prog)
    assert ratio <= 1 + F_TOL
    # the result says the same (its own figure, within float rounding of the independent one)
    assert res.contour.max_feed_ratio == pytest.approx(ratio, rel=1e-6)
    assert all(p.max_feed_ratio is not None and p.max_feed_ratio <= 1 + F_TOL for p in res.contour.passes)
    # F is reached: the program has moves long enough to cruise at their F
    assert ratio >= 0.9


def test_exported_program_runs_no_move_faster_than_F(planned):
    """The exported inverse-time program read back: every XY move between cut samples runs at
    most the largest F of the program (its length over its G93 duration), to the printed
    precision; and moves on the slowest move's line at most that F."""
    prog, res = planned
    back = read_gcode(to_gcode(res, prog), readback=True)
    f_max = max(feed_by_line(prog)[n] for n in range(1, len(prog.splitlines()) + 1))
    speeds = [e.length_m / e.duration_s for b in back.blocks if b.kind == "cut" for e in b.elements
              if e.duration_s and e.length_m > 1e-7]
    assert speeds, "the exported program has no cutting move"
    assert max(speeds) <= f_max * (1 + EXPORT_TOL)


def test_program_feed_time_against_the_F_capped_optimum(planned):
    prog, res = planned
    program = read_gcode(prog)
    bound = sum(toppra_at_feed(b.elements, ORIGIN) for b in program.passes)
    nominal = sum(e.length_m / e.feed_m_s for b in program.passes for e in b.elements)
    assert bound >= nominal * (1 - 1e-3)  # the bound itself: never faster than F
    ratio = res.contour.cut_time_s / bound
    assert LOWER <= ratio <= UPPER, (ratio, res.contour.cut_time_s, bound)


def test_fastest_reports_how_far_over_F():
    """``fastest`` ignores F: the result says by how much it went over it (the independent
    figure), and it went over on this program of slow feeds."""
    prog = mixed_feed_program(np.random.default_rng(3500))
    res = plan_contour({"program": prog, "origin": ORIGIN, "feed": "fastest"})
    ratio = feed_ratio(res, prog)
    assert res.contour is not None and res.contour.max_feed_ratio == pytest.approx(ratio, rel=1e-6)
    assert ratio > 1.5
