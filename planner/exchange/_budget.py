"""Bounds on what a drawing may expand to, checked before it expands (issue 21).

A few hundred bytes of DXF or SVG can describe billions of shapes: blocks that insert
blocks that insert blocks (DXF ``INSERT``, ``MINSERT`` grids), ``<use>`` elements that
reference groups of ``<use>`` elements (SVG), or thousands of large arcs each flattened into
as many chords as a shape may have. Each is refused with ``too_large`` naming the cause
before the work is done:

* :func:`dxf_expanded_entities`: the entities the modelspace holds once every block
  reference is exploded, counted from the block definitions (no entity is made);
* :func:`svg_expanded_elements`: the path segments the document holds as written and once
  every ``<use>`` is resolved, counted on the XML tree (before svgelements reads anything: it
  reads a few thousand segments a second, arcs a third of that);
* :func:`vertex_budget` / :func:`charge`: the vertices all curves of one drawing are
  flattened into, charged by :func:`planner.exchange._flatten.chords` before a curve's points
  are made;
* :func:`spline_points`: a DXF spline's control and fit points, counted before ezdxf builds
  the curve (issue 33: a spline given by fit points only is interpolated through a dense
  system, ~n^2 time and memory: 2 000 fit points 0.19 s, 20 000 held a worker 10-22 s until the
  2 GiB cap; control points flatten in linear time, ~75 us each at 0.01 mm).
"""

from __future__ import annotations

import contextvars
import re
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from ..errors import PlannerError

__all__ = ["MAX_BLOCK_DEPTH", "MAX_DRAWING_ENTITIES", "MAX_DRAWING_VERTICES", "MAX_SPLINE_CONTROL_POINTS",
           "MAX_SPLINE_FIT_POINTS", "MAX_SVG_SEGMENTS", "charge", "dxf_expanded_entities", "spline_points",
           "svg_expanded_elements", "vertex_budget"]

#: deepest nesting of block references (DXF) or ``<use>`` references (SVG) followed
MAX_BLOCK_DEPTH = 8
#: most entities (DXF, block references exploded) or elements (SVG, ``<use>`` resolved) of a drawing
MAX_DRAWING_ENTITIES = 50_000
#: most vertices all curves of one drawing are flattened into (a shape has at most
#: MAX_POLYGON_POINTS; a layout at most MAX_OBSTACLES shapes, but no drawing that imports in
#: seconds has this many)
MAX_DRAWING_VERTICES = 500_000

#: most path segments of an SVG (ARC_WEIGHT each for arcs), ``<use>`` references resolved:
#: svgelements reads a few thousand a second
MAX_SVG_SEGMENTS = 10_000

#: most fit points of a DXF spline without control points (ezdxf interpolates them through a
#: dense n x n system: 2 000 take 0.19 s and 32 MB, time and memory growing as n^2)
MAX_SPLINE_FIT_POINTS = 2_000
#: most control points of a DXF spline (each flattens into one chord at least, and a shape has
#: at most MAX_POLYGON_POINTS vertices)
MAX_SPLINE_CONTROL_POINTS = 10_000

_budget: contextvars.ContextVar[list[int] | None] = contextvars.ContextVar("rangeplan_vertex_budget", default=None)


@contextmanager
def vertex_budget(limit: int = MAX_DRAWING_VERTICES) -> Iterator[None]:
    """Within this block, :func:`charge` counts flattened vertices against ``limit``."""
    token = _budget.set([int(limit), int(limit)])
    try:
        yield
    finally:
        _budget.reset(token)


def charge(n: int) -> None:
    """Count ``n`` vertices about to be made; ``too_large`` when the drawing's budget is spent."""
    budget = _budget.get()
    if budget is None:
        return
    budget[0] -= int(n)
    if budget[0] < 0:
        raise PlannerError("too_large", f"the drawing's curves need more than {budget[1]} vertices in all to stay "
                           "within flatten_tolerance (many or large arcs and curves); use a larger flatten_tolerance "
                           "or fewer curves", "flatten_tolerance")


def _too_many(what: str, limit: int) -> PlannerError:
    return PlannerError("too_large", f"the drawing expands to more than {limit} {what}; flatten or simplify it in "
                        "the CAD program", "drawing")


def dxf_expanded_entities(doc: Any, limit: int = MAX_DRAWING_ENTITIES, max_depth: int = MAX_BLOCK_DEPTH) -> int:
    """Entities of ``doc``'s modelspace with every block reference exploded (references
    nested deeper than ``max_depth`` count as one: they are skipped); raises ``too_large``
    past ``limit`` (as soon as a partial count passes it)."""
    memo: dict[tuple[str, int], int] = {}

    def copies(e: Any) -> int:  # a MINSERT is a grid of references
        try:
            return max(1, int(e.dxf.get("row_count", 1))) * max(1, int(e.dxf.get("column_count", 1)))
        except (TypeError, ValueError):
            return 1

    def count(entities: Any, depth: int) -> int:
        total = 0
        for e in entities:
            total += 1
            if e.dxftype() == "INSERT" and depth < max_depth:
                total += copies(e) * block(str(e.dxf.get("name", "")), depth + 1)
            if total > limit:
                raise _too_many("entities once its block references (INSERT) are exploded", limit)
        return total

    def block(name: str, depth: int) -> int:
        key = (name, depth)
        if key not in memo:
            blk = doc.blocks.get(name)
            memo[key] = 0 if blk is None else count(blk, depth)
        return memo[key]

    return count(doc.modelspace(), 0)


_COMMAND = re.compile(r"([MmLlHhVvCcSsQqTtAaZz])([^MmLlHhVvCcSsQqTtAaZz]*)")
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_PARAMETERS = {"m": 2, "l": 2, "h": 1, "v": 1, "c": 6, "s": 4, "q": 4, "t": 2, "a": 7, "z": 0}
#: what an arc costs the SVG reader (svgelements), in straight segments (measured: ~3x)
ARC_WEIGHT = 3


def _segments(el: Any) -> int:
    """Path segments an SVG element stands for (an arc counts ARC_WEIGHT; a shape one)."""
    tag = el.tag.rsplit("}", 1)[-1]
    if tag == "path":
        total = 0
        for cmd, args in _COMMAND.findall(el.get("d") or ""):
            per = _PARAMETERS[cmd.lower()]
            reps = max(1, len(_NUMBER.findall(args)) // per) if per else 1
            total += reps * (ARC_WEIGHT if cmd in "Aa" else 1)
        return max(total, 1)
    if tag in ("polygon", "polyline"):
        return max(len(_NUMBER.findall(el.get("points") or "")) // 2, 1)
    return 1


def svg_expanded_elements(root: Any, limit: int = MAX_SVG_SEGMENTS, max_depth: int = MAX_BLOCK_DEPTH) -> int:
    """Path segments (:func:`_segments`; every element counts at least one) of the SVG tree
    ``root`` (xml.etree), as written and then with every ``<use>`` replaced by what it
    references; raises ``too_large`` past ``limit`` (naming which), and for references nested
    deeper than ``max_depth`` (a reference cycle included). The SVG reader's time grows with
    this count: it is bounded before the reader runs."""
    own = {id(el): _segments(el) for el in root.iter()}
    if sum(own.values()) > limit:
        raise PlannerError("too_large", f"the SVG has more than {limit} path segments (lines, curves; an arc counts "
                           f"{ARC_WEIGHT}: the reader's cost); simplify it or save it as DXF", "drawing")
    by_id = {el.get("id"): el for el in root.iter() if el.get("id")}
    memo: dict[int, int] = {}
    xlink = "{http://www.w3.org/1999/xlink}href"

    def size(el: Any, depth: int) -> int:
        key = id(el)
        if key in memo:
            return memo[key]
        if depth > max_depth:
            raise _too_many("levels of <use> references (or a reference cycle)", max_depth)
        total = own.get(key, 1)
        if el.tag == "use" or el.tag.endswith("}use"):
            ref = (el.get("href") or el.get(xlink) or "").strip()
            target = by_id.get(ref[1:]) if ref.startswith("#") else None
            if target is not None:
                total += size(target, depth + 1)
        for child in el:
            total += size(child, depth)
            if total > limit:
                raise _too_many("path segments once its <use> references are resolved", limit)
        if total > limit:
            raise _too_many("path segments once its <use> references are resolved", limit)
        memo[key] = total
        return total

    try:
        return size(root, 0)
    except RecursionError:
        raise _too_many("levels of nested elements", max_depth) from None


def entity_ref(entity: Any, kind: str) -> str:
    """How a message names a DXF entity: its type and handle (a block's exploded copy has none)."""
    handle = entity.dxf.get("handle") if entity.dxf.hasattr("handle") else None
    return f"{kind} (handle {handle})" if handle else f"{kind} (in a block reference)"


def spline_points(spline: Any, ref: str) -> None:
    """Refuse a DXF spline (an entity's ``SPLINE`` or a hatch's spline edge) whose curve would
    cost more than a drawing may before ezdxf builds it, from its point counts alone:
    ``too_large`` naming ``ref`` (the entity) and what to change."""
    control = len(spline.control_points)
    fit = len(spline.fit_points)
    if control == 0 and fit > MAX_SPLINE_FIT_POINTS:
        raise PlannerError("too_large", f"{ref} is a spline through {fit} fit points without control points, more "
                           f"than the limit of {MAX_SPLINE_FIT_POINTS} (interpolating them takes time and memory "
                           "growing as their square); save it with control points, or as a polyline, or split it",
                           "drawing")
    if control > MAX_SPLINE_CONTROL_POINTS:
        raise PlannerError("too_large", f"{ref} is a spline of {control} control points, more than the limit of "
                           f"{MAX_SPLINE_CONTROL_POINTS} (each becomes at least one vertex of its outline); "
                           "split it or save it with fewer control points", "drawing")
