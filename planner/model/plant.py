"""The plant: the nonlinear model integrated over one sample (the simulation the receding
horizon loop steps; numpy reference of :func:`planner.model.kernels.rk4`)."""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernels_off
from . import kernels
from .dynamics import factorised_blocks, state_derivative
from .robot import RobotModel

__all__ = ["PLANT_STEP_RATE", "plant_substeps", "rk4_sample"]

#: the plant's RK4 steps are at most this many of the robot's fastest time constants long
#: (``|lambda| h``, ``lambda`` the largest eigenvalue of the velocity block of eq. 8 at rest:
#: the leg friction over the masses it moves). Issue 31: Table I with a leg friction of 500 N s/m
#: (``|lambda|`` 54 1/s, ``|lambda| Ts`` 0.54 at Ts 10 ms) was refused with one step a sample and
#: planned with 4 (0.13), within 0.002 um of RK4 with 16 steps a sample
PLANT_STEP_RATE = 0.15


def plant_substeps(model: RobotModel, Ts: float, pose: np.ndarray | None = None) -> int:
    """RK4 steps a sample of ``Ts`` [s] needs for the robot's stiffness: ``|lambda| Ts /``
    :data:`PLANT_STEP_RATE`, at least 1 (at most 50, the setting's bound), ``lambda`` the
    largest eigenvalue of the velocity block ``A22`` of eq. 8 at rest at ``pose`` (default the
    home pose): the viscous leg friction over the masses it moves. The Moving Slide (5 N s/m):
    0.5 1/s, one step at any Ts up to 0.3 s."""
    x = np.zeros(6)
    if pose is not None:
        x[:3] = pose
    if kernels_off():
        A22 = factorised_blocks(model, x)[0]
    else:  # the compiled twin: ~10 us instead of ~2 ms (a quarter of a paper-mode Table I plan)
        A22, B2 = np.empty((3, 3)), np.empty((3, model.n_legs))
        kernels.factorised_blocks(model.packed, x, A22, B2)
    rate = float(np.max(np.abs(np.linalg.eigvals(A22))))
    return int(min(max(1, math.ceil(rate * Ts / PLANT_STEP_RATE - 1e-9)), 50))


def rk4_sample(model: RobotModel, x: np.ndarray, u: np.ndarray, Ts: float, substeps: int,
               f0: np.ndarray | None = None) -> np.ndarray:
    """The nonlinear model (eqs. 6-7) under a constant drive force ``u`` [N] over one sample
    ``Ts`` [s], by ``substeps`` classical Runge-Kutta steps. ``f0`` may pass ``x_dot`` at ``x``."""
    h = Ts / substeps
    for i in range(substeps):
        k1 = f0 if (i == 0 and f0 is not None) else state_derivative(model, x, u)
        k2 = state_derivative(model, x + 0.5 * h * k1, u)
        k3 = state_derivative(model, x + 0.5 * h * k2, u)
        k4 = state_derivative(model, x + h * k3, u)
        x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x
