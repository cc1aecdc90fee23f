"""The tool's motion limits as constraints: the tool-point speed (rows).

**Tool speed** (:class:`ToolSpeedConstraint`): ``|(x_dot, y_dot)_j| <= v`` for every sample
``j`` of the horizon, ``v = settings.tool_speed_max_m_s`` (None: no rows). The speed is a
norm of the predicted velocity, which the QP's linear rows cannot state exactly; the circle of
radius ``v`` is replaced by the regular polygon of :data:`TOOL_SPEED_SIDES` sides inscribed in
it: ``|n_h . (x_dot, y_dot)_j| <= v cos(pi / TOOL_SPEED_SIDES) (1 - SPEED_MARGIN)`` for the
``TOOL_SPEED_SIDES / 2`` directions ``n_h`` (each row two-sided). Inside the polygon the speed
is at most ``v``; in the worst direction (a side's middle) the plan is held 0.5 % below it
(32 sides, issue 35 goal 2: with 16 the worst direction was held 1.9 % below, so rows at F
could not keep a program feed's circle at its cells' 0.995 F, and rows a little above F let
its catch-ups run up to 1.5 % over F in the vertex directions).
The rows are linear in the states, exact (no linearisation) and hard, of the speed kind: the
slack problem softens them with the leg speeds'. The actual (nonlinear) plant lands within
the one-step mismatch of the prediction (~1e-9 m/s), far inside the margin; the rows stand
``RELAX_M`` (8e-7 m/s) lower still, so a step solved with its rows widened by that keeps the limit.

Why rows on the velocity states and not on the moves: the range-space criterion predicts the
states over the horizon; a speed row is a selection of two of them (as the arrival rows),
cheap for the stage-wise solver (a stage's own rows).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..corridor import RangeSequence
from ..model import RobotModel
from ..schema import Segment, Settings
from . import kernels as ck
from .drives import SPEED_MARGIN
from .rows import RELAX_M, RowBlock, RowConstraint, RowKind, StepContext

__all__ = ["TOOL_SPEED_SIDES", "ToolSpeedConstraint"]

#: sides of the polygon that stands for the speed circle (even; rows per sample: half of it):
#: the speed is held within ``1 - cos(pi / sides)`` (0.5 %) below the limit in the worst direction
TOOL_SPEED_SIDES = 32


class ToolSpeedConstraint(RowConstraint):
    """``|n_h . (x_dot, y_dot)_j| <= limit`` [m/s] per sample ``j`` and direction ``h`` (see the
    module docstring); no rows where ``settings.tool_speed_max_m_s`` is None. Compiled twin:
    ``kernels.tool_speed_fill``."""

    kind = RowKind.SPEED

    @classmethod
    def of(cls, model: RobotModel, seq: RangeSequence, segments: Sequence[Segment] | None,
           st: Settings) -> ToolSpeedConstraint:
        return cls(st.tool_speed_max_m_s)

    def __init__(self, speed_max: float | None):
        #: the speed limit [m/s], or None
        self.speed_max = speed_max
        half = TOOL_SPEED_SIDES // 2
        angles = np.pi * np.arange(half) / half
        #: (TOOL_SPEED_SIDES / 2, 2) the sides' normals
        self.normals = np.ascontiguousarray(np.column_stack((np.cos(angles), np.sin(angles))))
        #: the rows' bound [m/s] (0 without a limit): :data:`~planner.constraints.rows.RELAX_M` below
        #: the polygon, so that a relaxed step (its rows widened by that) keeps the limit too (with
        #: the relative margin alone a plan at 0.05 m/s riding a vertex direction ran 3e-7 m/s over)
        self.limit = 0.0 if speed_max is None else \
            max(float(speed_max * math.cos(math.pi / TOOL_SPEED_SIDES) * (1.0 - SPEED_MARGIN)) - RELAX_M, 0.0)

    def rows(self, step: StepContext) -> RowBlock:
        """The directions' rows sample by sample."""
        N = len(step.idx) if self.speed_max is not None else 0
        h = len(self.normals)
        cols = (6 * np.arange(N)[:, None, None] + np.array([3, 4])) + np.zeros((1, h, 1), int)
        lim = np.full(N * h, self.limit)
        return RowBlock(cols.reshape(N * h, 2), np.tile(self.normals, (N, 1)), -lim, lim, self.kind)

    @property
    def kernel_args(self) -> ck.ToolSpeedArgs:
        return ck.ToolSpeedArgs(self.speed_max is not None, self.normals, self.limit)
