"""Free-space segmentation (paper Section V.B): a workspace with obstacles, a start and an end
-> uniform square or triangle cells -> the cells on a path from start to end -> a corridor.

Layout (all lengths in m, angles in rad)::

    {"bounds": {"lower": [x, y], "upper": [x, y]},
     "obstacles": [{"type": "rectangle", "lower": [x, y], "upper": [x, y]}
                   | {"type": "polygon", "points": [[x, y], ...]}
                   | {"type": "circle", "center": [x, y], "radius": r}, ...],
     "clearance": c,                                   # distance the tool keeps from obstacles
     "cell": {"shape": "square" | "triangle", "size": s | null},
     "start": [x, y, psi], "end": [x, y, psi], "psi_range": [lo, hi] | null}

Steps (:func:`segment`):

1. **Free space** = bounds minus every obstacle grown by the clearance (shapely ``buffer``:
   flat sides offset exactly; circular arcs, of circles and of rounded corners, replaced by
   polygons *circumscribing* them, so conservative by at most 0.13 % of the radius), minus
   what the robot cannot reach or is singular at over the allowed psi range.
2. **Cells**: a uniform grid over the bounds, anchored at ``bounds.lower``. Squares of edge
   ``s``; or equilateral triangles of edge ``s`` (rows of height ``s sqrt(3)/2``, alternately
   pointing up and down). A cell is *free* only if it lies wholly inside the bounds and its
   interior meets no grown obstacle (touching is allowed: there the tool is exactly at the
   clearance; overlaps under 1e-9 of the cell size count as touching); *blocked* otherwise;
   *unreachable* if free of obstacles but some pose in its bounding box at some allowed angle
   is outside the legs' stroke or singular (stroke: exact per angle; singularity: on the
   box's 3 x 3 grid, as the planner's segment check; angles: :func:`psi_samples`).
3. **Path**: cells are adjacent when they share an edge. Among all paths of free cells from a
   cell holding the start to a cell holding the end, the one with the fewest cells is chosen,
   and among those the one with the fewest turns (breadth-first distances, then a dynamic
   programme over the shortest-path DAG with state = (cell, incoming direction)). A *turn* is
   a change of direction for squares; for triangles a straight run through a strip of
   triangles crosses edges of two alternating orientations, so a turn is a crossing whose
   edge orientation differs from the one two crossings back.
4. **Segments** (Table I): the start point (``lower == upper == start``), one segment per path
   cell, the end point. A cell's segment is its axis-aligned bounding box in (x, y) and the
   psi range in ``[2]``; triangles (and squares) also carry ``polygon``, the exact cell
   (counter-clockwise), whose half-planes ``A p <= b`` (:func:`halfplanes`) the constrained
   mode uses.

**What the soft (paper) criterion uses for a triangle**: its bounding box ``[lower, upper]``
(``s`` wide, ``s sqrt(3)/2`` high). The criterion (22) penalises the distance to both box
corners, so over a box it pulls towards the box centre, which for a triangle's box lies inside
the triangle (on its axis at half height). The box itself reaches beyond the triangle (twice
its area), and can reach into a neighbouring blocked cell: only the constrained mode keeps the
robot inside the exact triangles. Reach and singularity are checked over the whole box (as the
planner's segment check does), so a triangle near the edge of the reachable workspace may be
*unreachable* although the triangle alone is reachable.

**Default cell size** (the paper: "the density of segmentation follows from rough distance of
the start and end points and selected sampling period"): each cell becomes one segment held
for ``S`` samples (``settings.samples_per_segment``, default ``N``), so at a nominal speed
``v = 0.1 m/s`` the robot crosses one cell in ``S Ts`` seconds::

    s = clamp(v S Ts, d / 50, d / 4),   d = |end - start| (x, y) [m]

then limited to half the smaller workspace side and enlarged, if needed, so the grid has at
most :data:`MAX_CELLS` cells. The Table I example (``Ts = 0.01 s``, ``N = 20``) gives 0.02 m,
the paper's cell. Smaller ``Ts`` -> smaller cells (denser), as the paper asks; the clamp keeps
the straight start-end line between 4 and 50 cells long.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import shapely
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from pydantic import ValidationError

from ..errors import PlannerError, invalid
from ..model import SINGULAR_TOL, RobotModel, load_robot
from ..model.reach import boxes_within_stroke, check_pose
from ..schema import MAX_CELLS, MAX_SEGMENTS, MAX_TOTAL_STEPS, SQRT3_2, PlanRequest, Segment, Settings, cell_count, \
    planner_error
from ..schema import Layout as LayoutSpec
from .geometry import halfplanes

Robot = RobotModel
#: nominal tool speed of the default cell-size rule [m/s]
DEFAULT_SPEED = 0.1
#: segments of a quarter circle in grown outlines (circumscribed: conservative by <= 0.13 %)
QUAD_SEGS = 16
_GROW = 1.0 / math.cos(math.pi / (4 * QUAD_SEGS))
#: largest angle step between the psi samples of the reach check [rad]
PSI_STEP = 0.05

FREE, BLOCKED, UNREACHABLE = 0, 1, 2
STATE_NAMES = ("free", "blocked", "unreachable")

_LAYOUT_KEYS = ("bounds", "obstacles", "clearance", "cell", "start", "end", "psi_range")
_OBSTACLE_KEYS = {"rectangle": ("lower", "upper"), "polygon": ("points",), "circle": ("center", "radius")}


# ---------------------------------------------------------------------------------------
# layout validation
# ---------------------------------------------------------------------------------------

@dataclass
class Layout:
    """A validated layout (SI: m, rad)."""

    lower: np.ndarray  # (2,) workspace lower corner [m]
    upper: np.ndarray  # (2,) workspace upper corner [m]
    obstacles: list  # shapely Polygons (exact obstacles)
    clearance: float  # [m]
    shape: str  # "square" | "triangle"
    size: float | None  # cell edge [m]; None = default rule
    start: np.ndarray  # (3,) [m, m, rad]
    end: np.ndarray  # (3,)
    psi_range: np.ndarray  # (2,) [rad]
    circles: dict = field(default_factory=dict)  # obstacle index -> (centre (2,), radius) [m]

    def grown_parts(self) -> tuple[np.ndarray, np.ndarray]:
        """The obstacles grown by the clearance, as pieces whose union is each grown obstacle
        (no union computed: the cell test checks each piece): ``(pieces, owner)``, shapely
        polygons and the obstacle index of each. Flat sides are exact (offset by the clearance);
        circles and the rounded corners (circles about each vertex) are circumscribed polygons,
        conservative by at most 0.13 % of their radius."""
        pieces, owner, centres, cowner = [], [], [], []
        for i, ob in enumerate(self.obstacles):
            if i in self.circles:
                c, r = self.circles[i]
                pieces.append(_discs(c[None], r + self.clearance)[0])
                owner.append(i)
            elif self.clearance > 0:
                pieces.append(ob.buffer(self.clearance, quad_segs=QUAD_SEGS))
                owner.append(i)
                v = np.asarray(ob.exterior.coords)[:-1]
                centres.append(v)
                cowner.append(np.full(len(v), i))
            else:
                pieces.append(ob)
                owner.append(i)
        pieces = np.array(pieces, dtype=object)
        owner = np.array(owner, dtype=np.int64)
        if centres:
            pieces = np.concatenate((pieces, _discs(np.concatenate(centres), self.clearance)))
            owner = np.concatenate((owner, np.concatenate(cowner)))
        return pieces, owner


def _discs(centres: np.ndarray, radius: float) -> np.ndarray:
    """Regular ``4 QUAD_SEGS``-gons circumscribing circles of ``radius`` [m] about ``centres``
    (k, 2): their edges touch the circle at multiples of ``pi / (2 QUAD_SEGS)``, so the
    extreme sides (left, right, bottom, top) are exact."""
    a = (np.arange(4 * QUAD_SEGS) + 0.5) * (math.pi / (2 * QUAD_SEGS))
    ring = (radius * _GROW) * np.column_stack((np.cos(a), np.sin(a)))
    return shapely.polygons(centres[:, None, :] + ring[None])


def parse_layout(raw, path: str = "layout") -> Layout:
    """The workspace of a validated layout (:class:`planner.schema.Layout`, or a dict that is
    validated here; errors name the field under ``path``): obstacles as shapely polygons."""
    if not isinstance(raw, LayoutSpec):
        try:
            raw = LayoutSpec.model_validate(raw)
        except ValidationError as exc:
            raise planner_error(exc, path) from None
    obstacles, circles = [], {}
    for i, o in enumerate(raw.obstacles):
        if o.type == "rectangle":
            obstacles.append(shapely.box(o.lower[0], o.lower[1], o.upper[0], o.upper[1]))
        elif o.type == "circle":
            obstacles.append(_discs(np.asarray(o.center, float)[None], float(o.radius))[0])  # circumscribes it
            circles[i] = (np.array(o.center, dtype=float), float(o.radius))
        else:
            obstacles.append(shapely.Polygon(o.points))
    return Layout(np.array(raw.bounds.lower, float), np.array(raw.bounds.upper, float), obstacles,
                  float(raw.clearance), raw.cell.shape, raw.cell.size, np.array(raw.start_pose, float),
                  np.array(raw.end_pose, float), np.array(raw.angle_range, float), circles)


# ---------------------------------------------------------------------------------------
# geometry helpers
# ---------------------------------------------------------------------------------------

def sigma_min_fast(robot: Robot, x: np.ndarray, y: np.ndarray, psi: float) -> np.ndarray:
    """:meth:`Robot.singularity_measure_batch` at poses ``(x, y, psi)`` (1-D arrays, one angle):
    smallest singular value of the dimensionless leg Jacobian, from the closed-form smallest
    eigenvalue of the 3 x 3 Gram matrix (much faster than a batched SVD)."""
    c, s = math.cos(psi), math.sin(psi)
    r0 = robot.r0
    k = 1.0 / robot.char_length
    a11 = a22 = a33 = a12 = a13 = a23 = 0.0
    for i in range(robot.n_legs):  # a few legs: accumulate the Gram matrix leg by leg
        rx = c * r0[i, 0] - s * r0[i, 1]
        ry = s * r0[i, 0] + c * r0[i, 1]
        dx = x + (rx - robot.base[i, 0])
        dy = y + (ry - robot.base[i, 1])
        inv = 1.0 / np.hypot(dx, dy)
        ex, ey = dx * inv, dy * inv
        ez = (k * rx) * ey - (k * ry) * ex
        a11 = a11 + ex * ex
        a22 = a22 + ey * ey
        a33 = a33 + ez * ez
        a12 = a12 + ex * ey
        a13 = a13 + ex * ez
        a23 = a23 + ey * ez
    q = (a11 + a22 + a33) / 3.0
    p1 = a12 * a12 + a13 * a13 + a23 * a23
    b11, b22, b33 = a11 - q, a22 - q, a33 - q
    p = np.sqrt((b11 * b11 + b22 * b22 + b33 * b33 + 2.0 * p1) / 6.0)
    ps = np.where(p > 0, p, 1.0)
    det = (b11 * (b22 * b33 - a23 * a23) - a12 * (a12 * b33 - a23 * a13) + a13 * (a12 * a23 - b22 * a13))
    r = np.clip(det / (2.0 * ps**3), -1.0, 1.0)
    lam = np.where(p > 0, q + 2.0 * p * np.cos(np.arccos(r) / 3.0 + 2.0 * math.pi / 3.0), q)
    return np.sqrt(np.maximum(lam, 0.0))


def psi_samples(psi_range) -> np.ndarray:
    """Angles [rad] at which reach is checked: ``4k + 1`` evenly spaced samples (so they
    include the planner's 5-sample check), at most :data:`PSI_STEP` apart, capped at 33."""
    lo, hi = float(psi_range[0]), float(psi_range[1])
    if hi <= lo:
        return np.array([lo])
    k = min(max(1, math.ceil((hi - lo) / (4 * PSI_STEP))), 8)
    return np.linspace(lo, hi, 4 * k + 1)


def box_reach(robot: Robot, lo: np.ndarray, hi: np.ndarray, psis) -> np.ndarray:
    """Whether every pose in each box ``[lo, hi]`` ((C, 2) each, m) at every angle in ``psis``
    keeps every leg within its stroke (C,) bool (:func:`planner.model.reach.boxes_within_stroke`)."""
    return boxes_within_stroke(robot, lo, hi, psis)


def _regular_windows(robot: Robot, lattice, rows: np.ndarray, cols: np.ndarray, psis) -> np.ndarray:
    """Non-singular at every angle on all 9 points of each cell's 3 x 3 box window (C,) bool.
    The lattice ``(x0, y0, dx, dy, nx, ny)`` holds the points ``x0 + i dx, y0 + j dy``; shared
    points are evaluated once, and only those some window needs."""
    x0, y0, dx, dy, nx, ny = lattice
    a, b = np.divmod(np.arange(9), 3)
    flat = (rows[:, None] + a) * nx + (cols[:, None] + b)  # (C, 9)
    pts, inv = np.unique(flat, return_inverse=True)
    j, i = np.divmod(pts, nx)
    X, Y = x0 + dx * i, y0 + dy * j
    ok = np.ones(len(pts), dtype=bool)
    for psi in psis:
        ok &= sigma_min_fast(robot, X, Y, psi) >= SINGULAR_TOL
    return ok[inv.reshape(flat.shape)].all(axis=1)


def reachable_region(robot, bounds, psi_range=(0.0, 0.0), resolution: float = 0.005) -> list[dict]:
    """The part of ``bounds`` the robot's tool point reaches, regular, at every angle in
    ``psi_range`` [rad], at ``resolution`` [m]: the union of the grid squares whose every pose
    is within the legs' stroke and non-singular (the same test as the segmentation's cells).

    ``bounds`` is ``{"lower": [x, y], "upper": [x, y]}`` or ``(lower, upper)``. Returns a list
    of polygons ``{"exterior": [[x, y], ...], "holes": [[[x, y], ...], ...]}`` in m (rings
    not closed), for the editor to draw. At most :data:`MAX_CELLS` grid squares.
    """
    robot = load_robot(robot)
    if isinstance(bounds, dict):
        lower, upper = np.asarray(bounds.get("lower"), float), np.asarray(bounds.get("upper"), float)
    else:
        lower, upper = np.asarray(bounds[0], float), np.asarray(bounds[1], float)
    if lower.shape != (2,) or upper.shape != (2,) or not np.all(np.isfinite(np.concatenate((lower, upper)))):
        raise invalid("bounds", "must be {lower: [x, y], upper: [x, y]} in m")
    res = float(resolution)
    if not (math.isfinite(res) and res > 0):
        raise invalid("resolution", "must be a finite number > 0")
    if not np.all(upper > lower):
        raise invalid("bounds.upper", "must be greater than bounds.lower")
    nx, ny = (int(math.ceil((upper[i] - lower[i]) / res - 1e-9)) for i in range(2))
    if nx * ny > MAX_CELLS:
        raise PlannerError("too_large", f"{nx} x {ny} grid squares exceed the limit of {MAX_CELLS}; use a coarser "
                           "resolution", "resolution")
    psis = psi_samples(psi_range)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    i, j = i.ravel(), j.ravel()
    xs = np.minimum(lower[0] + res * np.arange(nx + 1), upper[0])  # shared edges: identical floats
    ys = np.minimum(lower[1] + res * np.arange(ny + 1), upper[1])
    lo = np.column_stack((xs[i], ys[j]))
    hi = np.column_stack((xs[i + 1], ys[j + 1]))
    ok = box_reach(robot, lo, hi, psis)
    ok[ok] = _regular_windows(robot, (lower[0], lower[1], res / 2, res / 2, 2 * nx + 1, 2 * ny + 1),
                              2 * j[ok], 2 * i[ok], psis)
    if not ok.any():
        return []
    geom = shapely.coverage_union_all(shapely.box(lo[ok, 0], lo[ok, 1], hi[ok, 0], hi[ok, 1]))
    geom = shapely.simplify(geom, 0.0)  # drop the collinear grid vertices
    out = []
    for poly in shapely.get_parts(geom):
        out.append({"exterior": np.asarray(poly.exterior.coords)[:-1].tolist(),
                    "holes": [np.asarray(r.coords)[:-1].tolist() for r in poly.interiors]})
    return out


# ---------------------------------------------------------------------------------------
# the grid
# ---------------------------------------------------------------------------------------

@dataclass
class _Grid:
    polygons: np.ndarray  # (C, k, 2) cell vertices, counter-clockwise [m]
    lo: np.ndarray  # (C, 2) bounding boxes [m]
    hi: np.ndarray  # (C, 2)
    edges: np.ndarray  # (E, 3) directed adjacency (src, dst, label)
    win_rows: np.ndarray  # (C,) 3 x 3 singularity window of each box on the lattice
    win_cols: np.ndarray
    lattice: tuple  # (x0, y0, dx, dy, nx, ny)
    n_states: int  # DP states per cell
    trans: np.ndarray  # (n_states, labels) next state
    cost: np.ndarray  # (n_states, labels) turn cost
    init_state: int
    index: tuple = ()  # (x0, y0, xstep, ystep, ncols, nrows, col_offset, width_steps): id = row * ncols + col

    def near(self, xmin: float, ymin: float, xmax: float, ymax: float) -> np.ndarray:
        """Ids of the cells whose bounding box may meet the box [xmin, xmax] x [ymin, ymax]
        (a superset, from the grid arithmetic)."""
        x0, y0, xs, ys, nc, nr, off, w = self.index
        c0 = max(int(math.floor((xmin - x0) / xs)) - off - w - 1, 0)
        c1 = min(int(math.floor((xmax - x0) / xs)) - off + 1, nc - 1)
        r0 = max(int(math.floor((ymin - y0) / ys)) - 1, 0)
        r1 = min(int(math.floor((ymax - y0) / ys)) + 1, nr - 1)
        if c0 > c1 or r0 > r1:
            return np.empty(0, dtype=np.int64)
        return (np.arange(r0, r1 + 1)[:, None] * nc + np.arange(c0, c1 + 1)[None, :]).ravel()


def default_cell_size(lay: Layout, settings: Settings) -> float:
    """The default cell edge [m] (see the module docstring)."""
    d = float(np.hypot(*(lay.end[:2] - lay.start[:2])))
    s = DEFAULT_SPEED * settings.samples_per_segment * settings.Ts
    if d > 0:
        s = min(max(s, d / 50.0), d / 4.0)
    W, H = lay.upper - lay.lower
    s = min(s, 0.5 * min(W, H))
    area = W * H if lay.shape == "square" else 2.0 * W * H / SQRT3_2  # cells ~ area / cell area
    s_cap = math.sqrt(area / (0.9 * MAX_CELLS))
    return max(s, s_cap)


def _square_grid(x0, y0, s, nx, ny) -> _Grid:
    j, i = np.divmod(np.arange(nx * ny), nx)
    xs, ys = x0 + s * np.arange(nx + 1), y0 + s * np.arange(ny + 1)  # shared edges: identical floats
    lo = np.column_stack((xs[i], ys[j]))
    hi = np.column_stack((xs[i + 1], ys[j + 1]))
    poly = np.stack((lo, np.column_stack((hi[:, 0], lo[:, 1])), hi, np.column_stack((lo[:, 0], hi[:, 1]))), axis=1)
    ids = np.arange(nx * ny)
    east = ids[i < nx - 1]
    north = ids[j < ny - 1]
    src = np.concatenate((east, east + 1, north, north + nx))
    dst = np.concatenate((east + 1, east, north + nx, north))
    lab = np.concatenate((np.full(len(east), 0), np.full(len(east), 1), np.full(len(north), 2), np.full(len(north), 3)))
    # state = direction of the last move (0 E, 1 W, 2 N, 3 S) or 4 (none yet); a turn: a new direction
    trans = np.tile(np.arange(4), (5, 1))
    cost = (np.arange(5)[:, None] != np.arange(4)[None, :]).astype(np.int64)
    cost[4] = 0
    return _Grid(poly, lo, hi, np.column_stack((src, dst, lab)), 2 * j, 2 * i,
                 (x0, y0, s / 2, s / 2, 2 * nx + 1, 2 * ny + 1), 5, trans, cost, 4,
                 (x0, y0, s, s, nx, ny, 0, 1))


def _triangle_grid(x0, y0, s, T, ny) -> _Grid:
    """Equilateral triangles of edge ``s``: row ``b`` spans ``y0 + b h .. y0 + (b+1) h``; in
    half-edge units a triangle's left end is at ``m = -1 .. T-2``; it points up when
    ``m - b`` is even (base on the row's bottom line), down otherwise."""
    h = s * SQRT3_2
    b, t = np.divmod(np.arange(T * ny), T)
    m = t - 1
    up = (m - b) % 2 == 0
    xs = x0 + 0.5 * s * np.arange(-1, T + 2)  # lattice lines: shared edges get identical floats
    ys = y0 + h * np.arange(ny + 1)
    xl, xm, xr = xs[m + 1], xs[m + 2], xs[m + 3]
    yb, yt = ys[b], ys[b + 1]
    p0 = np.column_stack((xl, np.where(up, yb, yt)))
    p1 = np.column_stack((np.where(up, xr, xm), yb))
    p2 = np.column_stack((np.where(up, xm, xr), yt))
    poly = np.stack((p0, p1, p2), axis=1)  # up: (l,b) (r,b) (m,t); down: (l,t) (m,b) (r,t): both CCW
    lo = np.column_stack((xl, yb))
    hi = np.column_stack((xr, yt))
    ids = np.arange(T * ny)
    side = ids[t < T - 1]  # shares its right edge with the next triangle of the row
    lab_side = np.where(up[side], 1, 2)  # up: right edge '\' (1); down: right edge '/' (2)
    vert = ids[(~up) & (b < ny - 1)]  # a down triangle's top edge is the base of the up triangle above
    src = np.concatenate((side, side + 1, vert, vert + T))
    dst = np.concatenate((side + 1, side, vert + T, vert))
    lab = np.concatenate((lab_side, lab_side, np.zeros(2 * len(vert), dtype=np.int64)))
    # state = (last, previous) edge orientation, 3 = none; turn: orientation != the one two crossings back
    last, prev = np.divmod(np.arange(16), 4)
    labels = np.arange(3)
    trans = labels[None, :] * 4 + last[:, None]
    cost = ((prev[:, None] != 3) & (prev[:, None] != labels[None, :])).astype(np.int64)
    return _Grid(poly, lo, hi, np.column_stack((src, dst, lab)), 2 * b, m + 1,
                 (x0 - 0.5 * s, y0, s / 2, h / 2, T + 2, 2 * ny + 1), 16, trans, cost, 15,
                 (x0, y0, s / 2, h, T, ny, -1, 2))


# ---------------------------------------------------------------------------------------
# the result
# ---------------------------------------------------------------------------------------

@dataclass
class Segmentation:
    """Cells, their states, the chosen path and the corridor's segments (SI units)."""

    shape: str
    size: float  # cell edge [m]
    lower: np.ndarray  # (2,) bounds [m]
    upper: np.ndarray
    clearance: float  # [m]
    psi_range: np.ndarray  # (2,) [rad]
    start: np.ndarray  # (3,) [m, m, rad]
    end: np.ndarray
    polygons: np.ndarray  # (C, k, 2) cell vertices, CCW [m]
    state: np.ndarray  # (C,) FREE | BLOCKED | UNREACHABLE
    path: list[int]  # cell ids, start -> end
    segments: list[Segment]  # start point, path cells' boxes, end point
    turns: int  # direction changes along the path
    grown_parts: tuple = ()  # (pieces, owner): obstacles grown by the clearance (Layout.grown_parts)
    compute_ms: float = 0.0

    @property
    def grown(self) -> list:
        """Each obstacle grown by the clearance, as one shapely geometry (list in obstacle order)."""
        if not self.grown_parts or not len(self.grown_parts[0]):
            return []
        pieces, owner = self.grown_parts
        return [shapely.union_all(pieces[owner == i]) for i in range(int(owner.max()) + 1)]

    @property
    def counts(self) -> dict:
        return {name: int(np.count_nonzero(self.state == k)) for k, name in enumerate(STATE_NAMES)}

    def to_dict(self) -> dict:
        """JSON-ready: cells (id, polygon, state), path, segments {lower, upper, polygon}
        (usable as a plan request's ``segments``), the half-planes of each segment's polygon
        (``halfplanes[i]``: {A, b} with ``A p <= b``, or null for a point), and the grown
        obstacles' outlines (m)."""
        names = np.array(STATE_NAMES)[self.state]
        polys = np.round(self.polygons, 12).tolist()
        cells = [{"id": i, "polygon": p, "state": s} for i, (p, s) in enumerate(zip(polys, names.tolist()))]
        segs, hps = [], []
        for seg in self.segments:
            poly = None if seg.polygon is None else seg.polygon.tolist()
            segs.append({"lower": seg.lower.tolist(), "upper": seg.upper.tolist(), "polygon": poly})
            if seg.polygon is None:
                hps.append(None)
            else:
                A, b = halfplanes(seg.polygon)
                hps.append({"A": A.tolist(), "b": b.tolist()})
        grown = []
        for g in self.grown:
            for part in shapely.get_parts(g):
                grown.append(np.asarray(part.exterior.coords)[:-1].tolist())
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


# ---------------------------------------------------------------------------------------
# segmentation
# ---------------------------------------------------------------------------------------

def _fmt(p) -> str:
    return f"({p[0]:.4f} m, {p[1]:.4f} m)"


def _check_endpoint(lay: Layout, robot: Robot, key: str, path: str) -> None:
    pose = lay.start if key == "start" else lay.end
    x, y = pose[0], pose[1]
    if not (lay.lower[0] <= x <= lay.upper[0] and lay.lower[1] <= y <= lay.upper[1]):
        raise invalid(f"{path}.{key}", f"the {key} {_fmt(pose)} is outside the bounds "
                      f"{_fmt(lay.lower)} .. {_fmt(lay.upper)}")
    for i, ob in enumerate(lay.obstacles):
        if i in lay.circles:  # exact circle
            c, r = lay.circles[i]
            dist = max(float(np.hypot(x - c[0], y - c[1])) - r, 0.0)
            inside = dist == 0.0 and np.hypot(x - c[0], y - c[1]) < r
        else:
            dist = float(shapely.distance(ob, shapely.Point(x, y)))
            inside = bool(shapely.contains_xy(ob, x, y))
        if inside or dist < lay.clearance:
            why = "inside" if inside else f"within the clearance ({lay.clearance:g} m) of"
            raise invalid(f"{path}.{key}", f"the {key} {_fmt(pose)} is {why} obstacle {i} "
                          f"({path}.obstacles[{i}])")
    check_pose(robot, pose, f"{path}.{key}")


def _holding(grid: _Grid, p) -> np.ndarray:
    """Ids of the cells whose closure holds point p (usually 1; more on an edge or vertex)."""
    P = grid.polygons
    d = np.roll(P, -1, axis=1) - P
    cross = d[..., 0] * (p[1] - P[..., 1]) - d[..., 1] * (p[0] - P[..., 0])  # >= 0 inside (CCW)
    scale = np.hypot(d[..., 0], d[..., 1])
    return np.nonzero(np.all(cross >= -1e-13 * scale, axis=1))[0]  # within 1e-13 m


def _endpoint_cells(grid: _Grid, state, blocker, lay: Layout, key: str, path: str) -> np.ndarray:
    p = lay.start if key == "start" else lay.end
    cells = _holding(grid, p)
    free = cells[state[cells] == FREE]
    if free.size:
        return free
    c = int(cells[0]) if cells.size else -1
    if c < 0:  # cannot happen inside the bounds, kept for safety
        raise PlannerError("no_path", f"no cell holds the {key} {_fmt(p)}", f"{path}.{key}")
    if state[c] == UNREACHABLE:
        raise PlannerError("unreachable", f"the {key} {_fmt(p)} is reachable, but its cell {c} is not wholly "
                           f"reachable (a leg leaves its stroke or the robot is singular somewhere in the cell at "
                           f"some angle in psi_range [{lay.psi_range[0]:g}, {lay.psi_range[1]:g}] rad); use smaller "
                           "cells, a narrower psi_range or move the point", f"{path}.{key}")
    why = (f"overlaps obstacle {blocker[c]} grown by the clearance ({lay.clearance:g} m)" if blocker[c] >= 0
           else "extends past the bounds")
    raise PlannerError("no_path", f"the cell {c} holding the {key} {_fmt(p)} is not wholly free: it {why}; use "
                       "smaller cells, a smaller clearance or move the point", f"{path}.{key}")


def _search(grid: _Grid, free: np.ndarray, sources: np.ndarray, targets: np.ndarray):
    """Fewest cells, then fewest turns, from any source to any target over free cells.
    Returns (path ids, turns) or None."""
    common = np.intersect1d(sources, targets)
    if common.size:
        return [int(common[0])], 0
    C = len(free)
    e = grid.edges
    e = e[free[e[:, 0]] & free[e[:, 1]]]
    G = csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(C, C))
    ds = dijkstra(G, directed=True, indices=sources, unweighted=True, min_only=True)
    D = ds[targets].min()
    if not np.isfinite(D):
        return None
    de = dijkstra(G, directed=True, indices=targets, unweighted=True, min_only=True)  # symmetric graph
    D = int(D)
    # the DAG of all shortest paths: u -> v with ds[u] + 1 + de[v] == D
    on = ds[e[:, 0]] + 1 + de[e[:, 1]] == D
    e = e[on]
    layer = ds[e[:, 0]].astype(np.int64)
    S = grid.n_states
    # every (edge, incoming state) transition, sorted by (layer, target state): each layer's
    # transitions are one slice, and the transitions into one target state are contiguous
    u, v, lab = e[:, 0], e[:, 1], e[:, 2]
    src = (u[:, None] * S + np.arange(S)).ravel()
    tgt = (v[:, None] * S + grid.trans[:, lab].T).ravel()
    cst = grid.cost[:, lab].T.ravel()
    lay_t = np.repeat(layer, S)
    order = np.lexsort((tgt, lay_t))
    src, tgt, cst, lay_t = src[order], tgt[order], cst[order], lay_t[order]
    n = len(tgt)
    gstart = np.flatnonzero(np.r_[True, (tgt[1:] != tgt[:-1]) | (lay_t[1:] != lay_t[:-1])]) if n else np.empty(0, int)
    cuts = np.searchsorted(lay_t, np.arange(D + 1))
    gcuts = np.searchsorted(gstart, cuts)
    INF = np.int64(1) << 40
    V = np.full(C * S, INF, dtype=np.int64)
    back = np.full(C * S, -1, dtype=np.int64)
    src0 = sources[de[sources] == D]
    V[src0 * S + grid.init_state] = 0
    for L in range(D):  # one layer of the shortest-path DAG at a time, vectorised within
        a, b = cuts[L], cuts[L + 1]
        K = np.int64(b - a)
        key = (V[src[a:b]] + cst[a:b]) * K + np.arange(K)  # value, then position (ties: first)
        best = np.minimum.reduceat(key, gstart[gcuts[L]:gcuts[L + 1]] - a)
        val, idx = np.divmod(best, K)
        ok = val < INF
        t = tgt[gstart[gcuts[L]:gcuts[L + 1]]][ok]
        V[t] = val[ok]
        back[t] = src[a + idx[ok]]
    tv = V.reshape(C, S)[targets]
    k = np.argmin(tv)
    turns = int(tv.flat[k])
    node = int(targets[k // S]) * S + int(k % S)
    path = []
    while node >= 0:
        path.append(node // S)
        node = int(back[node])
    return path[::-1], turns


def count_turns(seg_or_shape, path=None, polygons=None) -> int:
    """Turns along a path of cells (same definition as the search), from the cell polygons:
    squares: the direction between consecutive centres changes; triangles: the orientation of
    the crossed edge differs from the one two crossings back."""
    if isinstance(seg_or_shape, Segmentation):
        shape, path, polygons = seg_or_shape.shape, seg_or_shape.path, seg_or_shape.polygons
    else:
        shape = seg_or_shape
    labels = []
    for a, b in zip(path[:-1], path[1:]):
        if shape == "square":
            d = polygons[b].mean(axis=0) - polygons[a].mean(axis=0)
            labels.append((round(float(np.sign(d[0]))), round(float(np.sign(d[1])))))
        else:
            shared = [p for p in polygons[a] if np.min(np.linalg.norm(polygons[b] - p, axis=1)) < 1e-9]
            d = shared[1] - shared[0]
            labels.append(round(math.degrees(math.atan2(d[1], d[0]))) % 180)
    lag = 1 if shape == "square" else 2
    return sum(1 for i in range(lag, len(labels)) if labels[i] != labels[i - lag])


def segment(layout: dict, robot, settings: Settings | None = None, field_path: str = "layout") -> Segmentation:
    """Segment a layout (module docstring) into cells and a corridor for ``robot``.

    Raises :class:`PlannerError`: ``invalid_input`` (a malformed field; start or end outside
    the bounds or inside an obstacle grown by the clearance), ``unreachable``/``singular``
    (start or end not reachable by the robot, or its cell not wholly reachable), ``no_path``
    (no chain of free cells joins start and end), ``too_large`` (too many cells or samples).
    """
    t0 = time.perf_counter()
    robot = load_robot(robot)
    settings = settings or Settings()
    lay = parse_layout(layout, field_path)
    for key in ("start", "end"):
        _check_endpoint(lay, robot, key, field_path)
    size_path = f"{field_path}.cell.size"
    s = lay.size if lay.size is not None else default_cell_size(lay, settings)
    W, H = lay.upper - lay.lower
    need = (s, s) if lay.shape == "square" else (s, s * SQRT3_2)
    if need[0] > W + 1e-12 or need[1] > H + 1e-12:
        raise invalid(size_path, f"a {lay.shape} cell of size {s:g} m does not fit in the {W:g} m x {H:g} m bounds")
    n, nx, ny = cell_count(lay.lower, lay.upper, lay.shape, s)
    if n > MAX_CELLS:
        raise PlannerError("too_large", f"cell size {s:g} m gives {n} {lay.shape} cells over the bounds, more than "
                           f"the limit of {MAX_CELLS}; use larger cells", size_path)
    x0, y0 = lay.lower
    grid = _square_grid(x0, y0, s, nx, ny) if lay.shape == "square" else _triangle_grid(x0, y0, s, nx, ny)
    C = len(grid.lo)

    # --- obstacles and bounds
    state = np.full(C, FREE, dtype=np.int8)
    blocker = np.full(C, -1, dtype=np.int64)
    tol = 1e-9 * s
    inside = np.all((grid.lo >= lay.lower - tol) & (grid.hi <= lay.upper + tol), axis=1)
    state[~inside] = BLOCKED
    garr, owner = lay.grown_parts()
    if len(garr):
        gb = shapely.bounds(garr)  # (G, 4) xmin, ymin, xmax, ymax
        # candidate pairs: cells near each piece's bounding box (grid arithmetic), then the
        # exact test in shapely
        cand = [grid.near(*b) for b in gb]
        gi = np.repeat(np.arange(len(garr)), [len(c) for c in cand])
        ci = np.concatenate(cand) if cand else np.empty(0, dtype=np.int64)
        keep = inside[ci]
        gi, ci = gi[keep], ci[keep]
        if ci.size:
            uc, inv = np.unique(ci, return_inverse=True)
            # interiors meet (touching is allowed): test the cell shrunk about its centre by
            # 1e-9 of its size, which also absorbs rounding in the grown outlines
            P = grid.polygons[uc]
            centre = P.mean(axis=1, keepdims=True)
            cells = shapely.polygons(centre + (P - centre) * (1.0 - 1e-9))[inv]
            shapely.prepare(garr)
            hit = shapely.intersects(garr[gi], cells)
            gi, ci = owner[gi[hit]], ci[hit]
            state[ci] = BLOCKED
            blocker[ci[::-1]] = gi[::-1]  # the lowest obstacle index wins

    # --- robot reach and singularity over each free cell's box, at every allowed angle
    psis = psi_samples(lay.psi_range)
    cand = np.nonzero(state == FREE)[0]
    if cand.size:
        ok = box_reach(robot, grid.lo[cand], grid.hi[cand], psis)
        ok[ok] = _regular_windows(robot, grid.lattice, grid.win_rows[cand[ok]], grid.win_cols[cand[ok]], psis)
        state[cand[~ok]] = UNREACHABLE

    # --- path
    sources = _endpoint_cells(grid, state, blocker, lay, "start", field_path)
    targets = _endpoint_cells(grid, state, blocker, lay, "end", field_path)
    found = _search(grid, state == FREE, sources, targets)
    if found is None:
        cnt = {name: int(np.count_nonzero(state == k)) for k, name in enumerate(STATE_NAMES)}
        raise PlannerError("no_path", f"no chain of free {lay.shape} cells (sharing edges) joins the start "
                           f"{_fmt(lay.start)} to the end {_fmt(lay.end)}: {cnt['free']} of {C} cells are free, "
                           f"{cnt['blocked']} blocked by obstacles (grown by the clearance {lay.clearance:g} m) or "
                           f"the bounds, {cnt['unreachable']} unreachable by the robot; try smaller cells "
                           f"(now {s:g} m), a smaller clearance or a narrower psi_range", field_path)
    path, turns = found
    n_seg = len(path) + 2
    if n_seg > MAX_SEGMENTS or n_seg * settings.samples_per_segment > MAX_TOTAL_STEPS:
        raise PlannerError("too_large", f"the corridor has {n_seg} segments x {settings.samples_per_segment} samples, more than the "
                           f"limits ({MAX_SEGMENTS} segments, {MAX_TOTAL_STEPS} steps); use larger cells", size_path)

    # --- segments (Table I): start point, cells, end point
    plo, phi = lay.psi_range
    segs = [_segment(lay.start.copy(), lay.start.copy())]
    for c in path:
        segs.append(_segment(np.array([grid.lo[c, 0], grid.lo[c, 1], plo]),
                            np.array([grid.hi[c, 0], grid.hi[c, 1], phi]), polygon=grid.polygons[c].copy()))
    segs.append(_segment(lay.end.copy(), lay.end.copy()))
    return Segmentation(lay.shape, float(s), lay.lower, lay.upper, lay.clearance, lay.psi_range, lay.start, lay.end,
                        grid.polygons, state, path, segs, turns, (garr, owner), (time.perf_counter() - t0) * 1e3)


def _segment(lower: np.ndarray, upper: np.ndarray, polygon: np.ndarray | None = None) -> Segment:
    """A corridor segment built from the grid (valid by construction: not re-validated)."""
    return Segment.model_construct(lower=lower, upper=upper, q_ra=None, q_rb=None, polygon=polygon)


def corridor_from_request(req: PlanRequest, robot=None) -> Segmentation:
    """Segment a parsed request's ``layout`` with its settings (the plan loop's entry)."""
    if req.layout is None:
        raise invalid("layout", "the request has no layout to segment")
    return segment(req.layout, load_robot(robot if robot is not None else req.robot), req.settings)


def segment_request(raw: dict) -> dict:
    """A plan request dict with a ``layout`` -> :meth:`Segmentation.to_dict` (no planning)."""
    from ..schema import parse_request
    req = parse_request(raw)
    return corridor_from_request(req).to_dict()
