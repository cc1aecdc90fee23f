"""The Z of a cut within the Z axis speed and acceleration (issue 32, goal 3), piece by piece:
:func:`planner.contour.zaxis.plan_z` on programmed Z sequences whose slope changes, checked by
finite differences; plunges and retracts from rest to rest (:func:`accel_dwell`); the request's
field refused where it is not a positive acceleration."""

from __future__ import annotations

import numpy as np
import pytest

from planner.contour import plan_contour
from planner.contour.zaxis import accel_dwell, plan_z
from planner.errors import PlannerError
from planner.exchange import read_gcode


def ramp_then_level(v_xy: float, g: float, ts: float, n: int = 300) -> np.ndarray:
    """The programmed Z of samples running along a ramp of slope ``g`` from rest (the XY speed
    rising at 0.4 m/s^2 to ``v_xy`` [m/s]: Z's acceleration ``0.4 g`` within the axis's) that
    levels off at the middle sample (Z's velocity jumps from ``g v_xy`` to 0 there)."""
    t = ts * np.arange(n)
    s = np.concatenate(([0.0], np.cumsum(np.minimum(v_xy, 0.4 * t[1:]) * ts)))[:n]
    return -g * np.minimum(s, s[n // 2])


@pytest.mark.parametrize("v_xy", [0.002, 0.005, 0.02])
def test_plan_z_holds_the_axis_limits_and_says_where_the_tolerance_cannot_hold(v_xy):
    """Whatever the XY speed, the planned Z's steps and second differences (at rest before and
    after) are within the axis speed and acceleration; where a blend within the budget exists
    (a velocity jump dv with dv^2 / (8 a) inside it) the plan holds it at every sample, and
    where it does not, the samples it misses are about the slope change, none far from it."""
    ts, a, v, tol, g = 0.01, 1.0, 0.05, 2e-5, 1.0
    zp = ramp_then_level(v_xy, g, ts)
    got = plan_z(zp, np.full(len(zp), tol), ts, v, a)
    z = got.z
    steps = np.abs(np.diff(z))
    second = np.abs(np.diff(np.r_[z[0], z, z[-1]], 2))
    assert steps.max() <= v * ts * (1 + 1e-6)
    assert second.max() <= a * ts * ts * (1 + 1e-5)
    dv = g * v_xy
    blend_needs = dv * dv / (8 * a)
    if blend_needs < 0.5 * tol:
        assert got.ok
        assert np.abs(z - zp).max() <= tol * (1 + 1e-6)
        assert z[0] == pytest.approx(zp[0], abs=1e-12) and z[-1] == pytest.approx(zp[-1], abs=1e-12)
    elif blend_needs > 2 * tol:
        assert not got.ok
        where = np.flatnonzero(got.miss > 0)
        assert np.all(np.abs(where - len(zp) // 2) < 40), where


def _joined_second_differences(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Two pieces' Z joined as the contour's join does (the second piece's first sample is the
    first piece's last, and dropped), at rest before and after: its second differences [m]."""
    z = np.r_[first, second[1:]]
    return np.abs(np.diff(np.r_[z[0], z, z[-1]], 2))


def test_z_accelerates_within_the_axis_across_two_pieces():
    """A ramp piece whose last sample rests 3.6 um from the level piece's programmed Z, still
    moving down where the level piece's Z is above (the two project onto different moves at the
    slope change, as in a generated ramp, tab and helix at Ts 3.5 ms, `fastest`):
    the level piece planned from the ramp's last two samples (``before``) keeps the joined Z's
    second differences within ``a Ts^2``; planned on its own from rest at its programmed Z, the
    join accelerates beyond the axis (the defect this guards against)."""
    ts, a, v, tol = 0.0035, 0.5, 0.05, 5e-5
    n = 40
    ramp = np.linspace(-1.0e-3, -1.4964e-3, n)
    level = np.full(n, -1.4928e-3)
    first = plan_z(ramp, np.full(n, tol), ts, v, a)
    assert first.ok
    level_from = level.copy()
    level_from[0] = first.z[-1]
    joined = plan_z(level_from, np.full(n, tol), ts, v, a, before=float(first.z[-2]))
    assert joined.ok
    assert _joined_second_differences(first.z, joined.z).max() <= a * ts * ts * (1 + 1e-6)
    apart = plan_z(level_from, np.full(n, tol), ts, v, a)  # from rest at the shared sample only
    assert _joined_second_differences(first.z, apart.z).max() > a * ts * ts * 1.05
    assert np.abs(joined.z - level).max() <= tol


def test_plan_z_keeps_a_level_z():
    zp = np.full(50, -0.001)
    got = plan_z(zp, np.full(50, 1e-5), 0.01, 0.05, 1.0)
    assert got.ok and np.array_equal(got.z, zp)


def test_plunges_and_retracts_start_and_stop_within_the_z_acceleration():
    """A plunge at F300 and a rapid retract at 0.05 m/s: Z from its start to its end, at most at
    each move's speed, its acceleration (second differences of its samples) within the axis's,
    longer by about v / a each."""
    p = read_gcode("G21 G90\nG0 Z5\nG1 Z-1 F300\nG1 X10 F600\nG0 Z5\nM2\n")
    dwells = [b for b in p.blocks if b.kind == "dwell"]
    a, ts = 0.5, 0.001
    for b in dwells:
        out, z_at = accel_dwell(b, 0.0, a)
        assert z_at is not None and b.z_start_m is not None
        n = int(np.ceil(out.duration_s / ts)) + 1
        t = np.linspace(0.0, out.duration_s, n)
        z = z_at(t)
        dt = t[1] - t[0]
        assert z[0] == pytest.approx(b.z_start_m) and z[-1] == pytest.approx(b.z_moves[-1][1])
        v = abs(b.z_moves[-1][1] - b.z_start_m) / b.duration_s
        assert np.abs(np.diff(z)).max() / dt <= v * (1 + 1e-9)
        assert np.abs(np.diff(np.r_[z[0], z, z[-1]], 2)).max() / dt ** 2 <= a * (1 + 1e-6)
        assert out.duration_s == pytest.approx(b.duration_s + v / a, rel=1e-9)


@pytest.mark.parametrize("bad", [0, -1.0, 1000.0, "fast"])
def test_a_z_acceleration_that_is_not_one_is_refused_naming_the_field(bad):
    with pytest.raises(PlannerError) as exc:
        plan_contour({"program": "G21\nG0 X1\nM2\n", "z_accel_m_s2": bad})
    assert exc.value.field == "z_accel_m_s2", (exc.value.field, exc.value.message)
