"""A plan as a DXF drawing to overlay on the CAD drawing it came from, in mm
(``$INSUNITS`` = 4): the tool path as a polyline on layer ``PATH``, each corridor cell
(its exact polygon, or its box) as a closed polyline on ``CORRIDOR``, and, when the
layout is given, the obstacles on ``OBSTACLES`` (rectangles and polygons as closed
polylines, a polygon's holes as further closed polylines inside it, circles as circles)
and the workspace bounds on ``BOUNDS``.
"""

from __future__ import annotations

import io
from collections.abc import Sequence

import numpy as np

from ..schema import Layout, PlanResult

__all__ = ["DXF_LAYERS", "to_dxf"]

#: layer name -> ACI colour
DXF_LAYERS = {"PATH": 1, "CORRIDOR": 3, "OBSTACLES": 8, "BOUNDS": 5}
MM = 1e3  # mm per m


def _box(lower, upper) -> list[tuple[float, float]]:
    (x0, y0), (x1, y1) = np.asarray(lower, float)[:2] * MM, np.asarray(upper, float)[:2] * MM
    return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]


def _ring(points) -> list[tuple[float, float]]:
    return [(float(x), float(y)) for x, y in np.asarray(points, float)[:, :2] * MM]


def to_dxf(result: PlanResult, layout: Layout | None = None, header: Sequence[str] = ()) -> str:
    """The DXF text (see the module doc); ``header`` lines go into the DXF header as custom
    properties ``rangeplan1``, ``rangeplan2``, ... (the editor's design, plan id, request hash)."""
    from ezdxf import units
    from ezdxf.document import Drawing

    doc = Drawing.new("R2010")
    doc.units = units.MM
    doc.header["$MEASUREMENT"] = 1  # metric
    for i, line in enumerate(header):
        doc.header.custom_vars.append(f"rangeplan{i + 1}", " ".join(str(line).splitlines()))
    for name, colour in DXF_LAYERS.items():
        doc.layers.add(name, color=colour)
    msp = doc.modelspace()
    path = np.asarray(result.pose, float)[:, :2] * MM
    msp.add_lwpolyline(path.tolist(), dxfattribs={"layer": "PATH"})
    for seg in result.corridor.segments or []:
        pts = _ring(seg.polygon) if seg.polygon is not None else _box(seg.lower, seg.upper)
        if len({p for p in pts}) >= 2:  # a point segment (start, end) has no outline
            msp.add_lwpolyline(pts, close=True, dxfattribs={"layer": "CORRIDOR"})
    if layout is not None:
        msp.add_lwpolyline(_box(layout.bounds.lower, layout.bounds.upper), close=True,
                           dxfattribs={"layer": "BOUNDS"})
        for ob in layout.obstacles:
            if ob.type == "circle":
                c = np.asarray(ob.center, float) * MM
                msp.add_circle((float(c[0]), float(c[1])), float(ob.radius) * MM, dxfattribs={"layer": "OBSTACLES"})
            elif ob.type == "rectangle":
                msp.add_lwpolyline(_box(ob.lower, ob.upper), close=True, dxfattribs={"layer": "OBSTACLES"})
            else:
                for ring in (ob.points, *ob.holes):
                    msp.add_lwpolyline(_ring(ring), close=True, dxfattribs={"layer": "OBSTACLES"})
    doc.header["$EXTMIN"] = (*path.min(axis=0).tolist(), 0.0)
    doc.header["$EXTMAX"] = (*path.max(axis=0).tolist(), 0.0)
    buf = io.StringIO()
    doc.write(buf)
    return buf.getvalue()
