"""The plant: the nonlinear model integrated over one sample (the simulation the receding
horizon loop steps; numpy reference of :func:`planner.model.kernels.rk4`)."""

from __future__ import annotations

import numpy as np

from .dynamics import state_derivative
from .robot import RobotModel

__all__ = ["rk4_sample"]


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
