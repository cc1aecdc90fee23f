"""Drawings (DXF, SVG) to a :class:`~planner.schema.Layout`: the closed shapes of the chosen
layers become obstacles (nested shapes holes), placed in the robot's workspace in m.

    result = import_drawing(Path("part.dxf").read_bytes(), {"scale": 0.1, "offset": [-0.05, -0.04]})
    result.layout, result.report

The drawing's unit comes from the drawing (DXF ``$INSUNITS``, mm when unset; SVG: CSS px,
sized by the document's physical width/height) unless ``units`` says otherwise; every
tolerance and placement option is in m in the workspace (see
:class:`planner.schema.ImportOptions`). Errors are :class:`~planner.errors.PlannerError`
with code ``invalid_drawing`` (not a drawing, units unknown, no closed shape, unknown
layers, an element with a coordinate that is not finite or lies beyond ``MAX_COORDINATE`` m
once placed: named), ``invalid_input`` (an option) or ``too_large``.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np
import shapely
from pydantic import ValidationError

from ..errors import PlannerError
from ..schema import (
    DRAWING_UNITS,
    MAX_COORDINATE,
    MAX_HOLES,
    MAX_OBSTACLES,
    MAX_POLYGON_POINTS,
    PARTIAL_LAYOUT,
    ImportOptions,
    ImportReport,
    ImportResult,
    Layout,
    planner_error,
)
from ._budget import vertex_budget
from ._dxf_in import estimate_dxf, read_dxf
from ._pieces import Drawing, Piece
from ._regions import Chain, Region, regions
from ._svg_in import estimate_svg, read_svg
from ._work import ImportWork

__all__ = ["DRAWING_FORMATS", "ImportWork", "drawing_format", "estimate_import", "import_drawing"]

#: accepted drawing formats by content type
DRAWING_FORMATS: dict[str, Literal["dxf", "svg"]] = {
    "application/dxf": "dxf", "image/vnd.dxf": "dxf", "image/x-dxf": "dxf", "application/x-dxf": "dxf",
    "image/svg+xml": "svg"}


def drawing_format(data: bytes, filename: str | None = None, content_type: str | None = None) -> Literal["dxf", "svg"]:
    """The format of a drawing from its content type, its file name's extension, or its
    first bytes; raises ``invalid_drawing`` when none says DXF or SVG."""
    ct = (content_type or "").split(";")[0].strip().lower()
    if ct in DRAWING_FORMATS:
        return DRAWING_FORMATS[ct]
    name = (filename or "").lower()
    if name.endswith(".dxf"):
        return "dxf"
    if name.endswith((".svg", ".svgz")):
        return "svg"
    head = data[:4096].lstrip().lower()
    if head.startswith(b"autocad binary dxf") or head.startswith(b"0\r\nsection") or head.startswith(b"0\nsection") \
            or head.startswith(b"999"):
        return "dxf"
    if b"<svg" in head:
        return "svg"
    raise PlannerError("invalid_drawing", "not a DXF or SVG drawing (give a .dxf or .svg file, or the content type "
                       "application/dxf, image/vnd.dxf or image/svg+xml)", "drawing")


def _options(options: ImportOptions | dict[str, Any] | None) -> ImportOptions:
    if isinstance(options, ImportOptions):
        return options
    try:
        return ImportOptions.model_validate(options or {})
    except ValidationError as exc:
        raise planner_error(exc) from None


def _place(drawing: Drawing, opt: ImportOptions) -> list[Piece]:
    """The pieces in the workspace: ``offset + R(rotation) (scale metres_per_unit p)`` [m]."""
    k = opt.scale * drawing.metres_per_unit
    c, s = math.cos(opt.rotation), math.sin(opt.rotation)
    R = np.array([[c, -s], [s, c]]) * k
    off = np.asarray(opt.offset, float)
    out = []
    for p in drawing.pieces:
        pts = p.points @ R.T + off
        circle = None
        if p.circle is not None:
            cx, cy = np.array(p.circle[:2]) @ R.T + off
            circle = (float(cx), float(cy), p.circle[2] * k)
        out.append(Piece(pts, p.closed, p.layer, p.source, circle, p.ref))
    return out


def _check_placed(pieces: list[Piece]) -> None:
    """Raise ``invalid_drawing`` naming the first piece with a coordinate beyond
    ``MAX_COORDINATE`` m of the workspace origin once placed (a layout's limit), or not finite."""
    for p in pieces:
        reach = float(np.max(np.abs(p.points))) if len(p.points) else 0.0
        if p.circle is not None:
            reach = max(reach, abs(p.circle[0]) + p.circle[2], abs(p.circle[1]) + p.circle[2])
        if not reach <= MAX_COORDINATE:  # NaN too
            where = f"{reach:.3g} m" if math.isfinite(reach) else "infinitely far"
            raise PlannerError("invalid_drawing", f"{p.ref or p.source} on layer {p.layer!r} lies {where} from the "
                               f"workspace origin once placed, beyond the limit of {MAX_COORDINATE:g} m; check the "
                               "drawing's units and the scale and offset options, or leave its layer out", "drawing")


def _layers(drawing: Drawing, opt: ImportOptions) -> list[str]:
    present = drawing.layers
    if opt.bounds_layer is not None and opt.bounds_layer not in present:
        raise PlannerError("invalid_drawing", f"the bounds layer {opt.bounds_layer!r} has no geometry in the drawing; "
                           f"its layers: {', '.join(present) or 'none'}", "bounds_layer")
    if opt.layers is None:
        chosen = [name for name in present if name != opt.bounds_layer]
        if not chosen:
            raise PlannerError("invalid_drawing", f"no closed shape: the only layer with geometry is the bounds layer "
                               f"{opt.bounds_layer!r}", "layers")
        return chosen
    missing = [name for name in opt.layers if name not in present]
    if missing:
        raise PlannerError("invalid_drawing", f"no geometry on layer(s) {', '.join(map(repr, missing))}; the "
                           f"drawing's layers: {', '.join(present) or 'none'}", "layers")
    return list(opt.layers)


_DECIMALS = 12  # coordinates rounded to 1e-12 m: no float noise of the unit conversion in the JSON


def _round(a: np.ndarray) -> Any:
    return (np.round(np.asarray(a, float), _DECIMALS) + 0.0).tolist()


def _obstacle(region: Region) -> dict[str, Any]:
    if region.circle is not None:
        cx, cy, r = region.circle
        return {"type": "circle", "center": _round(np.array([cx, cy])), "radius": float(np.round(r, _DECIMALS))}
    poly = shapely.orient_polygons(region.polygon) if hasattr(shapely, "orient_polygons") else region.polygon
    rings = [np.asarray(poly.exterior.coords)[:-1, :2], *(np.asarray(h.coords)[:-1, :2] for h in poly.interiors)]
    if len(rings) - 1 > MAX_HOLES:
        raise PlannerError("too_large", f"a shape on layer {region.layer!r} has {len(rings) - 1} holes (shapes nested "
                           f"inside it), more than the limit of {MAX_HOLES}", "layers")
    if sum(len(r) for r in rings) > MAX_POLYGON_POINTS:
        raise PlannerError("too_large", f"a shape on layer {region.layer!r} has {sum(len(r) for r in rings)} vertices "
                           f"(outline and holes) after flattening, more than the limit of {MAX_POLYGON_POINTS}; use a "
                           "larger flatten_tolerance", "flatten_tolerance")
    out: dict[str, Any] = {"type": "polygon", "points": _round(rings[0])}
    if len(rings) > 1:
        out["holes"] = [_round(r) for r in rings[1:]]
    return out


def _chain_text(chains: list[Chain], limit: int = 3) -> str:
    parts = []
    for c in chains[:limit]:
        a, b = c.coords[0], c.coords[-1]
        parts.append(f"{c.pieces} piece(s) on layer {c.layer!r} from ({a[0]:.4f} m, {a[1]:.4f} m) to "
                     f"({b[0]:.4f} m, {b[1]:.4f} m), gap {float(np.hypot(*(b - a))) * 1e3:.3f} mm")
    more = f" and {len(chains) - limit} more" if len(chains) > limit else ""
    return "; ".join(parts) + more


class _Tolerance:
    """The flattening tolerance in drawing units for a drawing's metres per unit."""

    def __init__(self, opt: ImportOptions) -> None:
        self.opt = opt

    def __call__(self, metres_per_unit: float) -> float:
        return self.opt.flatten_tolerance / (self.opt.scale * metres_per_unit)


def estimate_import(data: bytes, options: ImportOptions | dict[str, Any] | None = None, *,
                    format: Literal["dxf", "svg"] | None = None, filename: str | None = None,
                    content_type: str | None = None) -> ImportWork:
    """The estimated compute time of :func:`import_drawing` with these arguments
    (:class:`~planner.exchange._work.ImportWork`: ``seconds``, ``detail``, ``field`` and
    ``message(limit_s)``), from the parsed file's counts (:mod:`planner.exchange._work`): the
    file parsed, no curve made. Raises what the import raises for a file it cannot read or
    whose block references or ``<use>`` references are over their bounds."""
    opt = _options(options)
    fmt = format or drawing_format(data, filename, content_type)
    units = (opt.units, DRAWING_UNITS[opt.units]) if opt.units is not None else None
    return estimate_dxf(data, units, _Tolerance(opt)) if fmt == "dxf" else estimate_svg(data, units, _Tolerance(opt))


def import_drawing(data: bytes, options: ImportOptions | dict[str, Any] | None = None, *,
                   format: Literal["dxf", "svg"] | None = None, filename: str | None = None,
                   content_type: str | None = None, work_limit_s: float | None = None) -> ImportResult:
    """A drawing's bytes as a layout and a report (:class:`planner.schema.ImportResult`).
    ``work_limit_s``: a drawing whose estimated import (:func:`estimate_import`) exceeds it
    is refused (``too_much_work``, naming what to change) once parsed, before its entities
    are exploded and its curves flattened."""
    opt = _options(options)
    fmt = format or drawing_format(data, filename, content_type)
    units = (opt.units, DRAWING_UNITS[opt.units]) if opt.units is not None else None
    tolerance = _Tolerance(opt)
    with vertex_budget():  # every curve of the drawing together (planner.exchange._budget)
        drawing = read_dxf(data, units, tolerance, work_limit_s) if fmt == "dxf" \
            else read_svg(data, units, tolerance, work_limit_s)
    if not drawing.pieces:
        found = ", ".join(f"{n} {k}" for k, n in sorted(drawing.ignored.items())) or "nothing"
        raise PlannerError("invalid_drawing", f"no closed shape: the drawing has no outlines (lines, arcs, circles, "
                           f"polylines, ellipses, splines, hatches); found {found}", "drawing")
    layers = _layers(drawing, opt)
    placed = _place(drawing, opt)
    chosen = [p for p in placed if p.layer in layers]
    _check_placed([p for p in placed if p.layer in layers or p.layer == opt.bounds_layer])
    found, chains = regions(chosen, opt.join_tolerance)
    if not found:
        why = f"; pieces left open: {_chain_text(chains)}" if chains else ""
        raise PlannerError("invalid_drawing", f"no closed shape on layer(s) {', '.join(map(repr, layers))}{why} "
                           "(close the outlines in the drawing or raise join_tolerance)",
                           "layers" if opt.layers else "drawing")
    if len(found) > MAX_OBSTACLES:
        raise PlannerError("too_large", f"the drawing has {len(found)} closed shapes, more than the limit of "
                           f"{MAX_OBSTACLES} obstacles; choose fewer layers", "layers")
    obstacles = [_obstacle(r) for r in found]
    # bounds: a layer's extents, or the shapes' (and start/end) extents plus the margin
    if opt.bounds_layer is not None:
        pts = np.concatenate([p.points for p in placed if p.layer == opt.bounds_layer])
        lower, upper, bounds_source = pts.min(axis=0), pts.max(axis=0), "layer"
    else:
        ext = np.array([shapely.bounds(r.polygon) for r in found])
        lower, upper = ext[:, :2].min(axis=0), ext[:, 2:].max(axis=0)
        for pose in (opt.start, opt.end):
            if pose is not None:
                lower, upper = np.minimum(lower, pose[:2]), np.maximum(upper, pose[:2])
        lower, upper, bounds_source = lower - opt.margin, upper + opt.margin, "extents"
    if not np.all(upper > lower):
        raise PlannerError("invalid_drawing", "the workspace bounds have no area (the bounds layer or the shapes "
                           "are a line); give a margin or a bounds layer with a rectangle", "bounds_layer"
                           if opt.bounds_layer else "margin")
    raw: dict[str, Any] = {"bounds": {"lower": _round(lower), "upper": _round(upper)}, "obstacles": obstacles}
    for key in ("start", "end"):
        pose = getattr(opt, key)
        if pose is not None:
            raw[key] = np.asarray(pose, float).tolist()
    try:
        layout = Layout.model_validate(raw, context=PARTIAL_LAYOUT)
    except ValidationError as exc:
        raise planner_error(exc, "layout") from None
    shapes = []
    for i, (r, ob) in enumerate(zip(found, obstacles)):
        circle = ob["type"] == "circle"
        holes = len(ob.get("holes", []))
        area = math.pi * r.circle[2] ** 2 if circle and r.circle else float(r.polygon.area)
        shapes.append({"obstacle": i, "kind": ob["type"], "layer": r.layer, "source": r.source, "area_m2": area,
                       "holes": holes, "vertices": 0 if circle else len(ob["points"]) + sum(map(len, ob.get("holes",
                                                                                                        [])))})
    report = ImportReport.model_validate({
        "format": fmt, "units": drawing.unit, "units_source": drawing.units_source,
        "metres_per_unit": drawing.metres_per_unit, "scale": opt.scale, "layers": layers,
        "layers_in_drawing": drawing.layers, "shapes": shapes, "holes": sum(s["holes"] for s in shapes),
        "open_chains": [{"layer": c.layer, "start": c.coords[0].tolist(), "end": c.coords[-1].tolist(),
                         "gap_m": float(np.hypot(*(c.coords[-1] - c.coords[0]))),
                         "length_m": float(np.sum(np.hypot(*np.diff(c.coords, axis=0).T))), "pieces": c.pieces,
                         "why": c.why} for c in chains],
        "ignored": drawing.ignored, "bounds_source": bounds_source, "area_m2": sum(s["area_m2"] for s in shapes),
        "flatten_tolerance_m": opt.flatten_tolerance, "join_tolerance_m": opt.join_tolerance})
    return ImportResult.model_construct(layout=layout, report=report)
