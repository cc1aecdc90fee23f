"""Predictions and the minimisation of the criterion (eqs. 10-23)."""

import numpy as np
import pytest
from scipy.optimize import minimize

from planner.horizon import prediction_matrices
from planner.horizon.solvers import solve_qr, solve_structured, square_root_solve, stacked_system
from planner.model import dynamics, load_robot
from planner.model.discretisation import zoh

C = np.eye(3, 6)


@pytest.fixture(scope="module")
def model():
    robot = load_robot("moving-slide")
    x = np.array([0.01, 0.02, 0.05, 0.1, -0.05, 0.2])
    A, B = dynamics.factorised(robot, x)
    Ad, Bd = zoh(A, B, 0.01)
    return x, Ad, Bd


def problem(N, rng, varying=True):
    qa = np.ones((N, 3)) * (rng.uniform(0.5, 2.0, (N, 1)) if varying else 1.0)
    qb = np.ones((N, 3)) * (rng.uniform(0.5, 2.0, (N, 1)) if varying else 1.0)
    qu = np.full((N, 4), 3e-3)
    ra = rng.normal(size=(N, 3)) * 0.02
    rb = ra + rng.uniform(0, 0.02, (N, 3))
    return qa, qb, qu, ra, rb


def test_predictions_equal_simulating_the_linear_model(model):
    x, Ad, Bd = model
    N = 7
    rng = np.random.default_rng(0)
    u = rng.normal(size=(N, 4))
    F, G = prediction_matrices(Ad, Bd, C, N)
    z, ys = x.copy(), []
    for j in range(N):
        z = Ad @ z + Bd @ u[j]
        ys.append(C @ z)
    assert np.allclose(F @ x + G @ u.ravel(), np.concatenate(ys), rtol=1e-13, atol=1e-15)
    # G is block lower-triangular (causality)
    Gb = G.reshape(N, 3, N, 4)
    for i in range(N):
        assert np.all(Gb[i, :, i + 1:, :] == 0)


def test_householder_solution_equals_independent_least_squares(model):
    x, Ad, Bd = model
    rng = np.random.default_rng(1)
    for N in (1, 5, 20):
        qa, qb, qu, ra, rb = problem(N, rng)
        F, G = prediction_matrices(Ad, Bd, C, N)
        A, b = stacked_system(F, G, x, qa, qb, qu, ra, rb)
        u_qr = square_root_solve(A, b)
        u_svd = np.linalg.lstsq(A, b, rcond=None)[0]  # SVD-based, independent of QR
        assert np.allclose(u_qr, u_svd, rtol=1e-9, atol=1e-9 * np.abs(u_svd).max())


def test_stacked_system_is_the_criterion(model):
    """||A u - b||^2 equals the criterion (22) evaluated by simulation, for any u."""
    x, Ad, Bd = model
    rng = np.random.default_rng(2)
    N = 6
    qa, qb, qu, ra, rb = problem(N, rng)
    F, G = prediction_matrices(Ad, Bd, C, N)
    A, b = stacked_system(F, G, x, qa, qb, qu, ra, rb)
    for _ in range(5):
        u = rng.normal(size=(N, 4)) * 10
        z, J = x.copy(), 0.0
        for j in range(N):
            z = Ad @ z + Bd @ u[j]
            y = C @ z
            J += np.sum((qa[j] * (y - ra[j])) ** 2) + np.sum((qb[j] * (y - rb[j])) ** 2) + np.sum((qu[j] * u[j]) ** 2)
        assert np.sum((A @ u.ravel() - b) ** 2) == pytest.approx(J, rel=1e-11)


@pytest.mark.parametrize("N", [1, 2, 10, 20, 40, 80])
def test_structured_solver_equals_paper_qr(model, N):
    x, Ad, Bd = model
    rng = np.random.default_rng(N)
    qa, qb, qu, ra, rb = problem(N, rng)
    u_qr = solve_qr(Ad, Bd, C, x, qa, qb, qu, ra, rb)
    u_st = solve_structured(Ad, Bd, C, x, qa, qb, qu, ra, rb)
    assert np.abs(u_qr - u_st).max() <= 1e-9 * max(1.0, np.abs(u_qr).max())


def test_solution_is_the_minimum(model):
    """No perturbation improves the criterion (first-order optimality checked numerically)."""
    x, Ad, Bd = model
    rng = np.random.default_rng(5)
    N = 4
    qa, qb, qu, ra, rb = problem(N, rng)
    F, G = prediction_matrices(Ad, Bd, C, N)
    A, b = stacked_system(F, G, x, qa, qb, qu, ra, rb)
    u = solve_structured(Ad, Bd, C, x, qa, qb, qu, ra, rb).ravel()
    J = lambda v: np.sum((A @ v - b) ** 2)  # noqa: E731
    res = minimize(J, np.zeros_like(u), method="BFGS", options={"gtol": 1e-14, "maxiter": 5000})
    assert J(u) <= res.fun * (1 + 1e-9) + 1e-15
    for _ in range(10):
        d = rng.normal(size=u.size)
        assert J(u + 1e-3 * d) > J(u)


def test_tracking_criterion_drops_the_second_range_term(model):
    x, Ad, Bd = model
    rng = np.random.default_rng(6)
    N = 10
    qa, _, qu, w, _ = problem(N, rng, varying=False)
    qb = np.zeros_like(qa)
    u_qr = solve_qr(Ad, Bd, C, x, qa, qb, qu, w, w)
    u_st = solve_structured(Ad, Bd, C, x, qa, qb, qu, w, w)
    assert np.allclose(u_qr, u_st, atol=1e-9 * np.abs(u_qr).max())
    # equal penalties: the two range terms equal one term towards the centre (method.md)
    u_mid = solve_qr(Ad, Bd, C, x, np.sqrt(2) * qa, qb, qu, w, w)
    u_pair = solve_qr(Ad, Bd, C, x, qa, qa, qu, w - 0.01, w + 0.01)
    assert np.allclose(u_mid, u_pair, atol=1e-9 * np.abs(u_mid).max())
