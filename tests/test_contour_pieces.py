"""``fastest``: a pass's pieces end where Z's slope changes sharply, each planned rest to rest
with its own timing (issue 35 goal 1, :func:`planner.contour.zaxis.slope_stops`); a piece's
search starts from the scale of a piece of the same shape only (:func:`planner.contour.search.piece_key`).

Properties, not outputs: a pass is no slower than its pieces planned apart (splitting into rest-to-rest
pieces is a restriction a good plan of the whole never needs); a ramp takes no less than its Z
axis allows it and not much more; a pass takes the same time after a pass of another shape as
alone (the timing of the pass before is no guess for it). The time against the exact path's
third-order optimum is measured by ``benchmarks/bench_contour_optimum.py``, not here."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.contour import plan_contour
from planner.contour.search import OPT_END_SAMPLES
from planner.contour.zaxis import FIRST_BUDGET, SLOPE_STOP_M_S, slope_stops
from planner.exchange import read_gcode

ORIGIN = [-0.004, -0.004]
HEAD = "G21 G90 G17\nG64 P0.02\nS5000 M3\n"
#: fusion360's first pass (tests/data/cam/fusion360.nc: a vertical lead-in arc read as a ramp of
#: slope 1, lines and an arc at Z -1, a ramp of slope 1 out), whole and in its three pieces
RAMP_IN = "G0 X-2 Y0 Z5\nG1 Z1 F333.3\nG1 X0 Z-1 F1000\n"
LEVEL = "G1 X8\nG3 X10 Y2 I0 J2\nG1 Y6\n"
RAMP_OUT = "G1 Y8 Z1\n"
WHOLE = HEAD + RAMP_IN + LEVEL + RAMP_OUT + "G0 Z5\nM2\n"
PIECES = [HEAD + RAMP_IN + "G0 Z5\nM2\n",
          HEAD + "G0 X0 Y0 Z5\nG1 Z-1 F333.3\nG1 X8 F1000\nG3 X10 Y2 I0 J2\nG1 Y6\nG0 Z5\nM2\n",
          HEAD + "G0 X10 Y6 Z5\nG1 Z-1 F333.3\nG1 Y8 Z1 F1000\nG0 Z5\nM2\n"]


def cut_time(text: str) -> float:
    res = plan_contour({"program": text, "origin": ORIGIN, "feed": "fastest"})
    assert res.contour is not None and res.metrics.within_limits
    assert res.contour.max_deviation_m <= res.contour.tolerance_m
    return float(res.contour.cut_time_s)


def test_pieces_end_where_z_lets_the_tool_pass_only_slowly():
    """A slope change the Z axis blends within the tolerance no faster than the threshold ends a
    piece (the blend's speed ``sqrt(8 a_z FIRST_BUDGET tol) / dg`` computed here: slope 1 at 0.02 mm
    and 1 m/s^2 is 4.9 mm/s); freecad's gentle helix into its circle (slope 0.042: 0.18 m/s) does
    not, nor does any slope change in ``program`` feed."""
    els = read_gcode(WHOLE).passes[0].elements
    g = [(e.z_end_m - e.z_start_m) / e.length_m for e in els]
    expect = [k for k in range(len(els) - 1)
              if g[k] != g[k + 1] and math.sqrt(8 * 1.0 * FIRST_BUDGET * 2e-5) / abs(g[k + 1] - g[k]) < SLOPE_STOP_M_S]
    assert expect == [0, len(els) - 2]  # the ramp's end, the ramp out's start
    assert slope_stops("fastest", els, 2e-5, 1.0) == expect
    assert slope_stops("program", els, 2e-5, 1.0) == []
    assert slope_stops("fastest", els, 2e-5, 1000.0) == []  # a Z axis that blends it fast: no stop
    from pathlib import Path

    helix = read_gcode((Path(__file__).parent / "data" / "cam" / "freecad_linuxcnc.ngc").read_text()).passes[1]
    assert helix.elements[0].z_end_m != helix.elements[0].z_start_m
    assert slope_stops("fastest", helix.elements, 5e-5, 1.0) == []


@pytest.mark.slow
def test_a_pass_with_ramps_is_no_slower_than_its_pieces_planned_apart():
    """fusion360's first pass (ramp in, lines and an arc, ramp out) cut ``fastest`` takes no
    longer than its three pieces cut as programs of their own (rest to rest each), one sample
    each aside; measured before the pieces: 0.711 s against about 0.41 s."""
    whole = cut_time(WHOLE)
    apart = [cut_time(t) for t in PIECES]
    Ts = plan_contour({"program": WHOLE, "origin": ORIGIN, "feed": "fastest"}).settings.Ts
    assert whole <= sum(apart) + 3 * Ts, (whole, apart)


def test_a_ramp_takes_what_its_z_axis_allows():
    """A ramp of slope 1 (2 mm down over 2 mm) from rest to rest within the Z axis (0.05 m/s,
    1 m/s^2): Z's own shortest move from rest to rest, ``2 sqrt(dz / a)`` (0.089 s; the speed
    is not reached), less the tolerance Z may cut at each end, is a lower bound; the plan takes at
    most 15 % more than that and the samples a plan from rest to rest adds (the start, the end
    point); measured before: 0.141 s (the time-optimal profile sped up beyond the Z axis, missed
    by Z, planned again slower)."""
    res = plan_contour({"program": PIECES[0], "origin": ORIGIN, "feed": "fastest"})
    c = res.contour
    assert c is not None and res.metrics.within_limits
    dz, a_z, tol = 0.002, 1.0, c.tolerance_m
    assert dz * a_z < 0.05 ** 2  # a triangle: the Z speed is not reached
    low = 2 * math.sqrt((dz - 2 * tol) / a_z)
    high = 1.15 * (2 * math.sqrt(dz / a_z) + OPT_END_SAMPLES * res.settings.Ts)
    assert low <= c.cut_time_s <= high, (low, c.cut_time_s, high)
    # Z within the axis: the samples' second differences (at rest before and after the cut)
    cut = np.asarray(c.cutting)
    assert c.z_m is not None
    z = np.asarray(c.z_m)[cut]
    Ts = res.settings.Ts
    assert np.abs(np.diff(np.r_[z[0], z, z[-1]], 2)).max() / Ts ** 2 <= a_z * (1 + 1e-3)


@pytest.mark.slow
def test_a_pass_after_one_of_another_shape_is_as_fast_as_alone():
    """fusion360's second pass (a line, a circle, a line at Z -0.8) planned after its first
    (ramps and other moves) takes the time it takes as a program of its own: the first's timing
    is not where its search starts (measured with the scale handed on: 0.261 s against 0.195 s)."""
    second = HEAD + "G0 X4 Y3 Z5\nG1 Z-0.8 F333.3\nG1 X6 F1000\nG2 X4 Y3 I-1 J0\nG61\nG1 Y5\nG64 P0.02\nG0 Z5\nM2\n"
    both = WHOLE.replace("G0 Z5\nM2\n", "G0 Z5\n") + second[len(HEAD):]
    res = plan_contour({"program": both, "origin": ORIGIN, "feed": "fastest"})
    assert res.contour is not None and len(res.contour.passes) == 2
    alone = plan_contour({"program": second, "origin": ORIGIN, "feed": "fastest"})
    assert alone.contour is not None
    assert res.contour.passes[1].time_s <= alone.contour.passes[0].time_s + res.settings.Ts
