"""The cells of a segmentation: uniform square or triangle grids over a workspace, their
adjacency, the default cell size, and which cells obstacles block. Lengths in m.

**Grids**, anchored at ``bounds.lower``: squares of edge ``s``; or equilateral triangles of
edge ``s`` (rows of height ``s sqrt(3)/2``, alternately pointing up and down). Cells are
adjacent when they share an edge. A cell is *free* only if it lies wholly inside the bounds
and its interior meets no obstacle grown by the clearance (touching is allowed: there the
tool is exactly at the clearance; overlaps under 1e-9 of the cell size count as touching);
*blocked* otherwise; *unreachable* (set by :mod:`planner.corridor.reach_region`) if free of
obstacles but not wholly reachable by the robot.

**Default cell size** (the paper: "the density of segmentation follows from rough distance
of the start and end points and selected sampling period"): each cell becomes one segment
held for ``S`` samples (``settings.samples_per_segment``, default ``N``), so at a nominal
speed ``v = 0.1 m/s`` (:data:`DEFAULT_SPEED`) the robot crosses one cell in ``S Ts``
seconds::

    s = clamp(v S Ts, d / 50, d / 4),   d = |end - start| (x, y) [m]

then limited to half the smaller workspace side and enlarged, if needed, so the grid has at
most :data:`~planner.schema.MAX_CELLS` cells. The Table I example (``Ts = 0.01 s``,
``N = 20``) gives 0.02 m, the paper's cell. Smaller ``Ts`` -> smaller cells (denser), as the
paper asks; the clamp keeps the straight start-end line between 4 and 50 cells long.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import PlannerError, invalid
from ..schema import MAX_CELLS, SQRT3_2, Settings, cell_count
from .workspace import Workspace

__all__ = ["BLOCKED", "DEFAULT_SPEED", "FREE", "STATE_NAMES", "UNREACHABLE", "Grid", "block_obstacles", "build_grid",
           "cell_size_rule", "count_states", "default_cell_size", "square_grid", "triangle_grid"]

#: nominal tool speed of the default cell-size rule [m/s]
DEFAULT_SPEED = 0.1

#: cell states (values of ``Segmentation.state``) and their names in results
FREE, BLOCKED, UNREACHABLE = 0, 1, 2
STATE_NAMES = ("free", "blocked", "unreachable")


def count_states(state: np.ndarray) -> dict[str, int]:
    """Cells per state name (count) of a state array (C,)."""
    return {name: int(np.count_nonzero(state == k)) for k, name in enumerate(STATE_NAMES)}


@dataclass
class Grid:
    """A grid of ``C`` cells with what the path search needs (:mod:`planner.corridor.search`)."""

    polygons: np.ndarray  # (C, k, 2) cell vertices, counter-clockwise [m]
    lo: np.ndarray  # (C, 2) bounding boxes [m]
    hi: np.ndarray  # (C, 2)
    edges: np.ndarray  # (E, 3) directed adjacency (src, dst, label): label = direction or crossed edge's orientation
    win_rows: np.ndarray  # (C,) each box's 3 x 3 window of singularity points on the lattice: first row
    win_cols: np.ndarray  # (C,) and first column
    lattice: tuple  # (x0, y0, dx, dy, nx, ny): points x0 + i dx, y0 + j dy [m] holding every box's 3 x 3 window
    n_states: int  # search states per cell (what the turn count needs to remember)
    trans: np.ndarray  # (n_states, labels) next state
    cost: np.ndarray  # (n_states, labels) turn cost
    init_state: int
    index: tuple = ()  # (x0, y0, xstep, ystep, ncols, nrows, col_offset, width_steps): id = row * ncols + col

    def near(self, xmin: float, ymin: float, xmax: float, ymax: float) -> np.ndarray:
        """Ids of the cells whose bounding box may meet the box [xmin, xmax] x [ymin, ymax]
        [m] (a superset, from the grid arithmetic)."""
        x0, y0, xs, ys, nc, nr, off, w = self.index
        c0 = max(math.floor((xmin - x0) / xs) - off - w - 1, 0)
        c1 = min(math.floor((xmax - x0) / xs) - off + 1, nc - 1)
        r0 = max(math.floor((ymin - y0) / ys) - 1, 0)
        r1 = min(math.floor((ymax - y0) / ys) + 1, nr - 1)
        if c0 > c1 or r0 > r1:
            return np.empty(0, dtype=np.int64)
        return (np.arange(r0, r1 + 1)[:, None] * nc + np.arange(c0, c1 + 1)[None, :]).ravel()

    def holding(self, p: np.ndarray) -> np.ndarray:
        """Ids of the cells whose closure holds point ``p`` [m] to 1e-13 m (usually 1; more on
        an edge or a vertex)."""
        P = self.polygons
        d = np.roll(P, -1, axis=1) - P
        cross = d[..., 0] * (p[1] - P[..., 1]) - d[..., 1] * (p[0] - P[..., 0])  # >= 0 inside (CCW)
        scale = np.hypot(d[..., 0], d[..., 1])
        return np.nonzero(np.all(cross >= -1e-13 * scale, axis=1))[0]


def default_cell_size(ws: Workspace, settings: Settings) -> float:
    """The default cell edge [m] (the module docstring)."""
    return cell_size_rule(ws.lower, ws.upper, ws.start, ws.end, ws.shape, settings)


def cell_size_rule(lower: np.ndarray, upper: np.ndarray, start: np.ndarray, end: np.ndarray, shape: str,
                   settings: Settings) -> float:
    """The default cell edge [m] for bounds ``lower``, ``upper`` (x, y) [m], ``start`` and
    ``end`` poses and a cell ``shape`` (the module docstring)."""
    d = float(np.hypot(*(np.asarray(end[:2], float) - np.asarray(start[:2], float))))
    s = DEFAULT_SPEED * settings.samples_per_segment * settings.Ts
    if d > 0:
        s = min(max(s, d / 50.0), d / 4.0)
    W, H = (np.asarray(upper, float) - np.asarray(lower, float)).tolist()
    s = min(s, 0.5 * min(W, H))
    area = W * H if shape == "square" else 2.0 * W * H / SQRT3_2  # cells ~ area / cell area
    s_cap = math.sqrt(area / (0.9 * MAX_CELLS))
    return max(s, s_cap)


def build_grid(ws: Workspace, size: float, size_path: str = "layout.cell.size") -> Grid:
    """The workspace's grid of cells of edge ``size`` [m]; a
    :class:`~planner.errors.PlannerError` naming ``size_path`` if one cell does not fit in
    the bounds (``invalid_input``) or there are more than ``MAX_CELLS`` (``too_large``)."""
    W, H = ws.upper - ws.lower
    need = (size, size) if ws.shape == "square" else (size, size * SQRT3_2)
    if need[0] > W + 1e-12 or need[1] > H + 1e-12:
        raise invalid(size_path, f"a {ws.shape} cell of size {size:g} m does not fit in the {W:g} m x {H:g} m bounds")
    n, nx, ny = cell_count(ws.lower, ws.upper, ws.shape, size)
    if n > MAX_CELLS:
        raise PlannerError("too_large", f"cell size {size:g} m gives {n} {ws.shape} cells over the bounds, more than "
                           f"the limit of {MAX_CELLS}; use larger cells", size_path)
    x0, y0 = ws.lower
    return square_grid(x0, y0, size, nx, ny) if ws.shape == "square" else triangle_grid(x0, y0, size, nx, ny)


def square_grid(x0: float, y0: float, s: float, nx: int, ny: int) -> Grid:
    """``nx`` x ``ny`` squares of edge ``s`` [m] from ``(x0, y0)`` [m]; id = row * nx + column.
    Search state: the direction of the last move; a turn is a new direction."""
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
    return Grid(poly, lo, hi, np.column_stack((src, dst, lab)), 2 * j, 2 * i,
                (x0, y0, s / 2, s / 2, 2 * nx + 1, 2 * ny + 1), 5, trans, cost, 4,
                (x0, y0, s, s, nx, ny, 0, 1))


def triangle_grid(x0: float, y0: float, s: float, T: int, ny: int) -> Grid:
    """Equilateral triangles of edge ``s`` [m], ``T`` per row, ``ny`` rows: row ``b`` spans
    ``y0 + b h .. y0 + (b+1) h``; in half-edge units a triangle's left end is at
    ``m = -1 .. T-2``; it points up when ``m - b`` is even (base on the row's bottom line),
    down otherwise. A straight run through a strip of triangles crosses edges of two
    alternating orientations, so the search state is the last two crossed orientations and a
    turn is a crossing whose orientation differs from the one two crossings back."""
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
    return Grid(poly, lo, hi, np.column_stack((src, dst, lab)), 2 * b, m + 1,
                (x0 - 0.5 * s, y0, s / 2, h / 2, T + 2, 2 * ny + 1), 16, trans, cost, 15,
                (x0, y0, s / 2, h, T, ny, -1, 2))


def block_obstacles(grid: Grid, ws: Workspace, size: float,
                    grown: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Cell states after the bounds and the obstacles: ``(state, blocker)``, (C,) each:
    :data:`FREE` or :data:`BLOCKED`, and the lowest index of an obstacle that blocks the cell
    (-1: none, or only the bounds). ``grown`` is :meth:`Workspace.grown_parts`; ``size`` the
    cell edge [m]."""
    C = len(grid.lo)
    state = np.full(C, FREE, dtype=np.int8)
    blocker = np.full(C, -1, dtype=np.int64)
    tol = 1e-9 * size
    inside = np.all((grid.lo >= ws.lower - tol) & (grid.hi <= ws.upper + tol), axis=1)
    state[~inside] = BLOCKED
    garr, owner = grown
    if not len(garr):
        return state, blocker
    # candidate pairs: cells near each piece's bounding box (grid arithmetic), then the exact
    # test in shapely
    import shapely  # loaded on first use: plans of given segments never need it
    cand = [grid.near(*b) for b in shapely.bounds(garr)]  # bounds: (G, 4) xmin, ymin, xmax, ymax
    gi = np.repeat(np.arange(len(garr)), [len(c) for c in cand])
    ci = np.concatenate(cand)
    keep = inside[ci]
    gi, ci = gi[keep], ci[keep]
    if ci.size:
        uc, inv = np.unique(ci, return_inverse=True)
        # interiors meet (touching is allowed): test the cell shrunk about its centre by 1e-9 of
        # its size, which also absorbs rounding in the grown outlines
        P = grid.polygons[uc]
        centre = P.mean(axis=1, keepdims=True)
        cells = shapely.polygons(centre + (P - centre) * (1.0 - 1e-9))[inv]
        shapely.prepare(garr)
        hit = shapely.intersects(garr[gi], cells)
        gi, ci = owner[gi[hit]], ci[hit]
        state[ci] = BLOCKED
        blocker[ci[::-1]] = gi[::-1]  # the lowest obstacle index wins
    return state, blocker
