"""Free-space segmentation (paper Section V.B): a workspace with obstacles, a start and an end
-> uniform square or triangle cells -> the cells on a path from start to end -> a corridor.

Layout (:class:`planner.schema.Layout`; all lengths in m, angles in rad)::

    {"bounds": {"lower": [x, y], "upper": [x, y]},
     "obstacles": [{"type": "rectangle", "lower": [x, y], "upper": [x, y]}
                   | {"type": "polygon", "points": [[x, y], ...]}
                   | {"type": "circle", "center": [x, y], "radius": r}, ...],
     "clearance": c,                                   # distance the tool keeps from obstacles
     "cell": {"shape": "square" | "triangle", "size": s | null},
     "start": [x, y, psi], "end": [x, y, psi], "psi_range": [lo, hi] | null}

Steps of :func:`segment`, each in its module:

1. **Workspace** (:mod:`.workspace`): the obstacles as shapely polygons, grown by the
   clearance; start and end must be inside the bounds, clear of every grown obstacle and
   reachable.
2. **Cells** (:mod:`.cells`): a uniform grid over the bounds (edge ``s`` given, or the
   default rule); cells outside the bounds or meeting a grown obstacle are *blocked*.
3. **Reach** (:mod:`.reach_region`): a free cell is *unreachable* if some pose in its bounding
   box at some allowed angle is outside the legs' stroke or singular.
4. **Path** (:mod:`.search`): the fewest free cells from a cell holding the start to a cell
   holding the end, then the fewest turns.
5. **Segments** (Table I): the start point (``lower == upper == start``), one segment per
   path cell, the end point. A cell's segment is its axis-aligned bounding box in (x, y) and
   the psi range in ``[2]``; it also carries ``polygon``, the exact cell
   (counter-clockwise), whose half-planes ``A p <= b``
   (:func:`planner.corridor.geometry.halfplanes`) the constrained mode uses.

**What the soft (paper) criterion uses for a triangle**: its bounding box ``[lower, upper]``
(``s`` wide, ``s sqrt(3)/2`` high). The criterion (22) penalises the distance to both box
corners, so over a box it pulls towards the box centre, which for a triangle's box lies inside
the triangle (on its axis at half height). The box itself reaches beyond the triangle (twice
its area), and can reach into a neighbouring blocked cell: only the constrained mode keeps the
robot inside the exact triangles. Reach and singularity are checked over the whole box (as the
planner's segment check does), so a triangle near the edge of the reachable workspace may be
*unreachable* although the triangle alone is reachable.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import PlannerError
from ..model import load_robot
from ..schema import (
    MAX_CELLS,
    MAX_SEGMENTS,
    MAX_TOTAL_STEPS,
    MIN_CELL_SIZE,
    SQRT3_2,
    Layout,
    Segment,
    SegmentationResult,
    Settings,
    cell_count,
)
from .cells import FREE, STATE_NAMES, UNREACHABLE, Grid, block_obstacles, build_grid, count_states, default_cell_size
from .geometry import halfplanes
from .reach_region import boxes_reachable, psi_samples
from .search import fewest_turns_path
from .workspace import Workspace, check_endpoint, format_point, parse_layout

__all__ = ["Segmentation", "remedy_cells", "segment"]


@dataclass
class Segmentation:
    """Cells, their states, the chosen path and the corridor's segments (SI units)."""

    shape: str  # "square" | "triangle"
    size: float  # cell edge [m]
    lower: np.ndarray  # (2,) bounds [m]
    upper: np.ndarray
    clearance: float  # [m]
    psi_range: np.ndarray  # (2,) [rad]
    start: np.ndarray  # (3,) [m, m, rad]
    end: np.ndarray
    polygons: np.ndarray  # (C, k, 2) cell vertices, CCW [m]
    state: np.ndarray  # (C,) FREE | BLOCKED | UNREACHABLE (planner.corridor.cells)
    path: list[int]  # cell ids, start -> end
    segments: list[Segment]  # start point, path cells' boxes, end point
    turns: int  # direction changes along the path
    grown_parts: tuple = ()  # (pieces, owner): obstacles grown by the clearance (Workspace.grown_parts)
    compute_ms: float = 0.0

    @property
    def grown(self) -> list:
        """Each obstacle grown by the clearance, as one shapely geometry (list in obstacle order)."""
        if not self.grown_parts or not len(self.grown_parts[0]):
            return []
        pieces, owner = self.grown_parts
        import shapely  # loaded on first use: plans of given segments never need it
        return [shapely.union_all(pieces[owner == i]) for i in range(int(owner.max()) + 1)]

    @property
    def counts(self) -> dict[str, int]:
        """Cells per state name (count)."""
        return count_states(self.state)

    def to_dict(self) -> dict[str, Any]:
        """The JSON the API sends, in the shape of :class:`planner.schema.SegmentationResult`
        (:meth:`to_result` validates it into that model): cells (id, polygon rounded to
        1e-12 m, state), path, segments {lower, upper, polygon} (usable as a plan request's
        ``segments``), the half-planes of each segment's polygon (``halfplanes[i]``: {A, b}
        with ``A p <= b``, or null for a point), and the grown obstacles' outlines (m)."""
        names = np.array(STATE_NAMES)[self.state].tolist()
        polys = np.round(self.polygons, 12).tolist()
        cells = [{"id": i, "polygon": p, "state": s} for i, (p, s) in enumerate(zip(polys, names))]
        segs, hps = [], []
        for seg in self.segments:
            poly = None if seg.polygon is None else np.asarray(seg.polygon).tolist()
            segs.append({"lower": seg.lower.tolist(), "upper": seg.upper.tolist(), "polygon": poly})
            if seg.polygon is None:
                hps.append(None)
            else:
                A, b = halfplanes(seg.polygon)
                hps.append({"A": A.tolist(), "b": b.tolist()})
        import shapely  # loaded on first use: plans of given segments never need it
        grown = [np.asarray(part.exterior.coords)[:-1].tolist() for g in self.grown for part in shapely.get_parts(g)]
        return {
            "cell": {"shape": self.shape, "size": self.size},
            "bounds": {"lower": self.lower.tolist(), "upper": self.upper.tolist()},
            "clearance": self.clearance,
            "psi_range": self.psi_range.tolist(),
            "cells": cells,
            "counts": self.counts,
            "path": list(self.path),
            "turns": self.turns,
            "segments": segs,
            "halfplanes": hps,
            "grown_obstacles": grown,
            "start": self.start.tolist(),
            "end": self.end.tolist(),
            "compute_ms": self.compute_ms,
        }

    def to_result(self) -> SegmentationResult:
        """:meth:`to_dict` as the result model (validated: arrays as numpy arrays; dumping it
        as JSON gives :meth:`to_dict` again). Validating the JSON lists is faster than
        constructing thousands of cell models from arrays."""
        return SegmentationResult.model_validate(self.to_dict())


def _endpoint_cells(grid: Grid, state: np.ndarray, blocker: np.ndarray, ws: Workspace, key: str,
                    path: str) -> np.ndarray:
    """The free cells holding the start or end (``key``); a PlannerError naming
    ``{path}.{key}`` if none is free."""
    p = ws.start if key == "start" else ws.end
    cells = grid.holding(p)
    free = cells[state[cells] == FREE]
    if free.size:
        return free
    c = int(cells[0]) if cells.size else -1
    if c < 0:  # cannot happen inside the bounds, kept for safety
        raise PlannerError("no_path", f"no cell holds the {key} {format_point(p)}", f"{path}.{key}")
    if state[c] == UNREACHABLE:
        raise PlannerError("unreachable", f"the {key} {format_point(p)} is reachable, but its cell {c} is not wholly "
                           f"reachable (a leg leaves its stroke or the robot is singular somewhere in the cell at "
                           f"some angle in psi_range [{ws.psi_range[0]:g}, {ws.psi_range[1]:g}] rad)", f"{path}.{key}")
    grown = f" grown by the clearance ({ws.clearance:g} m)" if ws.clearance > 0 else ""
    why = f"overlaps obstacle {blocker[c]}{grown}" if blocker[c] >= 0 else "extends past the bounds"
    raise PlannerError("no_path", f"the cell {c} holding the {key} {format_point(p)} is not wholly free: it {why}",
                       f"{path}.{key}")


def _cell_segment(lower: np.ndarray, upper: np.ndarray, polygon: np.ndarray | None = None) -> Segment:
    """A corridor segment built from the grid (valid by construction: not re-validated)."""
    return Segment.model_construct(lower=lower, upper=upper, q_ra=None, q_rb=None, polygon=polygon)


def _cells_and_path(ws: Workspace, model: Any, s: float, grown: tuple, field_path: str,
                    size_path: str) -> tuple[Grid, np.ndarray, tuple[list[int], int]]:
    """Cells of edge ``s``, their states (obstacles, bounds, reach) and the path; a
    PlannerError (``no_path``, ``unreachable``) without advice when there is none."""
    grid = build_grid(ws, s, size_path)
    state, blocker = block_obstacles(grid, ws, s, grown)
    # robot reach and singularity over each free cell's box, at every allowed angle
    cand = np.nonzero(state == FREE)[0]
    if cand.size:
        ok = boxes_reachable(model, grid.lo[cand], grid.hi[cand], psi_samples(ws.psi_range), grid.lattice,
                             grid.win_rows[cand], grid.win_cols[cand])
        state[cand[~ok]] = UNREACHABLE
    sources = _endpoint_cells(grid, state, blocker, ws, "start", field_path)
    targets = _endpoint_cells(grid, state, blocker, ws, "end", field_path)
    found = fewest_turns_path(grid, state == FREE, sources, targets)
    if found is None:
        cnt = count_states(state)
        raise PlannerError("no_path", f"no chain of free {ws.shape} cells (sharing edges) joins the start "
                           f"{format_point(ws.start)} to the end {format_point(ws.end)}: {cnt['free']} of "
                           f"{len(state)} cells are free, {cnt['blocked']} blocked by obstacles"
                           f"{f' (grown by the clearance {ws.clearance:g} m)' if ws.clearance > 0 else ''} or the "
                           f"bounds, {cnt['unreachable']} unreachable by the robot", field_path)
    return grid, state, found


#: the remedy search of a failed segmentation segments at most this many cells in all (x MAX_CELLS):
#: both shapes at every size of its grid down to MAX_CELLS cells take ~5.6x, the sizes halfway
#: between in the rest (issue 31)
REMEDY_CELL_BUDGET = 10
#: the remedy search's cell sizes: each this factor smaller than the one before, down to the
#: smallest whose grid has at most MAX_CELLS cells (issue 31: halving skipped the sizes between,
#: where a grid's alignment lets a narrow gap through: 1.2 mm triangles or 0.8 mm squares planned
#: 6 of 30 layouts with 1-3 mm gaps refused after 5, 2.5 ... mm squares)
REMEDY_RATIO = 1.25
#: the psi-range and clearance remedies try cells of the given size and these fractions of it
REMEDY_OTHER_SIZES = (1.0, 0.5, 0.25)


def _has_path(ws: Workspace, model: Any, s: float, field_path: str) -> bool:
    try:
        _cells_and_path(ws, model, s, ws.grown_parts(), field_path, f"{field_path}.cell.size")
    except PlannerError:
        return False
    return True


def _fits(lower: np.ndarray, upper: np.ndarray, shape: str, size: float) -> bool:
    """Whether a grid of ``shape`` cells of edge ``size`` [m] is allowed over the bounds (at
    least :data:`~planner.schema.MIN_CELL_SIZE`, one cell fits, at most ``MAX_CELLS`` cells)."""
    W, H = (np.asarray(upper, float) - np.asarray(lower, float)).tolist()
    high = size if shape == "square" else size * SQRT3_2
    return (size >= MIN_CELL_SIZE and size <= W + 1e-12 and high <= H + 1e-12
            and cell_count(lower, upper, shape, size)[0] <= MAX_CELLS)


def _limit_size(lower: np.ndarray, upper: np.ndarray, shape: str) -> float:
    """The smallest cell edge [m] (4 digits) whose grid of ``shape`` over the bounds has at most
    ``MAX_CELLS`` cells."""
    W, H = (np.asarray(upper, float) - np.asarray(lower, float)).tolist()
    area = W * H if shape == "square" else 2.0 * W * H / SQRT3_2  # cells ~ area / size^2
    size = float(np.sqrt(area / MAX_CELLS))
    size = max(float(f"{size:.4g}"), MIN_CELL_SIZE)
    for _ in range(1000):
        if cell_count(lower, upper, shape, size)[0] <= MAX_CELLS:
            break
        size = float(f"{size * 1.0005:.4g}") if float(f"{size * 1.0005:.4g}") > size else size * 1.001
    return size


def _remedy_sizes(lower: np.ndarray, upper: np.ndarray, shape: str, s: float,
                  shapes: tuple[str, ...] | None = None) -> list[tuple[str, float]]:
    """The cells ``(shape, size)`` the remedy search of a layout with ``shape`` cells of edge
    ``s`` [m] segments, the largest first (the fewest segments), at equal sizes ``shape`` first:
    sizes from ``s`` down by :data:`REMEDY_RATIO` (rounded to 4 digits, so that a message's
    figure gives the same grid) and the smallest whose grid has at most ``MAX_CELLS`` cells, in
    both shapes (``shapes``: only these), the given ``(shape, s)`` left out; the smallest dropped
    beyond :data:`REMEDY_CELL_BUDGET` x ``MAX_CELLS`` cells in all; with budget left, the sizes
    halfway between (a factor ``sqrt(REMEDY_RATIO)``), the smallest first (a narrow gap passes
    where a grid's lines fall about it: sizes apart by less find more of them)."""
    order = (shape, "triangle" if shape == "square" else "square")
    if shapes is not None:
        order = tuple(sh for sh in order if sh in shapes)
    main: list[tuple[str, float]] = []
    for sh in order:
        least = _limit_size(lower, upper, sh)
        size, k = s, 0
        while size >= least * (1.0 + 1e-9):
            if not (k == 0 and sh == shape) and _fits(lower, upper, sh, size):
                main.append((sh, size))
            k += 1
            size = float(f"{s / REMEDY_RATIO ** k:.4g}")
        if least < s and _fits(lower, upper, sh, least) and (sh, least) not in main:
            main.append((sh, least))
    rank = {sh: i for i, sh in enumerate(order)}

    def ordered(cells: list[tuple[str, float]]) -> list[tuple[str, float]]:
        return sorted(cells, key=lambda c: (-c[1], rank[c[0]]))

    budget = REMEDY_CELL_BUDGET * MAX_CELLS
    out: list[tuple[str, float]] = []
    spent = 0
    for c in ordered(main):
        spent += cell_count(lower, upper, *c)[0]
        if spent > budget:
            return out
        out.append(c)
    halves = []
    for sh in order:
        sizes = sorted(size for shp, size in out if shp == sh)
        halves += [(sh, float(f"{np.sqrt(a * b):.4g}")) for a, b in zip(sizes[:-1], sizes[1:])]
    for c in sorted(halves, key=lambda c: c[1]):  # the smallest first
        n = cell_count(lower, upper, *c)[0]
        if c in out or spent + n > budget:
            continue
        spent += n
        out.append(c)
    return ordered(out)


def _other_sizes(lower: np.ndarray, upper: np.ndarray, shape: str, s: float) -> list[float]:
    """The cell sizes the psi-range and clearance remedies try (:data:`REMEDY_OTHER_SIZES`)."""
    return [s * f for f in REMEDY_OTHER_SIZES if f == 1.0 or _fits(lower, upper, shape, s * f)]


def remedy_cells(lower: np.ndarray, upper: np.ndarray, shape: str, s: float, clearance: float,
                 psi_narrows: bool) -> tuple[int, int]:
    """(cells, segmentations): the most that :func:`_remedies` segments when a layout of cells
    of edge ``s`` has no path (and that :func:`segment` segments at the default size before it
    finds one); the bound of the advice's work, known before the request starts
    (:func:`planner.orchestrator.estimate_work`). ``psi_narrows``: the layout's psi_range is
    wider than its start and end angles (a narrower one is tried)."""
    cand = _remedy_sizes(lower, upper, shape, s)
    cells, runs = sum(cell_count(lower, upper, sh, size)[0] for sh, size in cand), len(cand)
    others = _other_sizes(lower, upper, shape, s)
    again, k = sum(cell_count(lower, upper, shape, size)[0] for size in others), len(others)
    if psi_narrows:
        cells, runs = cells + again, runs + k
    if clearance > 0:
        cells, runs = cells + 2 * again, runs + 2 * k
    return cells, runs


def _cell_words(shape: str, size: float, ws: Workspace, s: float, field_path: str) -> str:
    """How a message names cells of ``shape`` and ``size`` [m] as a change of the layout's."""
    if shape == ws.shape:
        return f"cells of {size:g} m ({field_path}.cell.size; now {s:g} m)"
    return (f"{shape} cells of {size:g} m ({field_path}.cell.shape and {field_path}.cell.size; now {ws.shape} "
            f"cells of {s:g} m)")


def _first_path(ws: Workspace, model: Any, cand: list[tuple[str, float]],
                field_path: str) -> tuple[str, float, tuple[Grid, np.ndarray, tuple[list[int], int]]] | None:
    """The first of the cells ``cand`` ``(shape, size)`` that give a path, with the grid,
    states and path; None if none does."""
    grown = ws.grown_parts()
    for shape, size in cand:
        try:
            got = _cells_and_path(replace(ws, shape=shape), model, size, grown, field_path,
                                  f"{field_path}.cell.size")
        except PlannerError:
            continue
        return shape, size, got
    return None


def _remedies(ws: Workspace, model: Any, s: float, field_path: str,
              tried: tuple[tuple[str, float], ...] = ()) -> list[str]:
    """The changes of the layout that were tried and give a path (checked by segmenting
    again, within a budget of cells, :func:`remedy_cells`): other cells (both shapes, every
    size of :func:`_remedy_sizes`; none where the grown obstacles themselves cut the start off
    from the end), a narrower psi_range, a smaller clearance. Empty: none of the tried changes
    helps. ``tried``: cells already segmented without a path (the default size's search)."""
    out: list[str] = []
    if _separation(ws) is None:
        cand = [c for c in _remedy_sizes(ws.lower, ws.upper, ws.shape, s) if c not in tried]
        got = _first_path(ws, model, cand, field_path)
        if got is not None:
            out.append(f"{_cell_words(got[0], got[1], ws, s, field_path)} give a path")
    others = _other_sizes(ws.lower, ws.upper, ws.shape, s)
    default_psi = np.array([min(ws.start[2], ws.end[2]), max(ws.start[2], ws.end[2])])
    if np.any(np.abs(ws.psi_range - default_psi) > 1e-12):
        narrow = replace(ws, psi_range=default_psi)
        for size in others:
            if _has_path(narrow, model, size, field_path):
                out.append(f"psi_range [{default_psi[0]:g}, {default_psi[1]:g}] rad"
                           + (f" with cells of {size:g} m" if size != s else "") + " gives a path")
                break
    if ws.clearance > 0:
        for c in (0.5 * ws.clearance, 0.0):
            less = replace(ws, clearance=c)
            ok = next((size for size in others if _has_path(less, model, size, field_path)), None)
            if ok is not None:
                out.append(f"a clearance of {c:g} m ({field_path}.clearance; now {ws.clearance:g} m)"
                           + (f" with cells of {ok:g} m" if ok != s else "") + " gives a path")
                break
    return out


def _separation(ws: Workspace) -> str | None:
    """Which grown obstacles (with the bounds) cut the start off from the end in the free
    space itself (no cells), said with their extent; None when the free space joins them."""
    import shapely  # loaded on first use: plans of given segments never need it

    box = shapely.box(ws.lower[0], ws.lower[1], ws.upper[0], ws.upper[1])
    pieces, owner = ws.grown_parts()
    if not len(pieces):
        return None
    a, b = shapely.Point(ws.start[0], ws.start[1]), shapely.Point(ws.end[0], ws.end[1])

    def apart(blocked: Any) -> bool:
        free = shapely.difference(box, blocked)
        return not any(p.covers(a) and p.covers(b) for p in shapely.get_parts(free))

    union = shapely.union_all(pieces)
    if not apart(union):
        return None
    for comp in shapely.get_parts(union):
        if apart(comp):
            ids = sorted({int(i) for i in owner[shapely.intersects(pieces, comp)]})
            names = ", ".join(f"{i} (layout.obstacles[{i}])" for i in ids)
            x0, y0, x1, y1 = shapely.bounds(shapely.intersection(comp, box)).tolist()
            tol = 1e-9 * max(float(np.max(ws.upper - ws.lower)), 1e-9)
            if y0 <= ws.lower[1] + tol and y1 >= ws.upper[1] - tol:
                where = f"spans the bounds from y = {y0:.4f} m to {y1:.4f} m (at x = {x0:.4f} .. {x1:.4f} m)"
            elif x0 <= ws.lower[0] + tol and x1 >= ws.upper[0] - tol:
                where = f"spans the bounds from x = {x0:.4f} m to {x1:.4f} m (at y = {y0:.4f} .. {y1:.4f} m)"
            else:
                where = (f"cuts the start off from the end (it covers x = {x0:.4f} .. {x1:.4f} m, "
                         f"y = {y0:.4f} .. {y1:.4f} m)")
            grown = f" grown by the clearance {ws.clearance:g} m" if ws.clearance > 0 else ""
            return f"obstacle{'s' if len(ids) > 1 else ''} {names}{grown} {where}"
    ids = sorted({int(i) for i in owner})
    return (f"obstacles {', '.join(str(i) for i in ids)} grown by the clearance {ws.clearance:g} m together with "
            "the bounds cut the start off from the end")


def _endpoint_blocker(ws: Workspace, key: str) -> str | None:
    """Why every cell holding the start or end (``key``) meets an obstacle: the point touches
    an obstacle grown by the clearance (a cell holding it reaches into it at any size), said
    with the obstacle; None if it does not."""
    import shapely  # loaded on first use: plans of given segments never need it

    p = ws.start if key == "start" else ws.end
    pieces, owner = ws.grown_parts()
    if not len(pieces):
        return None
    d = shapely.distance(pieces, shapely.Point(p[0], p[1]))
    i = int(np.argmin(d))
    if d[i] > 1e-9 * max(float(np.max(ws.upper - ws.lower)), 1e-9):
        return None
    grown = f" grown by the clearance {ws.clearance:g} m" if ws.clearance > 0 else ""
    return f"the {key} lies on the edge of obstacle {int(owner[i])} (layout.obstacles[{int(owner[i])}]){grown}"


def _smallest_words(cand: list[tuple[str, float]], ws: Workspace, s: float) -> str:
    """The smallest cells of each shape the remedy search tried, in words."""
    least: dict[str, float] = {ws.shape: s}
    for shape, size in cand:
        least[shape] = min(least.get(shape, size), size)
    return " and ".join(f"{shape} cells down to {size:g} m" for shape, size in least.items())


def _no_path_error(exc: PlannerError, ws: Workspace, model: Any, s: float, field_path: str,
                   tried: tuple[tuple[str, float], ...] = ()) -> PlannerError:
    """The failed segmentation's error with advice that works: the remedies checked by
    segmenting again, or the obstacle that makes every cell size hopeless. ``tried``: the
    cells the default size's search segmented already (not segmented again)."""
    fixes = _remedies(ws, model, s, field_path, tried)
    if fixes:
        return PlannerError(exc.code, f"{exc.message}; " + "; or ".join(fixes), exc.field)
    cut = _separation(ws)
    if cut is not None:
        bare = replace(ws, clearance=0.0)
        hopeless = "no cell size can pass it" + (
            ", nor any clearance" if ws.clearance == 0 or _separation(bare) is not None else
            "; a smaller clearance opens a gap narrower than the smallest cells tried")
        return PlannerError(exc.code, f"{exc.message}; the {cut}: {hopeless}; move the start or the end",
                            exc.field)
    cand = list(tried) + [c for c in _remedy_sizes(ws.lower, ws.upper, ws.shape, s) if c not in tried]
    down_to = _smallest_words(cand, ws, s)
    if exc.field is not None and exc.field.endswith((".start", ".end")):
        key = exc.field.rsplit(".", 1)[1]
        why = _endpoint_blocker(ws, key)
        if why is not None:
            return PlannerError(exc.code, f"{exc.message}; {why}: no cell holding it is wholly free, at any size "
                                f"(tried {down_to}); move the {key}", exc.field)
    return PlannerError(exc.code, f"{exc.message}; {down_to} (every size a factor {REMEDY_RATIO:g} apart, to the "
                        f"limit of {MAX_CELLS} cells), a smaller clearance and the narrowest psi_range were tried and "
                        "give no path: the free space that joins them is narrower than that, or the robot cannot "
                        "reach it; move the start or the end", exc.field)


def segment(layout: Layout | dict[str, Any], robot: Any, settings: Settings | None = None,
            field_path: str = "layout", advise: bool = True) -> Segmentation:
    """Segment a layout (the module docstring) into cells and a corridor for ``robot`` (a
    :class:`~planner.model.RobotModel` or what :func:`~planner.model.load_robot` takes).

    Raises :class:`PlannerError`: ``invalid_input`` (a malformed field; start or end outside
    the bounds or inside an obstacle grown by the clearance), ``unreachable``/``singular``
    (start or end not reachable by the robot, or its cell not wholly reachable), ``no_path``
    (no chain of free cells joins start and end), ``too_large`` (too many cells or samples).
    ``advise=False``: a ``no_path`` at the given cells as it is, without the remedy search
    (and without the default size's search of other cells).
    """
    t0 = time.perf_counter()
    model = load_robot(robot)
    settings = settings or Settings.model_validate({})
    ws = parse_layout(layout, field_path)
    for key in ("start", "end"):
        check_endpoint(ws, model, key, field_path)
    size_path = f"{field_path}.cell.size"
    s = ws.size if ws.size is not None else default_cell_size(ws, settings)
    grown = ws.grown_parts()
    try:
        grid, state, found = _cells_and_path(ws, model, s, grown, field_path, size_path)
    except PlannerError as exc:
        if exc.code not in ("no_path", "unreachable") or exc.field not in (field_path, f"{field_path}.start",
                                                                              f"{field_path}.end"):
            raise
        if not advise:
            raise
        got, tried = None, ()
        if ws.size is None and _separation(ws) is None:
            # the default size: the first of the remedy search's cells that gives a path (issue 31:
            # 1-3 mm gaps were refused at the default size while smaller cells planned them); a
            # shape the request gave is kept
            cand = _remedy_sizes(ws.lower, ws.upper, ws.shape, s, (ws.shape,) if ws.shape_given else None)
            got = _first_path(ws, model, cand, field_path)
            tried = tuple(cand)
        if got is None:
            raise _no_path_error(exc, ws, model, s, field_path, tried) from None
        shape, s, (grid, state, found) = got
        ws = replace(ws, shape=shape)
    path, turns = found
    n_seg = len(path) + 2
    S = settings.samples_per_segment
    if n_seg > MAX_SEGMENTS or n_seg * S > MAX_TOTAL_STEPS:
        raise PlannerError("too_large", f"the corridor has {n_seg} segments x {S} samples, more than the limits "
                           f"({MAX_SEGMENTS} segments, {MAX_TOTAL_STEPS} steps); use larger cells", size_path)

    # segments (Table I): start point, cells, end point
    plo, phi = ws.psi_range
    segs = [_cell_segment(ws.start.copy(), ws.start.copy())]
    for c in path:
        segs.append(_cell_segment(np.array([grid.lo[c, 0], grid.lo[c, 1], plo]),
                                  np.array([grid.hi[c, 0], grid.hi[c, 1], phi]), polygon=grid.polygons[c].copy()))
    segs.append(_cell_segment(ws.end.copy(), ws.end.copy()))
    return Segmentation(ws.shape, float(s), ws.lower, ws.upper, ws.clearance, ws.psi_range, ws.start, ws.end,
                        grid.polygons, state, path, segs, turns, grown, (time.perf_counter() - t0) * 1e3)
