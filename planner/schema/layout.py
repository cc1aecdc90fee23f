"""The layout: a workspace with obstacles that the planner cuts into cells and a corridor
(the paper's Section V.B). Lengths in m, angles in rad.

A layout that passes validation has a usable outline for every obstacle (no degenerate or
self-crossing polygons, no zero-size rectangles) and, with an explicit cell size, a cell
count within :data:`~planner.schema.limits.MAX_CELLS`; whether start and end are free and
reachable needs the robot and is checked by :mod:`planner.corridor`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Any, Literal

import numpy as np
from pydantic import Discriminator, Field, Tag, ValidationInfo, field_validator, model_validator

if TYPE_CHECKING:
    import shapely

from ._types import Finite, Point2, PointPair, Pose3, Strict, array_of, fail
from .limits import MAX_CELLS, MAX_COORDINATE, MAX_HOLES, MAX_OBSTACLES, MAX_POLYGON_POINTS, MIN_CELL_SIZE

__all__ = ["Bounds", "Cell", "Circle", "Layout", "Obstacle", "Polygon", "Rectangle", "cell_count", "SQRT3_2"]

SQRT3_2 = math.sqrt(3.0) / 2.0  # height of an equilateral triangle of unit edge


class Bounds(Strict):
    lower: Point2 = Field(description="Workspace lower corner [x, y] in m")
    upper: Point2 = Field(description="Workspace upper corner [x, y] in m")

    @model_validator(mode="after")
    def _ordered(self) -> Bounds:
        for i, axis in enumerate("xy"):
            if not self.lower[i] < self.upper[i]:
                raise fail(f"must be greater than bounds.lower in {axis} ({self.upper[i]:g} <= {self.lower[i]:g})",
                           "upper")
        return self


class Rectangle(Strict):
    type: Literal["rectangle"] = Field(description="Obstacle shape")
    lower: Point2 = Field(description="Lower corner [x, y] in m")
    upper: Point2 = Field(description="Upper corner [x, y] in m")

    @model_validator(mode="after")
    def _size(self) -> Rectangle:
        for i, axis in enumerate("xy"):
            if not self.lower[i] < self.upper[i]:
                raise fail(f"degenerate rectangle: upper must be greater than lower in {axis} "
                           f"({self.upper[i]:g} <= {self.lower[i]:g})", "upper")
        return self


class Circle(Strict):
    type: Literal["circle"] = Field(description="Obstacle shape")
    center: Point2 = Field(description="Centre [x, y] in m")
    radius: Finite = Field(gt=0, le=MAX_COORDINATE, description="Radius in m")


#: a polygon's vertices [[x, y], ...] in m
Vertices = Annotated[np.ndarray, array_of(list[PointPair], min_length=3, max_length=MAX_POLYGON_POINTS)]


class Polygon(Strict):
    type: Literal["polygon"] = Field(description="Obstacle shape")
    points: Vertices = Field(
        description="Vertices [[x, y], ...] in m, in order (either orientation)")
    holes: list[Vertices] = Field(default_factory=list, max_length=MAX_HOLES,
                                  description="Holes: free areas inside the outline, each its vertices [[x, y], ...] "
                                  f"in m (e.g. a drawing's shapes nested inside another); at most {MAX_HOLES}, and "
                                  f"at most {MAX_POLYGON_POINTS} vertices in the outline and the holes together")

    @field_validator("points")
    @classmethod
    def _simple(cls, v: np.ndarray) -> np.ndarray:
        import shapely  # loaded on first use: plans of given segments never need it
        poly = shapely.Polygon(v)
        if not poly.is_valid:
            raise fail(f"degenerate polygon: {shapely.is_valid_reason(poly)} (the outline must not cross or touch "
                       "itself)")
        if not poly.area > 0:
            raise fail("degenerate polygon: zero area")
        return v

    @model_validator(mode="after")
    def _holes_inside(self) -> Polygon:
        n = len(self.points) + sum(len(h) for h in self.holes)
        if n > MAX_POLYGON_POINTS:
            raise fail(f"the polygon has {n} vertices in its outline and holes, more than the limit of "
                       f"{MAX_POLYGON_POINTS}", "holes", code="too_large")
        import shapely  # loaded on first use: plans of given segments never need it
        if self.holes:
            poly = shapely.Polygon(self.points, [np.asarray(h) for h in self.holes])
            if not poly.is_valid:
                raise fail(f"invalid holes: {shapely.is_valid_reason(poly)} (each hole must lie inside the outline "
                           "without crossing it or another hole)", "holes")
        return self

    @property
    def shape(self) -> shapely.Polygon:
        """The obstacle as a shapely polygon (with its holes) [m]."""
        import shapely  # loaded on first use: plans of given segments never need it
        return shapely.Polygon(self.points, [np.asarray(h) for h in self.holes] or None)


def _obstacle_kind(value: Any) -> str | None:
    kind = value.get("type") if isinstance(value, dict) else getattr(value, "type", None)
    return f"~{kind}" if kind in ("rectangle", "circle", "polygon") else None


def _drop_nulls(value: Any) -> Any:
    """Obstacles written by older clients carry the other shapes' fields as null."""
    if isinstance(value, dict):
        return {k: v for k, v in value.items() if v is not None}
    return value


Obstacle = Annotated[
    Annotated[Rectangle, Tag("~rectangle")] | Annotated[Circle, Tag("~circle")] | Annotated[Polygon, Tag("~polygon")],
    Discriminator(_obstacle_kind, custom_error_type="invalid_input",
                  custom_error_message="type must be 'rectangle', 'polygon' or 'circle'",
                  custom_error_context={"field": "type"}),
]


class Cell(Strict):
    shape: Literal["square", "triangle"] = Field("square", description="Cell shape")
    size: Finite | None = Field(None, ge=MIN_CELL_SIZE, le=MAX_COORDINATE,
                                description="Cell edge length in m; default from the start-end "
                                "distance and the sample time (see the README)")


def cell_count(lower: np.ndarray, upper: np.ndarray, shape: str, size: float) -> tuple[int, int, int]:
    """Cells a grid of ``shape`` with edge ``size`` [m] puts over the bounds: ``(count,
    columns, rows)``; for triangles the columns are triangles per row."""
    W, H = (np.asarray(upper, float) - np.asarray(lower, float)).tolist()
    if shape == "square":
        nx, ny = _ceil(W / size - 1e-9), _ceil(H / size - 1e-9)
        return nx * ny, nx, ny
    T, ny = _ceil(2.0 * W / size - 1e-9) + 1, _ceil(H / (size * SQRT3_2) - 1e-9)
    return T * ny, T, ny


def _ceil(x: float) -> int:
    # bounds near the float range (1e308 m) overflow the ratio to infinity: far more cells
    # than any limit (the callers answer too_large), not an OverflowError
    return math.ceil(x) if math.isfinite(x) else 2**62


class Layout(Strict):
    """A workspace, its obstacles, and where the corridor starts and ends."""

    bounds: Bounds
    obstacles: list[Obstacle] = Field(default_factory=list, max_length=MAX_OBSTACLES,
                                      description="Obstacles in the workspace")
    clearance: Finite = Field(0.0, ge=0, le=MAX_COORDINATE,
                              description="Distance in m the tool point keeps from every obstacle")
    cell: Cell = Field(default_factory=lambda: Cell.model_validate({}), description="Cell shape and size")
    start: Pose3 | None = Field(None, description="Start pose [x, y, psi] in m, m, rad (required here or at the "
                               "request's top level)")
    end: Pose3 | None = Field(None, description="End pose [x, y, psi] in m, m, rad (required here or at the "
                             "request's top level)")
    psi_range: Point2 | None = Field(None, description="Allowed platform angle [min, max] in rad along the "
                                   "corridor; default: between the start and end angles")

    @field_validator("obstacles", mode="before")
    @classmethod
    def _nulls(cls, v: Any) -> Any:
        return [_drop_nulls(o) for o in v] if isinstance(v, list) else v

    @field_validator("psi_range")
    @classmethod
    def _psi_pair(cls, v: np.ndarray | None) -> np.ndarray | None:
        if v is not None and v[0] > v[1]:
            raise fail(f"must be [min, max] with min <= max, got [{float(v[0]):g}, {float(v[1]):g}]")
        return v

    @model_validator(mode="after")
    def _consistent(self, info: ValidationInfo) -> Layout:
        partial = bool((info.context or {}).get("partial_layout"))  # an imported drawing: no start/end yet
        for key in ("start", "end"):
            pose = getattr(self, key)
            if pose is None and not partial:
                raise fail(f"the {key} pose [x, y, psi] (m, m, rad) is required (in the layout or at the request's "
                           "top level)", key)
        if self.psi_range is not None:
            lo, hi = self.psi_range
            for key in ("start", "end"):
                if getattr(self, key) is None:
                    continue
                angle = float(getattr(self, key)[2])
                if not lo - 1e-12 <= angle <= hi + 1e-12:
                    raise fail(f"must contain the {key} angle {angle:g} rad, got [{lo:g}, {hi:g}]", "psi_range")
        if self.cell.size is not None:
            n = cell_count(self.bounds.lower, self.bounds.upper, self.cell.shape, self.cell.size)[0]
            if n > MAX_CELLS:
                raise fail(f"cell size {self.cell.size:g} m gives {n} {self.cell.shape} cells over the bounds, more "
                           f"than the limit of {MAX_CELLS}; use larger cells", "cell.size", code="too_large")
        return self

    @property
    def start_pose(self) -> np.ndarray:
        """The start pose (validated to be present)."""
        assert self.start is not None
        return self.start

    @property
    def end_pose(self) -> np.ndarray:
        """The end pose (validated to be present)."""
        assert self.end is not None
        return self.end

    @property
    def angle_range(self) -> np.ndarray:
        """``psi_range``, or the range between the start and end angles [rad]."""
        if self.psi_range is not None:
            return self.psi_range
        a, b = float(self.start_pose[2]), float(self.end_pose[2])
        return np.array([min(a, b), max(a, b)])
