"""Drawings for the import tests: the real LibreCAD ones in tests/data/drawings, drawings
generated with ezdxf for each entity type, and an independent reference region.

The reference does not use rangeplan's import: each entity becomes a path by ezdxf's own
``ezdxf.path.make_path`` (arcs and ellipses as fine Bezier curves), flattened by ezdxf;
all the linework is noded together and polygonized by shapely, and a face is an obstacle
when an even number of faces' outlines enclose it (even-odd)."""

from __future__ import annotations

import io
import math
from pathlib import Path

import ezdxf
import numpy as np
import shapely
from ezdxf import path as ezpath

DRAWINGS = Path(__file__).resolve().parent / "data" / "drawings"
LIBRECAD = sorted(DRAWINGS.glob("*.dxf"))
#: $INSUNITS -> metres per unit, the test's own table (0: unset, mm by rangeplan's rule)
INSUNITS_M = {0: 1e-3, 1: 0.0254, 2: 0.3048, 4: 1e-3, 5: 1e-2, 6: 1.0, 14: 0.1}


def reference_region(data: bytes, tol_m: float, *, layers: list[str] | None = None, scale: float = 1.0,
                     units_m: float | None = None) -> shapely.Geometry:
    """The obstacle region of a DXF drawing [m] (see the module doc), flattened to ``tol_m``."""
    doc = ezdxf.read(io.StringIO(data.decode("utf-8", errors="replace")))
    k = scale * (units_m if units_m is not None else INSUNITS_M[int(doc.header.get("$INSUNITS", 0))])
    lines = []
    for e in doc.modelspace():
        if layers is not None and e.dxf.layer not in layers:
            continue
        kind = e.dxftype()
        if kind == "HATCH":
            paths = list(ezpath.from_hatch(e))
        elif kind in ("LINE", "ARC", "CIRCLE", "ELLIPSE", "LWPOLYLINE", "POLYLINE", "SPLINE"):
            paths = [ezpath.make_path(e, segments=64)]
        else:
            continue
        for p in paths:
            for sub in p.sub_paths():
                pts = np.array([(v.x, v.y) for v in sub.flattening(tol_m / k / 4, segments=64)]) * k
                if len(pts) >= 2:
                    lines.append(shapely.LineString(pts))
    return even_odd(lines)


def even_odd(lines: list) -> shapely.Geometry:
    """Faces of the noded linework at even depth (enclosed by an even number of face outlines)."""
    noded = shapely.union_all(lines, grid_size=1e-10)  # on a 1e-10 m grid: ends that meet are equal
    faces = list(shapely.get_parts(shapely.polygonize(shapely.get_parts(noded))))
    shells = [shapely.Polygon(f.exterior) for f in faces]
    keep = []
    for i, f in enumerate(faces):
        p = shapely.point_on_surface(f)
        depth = sum(1 for j, s in enumerate(shells) if j != i and s.area > f.area and s.contains(p))
        if depth % 2 == 0:
            keep.append(f)
    return shapely.union_all(keep) if keep else shapely.Polygon()


def obstacle_region(layout, circle_quad_segs: int = 1024) -> shapely.Geometry:
    """The union of a layout's obstacles [m] (circles finely polygonised)."""
    shapes = []
    for ob in layout.obstacles:
        if ob.type == "circle":
            shapes.append(shapely.Point(*ob.center).buffer(ob.radius, quad_segs=circle_quad_segs))
        elif ob.type == "rectangle":
            shapes.append(shapely.box(*ob.lower, *ob.upper))
        else:
            shapes.append(shapely.Polygon(ob.points, [np.asarray(h) for h in ob.holes]))
    return shapely.union_all(shapes)


def dxf_bytes(doc) -> bytes:
    buf = io.StringIO()
    doc.write(buf)
    return buf.getvalue().encode()


def new_doc(insunits: int = 4):
    doc = ezdxf.new("R2010", units=insunits)
    if insunits == 0:
        doc.header["$INSUNITS"] = 0
    return doc


def rounded_rectangle(msp, x0, y0, w, h, r, layer="0"):
    """Loose LINE and ARC pieces (as CAD programs draw them), drawn in a scrambled order and
    directions; exact area ``w h - (4 - pi) r^2``."""
    x1, y1 = x0 + w, y0 + h
    msp.add_line((x1 - r, y0), (x0 + r, y0), dxfattribs={"layer": layer})  # reversed
    msp.add_arc((x1 - r, y1 - r), r, 0, 90, dxfattribs={"layer": layer})
    msp.add_line((x0, y0 + r), (x0, y1 - r), dxfattribs={"layer": layer})
    msp.add_arc((x0 + r, y0 + r), r, 180, 270, dxfattribs={"layer": layer})
    msp.add_line((x1, y1 - r), (x1, y0 + r), dxfattribs={"layer": layer})  # reversed
    msp.add_arc((x0 + r, y1 - r), r, 90, 180, dxfattribs={"layer": layer})
    msp.add_line((x0 + r, y1), (x1 - r, y1), dxfattribs={"layer": layer})
    msp.add_arc((x1 - r, y0 + r), r, 270, 360, dxfattribs={"layer": layer})
    return w * h - (4 - math.pi) * r * r


def entity_drawing(kind: str) -> tuple[bytes, float, float]:
    """A drawing (mm) of one entity type: ``(dxf bytes, exact obstacle area [m^2], curved
    length [m] of its outline, for the flattening bound)``."""
    doc = new_doc(4)
    msp = doc.modelspace()
    mm2 = 1e-6
    if kind == "lwpolyline":  # closed, two bulged (semicircular) ends: a stadium 40 x 20 mm
        msp.add_lwpolyline([(0, 0, 0), (40, 0, 1), (40, 20, 0), (0, 20, 1)], format="xyb", close=True)
        return dxf_bytes(doc), (40 * 20 + math.pi * 10 ** 2) * mm2, 2 * math.pi * 10 * 1e-3
    if kind == "polyline":  # 2D POLYLINE, closed, one bulge -1 (a clockwise semicircle outwards)
        msp.add_polyline2d([(0, 0), (30, 0), (30, 20), (0, 20)], close=True)
        pl = msp.query("POLYLINE").first
        pl.vertices[1].dxf.bulge = -1.0  # 30,0 -> 30,20 bulging to +x? clockwise from below: outwards
        return dxf_bytes(doc), None, math.pi * 10 * 1e-3  # area checked against the reference only
    if kind == "circle":
        msp.add_circle((10, 5), 12.5)
        return dxf_bytes(doc), math.pi * 12.5 ** 2 * mm2, 2 * math.pi * 12.5 * 1e-3
    if kind == "ellipse":  # rotated 30 degrees, a = 20, b = 8 mm
        major = (20 * math.cos(math.radians(30)), 20 * math.sin(math.radians(30)), 0)
        msp.add_ellipse((5, 5), major_axis=major, ratio=0.4)
        return dxf_bytes(doc), math.pi * 20 * 8 * mm2, 2 * math.pi * 20 * 1e-3
    if kind == "spline":  # a clamped cubic B-spline whose last control point is its first: a closed blob
        pts = [(0, 0), (30, -5), (45, 15), (25, 35), (-5, 25), (0, 0)]
        msp.add_open_spline(pts, degree=3)
        return dxf_bytes(doc), None, 0.2
    if kind == "hatch":  # a polyline-path square with a hole, and an edge-path disc (line + arc edges)
        h = msp.add_hatch()
        h.paths.add_polyline_path([(0, 0), (40, 0), (40, 40), (0, 40)], is_closed=True)
        h.paths.add_polyline_path([(10, 10), (30, 10), (30, 30), (10, 30)], is_closed=True)
        h2 = msp.add_hatch()
        ep = h2.paths.add_edge_path()
        ep.add_line((60, 0), (80, 0))
        ep.add_arc((70, 0), 10, 0, 180)  # a half disc above the line
        return dxf_bytes(doc), (40 * 40 - 20 * 20 + math.pi * 10 ** 2 / 2) * mm2, math.pi * 10 * 1e-3
    if kind == "lines_arcs":
        area = rounded_rectangle(msp, 0, 0, 60, 30, 6)
        return dxf_bytes(doc), area * mm2, 2 * math.pi * 6 * 1e-3
    if kind == "nested":  # outline, a hole, an island in the hole, and a hole drawn as loose lines
        msp.add_lwpolyline([(0, 0), (100, 0), (100, 60), (0, 60)], close=True)
        msp.add_circle((30, 30), 20)  # hole
        msp.add_lwpolyline([(25, 25), (35, 25), (35, 35), (25, 35)], close=True)  # island in the hole
        for a, b in [((70, 20), (90, 20)), ((90, 20), (90, 40)), ((90, 40), (70, 40)), ((70, 40), (70, 20))]:
            msp.add_line(a, b)  # a square hole of loose lines
        area = 100 * 60 - math.pi * 20 ** 2 + 10 * 10 - 20 * 20
        return dxf_bytes(doc), area * mm2, 2 * math.pi * 20 * 1e-3
    raise ValueError(kind)


ENTITY_KINDS = ["lwpolyline", "polyline", "circle", "ellipse", "spline", "hatch", "lines_arcs", "nested"]
