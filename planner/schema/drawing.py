"""Drawing import: the options (:class:`ImportOptions`, shared by the CLI, the HTTP query
parameters and the docs), the report of what was read (:class:`ImportReport`) and the
answer (:class:`ImportResult`: a :class:`~planner.schema.Layout` and its report).

Units change here, at the edge: a drawing's coordinates are in its own units (DXF
``$INSUNITS``, SVG CSS pixels or the document's physical size), every field below is in
the robot's workspace in SI units (m, rad) after placement::

    p_workspace = offset + R(rotation) (scale * metres_per_unit * p_drawing)
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator

from ._types import Coordinate, Finite, Point2, Pose3, Strict, Vec2
from .layout import Layout
from .limits import MAX_COORDINATE

__all__ = ["DRAWING_UNITS", "DrawingShape", "ImportOptions", "ImportReport", "ImportResult", "OpenChain",
           "PARTIAL_LAYOUT"]

#: length units a drawing may be in, metres per unit
DRAWING_UNITS: dict[str, float] = {"um": 1e-6, "mm": 1e-3, "cm": 1e-2, "dm": 0.1, "m": 1.0, "in": 0.0254,
                                   "ft": 0.3048, "yd": 0.9144, "mil": 2.54e-5, "px": 0.0254 / 96,
                                   "pt": 0.0254 / 72}

#: validation context under which a layout may lack ``start`` and ``end`` (an imported
#: drawing before the user says where the robot starts and ends)
PARTIAL_LAYOUT = {"partial_layout": True}

#: smallest scale factor (and 1 / the largest) a drawing may be placed with
MIN_SCALE = 1e-9
#: smallest join and flatten tolerance [m] (1 nm; a curve flattened finer than its bound of
#: vertices per shape is refused before it is flattened)
MIN_TOLERANCE = 1e-9

Unit = Literal["um", "mm", "cm", "dm", "m", "in", "ft", "yd", "mil", "px", "pt"]


class ImportOptions(Strict):
    """How a drawing becomes a layout. Every length in m and angle in rad, in the robot's
    workspace (after units and scale), except ``units`` which names the drawing's unit."""

    units: Unit | None = Field(None, description="Length unit of the drawing's coordinates: um, mm, cm, dm, m, in, "
                               "ft, yd, mil, px (CSS, 1/96 in), pt (1/72 in). Default: from the drawing (DXF "
                               "$INSUNITS, "
                               "mm when unset; SVG: the document's width/height units, else CSS px)")
    layers: list[str] | None = Field(None, min_length=1, description="Layers whose closed shapes become obstacles "
                                     "(DXF layer names; SVG top-level groups by Inkscape label or id). Default: all "
                                     "layers except bounds_layer")
    offset: Point2 = Field(default_factory=lambda: np.zeros(2), description="Translation [x, y] in m applied after "
                           "units, scale and rotation")
    rotation: Coordinate = Field(0.0, description="Rotation in rad (counter-clockwise) about the drawing's origin, "
                             "applied after units and scale")
    scale: Finite = Field(1.0, ge=MIN_SCALE, le=1.0 / MIN_SCALE, description="Scale factor applied to the drawing "
                          "(after its units)")
    join_tolerance: Finite = Field(1e-5, ge=MIN_TOLERANCE, le=0.01, description="Loose pieces (LINE, ARC, open "
                                   "polylines) whose ends are closer than this (m, in the workspace) are joined into "
                                   "closed outlines")
    flatten_tolerance: Finite = Field(1e-4, ge=MIN_TOLERANCE, le=0.01, description="Largest distance in m (in the "
                                      "workspace) between a curve and the polygon that replaces it (arcs, ellipses, "
                                      "splines, Bezier curves)")
    margin: Finite = Field(0.01, ge=0, le=MAX_COORDINATE, description="Distance in m added around the drawing's "
                           "extents (the obstacles, start and end) to make the workspace bounds; not used with "
                           "bounds_layer")
    bounds_layer: str | None = Field(None, min_length=1, description="Layer whose extents are the workspace bounds "
                                     "(its shapes are not obstacles); default: the extents plus margin")
    start: Pose3 | None = Field(None, description="Start pose [x, y, psi] in m, m, rad (written into the layout)")
    end: Pose3 | None = Field(None, description="End pose [x, y, psi] in m, m, rad (written into the layout)")

    @field_validator("offset", mode="before")
    @classmethod
    def _offset_default(cls, v: Any) -> Any:
        return [0.0, 0.0] if v is None else v


class DrawingShape(Strict):
    """A closed shape of the drawing that became an obstacle."""

    obstacle: int = Field(description="Index of the obstacle in layout.obstacles")
    kind: Literal["polygon", "circle"] = Field(description="Obstacle type written")
    layer: str = Field(description="Layer (or SVG group) of the shape's outline")
    source: str = Field(description="What the outline was made of, e.g. 'LWPOLYLINE', 'CIRCLE', "
                        "'chain of 3 LINE + 4 ARC'")
    area_m2: float = Field(description="Obstacle area (holes subtracted), m^2")
    holes: int = Field(description="Holes in it: shapes nested inside it (count)")
    vertices: int = Field(description="Vertices of the outline and its holes (count; 0 for a circle)")


class OpenChain(Strict):
    """Pieces that do not close: left out of the layout, listed so the drawing can be fixed."""

    layer: str = Field(description="Layer of the chain's first piece")
    start: Vec2 = Field(description="One free end [x, y] in m (workspace)")
    end: Vec2 = Field(description="The other end [x, y] in m (workspace)")
    gap_m: float = Field(description="Distance between the two ends, m (join_tolerance would have to exceed it)")
    length_m: float = Field(description="Length of the chain, m")
    pieces: int = Field(description="Pieces in the chain (count)")
    why: Literal["open", "encloses nothing"] = Field(description="'open': an end meets nothing within the join "
                                                     "tolerance; 'encloses nothing': joined at both ends but not part "
                                                     "of a closed outline")


class ImportReport(Strict):
    """What the import read, used and left out."""

    format: Literal["dxf", "svg"] = Field(description="Drawing format")
    units: str = Field(description="Unit of the drawing's coordinates")
    units_source: Literal["drawing", "option", "default"] = Field(description="Where the unit came from: the "
                                                                   "drawing ($INSUNITS, SVG size), the units "
                                                                   "option, or the default (mm; SVG: CSS px)")
    metres_per_unit: float = Field(description="Metres per drawing unit (before scale)")
    scale: float = Field(description="Scale applied")
    layers: list[str] = Field(description="Layers whose shapes were used")
    layers_in_drawing: list[str] = Field(description="Every layer with geometry in the drawing")
    shapes: list[DrawingShape] = Field(description="Each obstacle written, with where it came from")
    holes: int = Field(description="Holes in all obstacles (count)")
    open_chains: list[OpenChain] = Field(description="Pieces left open (not in the layout), with their ends in m")
    ignored: dict[str, int] = Field(description="Entities that are not outlines (TEXT, DIMENSION, POINT, ...) by "
                                    "type (count)")
    bounds_source: Literal["layer", "extents"] = Field(description="'layer': the bounds layer's extents; "
                                                       "'extents': the shapes' (and start/end) extents plus margin")
    area_m2: float = Field(description="Total obstacle area, m^2")
    flatten_tolerance_m: float = Field(description="Curve flattening tolerance used, m")
    join_tolerance_m: float = Field(description="Join tolerance used, m")


class ImportResult(Strict):
    """``POST /v1/import``'s answer: the layout (start and end only when given) and the report."""

    layout: Layout = Field(description="The drawing as a layout (m, rad); a plan request's 'layout' once it has "
                           "start and end")
    report: ImportReport

    def to_json_dict(self) -> dict[str, Any]:
        """JSON types; the layout with the fields the import set (no null start/end)."""
        return {"layout": self.layout.model_dump(mode="json", exclude_unset=True),
                "report": self.report.model_dump(mode="json")}

    def to_request(self) -> dict[str, Any]:
        """A plan request (JSON types) with this layout."""
        return {"layout": self.to_json_dict()["layout"]}
