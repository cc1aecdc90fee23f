"""Distances of a trajectory outside its corridor in time linear in the number of samples
(compiled, numba): the compiled twins of
:func:`planner.corridor.geometry.corridor_violation` and
:func:`~planner.corridor.geometry.polygon_violation` (which compare every sample with every
segment: samples x segments work, 30 s and 2.7 GB for 2000 segments of 20 samples).

Each sample knows its segment (``RangeSequence.segment``). Its distance to that segment's
box, or to the box nearest to the previous sample (a robot lagging behind its range is near
that one), bounds the distance to the union; only the boxes within that distance can be nearer,
and a uniform grid over the corridor (cell size the boxes' median size, at most ``4 n``
cells; each box registered in the cells it overlaps) lists them: the cells within the bound
of the sample. For a sample inside or near the corridor that is a few cells with a few boxes
each, O(1); the functions return how many box (or polygon) distances they evaluated, which
``tests/test_result_metrics.py`` checks grows linearly with the corridor.

Per sample, the nearest boxes' psi ranges also give the angle outside the corridor's psi
range *where the sample is*: the smallest angle outside the psi ranges of the segments whose
box contains the sample's (x, y), or of the nearest ones if none does.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import njit

__all__ = ["build_grid", "union_distances"]

#: distances equal to this count as a tie [m]
TIE_M = 1e-12


@njit(cache=True)
def build_grid(lo, hi):
    """A uniform grid over the boxes ``[lo, hi]`` (n, 2): ``(origin (2,), h, nx, ny, start
    (nx ny + 1,), boxes)``: the boxes overlapping cell ``(i, j)`` (index ``j nx + i``) are
    ``boxes[start[c]:start[c + 1]]``."""
    n = lo.shape[0]
    x0, y0 = lo[:, 0].min(), lo[:, 1].min()
    x1, y1 = hi[:, 0].max(), hi[:, 1].max()
    sizes = np.empty(n)
    for b in range(n):
        sizes[b] = max(hi[b, 0] - lo[b, 0], hi[b, 1] - lo[b, 1])
    h = np.median(sizes)
    area = max(x1 - x0, 1e-12) * max(y1 - y0, 1e-12)
    h = max(h, math.sqrt(area / (4.0 * n)), 1e-9)
    nx = int((x1 - x0) / h) + 1
    ny = int((y1 - y0) / h) + 1
    count = np.zeros(nx * ny + 1, np.int64)
    for b in range(n):
        i0, i1 = int((lo[b, 0] - x0) / h), min(int((hi[b, 0] - x0) / h), nx - 1)
        j0, j1 = int((lo[b, 1] - y0) / h), min(int((hi[b, 1] - y0) / h), ny - 1)
        for j in range(j0, j1 + 1):
            for i in range(i0, i1 + 1):
                count[j * nx + i + 1] += 1
    start = np.cumsum(count)
    fill = start[:-1].copy()
    boxes = np.empty(start[-1], np.int64)
    for b in range(n):
        i0, i1 = int((lo[b, 0] - x0) / h), min(int((hi[b, 0] - x0) / h), nx - 1)
        j0, j1 = int((lo[b, 1] - y0) / h), min(int((hi[b, 1] - y0) / h), ny - 1)
        for j in range(j0, j1 + 1):
            for i in range(i0, i1 + 1):
                c = j * nx + i
                boxes[fill[c]] = b
                fill[c] += 1
    return np.array([x0, y0]), h, nx, ny, start, boxes


@njit(cache=True, inline="always")
def _box_distance(px, py, lo, hi, b):
    dx = max(lo[b, 0] - px, 0.0, px - hi[b, 0])
    dy = max(lo[b, 1] - py, 0.0, py - hi[b, 1])
    return math.sqrt(dx * dx + dy * dy)


@njit(cache=True)
def _polygon_distance(px, py, V, first, last):
    """Distance of ``(px, py)`` to the convex polygon ``V[first:last]`` (either orientation;
    0 inside)."""
    k = last - first
    area2 = 0.0
    for e in range(k):
        a, b = first + e, first + (e + 1) % k
        area2 += V[a, 0] * V[b, 1] - V[b, 0] * V[a, 1]
    inside = True
    best = np.inf
    for e in range(k):
        a, b = first + e, first + (e + 1) % k
        ex, ey = V[b, 0] - V[a, 0], V[b, 1] - V[a, 1]
        cross = ex * (py - V[a, 1]) - ey * (px - V[a, 0])
        if (cross < 0.0 if area2 > 0.0 else cross > 0.0):
            inside = False
        ee = ex * ex + ey * ey
        t = 0.0 if ee <= 1e-300 else min(max(((px - V[a, 0]) * ex + (py - V[a, 1]) * ey) / ee, 0.0), 1.0)
        best = min(best, math.hypot(px - V[a, 0] - t * ex, py - V[a, 1] - t * ey))
    return 0.0 if inside else best


@njit(cache=True)
def union_distances(poses, seg, lo, hi, psi_lo, psi_hi, poly_ptr, poly_V, origin, h, nx, ny, start, boxes, out_xy,
                    out_psi, out_poly):
    """Per sample ``k`` (pose ``poses[k]``, its segment ``seg[k]``): the distance of (x, y)
    outside the union of the boxes (``out_xy``), the angle outside the psi ranges of the
    nearest boxes (``out_psi``: those containing (x, y), else those at the smallest distance)
    and, if ``poly_ptr`` is not empty, the distance outside the union of the exact cells
    (``out_poly``; segment ``b``'s polygon is ``poly_V[poly_ptr[b]:poly_ptr[b + 1]]``, its box
    where that is empty). Returns the number of box and polygon distances evaluated."""
    K = poses.shape[0]
    n = lo.shape[0]
    polys = poly_ptr.shape[0] > 0
    evaluated = 0
    near = min(max(seg[0], 0), n - 1)  # the box nearest to the previous sample
    for k in range(K):
        px, py, psi = poses[k, 0], poses[k, 1], poses[k, 2]
        s = min(max(seg[k], 0), n - 1)
        # a first bound: the sample's own segment, and the box nearest to the previous sample
        # and its neighbours (the robot moves continuously: a lagging or leading robot is
        # near the previous sample's box, not its own)
        best = _box_distance(px, py, lo, hi, s)
        best_psi = max(psi_lo[s] - psi, 0.0, psi - psi_hi[s])
        best_b = s
        evaluated += 1
        for b in (near - 1, near, near + 1):
            if 0 <= b < n and b != s:
                d = _box_distance(px, py, lo, hi, b)
                evaluated += 1
                if d < best:
                    best, best_b = d, b
                    best_psi = max(psi_lo[b] - psi, 0.0, psi - psi_hi[b])
        # the cells within ``best`` of the sample (at least its own)
        i0 = max(int(math.floor((px - best - origin[0]) / h)), 0)
        i1 = min(int(math.floor((px + best - origin[0]) / h)), nx - 1)
        j0 = max(int(math.floor((py - best - origin[1]) / h)), 0)
        j1 = min(int(math.floor((py + best - origin[1]) / h)), ny - 1)
        for j in range(j0, j1 + 1):
            for i in range(i0, i1 + 1):
                c = j * nx + i
                for q in range(start[c], start[c + 1]):
                    b = boxes[q]
                    d = _box_distance(px, py, lo, hi, b)
                    evaluated += 1
                    e = max(psi_lo[b] - psi, 0.0, psi - psi_hi[b])
                    if d < best - TIE_M:
                        best, best_psi, best_b = d, e, b
                    elif d <= best + TIE_M:
                        best_psi = min(best_psi, e)
        out_xy[k] = best
        out_psi[k] = best_psi
        near = best_b
        if polys:
            # exact cells: a polygon is no nearer than its box, so only boxes within the
            # sample's own cell's distance need their polygon measured
            bound = _cell_distance(px, py, lo, hi, poly_ptr, poly_V, s)
            evaluated += 1
            i0 = max(int(math.floor((px - bound - origin[0]) / h)), 0)
            i1 = min(int(math.floor((px + bound - origin[0]) / h)), nx - 1)
            j0 = max(int(math.floor((py - bound - origin[1]) / h)), 0)
            j1 = min(int(math.floor((py + bound - origin[1]) / h)), ny - 1)
            for j in range(j0, j1 + 1):
                for i in range(i0, i1 + 1):
                    c = j * nx + i
                    for q in range(start[c], start[c + 1]):
                        b = boxes[q]
                        if _box_distance(px, py, lo, hi, b) < bound:
                            bound = min(bound, _cell_distance(px, py, lo, hi, poly_ptr, poly_V, b))
                            evaluated += 1
            out_poly[k] = bound
    return evaluated


@njit(cache=True, inline="always")
def _cell_distance(px, py, lo, hi, poly_ptr, poly_V, b):
    """Distance to segment ``b``'s exact cell: its polygon, or its box if it has none."""
    if poly_ptr[b + 1] > poly_ptr[b]:
        return _polygon_distance(px, py, poly_V, poly_ptr[b], poly_ptr[b + 1])
    return _box_distance(px, py, lo, hi, b)
