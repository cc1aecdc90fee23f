"""The drives' limits as constraints: force (bounds), leg speed and leg stroke (rows).

* **drive forces** (:class:`DriveForceConstraint`): ``|u_i| <= force_max_i``, always hard
  (they are physical): the bounds ``-1 <= z <= 1`` on the scaled moves ``z = u / force_max``;
* **leg speeds** (:class:`LegSpeedConstraint`): ``|J_l(y0_j) y_dot_j| <= speed_max
  (1 - SPEED_MARGIN)``, exact in the velocity, the Jacobian taken at a nominal pose ``y0_j``:
  the previous step's predicted pose (shifted) and, for the first sample, the plant's own next
  pose under the guessed move (:meth:`~LegSpeedConstraint.first_sample`);
* **leg strokes** (:class:`LegStrokeConstraint`): ``length_min <= l(y0_j) + J_l(y0_j)
  (y_j - y0_j) <= length_max`` (linearised the same way). With the corridor hard these rows
  are implied (every pose of every segment is within stroke:
  :func:`planner.model.reach.check_segments`, exact for boxes), so they enter only the slack
  problem, where the corridor is soft; tests check the actual leg lengths.
"""

from __future__ import annotations

import numpy as np

from ..model import RobotModel
from .rows import ROW_UNIT_M, RowBlock, RowConstraint, RowKind, Rows, StepContext

__all__ = ["SPEED_MARGIN", "DriveForceConstraint", "LegSpeedConstraint", "LegStrokeConstraint"]

#: relative margin on the leg speed limit [-]
SPEED_MARGIN = 1e-5


class DriveForceConstraint:
    """``|u_i| <= force_max_i`` [N]: the QP's variables are the scaled moves
    ``z = u / force_max``, so the limit is the bound ``|z| <= 1``: simple bounds of the QP in
    ``z`` (``kernels.solver_problem``, :class:`~planner.constraints.qp.DenseQP`), rows of the
    QP with its equalities eliminated (``kernels.reduce_problem``, screened by
    :data:`~planner.constraints.step.SCREEN_FORCE`), and the solution is clipped to it."""

    def __init__(self, model: RobotModel):
        #: force_max per drive (n_legs,) [N]
        self.umax = np.asarray(model.force_max, float)

    def forces(self, z: np.ndarray) -> np.ndarray:
        """The drive forces [N] of the first ``n_legs`` scaled moves of ``z``."""
        return z[:len(self.umax)] * self.umax


class LegSpeedConstraint(RowConstraint):
    """``-vmax <= J_l(y0_j) y_dot_j <= vmax`` per sample and leg, ``vmax = speed_max (1 -
    SPEED_MARGIN)`` [m/s]. Compiled twin: ``kernels.speed_fill``."""

    kind = RowKind.SPEED

    def __init__(self, model: RobotModel):
        self.vmax = np.ascontiguousarray(model.speed_max * (1.0 - SPEED_MARGIN), dtype=float)

    def rows(self, step: StepContext) -> RowBlock:
        N, n_legs = step.J.shape[:2]
        cols = (6 * np.arange(N)[:, None, None] + 3 + np.arange(3)) + np.zeros((1, n_legs, 1), int)
        return RowBlock(cols.reshape(N * n_legs, 3), step.J.reshape(N * n_legs, 3), np.tile(-self.vmax, N),
                        np.tile(self.vmax, N), self.kind)

    def first_sample(self, rows: Rows, J0: np.ndarray) -> None:
        """Sample 0's rows at the Jacobians ``J0`` (n_legs, 3) of the plant's next pose, in
        ``rows`` (the compiled twin: :meth:`Rows.relinearise_first_legs`)."""
        rows.val[rows.speed0:rows.speed0 + len(J0)] = J0 / ROW_UNIT_M

    @property
    def kernel_args(self) -> tuple:
        return (self.vmax,)


class LegStrokeConstraint(RowConstraint):
    """``length_min <= l(y0_j) + J_l(y0_j) (y_j - y0_j) <= length_max`` [m] per sample and
    leg; only in the slack problem (see the module docstring). Compiled twin:
    ``kernels.stroke_fill``."""

    kind = RowKind.STROKE
    hard = False

    def __init__(self, model: RobotModel):
        self.lmin = np.ascontiguousarray(model.length_min, dtype=float)
        self.lmax = np.ascontiguousarray(model.length_max, dtype=float)

    def rows(self, step: StepContext) -> RowBlock:
        N, n_legs = step.J.shape[:2]
        off = step.L - np.einsum("jia,ja->ji", step.J, step.y_nom)
        cols = (6 * np.arange(N)[:, None, None] + np.arange(3)) + np.zeros((1, n_legs, 1), int)
        return RowBlock(cols.reshape(N * n_legs, 3), step.J.reshape(N * n_legs, 3), (self.lmin - off).ravel(),
                        (self.lmax - off).ravel(), self.kind)

    def first_sample(self, rows: Rows, J0: np.ndarray, L0: np.ndarray, y1: np.ndarray) -> None:
        """Sample 0's rows linearised at the plant's next pose ``y1`` (Jacobians ``J0``
        (n_legs, 3), lengths ``L0`` (n_legs,)), in ``rows``."""
        s = slice(rows.stroke0, rows.stroke0 + len(J0))
        rows.val[s] = J0 / ROW_UNIT_M
        off = (L0 - J0 @ y1) / ROW_UNIT_M
        rows.lower[s] = self.lmin / ROW_UNIT_M - off
        rows.upper[s] = self.lmax / ROW_UNIT_M - off

    @property
    def kernel_args(self) -> tuple:
        return self.lmin, self.lmax
