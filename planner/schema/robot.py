"""The robot description: the JSON shape of ``planner/data/*.json`` and of a request's
``robot`` object. SI units: m, kg, kg m^2, N s/m, N, m/s.

Validation here is complete: a description that passes builds a robot model
(:class:`planner.model.RobotModel`) whose masses, strokes and limits are usable.
"""

from __future__ import annotations

import json
from functools import lru_cache
from importlib import resources
from typing import Annotated, Any

import numpy as np
from pydantic import Discriminator, Field, Tag, field_validator, model_validator

from ._types import Coordinate, Finite, Point2, PointPair, Strict, array_of, fail
from .limits import MAX_COORDINATE, MAX_LEGS, MAX_PHYSICAL

__all__ = ["BodyDescription", "LegDescription", "PlatformDescription", "RobotDescription",
           "builtin_robot_names", "builtin_description"]


class BodyDescription(Strict):
    """A leg's cylinder or rod."""

    mass: Finite = Field(ge=0, le=MAX_PHYSICAL, description="Mass in kg")
    com: Coordinate = Field(description="Distance of the centre of mass from the base pivot (cylinder) or the "
                        "platform pivot (rod) in m")
    inertia: Finite = Field(ge=0, le=MAX_PHYSICAL, description="Moment of inertia about the centre of mass in kg m^2")


class LegDescription(Strict):
    """One RPR leg: a cylinder turning about its base pivot, a rod sliding in it."""

    cylinder: BodyDescription
    rod: BodyDescription
    friction: Finite = Field(0.0, ge=0, le=MAX_PHYSICAL,
                             description="Viscous friction on the leg's sliding speed in N s/m")
    length_min: Finite = Field(gt=0, le=MAX_COORDINATE, description="Shortest leg length in m")
    length_max: Finite = Field(gt=0, le=MAX_COORDINATE, description="Longest leg length in m")
    force_max: Finite = Field(gt=0, le=MAX_PHYSICAL, description="Drive force limit in N")
    speed_max: Finite = Field(gt=0, le=MAX_PHYSICAL, description="Drive speed limit in m/s")

    @model_validator(mode="after")
    def _stroke(self) -> LegDescription:
        if self.length_min >= self.length_max:
            raise fail(f"must be smaller than length_max ({self.length_min:g} >= {self.length_max:g} m)", "length_min")
        return self


class PlatformDescription(Strict):
    mass: Finite = Field(gt=0, le=MAX_PHYSICAL, description="Platform mass in kg")
    inertia: Finite = Field(gt=0, le=MAX_PHYSICAL, description="Platform moment of inertia about its centre in kg m^2")


#: one pivot per leg, at least 3 legs [[x, y], ...] in m
Pivots = Annotated[np.ndarray, array_of(list[PointPair], min_length=3, max_length=MAX_LEGS)]


def _legs_kind(value: Any) -> str:
    return "~each" if isinstance(value, list) else "~shared"


#: one leg description for all legs, or one per leg
Legs = Annotated[Annotated[LegDescription, Tag("~shared")] | Annotated[list[LegDescription], Tag("~each")],
                 Discriminator(_legs_kind)]


def _distinct(points: np.ndarray, what: str) -> np.ndarray:
    n = len(points)
    gap = np.linalg.norm(points[:, None] - points[None], axis=-1) + np.eye(n)
    if n and gap.min() < 1e-6:
        i, j = np.unravel_index(np.argmin(gap), gap.shape)
        raise fail(f"{what} {int(i) + 1} and {int(j) + 1} coincide; each leg needs its own pivot")
    return points


class RobotDescription(Strict):
    """A planar nRPR parallel robot (n >= 3 legs for the platform's 3 degrees of freedom)."""

    name: str = Field("custom", max_length=200, description="Name of the robot")
    description: str = Field("", max_length=2000, description="Free text")
    base_pivots: Pivots = Field(
        description="Base pivots A_i [[x, y], ...], world frame, in m (one per leg, at least 3)")
    platform_pivots: Pivots = Field(
        description="Platform pivots b_i [[x, y], ...], platform frame about the platform centre, in m (one per leg)")
    platform: PlatformDescription
    legs: Legs = Field(
        description="One leg description shared by all legs, or one per leg")
    tool_offset: Point2 = Field(default_factory=lambda: np.zeros(2),
                              description="Tool point [x, y] in the platform frame, in m")

    @field_validator("base_pivots")
    @classmethod
    def _base_distinct(cls, v: np.ndarray) -> np.ndarray:
        return _distinct(v, "pivots")

    @field_validator("platform_pivots")
    @classmethod
    def _platform_distinct(cls, v: np.ndarray) -> np.ndarray:
        _distinct(v, "pivots")
        if float(np.ptp(v, axis=0).max()) < 1e-6:
            raise fail("the platform pivots must span a platform")
        return v

    @model_validator(mode="after")
    def _one_per_leg(self) -> RobotDescription:
        n = len(self.base_pivots)
        if len(self.platform_pivots) != n:
            raise fail(f"must have {n} points (one per leg), got {len(self.platform_pivots)}", "platform_pivots")
        if isinstance(self.legs, list) and len(self.legs) != n:
            raise fail(f"must describe {n} legs (one per pivot), got {len(self.legs)}", "legs")
        return self

    @property
    def n_legs(self) -> int:
        return len(self.base_pivots)

    def leg_list(self) -> list[LegDescription]:
        """One description per leg."""
        return list(self.legs) if isinstance(self.legs, list) else [self.legs] * self.n_legs


@lru_cache(maxsize=1)
def builtin_robot_names() -> tuple[str, ...]:
    """Names of the robots shipped in ``planner/data``."""
    return tuple(sorted(p.name[:-5] for p in resources.files("planner.data").iterdir() if p.name.endswith(".json")))


@lru_cache(maxsize=16)
def builtin_description(name: str) -> RobotDescription:
    """The description of a built-in robot (``KeyError`` if there is none by that name)."""
    if name not in builtin_robot_names():
        raise KeyError(name)
    text = resources.files("planner.data").joinpath(f"{name}.json").read_text()
    return RobotDescription.model_validate(json.loads(text))
