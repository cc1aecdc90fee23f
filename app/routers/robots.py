"""The built-in robots: ``GET /v1/robots``, ``GET /v1/robots/{name}``."""

from __future__ import annotations

from fastapi import APIRouter
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.errors import errors_doc
from planner.schema import RobotDescription, RobotSummary, builtin_description, builtin_robot_names

__all__ = ["router"]

router = APIRouter(tags=["robots"])


@router.get("/v1/robots", response_model=list[RobotSummary])
def robots() -> list[RobotSummary]:
    """The built-in robots."""
    return [RobotSummary(name=name, description=builtin_description(name).description,
                         legs=builtin_description(name).n_legs) for name in builtin_robot_names()]


@router.get("/v1/robots/{name}", response_model=RobotDescription, responses=errors_doc(404))
def robot(name: str) -> RobotDescription:
    """A built-in robot's full description (pivots in m, masses in kg, inertias in kg m^2,
    limits in m, N, m/s); the same object a request may give as ``robot``."""
    if name not in builtin_robot_names():
        raise StarletteHTTPException(404, f"unknown robot {name!r}; built-in robots: "
                                     f"{', '.join(builtin_robot_names())}")
    return builtin_description(name)
