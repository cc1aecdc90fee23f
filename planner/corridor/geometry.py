"""Plane geometry of corridors: half-planes of convex cells and distances of points outside
boxes, polygons and unions of segments (m). One implementation, used by the segmentation,
the constrained mode's corridor rows and the result's metrics."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["halfplanes", "box_distance", "polygon_distance", "corridor_violation", "polygon_violation"]


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
    """Distance [m] of each pose's (x, y) outside the union of the segments' boxes.

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
    ``polygon`` where a segment has one, else its x/y box)."""
    best = np.full(len(points), np.inf)
    for seg in segments:
        poly = getattr(seg, "polygon", None)
        if poly is None:
            d = box_distance(points, seg.lower[:2], seg.upper[:2])
        else:
            d = polygon_distance(points, np.asarray(poly, float))
        best = np.minimum(best, d)
    return best
