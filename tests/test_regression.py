"""Trajectories recorded before the redesign (tests/data/regression/trajectories.json, on
f0e9b8a): every case planned now gives the same number of steps and the same poses to
1e-9 m (the redesign moves code, not numbers)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from planner import plan

RECORDED = json.loads((Path(__file__).resolve().parent / "data" / "regression" / "trajectories.json").read_text())
TOL_M = 1e-9


@pytest.mark.parametrize("case", sorted(RECORDED))
def test_trajectory_equals_the_recorded_one(case):
    rec = RECORDED[case]
    res = plan(rec["request"])
    pose, recorded = res.pose, np.array(rec["pose"])
    assert res.metrics.steps == rec["steps"]
    assert pose.shape == recorded.shape
    assert np.abs(pose - recorded).max() <= TOL_M
