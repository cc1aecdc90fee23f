"""The grid-fast singularity measure (planner.model.kinematics.singularity_measure_grid, a
closed form used by the segmentation) equals the reference (singularity_measure: compiled
one-sided Jacobi, itself equal to numpy's SVD) to 1e-10 relative: over each robot's
reachable workspace, far outside it, at symmetric poses where singular values coincide and
near singular poses."""

from __future__ import annotations

import json

import numpy as np
import pytest

from planner.model import kinematics, load_robot
from planner.model.kinematics import leg_lengths, singularity_measure, singularity_measure_grid
from planner.model.robot import RobotModel
from planner.schema import builtin_description

REL = 1e-10


def robots() -> list[RobotModel]:
    """The built-in robots, one with a tool offset, and one whose legs all point at the
    platform centre at the home pose (singular there, near singular around it)."""
    offset = json.loads(builtin_description("moving-slide").model_dump_json())
    offset["tool_offset"] = [0.012, -0.007]
    central = json.loads(builtin_description("moving-slide").model_dump_json())
    central["base_pivots"] = [[-0.3, -0.3], [0.3, -0.3], [0.3, 0.3], [-0.3, 0.3]]
    return [load_robot("moving-slide"), load_robot("tri-slide"), load_robot(offset), load_robot(central)]


def assert_equal_to_reference(model: RobotModel, points: np.ndarray, psi: float) -> None:
    got = singularity_measure_grid(model, points, psi)
    ref = singularity_measure(model, np.column_stack((points, np.full(len(points), psi))))
    assert got.shape == ref.shape
    np.testing.assert_allclose(got, ref, rtol=REL, atol=0.0)


@pytest.mark.parametrize("ri", range(4))
def test_grid_measure_equals_the_reference_in_the_reachable_workspace(ri):
    model = robots()[ri]
    g = np.linspace(-0.3, 0.3, 241)
    X, Y = np.meshgrid(g, g)
    pts = np.column_stack((X.ravel(), Y.ravel()))
    checked = 0
    for psi in np.linspace(-np.pi, np.pi, 41):
        L = leg_lengths(model, np.column_stack((pts, np.full(len(pts), psi))))
        inside = np.all((L >= model.length_min) & (L <= model.length_max), axis=1)
        checked += np.count_nonzero(inside)
        assert_equal_to_reference(model, pts[inside], psi)
    assert checked > 10_000


@pytest.mark.parametrize("ri", range(4))
def test_grid_measure_equals_the_reference_anywhere(ri):
    """Random poses far outside the stroke too (legs of any length, any direction)."""
    model = robots()[ri]
    rng = np.random.default_rng(ri)
    pts = rng.uniform(-1.0, 1.0, (20_000, 2))
    for psi in rng.uniform(-np.pi, np.pi, 8):
        assert_equal_to_reference(model, pts, psi)


def test_grid_measure_where_singular_values_coincide():
    """moving-slide is symmetric: at the origin two or all three singular values coincide for
    some angles (the closed form's hard case, recomputed by the reference)."""
    model = robots()[0]
    psi = np.concatenate((np.linspace(-np.pi, np.pi, 721), np.linspace(-1.7, -1.6, 1001)))
    pts = np.array([[0.0, 0.0], [1e-12, 0.0], [0.0, -1e-9], [1e-7, 1e-7]])
    for a in psi:
        assert_equal_to_reference(model, pts, a)


def test_grid_measure_near_and_at_singular_poses():
    model = robots()[3]  # singular at the home pose
    r = np.concatenate(([0.0], np.geomspace(1e-9, 1e-1, 60)))
    pts = np.column_stack((r, 0.5 * r))
    for psi in (0.0, 1e-8, 1e-4, 0.01, -0.2):
        assert_equal_to_reference(model, pts, psi)
    assert singularity_measure_grid(model, np.zeros((1, 2)), 0.0)[0] < 1e-12
    # a pose with a zero-length leg (no leg direction) is singular in both: 0, not NaN
    ms = robots()[0]
    base, r0 = ms.base[0], ms.r0[0]
    at_pivot = (base - r0)[None]
    assert singularity_measure_grid(ms, at_pivot, 0.0)[0] == singularity_measure(ms, np.r_[base - r0, 0.0])[0] == 0.0


def test_grid_measure_uses_its_closed_form_almost_everywhere(monkeypatch):
    """The reference is only the fallback: over a workspace grid it recomputes < 1 % of poses."""
    model = robots()[0]
    redone = []

    def counting(m: RobotModel, poses: np.ndarray) -> np.ndarray:
        redone.append(len(poses))
        return singularity_measure(m, poses)

    monkeypatch.setattr(kinematics, "singularity_measure", counting)
    g = np.linspace(-0.15, 0.15, 101)
    X, Y = np.meshgrid(g, g)
    pts = np.column_stack((X.ravel(), Y.ravel()))
    for psi in np.linspace(-0.5, 0.5, 11):
        kinematics.singularity_measure_grid(model, pts, psi)
    assert sum(redone) < 0.01 * 11 * len(pts)
