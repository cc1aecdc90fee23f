"""DXF drawings to pieces (ezdxf): the outline entities of the modelspace, block
references exploded, curves flattened, in the drawing's units (WCS x, y)."""

from __future__ import annotations

import io
import math
from collections import Counter
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from ..errors import PlannerError
from . import _flatten as fl
from ._budget import MAX_BLOCK_DEPTH, charge, dxf_expanded_entities, entity_ref, spline_points
from ._pieces import Drawing, Piece, check_finite
from ._work import ImportWork, check_import_work, dxf_work

__all__ = ["INSUNITS", "estimate_dxf", "parse_dxf", "read_dxf"]

#: DXF $INSUNITS code -> (name, metres per unit); 0 (unitless) is not here: the default applies
INSUNITS: dict[int, tuple[str, float]] = {
    1: ("in", 0.0254), 2: ("ft", 0.3048), 3: ("mi", 1609.344), 4: ("mm", 1e-3), 5: ("cm", 1e-2), 6: ("m", 1.0),
    7: ("km", 1e3), 8: ("uin", 2.54e-8), 9: ("mil", 2.54e-5), 10: ("yd", 0.9144), 11: ("angstrom", 1e-10),
    12: ("nm", 1e-9), 13: ("um", 1e-6), 14: ("dm", 0.1), 15: ("dam", 10.0), 16: ("hm", 100.0),
    21: ("us-ft", 1200 / 3937), 22: ("us-in", 100 / 3937), 23: ("us-yd", 3600 / 3937),
}
_OUTLINES = {"LINE", "ARC", "CIRCLE", "ELLIPSE", "LWPOLYLINE", "POLYLINE", "SPLINE", "HATCH", "MPOLYGON"}


def parse_dxf(data: bytes, units: tuple[str, float] | None) -> tuple[Any, str, float, str]:
    """A DXF file's bytes parsed (ezdxf's recover mode): the document and its unit (name,
    metres per unit, where from: ``option``, ``drawing`` or ``default``); ``units`` (name,
    metres per unit) overrides ``$INSUNITS``."""
    from ezdxf import recover
    from ezdxf.lldxf.const import DXFError

    try:
        doc, _auditor = recover.read(io.BytesIO(data))
    except (DXFError, UnicodeDecodeError, ValueError, EOFError, IndexError) as exc:
        raise PlannerError("invalid_drawing", f"not a DXF drawing ({type(exc).__name__}: {exc}); save it as DXF "
                           "(ASCII or binary) from your CAD program", "drawing") from None
    except Exception as exc:  # ezdxf may raise anything on garbage; the input's fault
        raise PlannerError("invalid_drawing", f"not a readable DXF drawing ({type(exc).__name__})", "drawing") from None
    if units is not None:
        name, mpu, source = units[0], units[1], "option"
    else:
        code = int(doc.header.get("$INSUNITS", 0) or 0)
        if code == 0:
            name, mpu, source = "mm", 1e-3, "default"
        elif code in INSUNITS:
            (name, mpu), source = INSUNITS[code], "drawing"
        else:
            raise PlannerError("invalid_drawing", f"units unknown: the drawing's $INSUNITS is {code}, which is not a "
                               "length unit rangeplan converts; give the drawing's unit with the units option "
                               "(e.g. units=mm)", "units")
    return doc, name, mpu, source


def estimate_dxf(data: bytes, units: tuple[str, float] | None, tolerance: Callable[[float], float]) -> ImportWork:
    """The estimated import of a DXF file's bytes (:func:`planner.exchange._work.dxf_work`),
    block references bounded first (:func:`~planner.exchange._budget.dxf_expanded_entities`)."""
    doc, _name, mpu, _source = parse_dxf(data, units)
    dxf_expanded_entities(doc)
    return dxf_work(doc, tolerance(mpu), len(data), _OUTLINES)


def read_dxf(data: bytes, units: tuple[str, float] | None,
             tolerance: Callable[[float], float], work_limit_s: float | None = None) -> Drawing:
    """Read a DXF file's bytes. ``units`` (name, metres per unit) overrides ``$INSUNITS``;
    ``tolerance(metres_per_unit)`` is the flattening tolerance in drawing units.
    ``work_limit_s``: refused (``too_much_work``) before any entity is read where the import's
    estimate (:func:`~planner.exchange._work.dxf_work`) exceeds it."""
    doc, name, mpu, source = parse_dxf(data, units)
    dxf_expanded_entities(doc)  # block references bounded before any is exploded
    tol = tolerance(mpu)
    if work_limit_s is not None:  # the work, estimated before it is done
        check_import_work(dxf_work(doc, tol, len(data), _OUTLINES), work_limit_s)
    pieces: list[Piece] = []
    ignored: Counter[str] = Counter()
    for entity, layer in _entities(doc.modelspace(), None, 0, ignored):
        kind = entity.dxftype()
        if kind not in _OUTLINES:
            ignored[kind] += 1
            continue
        try:
            got = list(_pieces(entity, kind, layer, tol))
        except PlannerError:  # a bound of the import (too many vertices): the drawing's answer
            raise
        except (ValueError, ZeroDivisionError, ArithmeticError, AttributeError, IndexError, TypeError):
            got = []
        ref = _ref(entity, kind)
        for p in got:
            p.ref = ref
        check_finite(got, ref, layer)
        if got:
            pieces.extend(got)
        else:
            ignored[f"{kind} (degenerate)"] += 1
    layers = sorted({p.layer for p in pieces})
    return Drawing(pieces, layers, dict(ignored), name, mpu, source)


_ref = entity_ref  # how a message names a DXF entity (planner.exchange._budget)


def _entities(space: Any, insert_layer: str | None, depth: int, ignored: Counter) -> Iterator[tuple[Any, str]]:
    """Every entity of ``space`` with its layer; block references exploded (entities on
    layer 0 take the reference's layer)."""
    for e in space:
        layer = str(e.dxf.get("layer", "0"))
        if insert_layer is not None and layer == "0":
            layer = insert_layer
        if e.dxftype() == "INSERT":
            if depth >= MAX_BLOCK_DEPTH:
                ignored["INSERT (nested too deep)"] += 1
                continue
            try:  # a MINSERT is a grid of references: each cell's copy
                refs = list(e.multi_insert()) if int(getattr(e, "mcount", 1)) > 1 else [e]  # type: ignore[attr-defined]
                virtual = [v for r in refs for v in r.virtual_entities()]
            except Exception:
                ignored["INSERT (not explodable)"] += 1
                continue
            yield from _entities(virtual, layer, depth + 1, ignored)
        else:
            yield e, layer


def _flattened(curve, tol: float) -> np.ndarray:
    """ezdxf's adaptive flattening of a spline within ``tol``, stopped with the error of
    :func:`~planner.exchange._flatten.chords` once it passes the vertices a shape may have."""
    pts = []
    for p in curve.flattening(tol):
        pts.append((float(p[0]), float(p[1])))
        if len(pts) > fl.MAX_POLYGON_POINTS + 1:
            raise fl.too_many_vertices()
    charge(len(pts))
    return np.array(pts, dtype=float).reshape(-1, 2)


def _xy(points) -> np.ndarray:
    return np.array([(float(p[0]), float(p[1])) for p in points], dtype=float).reshape(-1, 2)


def _wcs(entity, pts: np.ndarray, elevation: float = 0.0) -> np.ndarray:
    """OCS points (n, 2) of ``entity`` at ``elevation`` to WCS x, y."""
    ocs = entity.ocs()
    if not ocs.transform:
        return pts
    from ezdxf.math import Vec3
    return _xy(ocs.points_to_wcs([Vec3(x, y, elevation) for x, y in pts]))


def _closed(pts: np.ndarray, tol: float) -> bool:
    return len(pts) > 2 and float(np.hypot(*(pts[0] - pts[-1]))) <= tol


def _piece(pts: np.ndarray, closed: bool, layer: str, source: str, circle=None) -> Piece:
    if closed and len(pts) > 1 and np.array_equal(pts[0], pts[-1]):
        pts = pts[:-1]
    return Piece(np.ascontiguousarray(pts, dtype=float), closed, layer, source, circle)


def _pieces(e, kind: str, layer: str, tol: float) -> Iterator[Piece]:
    if kind == "LINE":
        yield _piece(_xy([e.dxf.start, e.dxf.end]), False, layer, kind)
    elif kind in ("ARC", "CIRCLE"):
        c, r = e.dxf.center, float(e.dxf.radius)
        if not r > 0:
            return
        if kind == "CIRCLE":
            pts = fl.arc((c[0], c[1]), r, 0.0, 2 * math.pi, tol)
            centre = _wcs(e, np.array([[c[0], c[1]]]), float(c[2]))[0]
            yield _piece(_wcs(e, pts, float(c[2])), True, layer, kind, (float(centre[0]), float(centre[1]), r))
        else:
            a0, a1 = math.radians(e.dxf.start_angle), math.radians(e.dxf.end_angle)
            sweep = (a1 - a0) % (2 * math.pi) or 2 * math.pi
            pts = fl.arc((c[0], c[1]), r, a0, sweep, tol)
            yield _piece(_wcs(e, pts, float(c[2])), sweep >= 2 * math.pi, layer, kind)
    elif kind == "ELLIPSE":
        ct = e.construction_tool()
        t0, t1 = float(ct.start_param), float(ct.end_param)
        sweep = (t1 - t0) % (2 * math.pi)
        full = sweep < 1e-9 or abs(sweep - 2 * math.pi) < 1e-9
        sweep = 2 * math.pi if full else sweep
        pts = fl.ellipse(ct.center, ct.major_axis, ct.minor_axis, t0, sweep, tol)
        yield _piece(pts, full, layer, kind)
    elif kind == "LWPOLYLINE":
        rows = np.array(list(e.get_points("xyb")), dtype=float).reshape(-1, 3)
        if len(rows) < 2:
            return
        pts = fl.bulge_polyline(rows[:, :2], rows[:, 2], bool(e.closed), tol)
        pts = _wcs(e, pts, float(e.dxf.get("elevation", 0.0)))
        yield _piece(pts, bool(e.closed) or _closed(pts, 0.0), layer, kind)
    elif kind == "POLYLINE":
        if not (e.is_2d_polyline or e.is_3d_polyline):
            return  # meshes and polyface meshes are not outlines
        verts = list(e.vertices)
        rows = np.array([(v.dxf.location[0], v.dxf.location[1], v.dxf.get("bulge", 0.0) if e.is_2d_polyline else 0.0)
                         for v in verts], dtype=float).reshape(-1, 3)
        if len(rows) < 2:
            return
        pts = fl.bulge_polyline(rows[:, :2], rows[:, 2], bool(e.is_closed), tol)
        if e.is_2d_polyline:
            pts = _wcs(e, pts, float(e.dxf.get("elevation", (0, 0, 0))[2]))
        yield _piece(pts, bool(e.is_closed) or _closed(pts, 0.0), layer, kind)
    elif kind == "SPLINE":
        spline_points(e, _ref(e, kind))  # counted before ezdxf builds the curve
        pts = _flattened(e.construction_tool(), tol)
        if len(pts) >= 2:
            yield _piece(pts, bool(e.closed) or _closed(pts, 0.0), layer, kind)
    else:  # HATCH, MPOLYGON: boundary paths
        yield from _hatch(e, kind, layer, tol)


def _hatch(e, kind: str, layer: str, tol: float) -> Iterator[Piece]:
    elevation = float(e.dxf.get("elevation", (0, 0, 0))[2])
    for path in e.paths:
        if path.type.name == "POLYLINE":  # BoundaryPathType.POLYLINE
            rows = np.array([(v[0], v[1], v[2] if len(v) > 2 else 0.0) for v in path.vertices], float).reshape(-1, 3)
            if len(rows) >= 2:
                pts = _wcs(e, fl.bulge_polyline(rows[:, :2], rows[:, 2], True, tol), elevation)
                yield _piece(pts, True, layer, kind)
            continue
        for edge in path.edges:  # loose pieces: joined like LINE and ARC
            t = edge.type.name
            if t == "LINE":
                pts = _xy([edge.start, edge.end])
            elif t == "ARC":  # counter-clockwise after loading (ezdxf)
                a0, a1 = math.radians(edge.start_angle), math.radians(edge.end_angle)
                sweep = (a1 - a0) % (2 * math.pi) or 2 * math.pi
                pts = fl.arc(edge.center, float(edge.radius), a0, sweep, tol)
            elif t == "ELLIPSE":
                ct = edge.construction_tool()
                t0, t1 = float(ct.start_param), float(ct.end_param)
                sweep = (t1 - t0) % (2 * math.pi) or 2 * math.pi
                pts = fl.ellipse(ct.center, ct.major_axis, ct.minor_axis, t0, sweep, tol)
            elif t == "SPLINE":
                spline_points(edge, f"a spline edge of {_ref(e, kind)}")
                pts = _flattened(edge.construction_tool(), tol)
            else:
                continue
            yield _piece(_wcs(e, pts, elevation), False, layer, kind)
