"""Where a contour program sits in the robot's frame (issue 32, goal 4): the origin checked
(:func:`check_reach`: the numbers; :func:`check_reachable`: every move's path and travel box
inside the robot's reach, else the line and an origin that fits, :func:`proposal`) or fitted
(``origin: "fit"``, :func:`fit_origin`: the program's moves centred on the reachable region
with a margin, as the drawing import places a drawing, else wherever they fit: the most
inscribed placement on the rasterised region, :func:`_offsets`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import PlannerError
from ..model import RobotModel
from ..model.placement import fit_shape, reach_extent, reachable_mask, reachable_points
from ..schema import MAX_COORDINATE, Program
from .passes import RAPID_MARGIN_M, walk_program

__all__ = ["CONTOUR_PSI", "FIT_MARGIN_M", "check_reach", "check_reachable", "fit_origin", "proposal"]

#: the margin [m] between the program's moves and the edge of the reach that ``origin: "fit"``
#: keeps (beyond the tolerance): the tube's cells and the travel boxes are boxes about the path
FIT_MARGIN_M = 0.003
#: the platform angle a contour plans at [rad]
CONTOUR_PSI = 0.0


def check_reach(program: Program, origin: np.ndarray) -> None:
    """Raise ``invalid_input`` naming the first line whose move reaches beyond
    ``MAX_COORDINATE`` m of the robot frame's origin once ``origin`` is added (an arc: its
    ends and the points of its circle it sweeps that are farthest along x or y)."""
    for b in program.blocks:
        for el in b.elements:
            pts = [np.asarray(el.start, float), np.asarray(el.end, float)]
            if el.kind == "arc" and el.centre is not None and el.radius_m and el.start_angle_rad is not None \
                    and el.sweep_rad is not None:
                a0, sweep = float(el.start_angle_rad), float(el.sweep_rad)
                for k in range(4):  # the axis extremes of the circle within the sweep
                    angle = k * math.pi / 2
                    if ((angle - a0) * np.sign(sweep)) % (2 * math.pi) <= abs(sweep):
                        pts.append(np.asarray(el.centre, float) + el.radius_m * np.array([math.cos(angle),
                                                                                           math.sin(angle)]))
            reach = max(float(np.max(np.abs(p + origin))) for p in pts)
            if not reach <= MAX_COORDINATE:
                raise PlannerError("invalid_input", f"line {el.line}: the move reaches {reach:.3g} m from the robot "
                                   f"frame's origin (program zero at {origin.tolist()} m), beyond the limit of "
                                   f"{MAX_COORDINATE:g} m; check the program's units (G20/G21) and the origin",
                                   "program")


def _travel_box(a: np.ndarray, b: np.ndarray) -> Any:
    """The box a travel from ``a`` to ``b`` plans in (:func:`planner.contour.join.plan_travel`):
    the straight move's bounding box grown by ``RAPID_MARGIN_M`` (a shapely polygon)."""
    import shapely

    lo, hi = np.minimum(a, b) - RAPID_MARGIN_M, np.maximum(a, b) + RAPID_MARGIN_M
    return shapely.box(lo[0], lo[1], hi[0], hi[1])


def _program_shapes(program: Program, tol: float) -> list[tuple[int, Any]]:
    """What of the program must be reachable, in the program frame, as (source line, shapely
    geometry): each cut move's path (sampled every mm) and the box each travel plans in (the
    straight move from where the tool is grown by ``RAPID_MARGIN_M``), as
    :func:`planner.contour.plan.plan_contour` moves."""
    import shapely

    out: list[tuple[int, Any]] = []
    pos = np.asarray(program.start, float)
    for step in walk_program(program, tol):  # the walk the estimate counts too
        if step.block is None:  # a travel run, or the approach to a pass away from the tool
            out.append((step.line, _travel_box(step.start, step.end)))
            continue
        for el in step.block.elements:
            n = max(2, math.ceil(el.length_m / 1e-3) + 1)
            pts = el.point_at(np.linspace(0.0, el.length_m, n))
            out.append((el.line, shapely.LineString(pts) if el.length_m > 0 else shapely.Point(pts[0])))
    if not out:
        out.append((1, shapely.Point(pos)))
    return out


def _reach(model: RobotModel) -> Callable[[np.ndarray, np.ndarray, float], np.ndarray]:
    """The reach test :func:`~planner.model.placement.fit_shape` takes: which points the robot reaches."""
    return lambda x, y, psi: reachable_points(model, x, y, psi)


#: the reachable region is rasterised on this many grid points per side (over its extent) for
#: the placement search: about 1.2 mm a pixel on the default robot
SEARCH_GRID = 241
#: candidates of the search verified on the exact reach test before it gives up on the raster's
SEARCH_CANDIDATES = 24
_grids: dict[tuple, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def _reach_grid(model: RobotModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reachable region at ψ :data:`CONTOUR_PSI` rasterised: grid coordinates ``xs``, ``ys``
    [m] and the mask [iy, ix] of the points whose pixel lies wholly inside it (the reach test's
    mask eroded by one pixel: a point rounded to its nearest grid point is then reachable)."""
    from scipy.ndimage import binary_erosion

    key = (id(model), np.asarray(model.packed).tobytes())
    if key not in _grids:
        lo, hi, _ = reach_extent(model, CONTOUR_PSI)
        pad = (hi - lo) / (SEARCH_GRID - 1) * 2
        xs, ys, mask = reachable_mask(model, lo - pad, hi + pad, CONTOUR_PSI, n=SEARCH_GRID)
        if len(_grids) > 8:
            _grids.clear()
        _grids[key] = (xs, ys, binary_erosion(mask))
    return _grids[key]


def _offsets(model: RobotModel, body: Any, margin: float, k: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Where the middle of ``body``'s bounding box may go (scaled by ``k`` about it, grown by
    ``margin``) so that all of it is reachable, on the reach grid (:func:`_reach_grid`): the
    grid points' coordinates (N, 2) [m] and their clearance (pixels to the nearest grid point
    that does not fit: the largest first is the most inscribed placement). The outline
    suffices: the region has no holes."""
    import shapely
    from scipy.ndimage import distance_transform_edt
    from shapely import affinity

    xs, ys, safe = _reach_grid(model)
    h = float(xs[1] - xs[0])
    x0, y0, x1, y1 = body.bounds
    mid = (0.5 * (x0 + x1), 0.5 * (y0 + y1))
    shape = affinity.scale(body, k, k, origin=mid) if k != 1.0 else body
    grown = shape.buffer(margin, quad_segs=4) if margin > 0 else shape
    pts = np.asarray(shapely.get_coordinates(shapely.segmentize(grown.boundary, 0.5 * h))) - mid
    rel = np.unique(np.round(pts / h).astype(np.int64), axis=0)  # (dx, dy) in pixels
    ny, nx = safe.shape
    fit = np.ones_like(safe)
    for dx, dy in rel:
        if abs(dx) >= nx or abs(dy) >= ny:
            return np.zeros((0, 2)), np.zeros(0)
        shifted = np.zeros_like(safe)  # shifted[i, j] = safe[i + dy, j + dx]
        shifted[max(-dy, 0):ny - max(dy, 0), max(-dx, 0):nx - max(dx, 0)] = \
            safe[max(dy, 0):ny - max(-dy, 0), max(dx, 0):nx - max(-dx, 0)]
        fit &= shifted
        if not fit.any():
            return np.zeros((0, 2)), np.zeros(0)
    clear = np.asarray(distance_transform_edt(fit), float)
    iy, ix = np.nonzero(fit)
    order = np.argsort(-clear[iy, ix], kind="stable")
    iy, ix = iy[order], ix[order]
    return np.column_stack((xs[ix], ys[iy])), clear[iy, ix]


def _fit(program: Program, model: RobotModel, tol: float) -> tuple[np.ndarray | None, str]:
    """The origin [m] at which the program's moves (:func:`_program_shapes`) grown by
    ``FIT_MARGIN_M`` + ``tol`` are all reachable: centred on the robot's reachable region where
    they fit there (the drawing import's placement, :func:`planner.model.placement.fit_shape`,
    unscaled), else the most inscribed placement the search over the rasterised region finds
    (:func:`_offsets`), verified on the reach test; or None and why none does and by how much the
    program is too large (the largest scale that fits anywhere)."""
    import shapely

    shapes = [g for _, g in _program_shapes(program, tol)]
    margin = FIT_MARGIN_M + tol
    body = shapely.union_all(shapes)
    x0, y0, x1, y1 = body.bounds
    mid = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1)])
    size = f"{x1 - x0:.4g} m x {y1 - y0:.4g} m"
    try:
        _, _, centre = reach_extent(model, CONTOUR_PSI)
        p = fit_shape(shapes, centre, margin, _reach(model), CONTOUR_PSI)
        if not p.shrunk:
            origin = _rounded(program, model, np.asarray(p.offset, float), tol)
            if origin is not None:
                return origin, ""
    except ValueError:
        pass
    where, _ = _offsets(model, body, margin)
    for q in where[:SEARCH_CANDIDATES]:
        origin = _rounded(program, model, q - mid, tol)
        if origin is not None:
            return origin, ""
    k = _largest_scale(model, body, margin)
    if k <= 0.0:
        return None, (f"no origin fits: the program's moves ({size}) grown by a margin of {margin:g} m do not fit "
                      "where the robot reaches at any scale")
    return None, (f"no origin fits: the program's moves span {size} (cuts, and the boxes its travel moves plan "
                  f"in); with a margin of {margin:g} m they fit where the robot reaches only at {k:.1%} of their "
                  f"size, {1 / k:.3g} times too large (about {(1 - k) * (x1 - x0):.3g} m too wide and "
                  f"{(1 - k) * (y1 - y0):.3g} m too tall)")


def _rounded(program: Program, model: RobotModel, origin: np.ndarray, tol: float) -> np.ndarray | None:
    """``origin`` rounded to 0.1 mm where that is reachable (:func:`_reachable_at`), else as it
    is where that is, else None."""
    for cand in (np.round(origin, 4) + 0.0, origin):
        if _reachable_at(program, model, cand, tol):
            return cand
    return None


def _largest_scale(model: RobotModel, body: Any, margin: float) -> float:
    """The largest factor (to 0.1 %) at which ``body`` scaled about its middle and grown by
    ``margin`` fits somewhere in the rasterised reach (:func:`_offsets`); 0: not even tiny."""
    lo, hi = 1e-3, 1.0
    if not len(_offsets(model, body, margin, lo)[0]):
        return 0.0
    while hi / lo > 1.001:
        k = math.sqrt(lo * hi)
        lo, hi = (k, hi) if len(_offsets(model, body, margin, k)[0]) else (lo, k)
    return lo


def _reachable_at(program: Program, model: RobotModel, origin: np.ndarray, tol: float) -> bool:
    """Whether the program's moves placed at ``origin``, grown by the fit's margin, are all
    within the robot's reach (the boundary sampled every mm)."""
    import shapely

    shapes = [g for _, g in _program_shapes(program, tol)]
    from shapely import affinity

    placed = affinity.translate(shapely.union_all(shapes), *origin).buffer(FIT_MARGIN_M + tol, quad_segs=4)
    pts = np.asarray(shapely.get_coordinates(shapely.segmentize(placed.boundary, 0.001)))
    return bool(np.all(reachable_points(model, pts[:, 0], pts[:, 1], CONTOUR_PSI)))


def fit_origin(program: Program, model: RobotModel, tol: float) -> np.ndarray:
    """The origin ``origin: "fit"`` places the program at (:func:`_fit`); raises ``unreachable``
    saying by how much the program is too large when none fits."""
    origin, why = _fit(program, model, tol)
    if origin is None:
        raise PlannerError("unreachable", why, "origin")
    return origin


def proposal(program: Program, model: RobotModel, tol: float) -> str:
    """The words an out-of-reach error ends with: an origin that fits, or why none does."""
    origin, why = _fit(program, model, tol)
    if origin is None:
        return why
    return (f"an origin that fits: [{origin[0]:g}, {origin[1]:g}] m (--origin={origin[0]:g},{origin[1]:g}, or "
            "'fit')")


def check_reachable(program: Program, model: RobotModel, origin: np.ndarray, tol: float) -> None:
    """Raise ``unreachable`` naming the first move (source line) some point of which (a cut's
    path sampled every mm, a travel's box) the robot does not reach at ``origin`` [m], with an
    origin that fits (or why none does)."""
    import shapely

    for line, g in _program_shapes(program, tol):
        edge = g.boundary if g.geom_type == "Polygon" else g
        # a zero-length move (a full circle's chord, a repeated point) is its point: GEOS cannot segmentize it
        dense = edge if edge.length == 0 else shapely.segmentize(edge, 1e-3)
        pts = np.asarray(shapely.get_coordinates(dense)) + origin
        ok = reachable_points(model, pts[:, 0], pts[:, 1], CONTOUR_PSI)
        if not ok.all():
            x, y = pts[int(np.argmin(ok))]
            raise PlannerError("unreachable", f"line {line}: the move passes ({x:.4f} m, {y:.4f} m) in the robot "
                               f"frame, out of the robot's reach with program zero at origin [{origin[0]:g}, "
                               f"{origin[1]:g}] m; {proposal(program, model, tol)}", "origin")
