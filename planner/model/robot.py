"""The robot model: a planar nRPR parallel robot as arrays (paper Section III).

Physical coordinates (paper's ``s``), for ``n`` legs::

    s = (x_c, y_c, psi, l_1..l_n, phi_1..phi_n)

the platform centre, the platform angle, each leg's length and each leg's angle. Leg ``i``
closes the loop ``A_i + l_i e(phi_i) - (c + Rot(psi) b_i) = 0`` (eq. 2, two rows per leg,
``2n`` constraints, 3 DOF). The independent coordinates (paper's ``y``) are the pose of the
tool point ``(x, y, psi)``: the platform centre plus ``Rot(psi) * tool_offset``.

The leg masses follow the usual RPR model: a cylinder turning about the base pivot ``A_i``
with its centre of mass at a fixed distance from ``A_i``, and a rod sliding in it with its
centre of mass at a fixed distance from the platform pivot. Drive ``u_i`` [N] is the force
of the prismatic drive along leg ``i`` (positive extends the leg); the robot is horizontal
(no gravity in the plane); viscous friction acts on each leg's sliding speed.

Like pinocchio's ``Model``, :class:`RobotModel` holds only constants (built once from a
:class:`~planner.schema.RobotDescription`, including :attr:`RobotModel.packed` for the
compiled kernels); the quantities of a pose are stateless functions of the model in
:mod:`~planner.model.kinematics`, :mod:`~planner.model.reach` and
:mod:`~planner.model.dynamics`. All SI: m, rad, s, kg, kg m^2, N, N s/m.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from ..errors import PlannerError, invalid
from ..schema import DEFAULT_ROBOT, RobotDescription, builtin_description, builtin_robot_names, planner_error
from .kernels import pack

__all__ = ["RobotModel", "load_robot"]

@dataclass(frozen=True, eq=False)
class RobotModel:
    """The constants of a planar nRPR robot, as arrays (one entry per leg where shaped (n,))."""

    name: str
    base: np.ndarray  #: (n, 2) base pivots A_i, world frame [m]
    platform: np.ndarray  #: (n, 2) platform pivots b_i, platform frame, about the platform centre [m]
    platform_mass: float  #: [kg]
    platform_inertia: float  #: about the platform centre [kg m^2]
    cyl_mass: np.ndarray  #: (n,) [kg]
    cyl_com: np.ndarray  #: (n,) distance of the cylinder's centre of mass from A_i [m]
    cyl_inertia: np.ndarray  #: (n,) about its centre of mass [kg m^2]
    rod_mass: np.ndarray  #: (n,) [kg]
    rod_com: np.ndarray  #: (n,) distance of the rod's centre of mass from b_i [m]
    rod_inertia: np.ndarray  #: (n,) [kg m^2]
    friction: np.ndarray  #: (n,) viscous friction on the leg's sliding speed [N s/m]
    length_min: np.ndarray  #: (n,) shortest leg [m]
    length_max: np.ndarray  #: (n,) longest leg [m]
    force_max: np.ndarray  #: (n,) drive force limit [N]
    speed_max: np.ndarray  #: (n,) drive speed limit [m/s]
    tool: np.ndarray = field(default_factory=lambda: np.zeros(2))  #: tool offset, platform frame [m]
    description: str = ""
    #: (n, 2) platform pivots relative to the tool point, platform frame [m]
    r0: np.ndarray = field(init=False)
    #: (n,) the part of each leg's inertia about A_i that does not depend on its length [kg m^2]
    leg_inertia_const: np.ndarray = field(init=False)
    #: characteristic platform radius [m]: scales the rotation column of the leg Jacobian
    #: to compare with the translation columns (singularity measure)
    char_length: float = field(init=False)
    #: the model packed into one float array for the compiled kernels (:func:`~planner.model.kernels.pack`)
    packed: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        r0 = self.platform - self.tool
        object.__setattr__(self, "r0", r0)
        object.__setattr__(self, "leg_inertia_const", self.cyl_inertia + self.cyl_mass * self.cyl_com**2
                           + self.rod_inertia)
        object.__setattr__(self, "char_length", float(max(np.max(np.linalg.norm(r0, axis=1)), 1e-3)))
        object.__setattr__(self, "packed", pack(self))

    @property
    def n_legs(self) -> int:
        """Number of legs (= drives)."""
        return len(self.base)

    @classmethod
    def from_description(cls, desc: RobotDescription) -> RobotModel:
        """The model of a validated description."""
        legs = desc.leg_list()

        def col(get: Any) -> np.ndarray:
            return np.array([float(get(leg)) for leg in legs])

        return cls(
            name=desc.name, base=np.array(desc.base_pivots, float), platform=np.array(desc.platform_pivots, float),
            platform_mass=desc.platform.mass, platform_inertia=desc.platform.inertia,
            cyl_mass=col(lambda g: g.cylinder.mass), cyl_com=col(lambda g: g.cylinder.com),
            cyl_inertia=col(lambda g: g.cylinder.inertia), rod_mass=col(lambda g: g.rod.mass),
            rod_com=col(lambda g: g.rod.com), rod_inertia=col(lambda g: g.rod.inertia),
            friction=col(lambda g: g.friction), length_min=col(lambda g: g.length_min),
            length_max=col(lambda g: g.length_max), force_max=col(lambda g: g.force_max),
            speed_max=col(lambda g: g.speed_max), tool=np.array(desc.tool_offset, float),
            description=desc.description,
        )


_builtin: dict[str, RobotModel] = {}


def load_robot(spec: Any = None, field_path: str = "robot") -> RobotModel:
    """The robot model of ``spec``: a built-in name (models of built-in robots are built once
    per process), a description (validated dict or :class:`RobotDescription`), a path to a
    JSON description, or a model (returned as is). Bad input is a PlannerError naming the
    field under ``field_path``."""
    if isinstance(spec, RobotModel):
        return spec
    if spec is None:
        spec = DEFAULT_ROBOT
    if isinstance(spec, str):
        model = _builtin.get(spec)
        if model is None:
            if spec not in builtin_robot_names():
                raise invalid(field_path, f"unknown robot {spec!r}; built-in robots: "
                              f"{', '.join(builtin_robot_names())}")
            model = _builtin[spec] = RobotModel.from_description(builtin_description(spec))
        return model
    if isinstance(spec, Path):
        spec = json.loads(spec.read_text())
    if isinstance(spec, dict):
        try:
            spec = RobotDescription.model_validate(spec)
        except ValidationError as exc:
            raise planner_error(exc, field_path) from None
    if not isinstance(spec, RobotDescription):
        raise PlannerError("invalid_input", "must be a built-in robot name or a robot description object", field_path)
    return RobotModel.from_description(spec)
