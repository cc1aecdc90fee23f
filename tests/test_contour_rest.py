"""``program`` feed on circles (issue 35 goal 2, branch feedcap6): the tool-speed rows hold a
circle's catch-ups at F, and the time-optimal profile's steps from and to rest are timed as
drives whose acceleration rises at a bounded jerk take them.

The constrained mode's criterion brakes onto a piece's end gently and, without a speed limit,
made up for it by running ahead over F (dxf2gcode's circle: 1.03 F for 25 samples); the
samples the search added for it let it brake more gently still. Under the tool-speed rows (a
32-gon, 0.5 % below the limit at worst) it cannot run ahead, and a circle keeps its first
candidate's sample counts.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import planner.contour.search as search
from planner.contour import plan_contour
from planner.contour.profiles import Optimal, rest_ends
from tests.test_contour_feed import F_TOL, chord_feed_ratio

CAM = Path(__file__).resolve().parent / "data" / "cam"


def _s_curve_time(h: float, v: float, j: float, dt: float = 1e-7) -> float:
    """The time a start from rest takes to cover ``h`` when its acceleration rises at ``j``
    to its peak and falls at ``j`` to zero at the speed ``v``, then cruises at ``v``: integrated
    in small steps (independent of the closed form under test)."""
    t1 = math.sqrt(v / j)  # the jerk phase's length each way
    t = x = s_dot = a = 0.0
    while x < h:
        jerk = j if t < t1 else (-j if t < 2 * t1 else 0.0)
        if t >= 2 * t1:
            a, s_dot = 0.0, v
        x += s_dot * dt + 0.5 * a * dt * dt
        s_dot += a * dt
        a += jerk * dt
        t += dt
    return t


def _profile(h: float, v: float, n: int) -> tuple[Optimal, np.ndarray]:
    """A grid profile from rest to rest on ``n`` steps of ``h`` at the speed ``v`` (its first and
    last step at a constant acceleration, ``2 h / v``, the others ``h / v``), segment ends every
    half step."""
    grid_t = np.concatenate(([0.0], 2 * h / v + h / v * np.arange(n - 1), [0.0]))
    grid_t[-1] = grid_t[-2] + 2 * h / v
    grid_s = h * np.arange(n + 1)
    s_end = np.linspace(0.0, grid_s[-1], 2 * n + 1)[1:]
    times = np.interp(s_end, grid_s, grid_t)
    return Optimal(times, v, (h, 2 * h / v, h, 2 * h / v), s_end), s_end


@pytest.mark.parametrize("h_samples", [0.94, 1.7])
def test_rest_ends_times_the_first_and_last_step_as_a_jerk_limited_start_and_stop(h_samples):
    """The first step ends when a start at the jerk bound covers it (an S-curve integrated
    apart), every later time comes earlier by the same, the last step's end by twice that; the
    times never fall and never go below zero; without a jerk bound they are the profile's."""
    Ts, v, j = 0.01, 400 / 6e4, 320.0  # dxf2gcode's circle: F400, Ts 10 ms, the moving-slide's jerk
    h = h_samples * v * Ts
    opt, s_end = _profile(h, v, 40)
    got = rest_ends(opt, j)
    first = int(np.argmin(abs(s_end - h)))
    assert got[first] == pytest.approx(_s_curve_time(h, v, j), rel=1e-4)
    gain = opt.times[first] - got[first]
    assert gain > 0.1 * Ts  # a tenth of a sample or more at these grid steps
    mid = (s_end > h) & (s_end < s_end[-1] - h)
    assert np.allclose(opt.times[mid] - got[mid], gain, rtol=0, atol=1e-12)
    assert opt.times[-1] - got[-1] == pytest.approx(2 * gain, rel=1e-9)
    assert np.all(np.diff(got) >= 0) and got.min() >= 0
    assert rest_ends(opt, None) is opt.times


def test_rest_ends_keeps_a_step_the_drives_cannot_beat():
    """A step so short that the drives at the jerk bound take longer than the profile's constant
    acceleration (``(6 h / j)^(1/3)`` against ``2 h / v``): the times unchanged."""
    v, j = 0.02, 320.0
    h = 1e-6  # 1 um: the drives need (6 h / j)^(1/3) = 2.7 ms, the profile 0.1 ms
    opt, _ = _profile(h, v, 10)
    assert np.array_equal(rest_ends(opt, j), opt.times)


def test_the_program_feed_rows_room_puts_the_polygon_sides_on_F():
    """The program feed's rows are at ``1 / cos(pi / sides)`` F for the constraint's own polygon:
    a speed along a side's normal is held at F exactly, none in any direction over the room."""
    from planner.constraints.motion import TOOL_SPEED_SIDES, ToolSpeedConstraint

    assert search.FEED_ROWS_SIDES == TOOL_SPEED_SIDES
    from planner.constraints.drives import SPEED_MARGIN
    from planner.constraints.rows import RELAX_M

    F = 0.01  # m/s
    rows = ToolSpeedConstraint(F * search.FEED_SPEED_ROOM)
    side = F * (1.0 - SPEED_MARGIN) - RELAX_M  # the margins below F: relative, and a relaxed step's widening
    assert rows.limit == pytest.approx(side, rel=1e-12)
    # the polygon's boundary in every direction: between F (the sides' middles) and the room (vertices)
    ang = np.linspace(0.0, 2 * np.pi, 3601)
    d = np.column_stack((np.cos(ang), np.sin(ang)))
    reach = rows.limit / np.abs(d @ rows.normals.T).max(axis=1)
    assert reach.min() == pytest.approx(side, rel=1e-9)
    assert reach.max() <= F * search.FEED_SPEED_ROOM * (1 + 1e-12)
    # a relaxed step (the rows widened by RELAX_M) keeps a limit of F in every direction but the vertices'
    assert (rows.limit + RELAX_M) <= F


@pytest.fixture(scope="module")
def circles():
    """dxf2gcode (one circle, F400) and pcb_gcode (its pass 1 a circle of r 1 mm as two
    semicircles, F508) in the ``program`` feed at the defaults, every candidate recorded:
    (piece, rows' limit, counts, plan or None, largest excess over F)."""
    seen: list[tuple[str, str, float | None, tuple, object, float]] = []
    attempt = search.TimingSearch.attempt
    current = [""]

    def recorded(self, t, counts):
        res = attempt(self, t, counts)
        over = np.nan
        if res is not None:
            over = float(search.overspeed_of(res, counts, np.minimum(self.feed_on(t), self.zcap_on(t))).max())
        seen.append((current[0], self.name, self.plan_st.tool_speed_max_m_s, tuple(counts.tolist()), res, over))
        return res

    mp = pytest.MonkeyPatch()
    mp.setattr(search.TimingSearch, "attempt", recorded)
    out = {}
    try:
        for name in ("dxf2gcode.ngc", "pcb_gcode.ngc"):
            current[0] = name
            text = (CAM / name).read_text()
            out[name] = (text, plan_contour({"program": text, "origin": "fit", "feed": "program"}))
    finally:
        mp.undo()
    return out, seen


def test_a_circle_within_2_percent_of_its_length_over_F_and_never_over_F(circles):
    """dxf2gcode's circle at the defaults: within 1.02 L / F (so within 1.02x the F-capped
    optimum, which is no shorter than L / F; main took 1.032 L / F), no sample nor exported
    move faster than F, the drive forces and force rates within their limits, the cut within
    the tolerance."""
    out, _ = circles
    text, res = out["dxf2gcode.ngc"]
    c = res.contour
    assert c is not None and len(c.passes) == 1
    p = c.passes[0]
    assert p.time_s <= 1.02 * p.length_m / p.max_programmed_feed_m_s
    assert p.max_feed_ratio <= 1.0
    assert chord_feed_ratio(res, text) <= 1 + F_TOL
    m = res.metrics
    assert m.max_force_ratio <= 1.0 + 1e-9
    assert m.max_force_rate_n_s <= 3000.0 * (1 + 1e-6)  # the default rise: 150 N in 50 ms
    assert p.max_deviation_m <= c.tolerance_m


def test_a_circle_keeps_its_first_candidate_under_the_rows(circles):
    """Both circles are planned under the tool-speed rows, and the plan kept has the first
    candidate's sample counts (no samples added for a catch-up over F; before, pcb_gcode's pass 1
    took 4 more, 0.84 s against 0.80); the kept plan's samples are within F."""
    out, seen = circles
    for name, line in (("dxf2gcode.ngc", None), ("pcb_gcode.ngc", 1)):
        _, res = out[name]
        c = res.contour
        assert c is not None
        piece_name = f"line {c.passes[-1].first_line}" if line is not None else f"line {c.passes[0].first_line}"
        piece = [s for s in seen if s[0] == name and s[1] == piece_name]
        assert piece, (name, piece_name)
        first = piece[0]
        assert first[2] is not None  # under the rows
        kept = [s for s in piece if s[4] is not None and s[5] <= 1.0]
        assert kept and kept[0][3] == first[3], name
        # the planner's own check (samples and the straight moves between them against F; the
        # tests' G-code reader of chord_feed_ratio reads millimetres, pcb_gcode is in inches)
        assert max(p.max_feed_ratio for p in c.passes) <= 1.0
