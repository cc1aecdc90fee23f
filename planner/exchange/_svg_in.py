"""SVG drawings to pieces (svgelements): every shape (path, rect, circle, ellipse,
polygon, polyline, line) with its transforms applied, curves flattened.

Coordinates: svgelements gives CSS pixels (96 per inch) with the document's viewBox and
physical size applied. The y axis is turned up (``y_up = height - y``, the document's
height in px) so the drawing keeps its orientation on screen in the workspace (+y up).
Layers are the top-level groups: their Inkscape label, else their id.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from collections import Counter
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import PlannerError
from ..schema.drawing import DRAWING_UNITS
from . import _flatten as fl
from ._budget import svg_expanded_elements
from ._pieces import Drawing, Piece, check_finite, not_finite
from ._work import ImportWork, check_import_work, svg_work

__all__ = ["estimate_svg", "read_svg"]

PX_M = 0.0254 / 96  # metres per CSS pixel
_LAYER_ATTR = "data-rangeplan-layer"
_INKSCAPE_LABEL = "{http://www.inkscape.org/namespaces/inkscape}label"
_PHYSICAL = re.compile(r"^\s*[-+]?[0-9.eE+-]+\s*(mm|cm|in|pt|pc|q|m)\s*$")


def _root(data: bytes) -> Any:
    """The SVG document's XML tree (its root element), or ``invalid_drawing``."""
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise PlannerError("invalid_drawing", f"not an SVG drawing: not well-formed XML ({exc})", "drawing") from None
    if not (root.tag == "svg" or root.tag.endswith("}svg")):
        raise PlannerError("invalid_drawing", f"not an SVG drawing: the root element is <{root.tag}>, not <svg>",
                           "drawing")
    return root


def _user_metres(root: Any, units: tuple[str, float] | None) -> float:
    """Metres per user unit of the document, from its attributes alone (before svgelements
    reads it, for the estimate: ``units``, else the physical width over the viewBox's, else CSS px)."""
    if units is not None:
        return units[1]
    width = _PHYSICAL.match(root.get("width", ""))
    per = DRAWING_UNITS[width.group(1)] if width and width.group(1) in DRAWING_UNITS else PX_M
    try:
        w = float(re.sub(r"[a-z%]+\s*$", "", root.get("width", "").strip())) if root.get("width") else None
        vb = [float(v) for v in re.split(r"[\s,]+", (root.get("viewBox") or "").strip()) if v]
    except ValueError:
        return per
    if w and len(vb) == 4 and vb[2] > 0 and math.isfinite(w * per / vb[2]):
        return w * per / vb[2]
    return per


def estimate_svg(data: bytes, units: tuple[str, float] | None, tolerance: Callable[[float], float],
                 root: Any = None) -> ImportWork:
    """The estimated import of an SVG file's bytes (:func:`planner.exchange._work.svg_work`;
    ``root``: its XML tree, if parsed already)."""
    root = _root(data) if root is None else root
    return svg_work(root, len(data), tolerance(_user_metres(root, units)))


def _tag_layers(data: bytes, units: tuple[str, float] | None = None,
                tolerance: Callable[[float], float] | None = None,
                work_limit_s: float | None = None) -> tuple[bytes, str | None]:
    """The document with each top-level group's layer name in an attribute svgelements
    passes down to the shapes; and the physical unit its size is given in (``width="200mm"``
    -> ``"mm"``), or None. ``work_limit_s``: refused (``too_much_work``) where the import's
    estimate (:func:`estimate_svg`) exceeds it, before svgelements reads anything."""
    root = _root(data)
    svg_expanded_elements(root)  # <use> references bounded before svgelements copies any
    if work_limit_s is not None and tolerance is not None:
        check_import_work(estimate_svg(data, units, tolerance, root), work_limit_s)
    size = _PHYSICAL.match(root.get("width", "")) or _PHYSICAL.match(root.get("height", ""))
    physical = size.group(1) if size else None
    for child in root:
        if child.tag == "g" or child.tag.endswith("}g"):
            name = child.get(_INKSCAPE_LABEL) or child.get("id")
            if name:
                child.set(_LAYER_ATTR, name)
    return ET.tostring(root), physical


def read_svg(data: bytes, units: tuple[str, float] | None, tolerance: Callable[[float], float],
             work_limit_s: float | None = None) -> Drawing:
    """Read an SVG file's bytes. ``units`` (name, metres per unit) says what one user unit
    (a coordinate of the document, before its viewBox scaling) is; by default the document's
    physical size, or CSS px. ``tolerance(metres_per_unit)`` is the flattening tolerance in
    drawing units."""
    import io

    from svgelements import SVG, Path, Shape

    tagged, physical = _tag_layers(data, units, tolerance, work_limit_s)
    try:
        svg = SVG.parse(io.BytesIO(tagged), reify=True, ppi=96.0)
    except Exception as exc:  # svgelements raises many kinds on bad documents
        raise PlannerError("invalid_drawing", f"not a readable SVG drawing ({type(exc).__name__}: {exc})",
                           "drawing") from None
    # px per user unit (the viewBox scaling): the override unit applies to user units
    px_per_user = 1.0
    vb = getattr(svg, "viewbox_transform", None)
    if vb:
        from svgelements import Matrix
        m = Matrix(vb)
        px_per_user = math.sqrt(abs(m.a * m.d - m.b * m.c)) or 1.0
    if units is not None:  # one user unit is units[1] m: coordinates in px are divided by px_per_user below
        name, mpu, source, per_px = units[0], units[1], "option", 1.0 / px_per_user
    elif physical in DRAWING_UNITS:  # sized in mm, cm, in, pt, m: coordinates in that unit, reported as such
        name, mpu, source = physical, DRAWING_UNITS[physical], "drawing"
        per_px = PX_M / mpu
    else:  # CSS px, sized by the document's physical width/height when it has them
        name, mpu, source, per_px = "px", PX_M, ("drawing" if physical else "default"), 1.0
    height = float(svg.height) if getattr(svg, "height", None) else 0.0
    if not (math.isfinite(height) and math.isfinite(px_per_user) and math.isfinite(per_px)):
        raise PlannerError("invalid_drawing", "the <svg> element's size or viewBox is not a finite number",
                           "drawing")
    tol = tolerance(mpu) / per_px  # in px
    pieces: list[Piece] = []
    ignored: Counter[str] = Counter()
    seen: Counter[str] = Counter()
    for el in svg.elements():
        if not isinstance(el, Shape):
            if type(el).__name__ in ("Text", "Image", "Use"):
                ignored[type(el).__name__.lower()] += 1
            continue
        values: Any = el.values or {}
        layer = str(values.get(_LAYER_ATTR, "(no layer)"))
        kind = type(el).__name__.lower()
        seen[kind] += 1
        ref = _ref(kind, values.get("id"), seen[kind])
        circle = _circle(el) if kind in ("circle", "ellipse") else None
        try:
            path = Path(el)
            path.reify()  # its transform into the segments (reify=True leaves it on rotated ellipses)
        except Exception:
            ignored[f"{kind} (unreadable)"] += 1
            continue
        if not _finite_path(path):
            raise not_finite(ref, layer)
        try:
            got = _subpaths(path, layer, kind, circle, height, tol)
        except PlannerError:  # a bound of the import (too many vertices): the drawing's answer
            raise
        except (ArithmeticError, ValueError) as exc:  # a curve too large to flatten in floating point
            raise PlannerError("invalid_drawing", f"{ref} on layer {layer!r} cannot be flattened: its coordinates "
                               f"are too large ({type(exc).__name__})", "drawing") from None
        for p in got:
            p.ref = ref
        check_finite(got, ref, layer)
        pieces.extend(got)
    if per_px != 1.0:
        for p in pieces:
            p.points = p.points * per_px
            if p.circle is not None:
                p.circle = (p.circle[0] * per_px, p.circle[1] * per_px, p.circle[2] * per_px)
    layers = sorted({p.layer for p in pieces})
    return Drawing(pieces, layers, dict(ignored), name, mpu, source)


def _ref(kind: str, element_id: Any, nth: int) -> str:
    """How a message names an SVG element: by its id, else by its place among its kind."""
    if element_id:
        return f"<{kind} id={str(element_id)[:60]!r}>"
    return f"<{kind}> number {nth}"


def _finite_path(path) -> bool:
    """Whether every point of an svgelements ``Path`` (ends, controls, arc radii) is finite."""
    for seg in path:
        for name in ("start", "end", "control", "control1", "control2", "center"):
            pt = getattr(seg, name, None)
            if pt is not None and not (math.isfinite(pt.x) and math.isfinite(pt.y)):
                return False
        for name in ("rx", "ry", "sweep"):
            value = getattr(seg, name, None)
            if value is not None and not math.isfinite(float(value)):
                return False
    return True


def _subpaths(path, layer: str, kind: str, circle, height: float, tol: float) -> list[Piece]:
    """The subpaths of an svgelements ``Path`` as pieces (y turned up)."""
    from svgelements import Close, Line, Move

    out: list[Piece] = []
    current: list[np.ndarray] = []

    def flush(closed: bool) -> None:
        if current:
            pts = np.concatenate(current)
            pts[:, 1] = height - pts[:, 1]
            if closed and len(pts) > 1 and np.array_equal(pts[0], pts[-1]):
                pts = pts[:-1]
            if len(pts) >= 2:
                c = (circle[0], height - circle[1], circle[2]) if closed and circle is not None else None
                out.append(Piece(pts, closed and len(pts) >= 3, layer, kind, c))
        current.clear()

    for seg in path:
        if isinstance(seg, Move):
            flush(False)
        elif isinstance(seg, Close):
            if seg.start is not None and seg.end is not None and seg.start != seg.end:
                current.append(np.array([[seg.end.x, seg.end.y]], float))
            flush(True)
        elif seg.start is not None and seg.end is not None:
            pts = _segment_points(seg, tol, Line)
            current.append(pts if not current else pts[1:])
    if current:
        pts = np.concatenate(current)
        flush(bool(len(pts) > 3 and np.array_equal(pts[0], pts[-1])))
    return out


def _xy(*points: Any) -> np.ndarray:
    return np.array([[p.x, p.y] for p in points], float)


def _segment_points(seg: Any, tol: float, line_type: Any) -> np.ndarray:
    from svgelements import Arc, CubicBezier, QuadraticBezier

    if isinstance(seg, line_type):
        return _xy(seg.start, seg.end)
    if isinstance(seg, QuadraticBezier):
        return fl.bezier(_xy(seg.start, seg.control, seg.end), tol)
    if isinstance(seg, CubicBezier):
        return fl.bezier(_xy(seg.start, seg.control1, seg.control2, seg.end), tol)
    if isinstance(seg, Arc):
        arc: Any = seg
        sweep = float(arc.sweep)
        n = fl.chords(max(float(arc.rx), float(arc.ry)) * sweep * sweep, tol, sweep)
        return np.asarray(arc.npoint(np.linspace(0.0, 1.0, n + 1)), float)
    return _xy(seg.start, seg.end)


def _circle(el) -> tuple[float, float, float] | None:
    """(cx, cy, r) in px of a circle (or an ellipse that is one after its transform)."""
    try:
        rx, ry = float(el.implicit_rx), float(el.implicit_ry)
    except (AttributeError, TypeError, ValueError):
        return None
    if rx > 0 and abs(rx - ry) <= 1e-9 * rx:
        m = el.transform
        if abs(m.b) < 1e-12 and abs(m.c) < 1e-12 or abs(abs(m.a * m.d - m.b * m.c) - (m.a ** 2 + m.b ** 2)) < 1e-9:
            return float(el.implicit_center.x), float(el.implicit_center.y), rx
    return None
