"""Plane geometry of corridors: half-planes of convex cells and distances of points outside
boxes, polygons and unions of segments (m). One implementation, used by the segmentation,
the constrained mode's corridor rows and the result's metrics."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .._jit import kernels_off
from . import kernels as gk

__all__ = ["APPROACH_MIN_M", "APPROACH_ROOM_M", "CorridorDistances", "Gap", "approach_direction", "box_distance",
           "corridor_distances", "corridor_gaps",
           "corridor_violation", "halfplanes", "polygon_distance", "polygon_violation", "psi_violation"]

#: a segment centre closer than this to the end point gives no approach direction [m]
APPROACH_MIN_M = 1e-9
#: the room [m] a direction of approach must leave the last cell behind the end point (10 times
#: the constrained mode's corridor margin, whose rows keep the samples that far inside it)
APPROACH_ROOM_M = 1e-5


def halfplanes(polygon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Half-planes ``A p <= b`` of a convex polygon given by its vertices (k, 2) [m], either
    orientation: ``A`` (h, 2) unit outward normals, ``b`` (h,) [m]. Degenerate edges are dropped."""
    P = np.asarray(polygon, dtype=float)
    area2 = np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1])
    if area2 < 0:
        P = P[::-1]
    E = np.roll(P, -1, axis=0) - P
    L = np.hypot(E[:, 0], E[:, 1])
    keep = L > 1e-15
    n = np.column_stack((E[keep, 1], -E[keep, 0])) / L[keep, None]  # outward for ccw
    return n, np.einsum("ij,ij->i", n, P[keep])


def clip_halfplanes(P: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The convex polygon ``P`` (k, 2) cut by the half-planes ``A p <= b`` (Sutherland-Hodgman,
    one half-plane at a time); its vertices (possibly none) [m]."""
    P = np.asarray(P, dtype=float)
    for a, c in zip(A, b, strict=True):
        if not len(P):
            break
        d = P @ a - c  # > 0: outside
        Q = np.roll(P, -1, axis=0)
        dq = np.roll(d, -1)
        out = []
        for p, q, dp_, dq_ in zip(P, Q, d, dq, strict=True):
            if dp_ <= 0:
                out.append(p)
            if (dp_ <= 0) != (dq_ <= 0):  # the edge crosses the line
                out.append(p + (q - p) * (dp_ / (dp_ - dq_)))
        P = np.asarray(out, dtype=float).reshape(-1, 2)
    return P


def box_distance(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Euclidean distance of points ``p`` (..., d) outside boxes ``[lo, hi]`` (0 inside)."""
    return np.linalg.norm(np.maximum(np.maximum(lo - p, 0.0), p - hi), axis=-1)


def polygon_distance(p: np.ndarray, V: np.ndarray) -> np.ndarray:
    """Distance of points ``p`` (k, 2) to a convex polygon ``V`` (h, 2) (0 inside) [m]."""
    A, b = halfplanes(V)
    inside = np.all(p @ A.T <= b, axis=1)
    E0, E1 = V, np.roll(V, -1, axis=0)
    e = E1 - E0
    t = np.clip(np.einsum("kia,ia->ki", p[:, None, :] - E0[None], e) / np.maximum(np.einsum("ia,ia->i", e, e), 1e-300),
                0.0, 1.0)
    q = E0[None] + t[..., None] * e[None]
    d = np.linalg.norm(p[:, None, :] - q, axis=2).min(axis=1)
    return np.where(inside, 0.0, d)


#: elements of the (samples x segments) block :func:`corridor_violation` works on at once: the
#: temporaries stay in cache (0.5 MB each) and memory stays bounded; one 40 000 x 2 000 array
#: took 7 s and 2.6 GB, these blocks take 0.5 s (issue 15)
_BLOCK_ELEMENTS = 1 << 16


def corridor_violation(poses: np.ndarray, segments: Sequence) -> np.ndarray:
    """Distance [m] of each pose's (x, y) outside the union of the segments' boxes, against
    every segment (the reference of :func:`corridor_distances`, which is linear in the
    samples).

    The same numbers as ``box_distance(poses[:, None, :2], lo, hi).min(axis=1)`` (the norm
    is the same sum of squares; the square root, being monotone, is taken after the minimum),
    computed over blocks of poses so that memory stays bounded for long corridors."""
    lo = np.array([s.lower[:2] for s in segments])
    hi = np.array([s.upper[:2] for s in segments])
    out = np.empty(len(poses))
    step = max(1, _BLOCK_ELEMENTS // max(len(lo), 1))
    for i in range(0, len(poses), step):
        px, py = poses[i:i + step, 0:1], poses[i:i + step, 1:2]
        dx = np.maximum(np.maximum(lo[:, 0] - px, 0.0), px - hi[:, 0])
        dy = np.maximum(np.maximum(lo[:, 1] - py, 0.0), py - hi[:, 1])
        dx *= dx
        dy *= dy
        dx += dy
        out[i:i + step] = np.sqrt(dx.min(axis=1))
    return out


def polygon_violation(points: np.ndarray, segments: Sequence) -> np.ndarray:
    """Distance [m] of each point (k, 2) outside the union of the segments' exact cells (the
    ``polygon`` where a segment has one, else its x/y box), against every segment (the
    reference of :func:`corridor_distances`)."""
    best = np.full(len(points), np.inf)
    for seg in segments:
        poly = getattr(seg, "polygon", None)
        if poly is None:
            d = box_distance(points, seg.lower[:2], seg.upper[:2])
        else:
            d = polygon_distance(points, np.asarray(poly, float))
        best = np.minimum(best, d)
    return best


def approach_direction(segments: Sequence) -> np.ndarray | None:
    """The unit direction (2,) in which a corridor reaches its end point (the last segment's
    centre): from the centre of the last segment before it whose centre is not the end point
    (farther than :data:`APPROACH_MIN_M`), usually the last cell's; where the end point is that
    cell's centre, the cell before it. None if every centre is the end point. The
    constrained mode's no-overshoot rows and the ``overshoot_m`` metric both use it.

    The robot enters the last cell from the segment before it, whose middle must lie behind the
    end point along the direction (the rows hold from its last sample on). An end point near
    its cell's centre but on the side the robot enters from (a jittered end) turns the
    direction from that centre against the way the robot comes, and the rows would cut the
    segment before away (issue 20: ``infeasible``); then the direction is taken from the next
    centres back, the first behind which that middle lies (else the one it lies least beyond).
    A direction is taken only if the last cell keeps room behind the end point (a vertex
    :data:`APPROACH_ROOM_M` behind it), where any does: an end point at the corner of its cell
    that the segment before reaches from beyond that corner made the direction from that
    segment's centre leave the cell nothing but the corner, which with the margins no sample of
    the cell can keep: every step of the cell's samples was infeasible, solved only with its rows
    widened, each after the stage-wise solver's iteration limit (issue 20: 69 of 120 steps, 2.4x
    the work estimate).
    """
    end = np.asarray(segments[-1].centre[:2], float)
    entry = None
    if len(segments) >= 3:
        poly = getattr(segments[-3], "polygon", None)
        # the middle of the segment before the last cell (of its exact cell if it has one)
        entry = (np.asarray(poly, float).mean(axis=0) if poly is not None
                 else np.asarray(segments[-3].centre[:2], float)) - end
    verts = None  # the last cell's vertices, relative to the end point
    if len(segments) >= 2:
        last = segments[-2]
        poly = getattr(last, "polygon", None)
        lo, hi = np.asarray(last.lower[:2], float), np.asarray(last.upper[:2], float)
        verts = (np.asarray(poly, float) if poly is not None
                 else np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]])) - end
    candidates = []  # (direction, how far the middle of the segment before lies past the end point, room)
    for seg in reversed(segments[:-1]):
        d = end - np.asarray(seg.centre[:2], float)
        n = float(np.hypot(d[0], d[1]))
        if n <= APPROACH_MIN_M:
            continue
        d = d / n
        if entry is None:
            return d
        room = verts is None or float(np.min(verts @ d)) <= -APPROACH_ROOM_M
        candidates.append((d, float(entry @ d), room))
    pool = [c for c in candidates if c[2]] or candidates
    for d, excess, _ in pool:
        if excess <= 0.0:
            return d
    return min(pool, key=lambda c: c[1])[0] if pool else None


def psi_violation(poses: np.ndarray, segments: Sequence) -> np.ndarray:
    """Angle [rad] of each pose outside the psi ranges of the segments whose box contains its
    (x, y), or of the nearest ones if none does (ties within 1e-12 m), against every
    segment (the reference of :func:`corridor_distances`)."""
    lo = np.array([s.lower for s in segments])
    hi = np.array([s.upper for s in segments])
    d = box_distance(poses[:, None, :2], lo[None, :, :2], hi[None, :, :2])
    e = np.maximum(np.maximum(lo[None, :, 2] - poses[:, None, 2], 0.0), poses[:, None, 2] - hi[None, :, 2])
    nearest = d <= d.min(axis=1, keepdims=True) + gk.TIE_M
    return np.where(nearest, e, np.inf).min(axis=1)


@dataclass(frozen=True)
class CorridorDistances:
    """How far each sample is outside the corridor (one value per sample)."""

    xy: np.ndarray  #: distance of (x, y) outside the union of the segments' boxes [m]
    psi: np.ndarray  #: angle outside the psi ranges of the segments the sample is in (or nearest to) [rad]
    polygon: np.ndarray | None  #: distance outside the union of the exact cells [m] (None: no polygons)
    evaluated: int  #: box and polygon distances computed (linear in the samples)


def corridor_distances(poses: np.ndarray, segment_of: np.ndarray, segments: Sequence) -> CorridorDistances:
    """The corridor distances of the poses (K, 3), each sample's segment ``segment_of`` (K,)
    known: linear in the samples (:mod:`planner.corridor.kernels`; the same numbers as
    :func:`corridor_violation`, :func:`psi_violation` and :func:`polygon_violation`, which
    it uses on the numpy reference backend: :func:`planner._jit.kernels_off`)."""
    if kernels_off():
        poses = np.asarray(poses, dtype=float)
        has_poly = any(getattr(s, "polygon", None) is not None for s in segments)
        return CorridorDistances(corridor_violation(poses, segments), psi_violation(poses, segments),
                                 polygon_violation(poses[:, :2], segments) if has_poly else None,
                                 len(poses) * len(segments) * (2 if has_poly else 1))
    lo = np.ascontiguousarray([s.lower for s in segments], dtype=float)
    hi = np.ascontiguousarray([s.upper for s in segments], dtype=float)
    polys = [getattr(s, "polygon", None) for s in segments]
    if any(p is not None for p in polys):
        counts = [0 if p is None else len(p) for p in polys]
        ptr = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
        V = np.ascontiguousarray(np.vstack([np.asarray(p, float) for p in polys if p is not None]))
    else:
        ptr, V = np.zeros(0, np.int64), np.zeros((0, 2))
    origin, h, nx, ny, start, boxes = gk.build_grid(np.ascontiguousarray(lo[:, :2]), np.ascontiguousarray(hi[:, :2]))
    K = len(poses)
    xy, psi, poly = np.empty(K), np.empty(K), np.empty(K)
    evaluated = gk.union_distances(np.ascontiguousarray(poses, dtype=float), np.ascontiguousarray(segment_of, np.int64),
                                   np.ascontiguousarray(lo[:, :2]), np.ascontiguousarray(hi[:, :2]),
                                   np.ascontiguousarray(lo[:, 2]), np.ascontiguousarray(hi[:, 2]), ptr, V, origin, h,
                                   nx, ny, start, boxes, xy, psi, poly)
    return CorridorDistances(xy, psi, poly if len(ptr) else None, int(evaluated))


@dataclass(frozen=True)
class Gap:
    """Two consecutive segments that do not touch."""

    index: int  #: the first of the two (``segments[index]`` and ``segments[index + 1]``)
    xy_m: float  #: distance between their (x, y) boxes [m] (0: they touch)
    psi_rad: float  #: distance between their psi ranges [rad] (0: they overlap)

    def describe(self) -> str:
        """``segments[i] and segments[i+1] do not touch (...)``."""
        parts = ([f"{self.xy_m * 1e3:.3f} mm apart in x/y"] if self.xy_m > 0 else []) + \
                ([f"their psi ranges {self.psi_rad:.4g} rad apart"] if self.psi_rad > 0 else [])
        return f"segments[{self.index}] and segments[{self.index + 1}] do not touch ({', '.join(parts)})"


def corridor_gaps(segments: Sequence, tol_m: float = 0.0, tol_rad: float = 0.0) -> list[Gap]:
    """Consecutive segments whose boxes are farther apart than ``tol_m`` in (x, y) or whose
    psi ranges are farther apart than ``tol_rad``. The range sequence holds one segment's
    range until the next one's: across such a gap the robot would have to jump (or turn)
    within one sample, which no timing makes possible."""
    gaps = []
    for i in range(len(segments) - 1):
        a, b = segments[i], segments[i + 1]
        d = np.maximum(np.maximum(a.lower - b.upper, b.lower - a.upper), 0.0)
        xy, psi = float(np.hypot(d[0], d[1])), float(d[2])
        if xy > tol_m or psi > tol_rad:
            gaps.append(Gap(i, xy, psi))
    return gaps
