"""A cut pass as a tube corridor of convex cells, the distance of points to the programmed
path (lines and arcs) and the distance of the programmed path from the cut (:func:`path_to_cut`),
all in the robot frame [m].

**Cells.** Each arc is replaced by chords whose sagitta is at most ``s_a = 0.18 tol`` (so the
chord polyline is within ``s_a`` of the arc); long pieces are split to at most ``piece_max``.
Each piece ``[p0, p1]`` gets the convex cell spanned by eight points on the circles of radius
``rho`` about its ends (at +-90 and +-30 degrees from the piece's direction, forward at ``p1``,
backward at ``p0``): it lies in ``piece + disk(rho)`` and contains the disk of radius
``rho cos 30`` about each end. Consecutive samples of the time-indexed range sequence lie in
the same cell or in two consecutive ones; the straight move between them lies in the convex
hull of the two cells, ``triangle(p0, v, p1) + disk(rho)`` (``v`` the shared vertex), which is
within ``bend + rho`` of the path, ``bend`` the height of ``v`` over ``p0 p1`` (two chords of
one arc: the arc passes through the three points and the triangle lies inside the circle, so
no point of it is farther than the bend, 4 sagittas of one chord; elsewhere the bend plus the
chords' sagitta ``s_a``). Where that exceeds ``0.95 tol`` (corners, where a line meets an
arc), the intersection of the two cells is a **junction** cell of its own between them (it
contains the disk of radius ``0.87 rho`` about the shared vertex), so the two samples on
either side of it lie in one convex cell. A pass with arcs has ``rho = 0.95 tol - 4 s_a``
(0.23 tol; the chords of an arc then need no junctions: half as many cells as with one
between every two chords, so a sample time can pass twice as much of an arc; a line-only pass
``rho = 0.95 tol``). Every chord is then within ``0.95 tol`` of the programmed path, which
is what the exported G93 program runs.

**Corners, the other way** (G64 P as LinuxCNC means it, issue 32: every point of the
programmed path within the tolerance of the cut too). The intersection of two cells reaches
``rho / sin(alpha / 2)`` from the vertex at an inner angle ``alpha`` (2.4 tol at 45 degrees),
so a junction is cut further to the regular polygon inscribed in the circle of radius
``0.95 tol`` about the vertex (:data:`CORNER_FRACTION`); a sample is held in it, so the cut
passes within that of the corner point, and of every point of the two pieces between the
vertex and that sample's foot on them (no farther from the sample than the vertex is);
elsewhere the cut, crossing a piece's cell from one end to the other, passes within ``rho``
(plus the sagitta on an arc) of each of its points.

**Lead cells.** The constrained mode's range sequence spreads the first cell linearly out of
the start point over its samples and narrows the last one onto the end point (the taper,
:mod:`planner.corridor.ranges`): at the first sample of a cell held ``S`` samples the range is
the cell shrunk by ``1 / S`` about the start point, and a tube cell is only ``2 rho`` wide
(4.6 um at 0.01 mm), so beyond a few samples the shrunk cell is narrower than the corridor
margin and the first step's QP has no solution: a slower timing failed where a faster one
planned. So the first and the last piece of a pass are split at :data:`LEAD_FRACTION` ``rho``
from the pass's ends: the short lead cells (``Tube.lead``) are held one sample each, so the
taper is the whole lead-in cell at the first sample and the end point at the last; the
robot at rest at either end lies in the lead cell's neighbour too (within ``0.87 rho`` of
its end), so it may wait there as long as the timing asks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..schema import PathElement, Segment

__all__ = ["BEND_SAGITTAS", "CORNER_FRACTION", "CORNER_VERTICES", "LEAD_FRACTION", "SAGITTA_FRACTION",
           "TUBE_FRACTION", "PathGeometry", "Tube", "path_to_cut", "sample_split", "tube"]

#: chord sagitta of the arcs' polylines, as a fraction of the tolerance
SAGITTA_FRACTION = 0.18
#: the bend of two consecutive chords of an arc (the height of their triangle over the chord of
#: both: the sagitta of twice the angle) is 4 sagittas of one: the cells of a pass with arcs
#: leave room for it, so that consecutive chords of an arc need no junction cell between them
BEND_SAGITTAS = 4.0
#: the cells' radius about the (chord) path, as a fraction of the tolerance, before the sagitta
TUBE_FRACTION = 0.95
#: a junction cell lies within this fraction of the tolerance of its corner's vertex (module docstring)
CORNER_FRACTION = TUBE_FRACTION
#: the vertices of the polygon inscribed in that circle
CORNER_VERTICES = 16
#: the lead cells' length at either end of a pass, as a fraction of the cells' radius
LEAD_FRACTION = 0.5
_CAP = np.radians([-90.0, -30.0, 30.0, 90.0])
_BACK = np.radians([90.0, 150.0, 210.0, 270.0])
_RING_ANGLES = np.linspace(0.0, 2 * np.pi, CORNER_VERTICES, endpoint=False)
_RING = np.stack((np.cos(_RING_ANGLES), np.sin(_RING_ANGLES)), axis=1)  # CCW, as _clip wants


@dataclass
class Tube:
    segments: list[Segment]  #: start point, cells and junctions, end point
    element: np.ndarray  #: (n,) index of the pass's element each segment belongs to
    length: np.ndarray  #: (n,) path length a segment stands for (0: junctions and points) [m]
    turn: np.ndarray  #: (n,) turn angle at a junction (0 elsewhere) [rad]
    radius: np.ndarray  #: (n,) curvature radius of the piece (inf for lines) [m]
    rho: float  #: the cells' radius about the chord path [m]
    lead: np.ndarray  #: (n,) the lead cells at the pass's ends (held one sample each)


def _bend(a: np.ndarray, v: np.ndarray, b: np.ndarray) -> float:
    """Distance of the vertex ``v`` from the line ``a b``: the farthest the triangle ``a v b`` (the
    convex hull of two consecutive pieces) lies from the pieces [m]."""
    e = b - a
    n = float(np.hypot(*e))
    if n < 1e-15:
        return float(np.hypot(*(v - a)))
    return abs(float(e[0] * (v[1] - a[1]) - e[1] * (v[0] - a[0]))) / n


def _cell(p0: np.ndarray, p1: np.ndarray, rho: float) -> np.ndarray:
    d = p1 - p0
    d = d / np.hypot(*d)
    n = np.array([-d[1], d[0]])
    fw = p1 + rho * (np.cos(_CAP)[:, None] * d + np.sin(_CAP)[:, None] * n)
    bw = p0 + rho * (np.cos(_BACK)[:, None] * d + np.sin(_BACK)[:, None] * n)
    return np.vstack((fw, bw))


def _clip(poly: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman: the convex polygon ``poly`` cut by the convex CCW polygon ``clip``."""
    out = poly
    for i in range(len(clip)):
        a, b = clip[i], clip[(i + 1) % len(clip)]
        e = b - a
        side = e[0] * (out[:, 1] - a[1]) - e[1] * (out[:, 0] - a[0])  # >= 0 inside (left of a->b)
        res = []
        for j in range(len(out)):
            p, q = out[j], out[(j + 1) % len(out)]
            sp, sq = side[j], side[(j + 1) % len(out)]
            if sp >= 0:
                res.append(p)
            if (sp >= 0) != (sq >= 0):
                res.append(p + (q - p) * (sp / (sp - sq)))
        if not res:
            return np.zeros((0, 2))
        out = np.array(res)
    keep = np.ones(len(out), bool)
    for j in range(1, len(out)):
        if np.hypot(*(out[j] - out[j - 1])) < 1e-10:
            keep[j] = False
    out = out[keep]
    if len(out) > 1 and np.hypot(*(out[0] - out[-1])) < 1e-10:
        out = out[:-1]
    return out


def _split(n: int, length: float, unit: float | None) -> np.ndarray:
    """The fractions (n + 1,) at which an element of ``length`` is split into ``n`` pieces: equal
    pieces, or with ``unit`` (the travel of one sample at the move's speed [m]) pieces of whole
    samples' travel each (:func:`sample_split`)."""
    if unit is not None and unit > 0:
        got = sample_split(n, length, unit)
        if got is not None:
            return got
    return np.arange(n + 1) / n


def sample_split(n: int, length: float, unit: float) -> np.ndarray | None:
    """The fractions (n + 1,) that split ``length`` into ``n`` pieces of whole samples' travel:
    ``T = ceil(length / unit)`` samples in all, each piece ``floor(T / n)`` or ``ceil(T / n)`` of
    them and its length in that proportion, so every piece is crossed at the same speed
    ``length / (T Ts)``, at most the ``unit``'s. Equal pieces of ``ceil`` samples each would
    lose up to a sample per piece: a move of ``n`` cells of ``k`` samples spends
    ``n k >= T`` (freecad's 8 mm lines at F300: 41 cells of 4 samples, 164 for 160.8). None
    where the move is shorter than ``n`` samples' travel (the pieces keep their equal split)."""
    T = math.ceil(length / unit - 1e-9)
    if T < n or n < 1:
        return None
    c = np.full(n, T // n, np.int64)
    c[:T - n * (T // n)] += 1
    c = np.sort(c)  # the shorter pieces first: the move's start is where the speed rises
    return np.concatenate(([0.0], np.cumsum(c))) / T


def _pieces(elements: list[PathElement], origin: np.ndarray, s_a: float, piece_max_of: float | np.ndarray,
            unit_of: np.ndarray | None = None):
    """(p0, p1, element index, curvature radius) per piece, robot frame (``piece_max_of``: one
    longest piece, or one per element; ``unit_of``: per element the travel of a sample at its
    speed, pieces of whole samples' travel, :func:`sample_split`)."""
    out = []
    for i, e in enumerate(elements):
        if e.length_m < 1e-9:
            continue
        piece_max = float(piece_max_of if np.ndim(piece_max_of) == 0 else np.asarray(piece_max_of)[i])
        unit = None if unit_of is None else float(unit_of[i])
        if e.kind == "arc":
            assert e.radius_m is not None and e.sweep_rad is not None and e.start_angle_rad is not None
            r = e.radius_m
            step = 2 * math.acos(max(1 - s_a / r, -1.0)) if s_a < r else math.pi / 2
            step = min(step, piece_max / r, math.pi / 2)
            n = max(1, math.ceil(abs(e.sweep_rad) / step))
            f = _split(n, e.length_m, unit)
            while float(np.diff(f).max()) * abs(e.sweep_rad) > step * (1 + 1e-9):  # a chord within its sagitta
                n += 1
                f = _split(n, e.length_m, unit)
            a = e.start_angle_rad + e.sweep_rad * f
            assert e.centre is not None
            pts = e.centre + r * np.stack((np.cos(a), np.sin(a)), axis=1) + origin
            pts[-1] = e.end + origin if abs(abs(e.sweep_rad) - 2 * math.pi) > 1e-9 else pts[0]
            for k in range(n):
                out.append((pts[k], pts[k + 1], i, r))
        else:
            n = max(1, math.ceil(e.length_m / piece_max))
            f = _split(n, e.length_m, unit)
            pts = (e.start + origin) + f[:, None] * (e.end - e.start)
            for k in range(n):
                out.append((pts[k], pts[k + 1], i, math.inf))
    return out


def tube(elements: list[PathElement], origin: np.ndarray, tol: float, psi: float,
         piece_max: float | np.ndarray, unit: np.ndarray | None = None) -> Tube:
    """The tube corridor of a pass (module docstring): point, cells (and junctions), point
    (``piece_max``: the longest piece, one or per element; ``unit``: per element the travel of
    one sample at its speed [m], each piece then a whole number of them, :func:`sample_split`)."""
    s_a = SAGITTA_FRACTION * tol
    pieces = _pieces(elements, origin, s_a, piece_max, unit)
    rho_arc = TUBE_FRACTION * tol - BEND_SAGITTAS * s_a * (1 + 1e-9)
    rho_line = TUBE_FRACTION * tol
    # all cells of one pass share one radius: the junction of a line and a chord then still
    # contains a disk of 0.87 rho about the vertex
    rho = rho_arc if any(p[3] < math.inf for p in pieces) else rho_line
    pieces, lead_at = _leads(pieces, LEAD_FRACTION * rho)
    segs: list[Segment] = []
    elem, length, turn, radius = [], [], [], []

    def add(poly: np.ndarray | None, point: np.ndarray | None, e: int, ln: float, tr: float, r: float) -> None:
        if poly is not None:
            lo, hi = poly.min(axis=0), poly.max(axis=0)
            segs.append(Segment.model_validate({"lower": [lo[0], lo[1], psi], "upper": [hi[0], hi[1], psi],
                                                "polygon": poly.tolist()}))
        else:
            assert point is not None
            p = [float(point[0]), float(point[1]), psi]
            segs.append(Segment.model_validate({"lower": p, "upper": p}))
        elem.append(e)
        length.append(ln)
        turn.append(tr)
        radius.append(r)

    add(None, pieces[0][0], pieces[0][2], 0.0, 0.0, math.inf)
    prev: np.ndarray | None = None
    prev_dir: np.ndarray | None = None
    prev_p0: np.ndarray | None = None
    prev_e = -1
    lead: list[bool] = []
    for q, (p0, p1, e, r) in enumerate(pieces):
        cell = _cell(p0, p1, rho)
        d = (p1 - p0) / np.hypot(*(p1 - p0))
        if prev is not None and prev_dir is not None and prev_p0 is not None:
            ang = math.atan2(prev_dir[0] * d[1] - prev_dir[1] * d[0], float(prev_dir @ d))
            # the two pieces' cells without a junction between them: their convex hull is the
            # triangle of the pieces grown by rho, within the bend (pieces of one arc: the arc
            # passes through the vertex and stays outside the triangle) or the bend plus the
            # chords' sagitta (elsewhere) plus rho of the path. And the other way (issue 32): the two
            # cells overlap up to rho / cos(ang / 2) from the vertex; beyond the corner's circle (a
            # sharp turn, a reversal: the whole retraced piece) samples may pass from the one cell
            # to the other far from the vertex, and the cut skip it, so a junction holds one there
            same_arc = e == prev_e and r < math.inf
            overlap = rho / max(math.cos(0.5 * ang), 1e-12)
            if abs(ang) > 1e-9 and (_bend(prev_p0, p0, p1) + (0.0 if same_arc else s_a) + rho > TUBE_FRACTION * tol
                                    or overlap > CORNER_FRACTION * tol):
                junction = _clip(_clip(prev, cell), p0 + CORNER_FRACTION * tol * _RING)
                if len(junction) < 3:  # pragma: no cover - the disk about the vertex is in both
                    raise AssertionError("empty junction")
                add(junction, None, e, 0.0, abs(ang), math.inf)
        add(cell, None, e, float(np.hypot(*(p1 - p0))), 0.0, r)
        lead += [False] * (len(segs) - len(lead) - 1) + [q in lead_at]
        prev, prev_dir, prev_p0, prev_e = cell, d, p0, e
    add(None, pieces[-1][1], pieces[-1][2], 0.0, 0.0, math.inf)
    lead += [False] * (len(segs) - len(lead))
    return Tube(segs, np.array(elem), np.array(length), np.array(turn), np.array(radius), rho, np.array(lead))


def _leads(pieces: list, ell: float) -> tuple[list, set[int]]:
    """The pieces with the first and the last split ``ell`` from the pass's ends (where they
    are longer than ``3 ell``), and the indices of those short lead pieces (module docstring)."""
    out = list(pieces)
    lead: set[int] = set()
    p0, p1, e, r = out[0]
    L = float(np.hypot(*(p1 - p0)))
    if L > 3 * ell:
        m = p0 + (p1 - p0) * (ell / L)
        out[0:1] = [(p0, m, e, r), (m, p1, e, r)]
        lead.add(0)
    p0, p1, e, r = out[-1]
    L = float(np.hypot(*(p1 - p0)))
    if L > 3 * ell:
        m = p1 - (p1 - p0) * (ell / L)
        out[-1:] = [(p0, m, e, r), (m, p1, e, r)]
        lead.add(len(out) - 1)
    return out, lead


def _norm(v: np.ndarray) -> np.ndarray:
    """Length of the last axis' 2-vectors (cheaper than numpy.linalg.norm here)."""
    return np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1])


class PathGeometry:
    """The programmed path of a pass (lines and arcs, robot frame) as arrays, for the distance
    of many points to a few candidate elements each (vectorised)."""

    def __init__(self, elements: list[PathElement], origin: np.ndarray):
        n = len(elements)
        self.n = n
        self.arc = np.array([e.kind == "arc" for e in elements])
        self.p0 = np.array([e.start for e in elements]) + origin
        self.p1 = np.array([e.end for e in elements]) + origin
        self.c = np.array([e.centre if e.centre is not None else e.start for e in elements]) + origin
        self.r = np.array([e.radius_m or 0.0 for e in elements])
        self.a0 = np.array([e.start_angle_rad or 0.0 for e in elements])
        self.sweep = np.array([e.sweep_rad or 0.0 for e in elements])
        self.line = np.array([e.line for e in elements])
        self.length = np.array([e.length_m for e in elements])

    def point_at(self, k: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Points at path length ``s`` (M,) from the start of the elements ``k`` (M,), (M, 2) [m]."""
        L = np.maximum(self.length[k], 1e-300)
        on_line = self.p0[k] + (s / L)[:, None] * (self.p1[k] - self.p0[k])
        r = np.maximum(self.r[k], 1e-300)
        a = self.a0[k] + np.sign(self.sweep[k]) * s / r
        on_arc = self.c[k] + self.r[k][:, None] * np.stack((np.cos(a), np.sin(a)), axis=1)
        return np.where(self.arc[k][:, None], on_arc, on_line)

    def near(self, reach: float) -> tuple[np.ndarray, np.ndarray]:
        """Per element ``k``: the first and the last element index within ``reach`` of it
        along the pass (its neighbours always included) (n,), (n,)."""
        cum = np.concatenate(([0.0], np.cumsum(self.length)))
        k = np.arange(self.n)
        lo = np.searchsorted(cum, cum[:-1] - reach, side="left") - 1
        hi = np.searchsorted(cum, cum[1:] + reach, side="right") - 1
        return np.clip(np.minimum(lo, k - 1), 0, self.n - 1), np.clip(np.maximum(hi, k + 1), 0, self.n - 1)

    def distance(self, pts: np.ndarray, cand: np.ndarray) -> np.ndarray:
        """Distance of ``pts`` (M, 2) to the union of the candidate elements ``cand`` (M, C)
        (indices clipped to the pass) [m]. Each point against each of its distinct candidates
        once (a row's repeats side by side are skipped), lines and arcs each by their own rule."""
        cand = np.clip(np.asarray(cand), 0, self.n - 1)
        if not cand.size:
            return np.zeros(len(pts))
        keep = np.ones(cand.shape, bool)
        keep[:, 1:] = cand[:, 1:] != cand[:, :-1]
        row, col = np.nonzero(keep)  # row by row: each row's pairs contiguous, its first column kept
        k = cand[row, col]
        P = pts[row]
        d = np.empty(len(k))
        arc = self.arc[k]
        li = np.flatnonzero(~arc)
        if li.size:
            p, kl = P[li], k[li]
            a = self.p0[kl]
            ab = self.p1[kl] - a
            pa = p - a
            L2 = np.maximum(ab[:, 0] * ab[:, 0] + ab[:, 1] * ab[:, 1], 1e-300)
            t = np.clip((pa[:, 0] * ab[:, 0] + pa[:, 1] * ab[:, 1]) / L2, 0.0, 1.0)
            d[li] = _norm(p - (a + t[:, None] * ab))
        ai = np.flatnonzero(arc)
        if ai.size:
            p, ka = P[ai], k[ai]
            v = p - self.c[ka]
            sw = self.sweep[ka]
            off = np.mod((np.arctan2(v[:, 1], v[:, 0]) - self.a0[ka]) * np.sign(sw), 2 * np.pi)
            inside = (off <= np.abs(sw) + 1e-12) | (np.abs(sw) >= 2 * np.pi - 1e-12)
            d_ends = np.minimum(_norm(p - self.p0[ka]), _norm(p - self.p1[ka]))
            d[ai] = np.where(inside, np.abs(_norm(v) - self.r[ka]), d_ends)
        starts = np.flatnonzero(np.r_[True, row[1:] != row[:-1]])
        return np.minimum.reduceat(d, starts)

def _to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of the points ``p`` (M, 2) to the segments ``a b`` (M, 2) each [m]."""
    ab = b - a
    t = np.clip(np.einsum("mj,mj->m", p - a, ab) / np.maximum(np.einsum("mj,mj->m", ab, ab), 1e-300), 0.0, 1.0)
    return _norm(p - a - t[:, None] * ab)


#: path_to_cut: the first points along the path, this many per tolerance; the pieces between
#: them subdivided by REFINE_SPLIT until the bound is within REFINE_GAP_M of the largest measured
REFINE_START = 4
REFINE_SPLIT = 8
REFINE_GAP_M = 1e-9
REFINE_ROUNDS = 16


def path_to_cut(geo: PathGeometry, cut: np.ndarray, tol: float) -> float:
    """The largest distance of a point of the programmed path ``geo`` from the cut, the polyline
    of the samples ``cut`` (K, 2) as the exported program runs them: the path-to-cut direction
    of the two-sided (Hausdorff) tolerance, ``max_{p in path} min_{q in cut} |p - q|`` [m]
    (issue 32), an upper bound within :data:`REFINE_GAP_M` of it. The path is measured at
    points ``tol / REFINE_START`` apart along each element (its ends included: the corners);
    a piece ``[a, b]`` of length ``l`` between two points is bounded by the least of
    ``(d(a) + d(b) + l) / 2`` (the distance is 1-Lipschitz along the path) and, for the cut's
    segment ``S`` nearest ``a`` and the one nearest ``b``, ``max(d_S(a), d_S(b))`` plus the
    arc's sagitta ``l^2 / (8 R)`` (the distance to one segment is convex along a line); the
    pieces whose bound exceeds the largest distance measured are split and measured again."""
    import shapely  # loaded on first use (planner._lazy)

    cut = np.asarray(cut, float)[:, :2]
    if len(cut) == 1:
        cut = np.vstack((cut, cut))
    A, B = cut[:-1], cut[1:]
    segments: Any = shapely.linestrings(np.stack((A, B), axis=1))  # (K - 1,) geometries
    tree = shapely.STRtree(segments)

    def measure(k: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pts = geo.point_at(k, s)
        idx, d = tree.query_nearest(shapely.points(pts), return_distance=True, all_matches=False)
        near = np.zeros(len(s), np.int64)
        dist = np.zeros(len(s))
        near[idx[0]], dist[idx[0]] = idx[1], d
        return pts, dist, near

    keep = np.flatnonzero(geo.length > 1e-12)
    n = np.maximum(np.ceil(geo.length[keep] * REFINE_START / tol).astype(np.int64), 1)
    k = np.repeat(keep, n)
    j = np.arange(len(k)) - np.repeat(np.cumsum(n) - n, n)
    s0 = j * np.repeat(geo.length[keep] / n, n)
    s1 = (j + 1) * np.repeat(geo.length[keep] / n, n)
    if not len(k):
        return 0.0
    seen = 0.0
    bound = np.zeros(0)
    for r in range(REFINE_ROUNDS):
        if r == 0:  # the first pieces of an element share their ends: each point measured once
            npt = n + 1
            kp = np.repeat(keep, npt)
            jp = np.arange(len(kp)) - np.repeat(np.cumsum(npt) - npt, npt)
            p, d_, nr = measure(kp, jp * np.repeat(geo.length[keep] / n, npt))
            ia = np.arange(len(k)) + np.repeat(np.arange(len(keep)), n)  # piece (element, j) -> its first point
            pa, da, na = p[ia], d_[ia], nr[ia]
            pb, db, nb = p[ia + 1], d_[ia + 1], nr[ia + 1]
        else:
            pa, da, na = measure(k, s0)
            pb, db, nb = measure(k, s1)
        seen = max(seen, float(da.max()), float(db.max()))
        ell = s1 - s0
        sag = np.where(geo.arc[k], ell * ell / (8 * np.maximum(geo.r[k], 1e-300)), 0.0)
        by_a = np.maximum(da, _to_segment(pb, A[na], B[na])) + sag
        by_b = np.maximum(db, _to_segment(pa, A[nb], B[nb])) + sag
        bound = np.maximum(np.minimum.reduce([(da + db + ell) / 2, by_a, by_b]), np.maximum(da, db))
        open_ = np.flatnonzero(bound > seen + REFINE_GAP_M)
        if not open_.size:
            return float(max(seen, bound.max()))
        frac = np.arange(REFINE_SPLIT) / REFINE_SPLIT
        k = np.repeat(k[open_], REFINE_SPLIT)
        width = np.repeat(ell[open_], REFINE_SPLIT)
        s0 = np.repeat(s0[open_], REFINE_SPLIT) + np.tile(frac, open_.size) * width
        s1 = s0 + width / REFINE_SPLIT
        bound = bound[open_]
    return float(max(seen, bound.max()))
