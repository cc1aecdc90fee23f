"""Robot model (eqs. 1-9): constraint null space, exact factorisation, energy, the reduced
model against an independent DAE solve, discretisation, and clear errors."""

import copy

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from planner.errors import PlannerError
from planner.model import dynamics, kinematics, load_robot, reach
from planner.model.discretisation import zoh
from tests.support import robot_description

ROBOTS = ["moving-slide", "tri-slide"]


def random_states(robot, rng, count=20):
    """Random regular states near the home pose."""
    out = []
    while len(out) < count:
        y = rng.uniform([-0.06, -0.06, -0.2], [0.06, 0.06, 0.2])
        L = kinematics.leg_lengths(robot, y)
        if np.all(L > robot.length_min) and np.all(L < robot.length_max):
            v = rng.normal(size=3) * [0.3, 0.3, 1.0]
            out.append(np.concatenate((y, v)))
    return out


@pytest.mark.parametrize("name", ROBOTS)
def test_constraints_hold_and_R_spans_null_space(name):
    robot = load_robot(name)
    rng = np.random.default_rng(1)
    for x in random_states(robot, rng):
        s = dynamics.physical_coordinates(robot, x[:3])
        assert np.abs(dynamics.loop_closure(robot, s)).max() < 1e-14
        Phi = dynamics.constraint_jacobian(robot, s)
        R = dynamics.R_matrix(robot, x[:3])
        assert np.abs(Phi @ R).max() < 1e-13  # eq. (3)
        assert np.linalg.matrix_rank(R) == 3
        # R is ds/dy: compare with central differences of s(y)
        eps = 1e-6
        fd = np.column_stack([(dynamics.physical_coordinates(robot, x[:3] + eps * e) -
                               dynamics.physical_coordinates(robot, x[:3] - eps * e)) / (2 * eps) for e in np.eye(3)])
        assert np.allclose(fd, R, atol=1e-8)


@pytest.mark.parametrize("name", ROBOTS)
def test_factorisation_is_exact(name):
    """Eq. (8): A(x) x + B(x) u == f(x) + G(x) u to rounding, at any state."""
    robot = load_robot(name)
    rng = np.random.default_rng(2)
    for x in random_states(robot, rng):
        u = rng.normal(size=robot.n_legs) * 50
        A, B = dynamics.factorised(robot, x)
        f = dynamics.state_derivative(robot, x, np.zeros(robot.n_legs))
        assert np.allclose(A @ x, f, rtol=1e-12, atol=1e-12)
        assert np.allclose(A @ x + B @ u, dynamics.state_derivative(robot, x, u), rtol=1e-12, atol=1e-10)
        assert np.allclose(A[:3], np.hstack((np.zeros((3, 3)), np.eye(3))))


@pytest.mark.parametrize("name", ROBOTS)
def test_reduced_model_equals_independent_dae_solve(name):
    """Eq. (6) against the DAE (1)-(2) solved directly with Lagrange multipliers:
    [M -Phi^T; Phi 0] [s_dd; lam] = [g + T u; -Phi_dot s_dot]."""
    robot = load_robot(name)
    n = robot.n_legs
    rng = np.random.default_rng(3)
    for x in random_states(robot, rng, 8):
        y, v = x[:3], x[3:]
        u = rng.normal(size=n) * 40
        s = dynamics.physical_coordinates(robot, y)
        R = dynamics.R_matrix(robot, y)
        s_dot = R @ v
        M = dynamics.mass_matrix(robot, s)
        Phi = dynamics.constraint_jacobian(robot, s)
        eps = 1e-6
        Phi_dot = (dynamics.constraint_jacobian(robot, s + eps * s_dot)
                   - dynamics.constraint_jacobian(robot, s - eps * s_dot)) / (2 * eps)
        T = np.zeros((3 + 2 * n, n))
        T[3:3 + n] = np.eye(n)
        K = np.block([[M, -Phi.T], [Phi, np.zeros((2 * n, 2 * n))]])
        rhs = np.concatenate((dynamics.forces_g(robot, s, s_dot) + T @ u, -Phi_dot @ s_dot))
        s_dd = np.linalg.solve(K, rhs)[:3 + 2 * n]
        y_dd = dynamics.acceleration(robot, y, v, u)
        R_dot = (dynamics.R_matrix(robot, y + eps * v) - dynamics.R_matrix(robot, y - eps * v)) / (2 * eps)
        assert np.allclose(R @ y_dd + R_dot @ v, s_dd, rtol=1e-7, atol=1e-7 * np.abs(s_dd).max())


@pytest.mark.parametrize("name", ROBOTS)
def test_unforced_frictionless_motion_conserves_kinetic_energy(name):
    desc = copy.deepcopy(robot_description(name))
    legs = desc["legs"] if isinstance(desc["legs"], list) else [desc["legs"]]
    for leg in legs:
        leg["friction"] = 0.0
    robot = load_robot(desc)
    x0 = np.array([0.01, -0.02, 0.05, 0.15, -0.1, 0.8])
    zero = np.zeros(robot.n_legs)
    sol = solve_ivp(lambda t, x: dynamics.state_derivative(robot, x, zero), (0, 0.25), x0, method="DOP853",
                    rtol=1e-11, atol=1e-13, dense_output=True)
    E0 = dynamics.kinetic_energy(robot, x0)
    energies = [dynamics.kinetic_energy(robot, sol.sol(t)) for t in np.linspace(0, 0.25, 26)]
    assert np.max(np.abs(np.array(energies) - E0)) < 1e-8 * E0
    # the motion is genuinely nonlinear (not a trivial straight line)
    assert np.linalg.norm(sol.y[3:, -1] - x0[3:]) > 1e-3


def test_friction_dissipates_energy():
    robot = load_robot("moving-slide")
    x0 = np.array([0.0, 0.0, 0.0, 0.2, 0.1, 0.5])
    zero = np.zeros(4)
    sol = solve_ivp(lambda t, x: dynamics.state_derivative(robot, x, zero), (0, 0.2), x0, rtol=1e-10, atol=1e-12)
    E = [dynamics.kinetic_energy(robot, x) for x in sol.y.T]
    assert np.all(np.diff(E) <= 1e-12) and E[-1] < E[0]


def test_drive_force_does_work_at_leg_speed():
    """Power balance: d/dt (kinetic energy) = u . l_dot - friction losses (frictionless: u . l_dot)."""
    desc = copy.deepcopy(robot_description("moving-slide"))
    desc["legs"]["friction"] = 0.0
    robot = load_robot(desc)
    x = np.array([0.02, 0.01, -0.1, 0.1, -0.2, 0.3])
    u = np.array([30.0, -10.0, 5.0, 20.0])
    xdot = dynamics.state_derivative(robot, x, u)
    M_r = dynamics.generalised_forces(robot, x[:3], x[3:])[0]
    eps = 1e-7
    dE = (dynamics.kinetic_energy(robot, x + eps * xdot) - dynamics.kinetic_energy(robot, x - eps * xdot)) / (2 * eps)
    l_dot = kinematics.leg_jacobians(robot, x[:3])[0] @ x[3:]
    assert dE == pytest.approx(u @ l_dot, rel=1e-6)
    assert M_r.shape == (3, 3) and np.all(np.linalg.eigvalsh(M_r) > 0)


def test_zoh_equals_fine_integration_of_the_frozen_model():
    """Eq. (9): Ad x + Bd u is the exact solution of x_dot = A x + B u over one sample."""
    robot = load_robot("moving-slide")
    x = np.array([0.02, -0.01, 0.1, 0.2, -0.1, 0.4])
    u = np.array([20.0, -15.0, 8.0, 3.0])
    A, B = dynamics.factorised(robot, x)
    Ts = 0.01
    Ad, Bd = zoh(A, B, Ts)
    sol = solve_ivp(lambda t, z: A @ z + B @ u, (0, Ts), x, method="DOP853", rtol=1e-13, atol=1e-15)
    assert np.allclose(Ad @ x + Bd @ u, sol.y[:, -1], rtol=0, atol=1e-12)
    # and the frozen model stays close to the nonlinear one over one sample (O(Ts^2) in velocity)
    sol_nl = solve_ivp(lambda t, z: dynamics.state_derivative(robot, z, u), (0, Ts), x, method="DOP853",
                       rtol=1e-12, atol=1e-14)
    err = np.abs(Ad @ x + Bd @ u - sol_nl.y[:, -1])
    assert err[:3].max() < 1e-6 and err[3:].max() < 1e-4


def test_singular_layout_is_rejected_with_a_clear_error():
    """All legs pointing at the platform centre: no torque about it, singular in rotation."""
    desc = copy.deepcopy(robot_description("moving-slide"))
    desc["base_pivots"] = [[-0.3, -0.3], [0.3, -0.3], [0.3, 0.3], [-0.3, 0.3]]
    robot = load_robot(desc)
    assert kinematics.singularity_measure(robot, np.zeros(3))[0] < 1e-12
    with pytest.raises(PlannerError) as err:
        reach.check_pose(robot, np.zeros(3), "segments[0]")
    assert err.value.code == "singular" and "singular" in err.value.message
    assert err.value.field == "segments[0]"


def test_zero_length_leg_is_singular_not_nan():
    """A pose that puts a platform pivot on its base pivot: no leg direction, so singular."""
    robot = load_robot("moving-slide")
    pose = np.array([robot.base[0, 0] - robot.platform[0, 0], robot.base[0, 1] - robot.platform[0, 1], 0.0])
    assert kinematics.singularity_measure(robot, pose)[0] == 0.0


def test_unreachable_pose_names_the_leg():
    robot = load_robot("moving-slide")
    with pytest.raises(PlannerError) as err:
        reach.check_pose(robot, np.array([0.3, 0.0, 0.0]), "segments[4]")
    assert err.value.code == "unreachable"
    assert "leg 1" in err.value.message and "0.4500" in err.value.message


@pytest.mark.parametrize("mutate, field", [
    (lambda d: d.update(base_pivots=[[0, 0], [1, 0]]), "robot.base_pivots"),
    (lambda d: d["platform"].update(mass=-1), "robot.platform.mass"),
    (lambda d: d["legs"].update(length_min=0.5), "robot.legs.length_min"),
    (lambda d: d["legs"]["rod"].update(mass=float("nan")), "robot.legs.rod.mass"),
    (lambda d: d.update(platform_pivots=[[0, 0]] * 3), "robot.platform_pivots"),
    (lambda d: d.update(platform_pivots=[[0.1, 0.1]] * 4), "robot.platform_pivots"),
    (lambda d: d.update(base_pivots=[[0.4, 0.2], [0.4, 0.2], [0.2, -0.4], [-0.2, 0.4]]), "robot.base_pivots"),
])
def test_bad_robot_description_names_the_field(mutate, field):
    desc = copy.deepcopy(robot_description("moving-slide"))
    mutate(desc)
    with pytest.raises(PlannerError) as err:
        load_robot(desc)
    assert err.value.field == field


def test_structured_zoh_equals_the_augmented_expm():
    from planner.model.discretisation import zoh_factorised
    robot = load_robot("tri-slide")
    rng = np.random.default_rng(7)
    for x in random_states(robot, rng, 5):
        A, B = dynamics.factorised(robot, x)
        A22, B2 = dynamics.factorised_blocks(robot, x)
        for Ts in (0.001, 0.01, 0.2):  # the last one exceeds the series' range: falls back
            Ad, Bd = zoh(A, B, Ts)
            Ad2, Bd2 = zoh_factorised(A22, B2, Ts)
            assert np.allclose(Ad2, Ad, rtol=0, atol=1e-14) and np.allclose(Bd2, Bd, rtol=1e-12, atol=1e-16)
