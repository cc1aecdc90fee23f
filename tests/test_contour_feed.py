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


def _cut_feed(result, program: str) -> tuple[np.ndarray, np.ndarray]:
    """Per sample: cutting or not, and its line's F [m/s] (inf off the program's lines)."""
    c = result.contour
    feed = feed_by_line(program)
    return np.asarray(c.cutting), np.array([feed[x] if x is not None else np.inf for x in c.program_line])


def chord_feed_ratio(result, program: str) -> float:
    """Largest straight move between two cut samples (its length over its time, as the exported
    program runs it) over the smaller F of the lines at its ends."""
    cut, F = _cut_feed(result, program)
    chord = np.hypot(*np.diff(result.pose[:, :2], axis=0).T) / np.diff(result.time)
    both = cut[:-1] & cut[1:]
    return float(np.where(both, chord / np.minimum(F[:-1], F[1:]), 0.0).max(initial=0.0))


def feed_ratio(result, program: str) -> float:
    """Largest tool speed / F while cutting: each cut sample's speed against its line's F, and
    :func:`chord_feed_ratio`."""
    cut, F = _cut_feed(result, program)
    ratio = np.where(cut, np.hypot(*result.velocity[:, :2].T) / F, 0.0)
    return float(max(ratio.max(), chord_feed_ratio(result, program)))


def toppra_at_feed(elements: list[PathElement], origin) -> float:
    """The exact path's second-order time optimum with the tool speed capped at each move's F:
    TOPP-RA (``toppra``) under the drive-force box (its generalised forces' zonotope facets) and
    the leg speeds, from rest to rest, stopping where the tangent jumps; a move's end point
    takes the smaller F of the two moves meeting there (``benchmarks/bench_contour.py``'s
    ``topp_time``, the peer of the contour benchmark, on a 0.1 mm grid)."""
    pytest.importorskip("toppra")
    return _bench_contour().topp_time(elements, np.asarray(origin, float), leg_speed=True, feed=True, step=1e-4)


def _bench_contour():
    """benchmarks/bench_contour.py (benchmarks/ is no package: loaded by path, once)."""
    import importlib.util
    import sys
    from pathlib import Path

    if "bench_contour" not in sys.modules:
        spec = importlib.util.spec_from_file_location(
            "bench_contour", Path(__file__).resolve().parent.parent / "benchmarks" / "bench_contour.py")
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules["bench_contour"] = module
    return sys.modules["bench_contour"]


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
