"""The constrained mode's constraints, composed (:class:`Constraints`): the drive-force
bounds and the row constraints of a plan, one of each section of the registry
(:data:`~planner.constraints.registry.SECTIONS`), in row order. Its own module so that the
controller and both assemblies (:mod:`~planner.constraints.compiled`,
:mod:`~planner.constraints.reference`) import it without importing one another.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeVar

from ..corridor import RangeSequence
from ..model import RobotModel
from ..schema import Segment, Settings
from .corridor import ArrivalConstraint, CorridorConstraint, EndApproachConstraint
from .drives import DriveForceConstraint, DriveForceRateConstraint, LegSpeedConstraint, LegStrokeConstraint, force_rate
from .registry import SECTIONS
from .rows import RowConstraint

__all__ = ["Constraints", "force_rate"]

C = TypeVar("C", bound=RowConstraint)


@dataclass(frozen=True, eq=False)
class Constraints:
    """The constrained mode's constraints, composed: the drive-force bounds and the row
    constraints, one per registry section in row order (the compiled assembly's order)."""

    forces: DriveForceConstraint
    rows: tuple[RowConstraint, ...]  #: the constraints that give rows, in row order (hard ones first)

    @classmethod
    def of(cls, model: RobotModel, seq: RangeSequence, segments: Sequence[Segment] | None,
           st: Settings) -> Constraints:
        """The constraints of a plan (``st``: its limits and the sample time)."""
        return cls(DriveForceConstraint(model), tuple(s.row_class.of(model, seq, segments, st) for s in SECTIONS))

    def get(self, row_class: type[C]) -> C:
        """The row constraint of that class."""
        for c in self.rows:
            if type(c) is row_class:
                return c
        raise KeyError(row_class.__name__)

    # the ones the controller and the assemblies read by name
    @property
    def corridor(self) -> CorridorConstraint:
        return self.get(CorridorConstraint)

    @property
    def approach(self) -> EndApproachConstraint:
        return self.get(EndApproachConstraint)

    @property
    def arrival(self) -> ArrivalConstraint:
        return self.get(ArrivalConstraint)

    @property
    def leg_speed(self) -> LegSpeedConstraint:
        return self.get(LegSpeedConstraint)

    @property
    def rate(self) -> DriveForceRateConstraint:
        return self.get(DriveForceRateConstraint)

    @property
    def stroke(self) -> LegStrokeConstraint:
        return self.get(LegStrokeConstraint)
