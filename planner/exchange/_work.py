"""The compute time of a drawing import, estimated before its curves are made (issue 33).

A drawing is read in three steps whose cost grows with different counts: the file parsed
(ezdxf, or the XML tree and svgelements: its bytes, and for an SVG its path segments, an arc
counting :data:`~planner.exchange._budget.ARC_WEIGHT`), the outline entities made (DXF block
references exploded into virtual entities, each a copy: nested ``INSERT`` and ``MINSERT`` grids
multiply), and the curves flattened and joined into regions (the vertices at the flattening
tolerance, the pieces). Each is counted from the parsed document without making a point:

* :func:`dxf_work`: the modelspace's entities with every block reference exploded (each
  block's counts once, multiplied by its references, their grid cells and, for the vertices,
  the square root of their scale), circles, arcs, ellipses and bulges by
  :func:`planner.exchange._flatten.chords`'s own rule, hatch boundary edges one by one,
  splines by their control points;
* :func:`svg_work`: the path segments with ``<use>`` references resolved
  (:func:`~planner.exchange._budget.svg_expanded_elements`), circles, ellipses, rounded rects
  and path arcs by the chord rule.

The unit costs (:data:`IMPORT_COSTS`) are CPU seconds measured on generated edge drawings
(``benchmarks/bench_estimates.py --only import``). :func:`check_import_work` refuses a drawing
over a limit naming the count that costs most and what to change.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

from ..errors import PlannerError, over_the_limit
from ._budget import MAX_BLOCK_DEPTH, entity_ref, spline_points, svg_expanded_elements
from ._flatten import MAX_CHORD_ANGLE

__all__ = ["IMPORT_COSTS", "ImportWork", "check_import_work", "dxf_work", "overlap", "svg_work"]

#: CPU seconds on the reference machine: a drawing's fixed cost, per byte of the file, per
#: entity read (DXF, block references exploded: the virtual entities they make cost as much
#: as the entities, no more), per vertex flattened, per piece (an outline or a hatch edge,
#: joined into regions), per curve flattened (a DXF circle, arc, bulge, hatch arc edge; an SVG
#: circle, ellipse, rounded corner or path arc costs more: svgelements' own points), per
#: squared spline fit point (ezdxf interpolates them), per SVG path segment (an arc
#: ARC_WEIGHT of them) and shape element (``<use>`` resolved), per pair of closed outlines
#: whose boxes overlap and per vertex of such pairs (the regions' pairwise tests: 1 500
#: circles of 50 mm on a 1 mm grid took 49 s, nearly all in them). Fitted (least squares on
#: the relative error) to the 19 drawings of ``benchmarks/bench_estimates.py --only import``
#: and rounded up 10 %.
IMPORT_COSTS = {"fixed": 0.09, "byte": 3.6e-7, "entity": 3.4e-5, "virtual": 0.0, "vertex": 3.3e-6, "piece": 4.8e-5,
                "curve": 2.6e-5, "fit2": 7.3e-8, "svg_segment": 2.2e-5, "svg_element": 1.4e-4, "svg_curve": 1.6e-4,
                "pair": 3.7e-5, "overlap": 2.7e-8}
#: the overlap count stops here (a drawing this tangled is refused by any limit)
OVERLAP_CAP = 1e11
#: a spline's flattened vertices per control (or fit) point, as ezdxf's adaptive flattening
#: makes them at a fine tolerance
SPLINE_VERTICES_PER_POINT = 8


def _chords(radius: float, sweep: float, tol: float) -> int:
    """The chords :func:`planner.exchange._flatten.chords` gives an arc of ``radius`` and
    ``sweep`` [rad] at ``tol`` (no budget charged; a tolerance that underflows: one per 45 degrees)."""
    bound = abs(radius) * sweep * sweep
    x = math.sqrt(bound / (8.0 * tol)) if bound > 0 and tol > 0 else 1.0
    if not math.isfinite(x):
        x = 1.0
    return max(math.ceil(min(x, 1e9)), math.ceil(abs(sweep) / MAX_CHORD_ANGLE - 1e-9), 1)


@dataclass(frozen=True)
class ImportWork:
    """The estimated compute time of a drawing import and what it is made of."""

    seconds: float  #: estimated CPU seconds on the reference machine
    counts: dict[str, float]  #: the counts the estimate is made of (:data:`IMPORT_COSTS`' keys)
    detail: str  #: the arithmetic, in words
    field: str = "drawing"  #: the option or input that contributes most
    advice: str = "simplify the drawing"  #: what to change

    def message(self, limit_s: float, time_limit_s: float | None = None) -> str:
        """Why a server admitting ``limit_s`` [s] of estimated work refuses this drawing
        (:func:`planner.errors.over_the_limit`)."""
        return (f"this drawing needs an estimated {self.seconds:.3g} s to import ({self.detail}), more than "
                f"{over_the_limit(limit_s, time_limit_s)}; {self.advice}")


_ADVICE = {
    "byte": ("drawing", "send a smaller file (only the layers needed)"),
    "entity": ("drawing", "simplify the drawing or choose a smaller one (fewer entities)"),
    "virtual": ("drawing", "explode fewer block references (INSERT, MINSERT grids) or simplify the blocks"),
    "vertex": ("flatten_tolerance", "use a larger flatten_tolerance (fewer vertices per curve) or fewer curves"),
    "piece": ("drawing", "join the outlines into polylines (fewer separate lines, arcs and hatch edges)"),
    "svg_segment": ("drawing", "simplify the paths or save the drawing as DXF"),
    "svg_element": ("drawing", "use fewer elements (fewer <use> copies; join shapes into paths)"),
    "curve": ("drawing", "use fewer curves (arcs, circles, bulges, hatch arc edges)"),
    "svg_curve": ("drawing", "use fewer curves (circles, ellipses, arcs, rounded corners)"),
    "fit2": ("drawing", "save the splines with control points (a spline through fit points is interpolated)"),
    "pair": ("drawing", "remove the outlines drawn over each other (overlapping closed shapes are compared pair by "
             "pair)"),
    "overlap": ("drawing", "remove the outlines drawn over each other (overlapping closed shapes are compared pair by "
                "pair) or use a larger flatten_tolerance"),
}


def _work(counts: dict[str, float], what: str) -> ImportWork:
    c = IMPORT_COSTS
    parts = {k: counts.get(k, 0.0) * c[k] for k in c if k != "fixed"}
    seconds = c["fixed"] + sum(parts.values())
    most = max(parts, key=parts.__getitem__)
    field, advice = _ADVICE[most]
    words = {"byte": "bytes", "entity": "entities", "virtual": "virtual entities of block references",
             "vertex": "vertices flattened", "piece": "outlines and edges", "svg_segment": "path segments",
             "curve": "curves", "svg_curve": "curves", "fit2": "squared spline fit points",
             "svg_element": "SVG elements (<use> resolved)", "pair": "pairs of overlapping closed outlines",
             "overlap": "vertices of overlapping closed outlines, pair by pair"}
    detail = what + ": " + ", ".join(f"{counts.get(k, 0):.0f} {words[k]}" for k in words if counts.get(k, 0)) + \
        f"; most of it {words[most]}"
    return ImportWork(seconds, dict(counts), detail, field, advice)


def overlap(boxes: list[tuple[float, float, float, float, float]]) -> tuple[float, float]:
    """The pairs of closed outlines whose boxes overlap, and the sum over them of their
    vertices (``boxes``: x0, y0, x1, y1, vertices), counted with an R-tree in chunks, stopped
    past :data:`OVERLAP_CAP`."""
    if len(boxes) < 2:
        return 0.0, 0.0
    import numpy as np
    import shapely

    a = np.asarray(boxes, float)
    a = a[np.all(np.isfinite(a), axis=1)]
    polys = shapely.box(a[:, 0], a[:, 1], a[:, 2], a[:, 3])
    tree = shapely.STRtree(polys)
    w = a[:, 4]
    total = pairs = 0.0
    for s in range(0, len(polys), 256):
        i, j = tree.query(polys[s:s + 256], predicate="intersects")
        i = i + s
        keep = i < j
        pairs += float(np.count_nonzero(keep))
        total += float(np.sum(w[i[keep]] + w[j[keep]]))
        if total > OVERLAP_CAP:
            break
    return pairs, total


def check_import_work(work: ImportWork, limit_s: float | None) -> None:
    """Refuse (``too_much_work``, naming what to change) a drawing whose estimate exceeds ``limit_s``."""
    if limit_s is not None and limit_s > 0 and work.seconds > limit_s:
        raise PlannerError("too_much_work", work.message(limit_s), work.field)


def _copies(e: Any) -> int:
    """The references a block reference stands for (a MINSERT: its grid's cells)."""
    try:
        return max(1, int(e.dxf.get("row_count", 1))) * max(1, int(e.dxf.get("column_count", 1)))
    except (TypeError, ValueError):
        return 1


def _scale(e: Any) -> float:
    """The largest of a block reference's scale factors (a curve's chords grow as its square root)."""
    try:
        s = max(abs(float(e.dxf.get(k, 1.0))) for k in ("xscale", "yscale"))
    except (TypeError, ValueError):
        return 1.0
    return s if math.isfinite(s) and s > 0 else 1.0


def _bulges(rows: Any, closed: bool, tol: float) -> tuple[int, int]:
    """(vertices, arcs) of a polyline with bulges (``rows``: x, y, bulge) flattened at ``tol``."""
    n = len(rows)
    total, arcs = 1, 0
    for i in range(n if closed else n - 1):
        (x0, y0, b), (x1, y1, _) = rows[i], rows[(i + 1) % n]
        chord = math.hypot(x1 - x0, y1 - y0)
        if abs(b) < 1e-12 or chord == 0.0 or not math.isfinite(b):
            total += 1
            continue
        sweep = 4.0 * math.atan(b)
        total += _chords(chord / (2.0 * abs(math.sin(sweep / 2.0))), sweep, tol)
        arcs += 1
    return total, arcs


def _spline(s: Any, ref: str) -> tuple[float, float]:
    """(vertices, squared fit points where ezdxf interpolates them) of a spline; a spline over
    the drawing's hard bounds is refused here already (``too_large`` naming ``ref``:
    :func:`planner.exchange._budget.spline_points`), as the reading would refuse it."""
    spline_points(s, ref)
    control, fit = len(s.control_points), len(s.fit_points)
    return SPLINE_VERTICES_PER_POINT * max(control, fit, 1), float(fit * fit) if control == 0 else 0.0


def _entity_counts(e: Any, kind: str, tol: float) -> tuple[float, float, float, float]:
    """(vertices, pieces, curves, squared spline fit points) an outline entity flattens into
    at ``tol`` (drawing units); a curve: each circle, arc, ellipse, bulge, hatch arc edge."""
    d = e.dxf
    if kind == "LINE":
        return 2, 1, 0, 0
    if kind == "CIRCLE":
        return _chords(float(d.radius), 2 * math.pi, tol) + 1, 1, 1, 0
    if kind == "ARC":
        sweep = math.radians((float(d.end_angle) - float(d.start_angle)) % 360.0) or 2 * math.pi
        return _chords(float(d.radius), sweep, tol) + 1, 1, 1, 0
    if kind == "ELLIPSE":
        major = math.hypot(*tuple(d.major_axis)[:2])
        big = max(major, major * abs(float(d.get("ratio", 1.0))))
        sweep = (float(d.get("end_param", 2 * math.pi)) - float(d.get("start_param", 0.0))) % (2 * math.pi)
        return _chords(big, sweep or 2 * math.pi, tol) + 1, 1, 1, 0
    if kind == "LWPOLYLINE":
        v, arcs = _bulges(list(e.get_points("xyb")), bool(e.closed), tol)
        return v, 1, arcs, 0
    if kind == "POLYLINE":
        return len(e.vertices), 1, 0, 0
    if kind == "SPLINE":
        v, fit2 = _spline(e, entity_ref(e, kind))
        return v, 1, 1, fit2
    if kind in ("HATCH", "MPOLYGON"):
        vertices = pieces = curves = fit2 = 0.0
        for path in e.paths:
            if path.type.name == "POLYLINE":
                rows = [(v[0], v[1], v[2] if len(v) > 2 else 0.0) for v in path.vertices]
                v, arcs = _bulges(rows, True, tol)
                vertices, pieces, curves = vertices + v, pieces + 1, curves + arcs
                continue
            for edge in path.edges:
                t = edge.type.name
                pieces += 1
                if t == "ARC":
                    sweep = math.radians((float(edge.end_angle) - float(edge.start_angle)) % 360.0) or 2 * math.pi
                    vertices += _chords(float(edge.radius), sweep, tol) + 1
                    curves += 1
                elif t == "ELLIPSE":
                    major = math.hypot(*tuple(edge.major_axis)[:2])
                    vertices += _chords(max(major, major * abs(float(edge.ratio))), 2 * math.pi, tol) + 1
                    curves += 1
                elif t == "SPLINE":
                    v, f2 = _spline(edge, f"a spline edge of {entity_ref(e, kind)}")
                    vertices, curves, fit2 = vertices + v, curves + 1, fit2 + f2
                else:
                    vertices += 2
        return vertices, pieces, curves, fit2
    return 0, 0, 0, 0


def _points_box(pts: Any) -> tuple[float, float, float, float] | None:
    xs = [float(q[0]) for q in pts]
    ys = [float(q[1]) for q in pts]
    return (min(xs), min(ys), max(xs), max(ys)) if xs else None


def _closed_box(e: Any, kind: str) -> tuple[float, float, float, float] | None:
    """The box of a closed outline entity (a circle, a closed polyline, a full ellipse, a
    hatch, a closed spline), None for an open one."""
    d = e.dxf
    if kind == "CIRCLE":
        (x, y), r = tuple(d.center)[:2], abs(float(d.radius))
        return x - r, y - r, x + r, y + r
    if kind == "ELLIPSE":
        (x, y), r = tuple(d.center)[:2], math.hypot(*tuple(d.major_axis)[:2])
        return x - r, y - r, x + r, y + r
    if kind == "LWPOLYLINE" and e.closed:
        return _points_box(e.get_points("xy"))
    if kind == "POLYLINE" and e.is_closed:
        return _points_box([v.dxf.location for v in e.vertices])
    if kind == "SPLINE" and e.closed:
        return _points_box(list(e.control_points) or list(e.fit_points))
    if kind in ("HATCH", "MPOLYGON"):
        pts = [v for path in e.paths if path.type.name == "POLYLINE" for v in path.vertices]
        return _points_box(pts)
    return None


def dxf_work(doc: Any, tol: float, nbytes: int, outlines: set[str] | frozenset[str]) -> ImportWork:
    """The estimated import of the parsed DXF ``doc`` (``nbytes`` long) at the flattening
    tolerance ``tol`` (drawing units); ``outlines``: the entity types read as outlines. Block
    references nested deeper than :data:`~planner.exchange._budget.MAX_BLOCK_DEPTH` count as
    one entity (the reader skips them)."""
    memo: dict[tuple[str, int], list[float]] = {}
    boxes: list[tuple[float, float, float, float, float]] = []  # the modelspace's closed outlines

    def tally(entities: Any, depth: int) -> list[float]:
        """[entities, virtual entities, vertices, pieces, curves, fit points squared] of
        ``entities`` with references exploded."""
        out = [0.0] * 6
        for e in entities:
            kind = e.dxftype()
            out[0] += 1
            if kind == "INSERT" and depth < MAX_BLOCK_DEPTH:
                name = str(e.dxf.get("name", ""))
                key = (name, depth + 1)
                if key not in memo:
                    blk = doc.blocks.get(name)
                    memo[key] = [0.0] * 7 if blk is None else [*tally(blk, depth + 1), float(len(blk))]
                inner = memo[key]
                k = _copies(e)
                root = math.sqrt(_scale(e))
                out[0] += k * inner[0]
                out[1] += k * (inner[6] + inner[1])
                out[2] += k * inner[2] * root
                out[3] += k * inner[3]
                out[4] += k * inner[4]
                out[5] += k * inner[5]
            elif kind in outlines:
                try:
                    v, p, c, f2 = _entity_counts(e, kind, tol)
                except (AttributeError, TypeError, ValueError, ArithmeticError, IndexError):
                    v, p, c, f2 = 0, 0, 0, 0
                out[2] += v
                out[3] += p
                out[4] += c
                out[5] += f2
                if depth == 0 and v > 0:
                    try:
                        box = _closed_box(e, kind)
                    except (AttributeError, TypeError, ValueError, ArithmeticError, IndexError):
                        box = None
                    if box is not None:
                        boxes.append((*box, float(v)))
        return out

    entities, virtual, vertices, pieces, curves, fit2 = tally(doc.modelspace(), 0)
    pairs, overlapping = overlap(boxes)
    return _work({"byte": nbytes, "entity": entities, "virtual": virtual, "vertex": vertices, "piece": pieces,
                  "curve": curves, "fit2": fit2, "pair": pairs, "overlap": overlapping}, "a DXF")


_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_ARCS = re.compile(r"[Aa]([^MmLlHhVvCcSsQqTtAaZz]*)")


def _float(el: Any, name: str) -> float:
    try:
        v = float(_NUMBER.match((el.get(name) or "0").strip()).group(0))  # type: ignore[union-attr]
    except (AttributeError, ValueError):
        return 0.0
    return v if math.isfinite(v) else 0.0


def svg_work(root: Any, nbytes: int, tol_px: float) -> ImportWork:
    """The estimated import of the SVG tree ``root`` (xml.etree; ``nbytes`` long) at the
    flattening tolerance ``tol_px`` (user units, before the viewBox: the chord counts of
    curves, for which this is the scale that matters): its path segments with ``<use>``
    resolved, the vertices of circles, ellipses, rounded rects and path arcs (a path arc
    taken as half a turn) at their radius stretched by their own and their ancestors'
    ``transform`` (:func:`_scaled`: a scaled-up circle flattens into more chords), one piece
    an element."""
    segments = svg_expanded_elements(root)
    vertices = pieces = curves = 0.0
    boxes: list[tuple[float, float, float, float, float]] = []
    for el, k in _scaled(root):
        tag = el.tag.rsplit("}", 1)[-1]
        if tag in ("circle", "ellipse"):
            r = max(_float(el, "r"), _float(el, "rx"), _float(el, "ry"))
            v = _chords(r * k, 2 * math.pi, tol_px) + 1
            vertices += v
            curves += 1
            x, y = _float(el, "cx"), _float(el, "cy")
            boxes.append((x - r, y - r, x + r, y + r, float(v)))
        elif tag == "rect" and (_float(el, "rx") or _float(el, "ry")):
            vertices += 4 * _chords(max(_float(el, "rx"), _float(el, "ry")) * k, math.pi / 2, tol_px)
            curves += 4
        elif tag == "path":
            for args in _ARCS.findall(el.get("d") or ""):
                nums = _NUMBER.findall(args)
                for i in range(0, len(nums) - 6, 7):
                    r = max(abs(float(nums[i])), abs(float(nums[i + 1]))) * k
                    vertices += _chords(r if math.isfinite(r) else 0.0, math.pi, tol_px)
                    curves += 1
        if tag in _SHAPES:
            pieces += 1
    vertices += segments
    pairs, overlapping = overlap(boxes)
    return _work({"byte": nbytes, "svg_segment": segments, "svg_element": _shapes(root), "vertex": vertices,
                  "piece": pieces, "svg_curve": curves, "pair": pairs, "overlap": overlapping}, "an SVG")


_SHAPES = ("path", "polygon", "polyline", "line", "rect", "circle", "ellipse")
_TRANSFORM = re.compile(r"(matrix|translate|scale|rotate|skewX|skewY)\s*\(([^)]*)\)")


def _linear(transform: str) -> list[float]:
    """The linear part ``[a, b, c, d]`` (x' = a x + c y, y' = b x + d y) of an SVG ``transform``
    attribute (its functions composed left to right; translations drop out; a malformed one
    counts as the identity)."""
    a, b, c, d = 1.0, 0.0, 0.0, 1.0
    for name, args in _TRANSFORM.findall(transform or ""):
        v = [float(x) for x in _NUMBER.findall(args)]
        if name == "matrix" and len(v) >= 4:
            m = v[:4]
        elif name == "scale" and v:
            m = [v[0], 0.0, 0.0, v[1] if len(v) > 1 else v[0]]
        elif name == "rotate" and v:
            t = math.radians(v[0])
            m = [math.cos(t), math.sin(t), -math.sin(t), math.cos(t)]
        elif name == "skewX" and v:
            m = [1.0, 0.0, math.tan(math.radians(v[0])), 1.0]
        elif name == "skewY" and v:
            m = [1.0, math.tan(math.radians(v[0])), 0.0, 1.0]
        else:
            continue
        a, b, c, d = a * m[0] + c * m[1], b * m[0] + d * m[1], a * m[2] + c * m[3], b * m[2] + d * m[3]
    out = [a, b, c, d]
    return out if all(math.isfinite(x) for x in out) else [1.0, 0.0, 0.0, 1.0]


def _scaled(root: Any) -> list[tuple[Any, float]]:
    """Every element of the SVG tree with the largest stretch of its ``transform`` and its
    ancestors' composed (the largest singular value of the linear part: a circle of radius r
    scaled by k flattens as one of radius k r; rotations and translations change nothing),
    in document order."""
    out: list[tuple[Any, float]] = []
    stack: list[tuple[Any, list[float]]] = [(root, [1.0, 0.0, 0.0, 1.0])]
    while stack:
        el, (a, b, c, d) = stack.pop()
        t = el.get("transform")
        if t:
            m = _linear(t)
            a, b, c, d = a * m[0] + c * m[1], b * m[0] + d * m[1], a * m[2] + c * m[3], b * m[2] + d * m[3]
        # the largest singular value of [[a, c], [b, d]]
        p, q = a * a + b * b + c * c + d * d, abs(a * d - b * c)
        k = math.sqrt(max(0.5 * (p + math.sqrt(max(p * p - 4 * q * q, 0.0))), 0.0))
        out.append((el, round(k, 9) if math.isfinite(k) and k > 0 else 1.0))  # a rotation: 1 exactly
        stack.extend((child, [a, b, c, d]) for child in reversed(list(el)))
    return out


def _shapes(root: Any) -> float:
    """The shape elements of the SVG tree with every ``<use>`` replaced by what it references
    (each reference's target counted once, memoised; the depth and cycles are bounded by
    :func:`~planner.exchange._budget.svg_expanded_elements`, which runs first)."""
    by_id = {el.get("id"): el for el in root.iter() if el.get("id")}
    xlink = "{http://www.w3.org/1999/xlink}href"
    memo: dict[int, float] = {}

    def size(el: Any, depth: int) -> float:
        key = id(el)
        if key in memo:
            return memo[key]
        if depth > MAX_BLOCK_DEPTH:
            return 0.0
        tag = el.tag.rsplit("}", 1)[-1]
        total = 1.0 if tag in _SHAPES else 0.0
        if tag == "use":
            ref = (el.get("href") or el.get(xlink) or "").strip()
            target = by_id.get(ref[1:]) if ref.startswith("#") else None
            if target is not None:
                total += size(target, depth + 1)
        for child in el:
            total += size(child, depth)
        memo[key] = total
        return total

    return size(root, 0)
