"""The compiled twins (planner/model/kernels.py, planner/horizon/kernels.py,
planner/orchestrator/kernels.py) equal the numpy reference implementation of every
stage, and a whole compiled plan equals the reference loop's plan."""

import json
from pathlib import Path

import numpy as np
import pytest

from planner.errors import PlannerError
from planner.horizon.solvers import solve_qr, solve_riccati
from planner.model import dynamics, kernels, kinematics, load_robot
from planner.model.discretisation import zoh, zoh_factorised
from planner.model.plant import rk4_sample
from planner.orchestrator import kernels as loop_kernels
from planner.orchestrator.simulate import C_POSE
from tests.support import TABLE1, robot_description
from tests.support import plan_json as plan

ROOT = Path(__file__).resolve().parent.parent


def robots():
    ms = load_robot("moving-slide")
    desc = json.loads((ROOT / "planner" / "data" / "moving-slide.json").read_text())
    desc["tool_offset"] = [0.012, -0.007]  # exercises the platform-centre terms
    return [ms, load_robot("tri-slide"), load_robot(desc)]


def states(rng, count=20):
    x = np.zeros((count, 6))
    x[:, :2] = rng.uniform(-0.03, 0.03, (count, 2))
    x[:, 2] = rng.uniform(-0.1, 0.1, count)
    x[:, 3:] = rng.normal(size=(count, 3)) * [0.3, 0.3, 1.0]
    return x


@pytest.mark.parametrize("ri", range(3))
def test_model_kernels_equal_the_reference_model(ri):
    robot = robots()[ri]
    rb = robot.packed
    n = robot.n_legs
    rng = np.random.default_rng(ri)
    for x in states(rng):
        u = rng.normal(size=n) * 20
        A22, B2 = np.empty((3, 3)), np.empty((3, n))
        assert kernels.factorised_blocks(rb, x, A22, B2)
        A22r, B2r = dynamics.factorised_blocks(robot, x)
        assert np.allclose(A22, A22r, rtol=1e-12, atol=1e-12 * np.abs(A22r).max())
        assert np.allclose(B2, B2r, rtol=1e-12, atol=1e-12 * np.abs(B2r).max())
        acc = np.empty(3)
        assert kernels.acceleration(rb, x, u, acc)
        ref = dynamics.acceleration(robot, x[:3], x[3:], u)
        assert np.allclose(acc, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
        # and the factorisation is exact in the kernel too: A22 v + B2 u == acceleration
        assert np.allclose(A22 @ x[3:] + B2 @ u, acc, rtol=1e-11, atol=1e-11 * np.abs(acc).max())


@pytest.mark.parametrize("ri", range(3))
def test_leg_kernel_equals_the_kinematics(ri):
    """The compiled leg geometry (``kernels.leg``, one leg at a pose) equals the numpy one
    (``kinematics.leg_vectors`` and the leg rows of ``R``, ``kinematics.leg_rows``), and the
    batched compiled leg rows (``kernels.leg_jacobians``, the constrained mode's leg
    linearisation) equal ``kinematics.leg_jacobians`` and ``kinematics.leg_lengths``; the
    leg vectors close the loop (eq. 2) with the physical coordinates."""
    robot = robots()[ri]
    rng = np.random.default_rng(ri)
    poses = np.column_stack((rng.uniform(-0.05, 0.05, (50, 2)), rng.uniform(-0.3, 0.3, 50)))
    rx, ry, dx, dy = kinematics.leg_vectors(robot, poses)
    for k, y in enumerate(poses):
        length, e, r, _, J_l, J_phi = kinematics.leg_rows(robot, y)
        assert np.allclose(np.column_stack((rx[k], ry[k])), r, rtol=0, atol=1e-15)
        assert np.allclose(np.hypot(dx[k], dy[k]), length, rtol=1e-15, atol=0)
        s = dynamics.physical_coordinates(robot, y)
        assert np.abs(dynamics.loop_closure(robot, s)).max() < 1e-14
        c, sn = np.cos(y[2]), np.sin(y[2])
        for i in range(robot.n_legs):
            got = kernels.leg(c, sn, *robot.r0[i], *robot.base[i], y[0], y[1])
            ref = (r[i, 0], r[i, 1], length[i], e[i, 0], e[i, 1], J_l[i, 2], J_phi[i, 2] * length[i])
            assert np.allclose(got, ref, rtol=0, atol=1e-15)
    J, L = np.empty((50, robot.n_legs, 3)), np.empty((50, robot.n_legs))
    kernels.leg_jacobians(np.ascontiguousarray(robot.r0), np.ascontiguousarray(robot.base), poses, J, L)
    assert np.allclose(J, kinematics.leg_jacobians(robot, poses), rtol=0, atol=1e-14)
    assert np.allclose(L, kinematics.leg_lengths(robot, poses), rtol=1e-14, atol=0)


@pytest.mark.parametrize("Ts", [0.001, 0.01, 0.5, 5.0])  # the last two take the expm branch
def test_zoh_kernel_equals_the_matrix_exponential(Ts):
    robot = load_robot("moving-slide")
    x = np.array([0.01, -0.02, 0.05, 0.4, -0.3, 2.0])
    A22, B2 = dynamics.factorised_blocks(robot, x)
    Ad, Bd = np.empty((6, 6)), np.empty((6, 4))
    kernels.zoh(A22, B2, Ts, Ad, Bd)
    A, B = dynamics.factorised(robot, x)
    Ae, Be = zoh(A, B, Ts)
    assert np.allclose(Ad, Ae, rtol=1e-12, atol=1e-13 * np.abs(Ae).max())
    assert np.allclose(Bd, Be, rtol=1e-12, atol=1e-13 * np.abs(Be).max())
    if Ts <= 0.01:
        Af, Bf = zoh_factorised(A22, B2, Ts)
        assert np.allclose(Ad, Af, rtol=1e-14, atol=1e-16) and np.allclose(Bd, Bf, rtol=1e-14, atol=1e-18)
    assert np.array_equal(Ad[:, :3], np.eye(6, 3))  # the structure the Riccati kernel relies on


@pytest.mark.parametrize("N", [1, 2, 10, 20, 80])
def test_riccati_equals_the_paper_qr(N):
    robot = load_robot("moving-slide")
    x = np.array([0.01, 0.02, 0.05, 0.1, -0.05, 0.2])
    A, B = dynamics.factorised(robot, x)
    Ad, Bd = zoh(A, B, 0.01)
    Ad[:, :3] = np.eye(6, 3)  # exact structure (expm gives it to rounding)
    rng = np.random.default_rng(N)
    qa = np.ones((N, 3)) * rng.uniform(0.5, 2.0, (N, 1))
    qb = np.ones((N, 3)) * rng.uniform(0.5, 2.0, (N, 1))
    qu = np.broadcast_to(np.array([2e-3, 3e-3, 1e-3, 5e-3]), (N, 4))
    ra = rng.normal(size=(N, 3)) * 0.02
    rb = ra + rng.uniform(0, 0.02, (N, 3))
    u_qr = solve_qr(Ad, Bd, C_POSE, x, qa, qb, qu, ra, rb)
    u_ric = solve_riccati(Ad, Bd, C_POSE, x, qa, qb, qu, ra, rb)
    assert np.abs(u_qr - u_ric).max() <= 1e-9 * max(1.0, np.abs(u_qr).max())


def test_riccati_refuses_a_model_without_the_hold_structure():
    Ad, Bd = np.eye(6) * 0.5, np.ones((6, 4))
    q = np.ones((3, 3))
    with pytest.raises(ValueError, match="Ad"):
        solve_riccati(Ad, Bd, C_POSE, np.zeros(6), q, q, np.ones((3, 4)), q, q)


@pytest.mark.parametrize("substeps", [1, 3])
def test_rk4_kernel_equals_the_reference_plant(substeps):
    robot = load_robot("moving-slide")
    rb = robot.packed
    rng = np.random.default_rng(substeps)
    for x in states(rng, 5):
        u = rng.normal(size=4) * 30
        f0 = dynamics.state_derivative(robot, x, u)
        ref = rk4_sample(robot, x, u, 0.01, substeps, f0)
        out = kernels.rk4(rb, x, u, 0.01, substeps, f0)
        assert np.allclose(out, ref, rtol=1e-13, atol=1e-15)


def test_cholesky_refuses_a_matrix_that_is_not_positive_definite():
    M = np.diag([1.0, -1.0, 1.0])
    assert not kernels._chol3_solve(M, np.ones((3, 1)))


def _with(req, **settings):
    return {**req, "settings": {**req.get("settings", {}), **settings}}


@pytest.mark.parametrize("settings", [{"mode": "paper"}, {"mode": "paper", "N": 10, "k_u": 2e-4},
                                      {"mode": "paper", "plant_substeps": 2, "Ts": 0.005, "require_settled": False}])
def test_compiled_plan_equals_the_reference_loop(settings):
    a = plan(_with(TABLE1, **settings))
    b = plan(_with(TABLE1, solver="structured", **settings))
    assert a["metrics"]["steps"] == b["metrics"]["steps"]
    assert np.abs(np.array(a["pose"]) - np.array(b["pose"])).max() < 1e-9
    assert np.abs(np.array(a["velocity"]) - np.array(b["velocity"])).max() < 1e-8
    fa, fb = np.array(a["drives"]["force"]), np.array(b["drives"]["force"])
    assert np.abs(fa - fb).max() < 1e-7 * np.abs(fb).max()
    assert np.abs(np.array(a["acceleration"]) - np.array(b["acceleration"])).max() < 1e-7


def test_compiled_plan_of_a_three_leg_robot_equals_the_reference_loop():
    req = {"robot": "tri-slide", "settings": {"mode": "paper"}, "segments": [
        {"lower": [-0.04, -0.02, 0.0], "upper": [-0.04, -0.02, 0.0]},
        {"lower": [-0.04, -0.02, 0.0], "upper": [-0.02, 0.0, 0.0]},
        {"lower": [0.02, 0.0, 0.0], "upper": [0.02, 0.0, 0.0]},
    ]}
    a, b = plan(req), plan(_with(req, solver="structured"))
    assert a["metrics"]["steps"] == b["metrics"]["steps"]
    assert np.abs(np.array(a["pose"]) - np.array(b["pose"])).max() < 1e-9


def test_compiled_loop_reports_a_degenerate_model_with_the_field():
    """A plant whose hold overflows the horizon problem (a strongly negative friction, which
    a valid description cannot have) stops the compiled loop with a clear error naming
    the robot, the time and the pose, not NaN output."""
    robot = load_robot(robot_description("moving-slide"))  # its own model, not the shared built-in
    packed = robot.packed.copy()
    n = robot.n_legs
    packed[kernels._FRIC * n:(kernels._FRIC + 1) * n] = -2e4  # N s/m
    object.__setattr__(robot, "packed", packed)
    with pytest.raises(PlannerError) as exc:
        plan(_with(TABLE1, mode="paper"), robot=robot)
    assert exc.value.code == "singular" and exc.value.field == "robot"
    assert "t = 0.000 s, pose (-0.0800 m, 0.0000 m, 0.0000 rad)" in str(exc.value)


def test_compiled_loop_stops_on_a_runaway_state():
    robot = load_robot("moving-slide")
    rb = robot.packed
    K, N = 5, 3
    rng = np.full((K + N, 3), 2000.0)  # ranges 2 km away: the first sample leaves the workspace
    q = np.ones((K + N, 3))
    x0 = np.array([1000.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    X, U, ACC, steps, settled, status = loop_kernels.simulate_paper(
        rb, x0, rng, rng, q, q, np.full(4, 1e-9), K, N, 0.01, 1, 50, rng[0], np.array([1e-4, 1e-4, 1e-3, 1e-3]))
    assert status == loop_kernels.DIVERGED and not settled
    assert steps == 1 and len(X) == 2 and abs(X[1, 0]) + abs(X[1, 1]) > 1e3


def test_smallest_singular_values_equal_the_svd():
    rng = np.random.default_rng(7)
    J = rng.normal(size=(200, 4, 3))
    J[:40, :, 2] = 0.3 * J[:40, :, 0] + 0.7 * J[:40, :, 1] + rng.normal(size=(40, 4)) * 1e-6  # near singular
    J[40:45, :, 2] = J[40:45, :, 0]  # singular
    J[45, 1, 1] = np.nan
    ok = np.all(np.isfinite(J), axis=(1, 2))
    ref = np.zeros(len(J))
    ref[ok] = np.linalg.svd(J[ok], compute_uv=False)[:, -1]
    got = kernels.smallest_singular_values(J)
    assert got[45] == 0.0
    assert np.allclose(got, ref, rtol=1e-10, atol=1e-14)
    # and the robot's measure uses it: a pose's sigma matches the SVD of its scaled Jacobian
    robot = load_robot("moving-slide")
    poses = np.column_stack((rng.uniform(-0.05, 0.05, (50, 2)), rng.uniform(-0.2, 0.2, 50)))
    Jn = kinematics.leg_jacobians(robot, poses) * np.array([1.0, 1.0, 1.0 / robot.char_length])
    assert np.allclose(kinematics.singularity_measure(robot, poses), np.linalg.svd(Jn, compute_uv=False)[:, -1],
                       rtol=1e-10, atol=1e-14)
