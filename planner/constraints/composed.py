"""The constrained mode's constraints, composed (:class:`Constraints`): the drive-force
bounds and the row constraints of a plan, in row order. Its own module so that the
controller and both assemblies (:mod:`~planner.constraints.compiled`,
:mod:`~planner.constraints.reference`) import it without importing one another.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from ..corridor import RangeSequence
from ..model import RobotModel
from ..schema import DEFAULT_FORCE_RISE_S, Segment, Settings
from .corridor import ArrivalConstraint, CorridorConstraint, EndApproachConstraint
from .drives import DriveForceConstraint, DriveForceRateConstraint, LegSpeedConstraint, LegStrokeConstraint
from .rows import RowConstraint

__all__ = ["Constraints", "force_rate"]


class Constraints(NamedTuple):
    """The constrained mode's constraints, composed: the drive-force bounds and the row
    constraints, in row order (the compiled assembly's kernel follows the same order)."""

    forces: DriveForceConstraint
    corridor: CorridorConstraint
    approach: EndApproachConstraint
    arrival: ArrivalConstraint
    leg_speed: LegSpeedConstraint
    rate: DriveForceRateConstraint
    stroke: LegStrokeConstraint

    @classmethod
    def of(cls, model: RobotModel, seq: RangeSequence, segments: Sequence[Segment] | None,
           st: Settings) -> Constraints:
        """The constraints of a plan (``st``: the force-rate limit and the sample time)."""
        return cls(DriveForceConstraint(model), CorridorConstraint(seq, segments), EndApproachConstraint(seq, segments),
                   ArrivalConstraint(seq, segments, st.Ts), LegSpeedConstraint(model),
                   DriveForceRateConstraint(model, force_rate(model, st), st.Ts), LegStrokeConstraint(model))

    @property
    def rows(self) -> tuple[RowConstraint, ...]:
        """The constraints that give rows, in row order (hard ones first)."""
        return self.corridor, self.approach, self.arrival, self.leg_speed, self.rate, self.stroke


def force_rate(model: RobotModel, st: Settings) -> np.ndarray | None:
    """The drive-force rate limit [N/s] per drive of ``settings.force_rate_n_s`` (None: no limit):
    by default each drive's ``force_max`` per :data:`~planner.schema.limits.DEFAULT_FORCE_RISE_S`."""
    rate = st.force_rate_n_s
    if isinstance(rate, str):  # "off"
        return None
    if rate is None:
        return np.asarray(model.force_max, float) / DEFAULT_FORCE_RISE_S
    return np.broadcast_to(np.asarray(rate, float), (model.n_legs,)).copy()
