"""Smooth drive forces in the constrained mode (issue 17): the drive-force rate limit
(``settings.force_rate_n_s``; default force_max per 0.05 s) holds on the returned forces,
including the first step from rest, and the robot arrives at the end at rest, without the
sign-alternating forces it had when it entered the stop box moving."""

from __future__ import annotations

import numpy as np
import pytest

from planner import PlannerError, plan
from planner.schema import DEFAULT_FORCE_RISE_S
from tests.support import TABLE1, with_settings

END = np.array([0.06, 0.04])


def force_steps(res) -> np.ndarray:
    """Each sample's force step (from zero before the start; the last row is the plan's end)."""
    U = res.drives.force
    return np.diff(np.vstack((np.zeros((1, U.shape[1])), U[:-1])), axis=0)


@pytest.mark.parametrize("rate", [None, 600.0, [400.0, 800.0, 600.0, 1000.0]])
def test_rate_limit_holds_on_the_forces(rate):
    """Every force step, the first from rest included, within rate x Ts per drive: the
    default (force_max / DEFAULT_FORCE_RISE_S), one number, or one per drive (to 1e-9
    relative: a relaxed step's applied move is clipped to its rate rows, issue 31)."""
    res = plan(with_settings(TABLE1, mode="constrained", force_rate_n_s=rate))
    assert res.metrics.contained and res.metrics.settled
    limit = 150.0 / DEFAULT_FORCE_RISE_S if rate is None else np.broadcast_to(np.asarray(rate, float), (4,))
    steps = np.abs(force_steps(res)) / res.settings.Ts
    assert np.all(steps <= limit * (1 + 1e-9))
    # a tight limit is active: some drive changes at (nearly) its limit
    if rate is not None:
        assert np.any(steps >= 0.99 * limit)


def test_without_the_limit_the_forces_jump():
    """'off': the fastest timing jumps by a full force_max in one sample, which the default
    limit forbids (and the default's plan is the slower)."""
    off = plan(with_settings(TABLE1, mode="constrained", fastest=True, force_rate_n_s="off"))
    on = plan(with_settings(TABLE1, mode="constrained", fastest=True))
    assert off.metrics.max_force_rate_n_s > 2 * 150.0 / DEFAULT_FORCE_RISE_S
    assert on.metrics.max_force_rate_n_s <= 150.0 / DEFAULT_FORCE_RISE_S * (1 + 1e-9)
    assert on.metrics.duration_s >= off.metrics.duration_s


@pytest.mark.parametrize("S", [20, 10])
def test_arrives_at_rest_without_chatter(S):
    """From the sample after the robot reaches the end point (within 10 um) the forces stay
    below 1 % of the plan's peak force: it arrives at rest instead of entering the
    micrometre stop box moving and reversing within every sample (on f0e9b8a: +-2.6 N of a
    17 N peak for ~0.05 s)."""
    res = plan(with_settings(TABLE1, mode="constrained", samples_per_segment=S))
    P, U, V = res.pose, res.drives.force, res.velocity
    arrived = int(np.argmax(np.linalg.norm(P[:, :2] - END, axis=1) < 1e-5))
    assert 0 < arrived < len(P) - 2
    assert np.hypot(*V[arrived, :2]) < 1e-3  # already slower than the settling speed
    after = U[arrived + 1:-1]
    assert np.abs(after).max() < 0.01 * np.abs(U).max()
    assert res.metrics.settled and res.metrics.duration_s <= len(TABLE1["segments"]) * S * 0.01


def test_rate_setting_is_validated():
    for bad, field in ((-1.0, "settings.force_rate_n_s"), ([100.0, 200.0], "settings.force_rate_n_s"),
                       ("fast", "settings.force_rate_n_s")):
        with pytest.raises(PlannerError) as exc:
            plan(with_settings(TABLE1, mode="constrained", force_rate_n_s=bad))
        assert exc.value.code == "invalid_input" and exc.value.field == field, exc.value


def test_a_rate_per_drive_of_a_robot_with_other_legs_is_accepted():
    """One force rate per drive of a 3-leg robot (the built-in tri-slide): the settings, sized
    for the default 4-leg robot before the request's robot is known, take it (the default
    horizon is the request's robot's), and the plan keeps each drive within its own rate; a
    count that fits neither robot is named on its field."""
    from planner.schema import PlanRequest

    req = PlanRequest.model_validate({**TABLE1, "robot": "tri-slide",
                                      "settings": {"mode": "constrained", "force_rate_n_s": [3000.0, 2500.0, 2000.0]}})
    assert req.robot_description.n_legs == 3 and len(req.settings.force_rate_n_s) == 3
    with pytest.raises(PlannerError) as exc:
        plan({**TABLE1, "robot": "tri-slide", "settings": {"mode": "constrained", "force_rate_n_s": [3000.0, 2500.0]}})
    assert exc.value.code == "invalid_input" and exc.value.field == "settings.force_rate_n_s", exc.value
