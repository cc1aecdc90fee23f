"""The drives' limits as constraints: force (bounds), force rate, leg speed and leg stroke (rows).

* **drive forces** (:class:`DriveForceConstraint`): ``|u_i| <= force_max_i``, always hard
  (they are physical): the bounds ``-1 <= z <= 1`` on the scaled moves ``z = u / force_max``;
* **drive-force rates** (:class:`DriveForceRateConstraint`): ``|u_i(j) - u_i(j-1)| <=
  rate_i Ts`` for every move of the horizon, the first against the force applied over the
  previous sample (zero before the start: the robot starts at rest). A machine feels a force
  step as jerk; this bounds it. ``settings.force_rate_n_s`` (default: each drive's
  ``force_max`` per :data:`~planner.schema.limits.DEFAULT_FORCE_RISE_S`). Always hard, like
  the forces (the slack problem stays feasible: repeating the previous force meets them).
  The moves after the first get :data:`RATE_RECOURSE` less (constraint tightening): a plan
  that uses the full rate in its second move would leave the next step no freedom to absorb
  the prediction error of a re-linearised model (on arrival, where position, velocity and
  psi are pinned, this made the next QP infeasible by a nanometre);
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

from collections.abc import Sequence

import numpy as np

from ..corridor import RangeSequence
from ..model import RobotModel
from ..schema import DEFAULT_FORCE_RISE_S, Segment, Settings
from . import kernels as ck
from .rows import ROW_UNIT_M, RowBlock, RowConstraint, RowKind, Rows, StepContext

__all__ = ["FORCE_RECOURSE", "RATE_RECOURSE", "SPEED_MARGIN", "DriveForceConstraint", "DriveForceRateConstraint",
           "LegSpeedConstraint", "LegStrokeConstraint", "force_rate"]

#: relative margin on the leg speed limit [-]
SPEED_MARGIN = 1e-5
#: the force-rate rows of the moves after the first are this fraction tighter [-]
RATE_RECOURSE = 0.02
#: the force bounds of the moves after the first are this fraction tighter [-]
FORCE_RECOURSE = 0.01


class DriveForceConstraint:
    """``|u_i| <= force_max_i`` [N]: the QP's variables are the scaled moves
    ``z = u / force_max``, so the limit is the bound ``|z| <= 1`` (``1 - FORCE_RECOURSE`` after
    the horizon's first move: :meth:`bounds`): simple bounds of the QP in
    ``z`` (:class:`~planner.constraints.qp.DenseQP`), constraints of the stage-wise dual
    method (:func:`planner.constraints.stagewise.dual_solve`, after the rows), and the
    solution is clipped to it."""

    def __init__(self, model: RobotModel):
        #: force_max per drive (n_legs,) [N]
        self.umax = np.asarray(model.force_max, float)

    def bounds(self, N: int) -> np.ndarray:
        """The bounds ``zmax`` (N m,) of the scaled moves: 1 for the first move, ``1 -
        FORCE_RECOURSE`` for the later ones (recourse, as for the rates: a plan braking at full
        force in every future move would leave the next step none to absorb the prediction
        error)."""
        m = len(self.umax)
        zmax = np.full(N * m, 1.0 - FORCE_RECOURSE)
        zmax[:m] = 1.0
        return zmax

    def forces(self, z: np.ndarray) -> np.ndarray:
        """The drive forces [N] of the first ``n_legs`` scaled moves of ``z``."""
        return z[:len(self.umax)] * self.umax


class DriveForceRateConstraint(RowConstraint):
    """``-rate_i Ts <= u_i(j) - u_i(j-1) <= rate_i Ts`` [N] (as rows on the scaled moves: divided
    by ``force_max_i``) per move ``j`` and drive ``i`` of the
    horizon (``1 - RATE_RECOURSE`` of it for ``j >= 1``), ``u(-1)`` the force applied over the
    previous sample (:attr:`StepContext.u_prev`),
    as rows on the moves ``z`` (``u = force_max z``). No rows where ``rate`` is None (no limit).
    Compiled twin: ``kernels.rate_fill``."""

    kind = RowKind.RATE

    @classmethod
    def of(cls, model: RobotModel, seq: RangeSequence, segments: Sequence[Segment] | None,
           st: Settings) -> DriveForceRateConstraint:
        return cls(model, force_rate(model, st), st.Ts)

    def __init__(self, model: RobotModel, rate: np.ndarray | None, Ts: float):
        self.umax = np.ascontiguousarray(model.force_max, dtype=float)
        #: largest change of each drive force over one sample [N], or None
        self.step = None if rate is None else np.ascontiguousarray(np.broadcast_to(rate, self.umax.shape) * Ts,
                                                                   dtype=float)

    def rows(self, step: StepContext) -> RowBlock:
        N, m = len(step.idx), len(self.umax)
        if self.step is None:
            return RowBlock(np.zeros((0, 2), int), np.zeros((0, 2)), np.zeros(0), np.zeros(0), self.kind)
        q = 6 * N + np.arange(N * m)  # the move of sample j, drive i
        col = np.column_stack((q, np.where(q >= 6 * N + m, q - m, -1)))
        val = np.column_stack((np.ones(N * m), np.where(col[:, 1] >= 0, -1.0, 0.0)))
        lim = np.tile(self.step / self.umax, N)  # in the scaled moves (force / force_max)
        lim[m:] *= 1.0 - RATE_RECOURSE
        first = np.concatenate((step.u_prev / self.umax, np.zeros((N - 1) * m)))
        return RowBlock(col, val, first - lim, first + lim, self.kind, unit=1.0)

    @property
    def kernel_args(self) -> ck.RateArgs:
        step = self.step if self.step is not None else np.zeros_like(self.umax)
        return ck.RateArgs(self.step is not None, self.umax, step, float(RATE_RECOURSE))


class LegSpeedConstraint(RowConstraint):
    """``-vmax <= J_l(y0_j) y_dot_j <= vmax`` per sample and leg, ``vmax = speed_max (1 -
    SPEED_MARGIN)`` [m/s]. Compiled twin: ``kernels.speed_fill``."""

    kind = RowKind.SPEED

    @classmethod
    def of(cls, model: RobotModel, seq: RangeSequence, segments: Sequence[Segment] | None,
           st: Settings) -> LegSpeedConstraint:
        return cls(model)

    def __init__(self, model: RobotModel):
        self.vmax = np.ascontiguousarray(model.speed_max * (1.0 - SPEED_MARGIN), dtype=float)

    def rows(self, step: StepContext) -> RowBlock:
        N, n_legs = step.J.shape[:2]
        cols = (6 * np.arange(N)[:, None, None] + 3 + np.arange(3)) + np.zeros((1, n_legs, 1), int)
        return RowBlock(cols.reshape(N * n_legs, 3), step.J.reshape(N * n_legs, 3), np.tile(-self.vmax, N),
                        np.tile(self.vmax, N), self.kind, legs=True)

    def first_sample(self, rows: Rows, J0: np.ndarray) -> None:
        """Sample 0's rows at the Jacobians ``J0`` (n_legs, 3) of the plant's next pose, in
        ``rows`` (the compiled twin: :meth:`Rows.relinearise_first_legs`)."""
        rows.val[rows.speed0:rows.speed0 + len(J0)] = J0 / ROW_UNIT_M

    @property
    def kernel_args(self) -> ck.LegSpeedArgs:
        return ck.LegSpeedArgs(self.vmax)


class LegStrokeConstraint(RowConstraint):
    """``length_min <= l(y0_j) + J_l(y0_j) (y_j - y0_j) <= length_max`` [m] per sample and
    leg; only in the slack problem (see the module docstring). Compiled twin:
    ``kernels.stroke_fill``."""

    kind = RowKind.STROKE
    hard = False

    @classmethod
    def of(cls, model: RobotModel, seq: RangeSequence, segments: Sequence[Segment] | None,
           st: Settings) -> LegStrokeConstraint:
        return cls(model)

    def __init__(self, model: RobotModel):
        self.lmin = np.ascontiguousarray(model.length_min, dtype=float)
        self.lmax = np.ascontiguousarray(model.length_max, dtype=float)

    def rows(self, step: StepContext) -> RowBlock:
        N, n_legs = step.J.shape[:2]
        off = step.L - np.einsum("jia,ja->ji", step.J, step.y_nom)
        cols = (6 * np.arange(N)[:, None, None] + np.arange(3)) + np.zeros((1, n_legs, 1), int)
        return RowBlock(cols.reshape(N * n_legs, 3), step.J.reshape(N * n_legs, 3), (self.lmin - off).ravel(),
                        (self.lmax - off).ravel(), self.kind, legs=True)

    def first_sample(self, rows: Rows, J0: np.ndarray, L0: np.ndarray, y1: np.ndarray) -> None:
        """Sample 0's rows linearised at the plant's next pose ``y1`` (Jacobians ``J0``
        (n_legs, 3), lengths ``L0`` (n_legs,)), in ``rows``."""
        s = slice(rows.stroke0, rows.stroke0 + len(J0))
        rows.val[s] = J0 / ROW_UNIT_M
        off = (L0 - J0 @ y1) / ROW_UNIT_M
        rows.lower[s] = self.lmin / ROW_UNIT_M - off
        rows.upper[s] = self.lmax / ROW_UNIT_M - off

    @property
    def kernel_args(self) -> ck.StrokeArgs:
        return ck.StrokeArgs(self.lmin, self.lmax)


def force_rate(model: RobotModel, st: Settings) -> np.ndarray | None:
    """The drive-force rate limit [N/s] per drive of ``settings.force_rate_n_s`` (None: no limit):
    by default each drive's ``force_max`` per :data:`~planner.schema.limits.DEFAULT_FORCE_RISE_S`."""
    rate = st.force_rate_n_s
    if isinstance(rate, str):  # "off"
        return None
    if rate is None:
        return np.asarray(model.force_max, float) / DEFAULT_FORCE_RISE_S
    return np.broadcast_to(np.asarray(rate, float), (model.n_legs,)).copy()
