"""Pieces (placed, in m) to closed regions: the outlines a drawing encloses, nested
outlines as holes (even-odd), and the pieces that enclose nothing.

1. A closed piece (closed polyline, circle, ellipse, closed spline, hatch boundary) is an
   outline by itself.
2. Open pieces (LINE, ARC, open polylines, hatch edges) are joined: their ends closer than
   the join tolerance are snapped together, the linework is noded, and the faces it
   encloses (``shapely.polygonize_full``) are outlines; the rest is reported as open chains.
3. Outlines drawn twice (a hatch over its own border) count once. An outline inside ``d``
   others has depth ``d``: even depths are obstacles, odd depths holes of the outline
   around them, so a shape drawn inside a hole is an obstacle again.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np
import shapely
from scipy.spatial import KDTree

from ._pieces import Piece

__all__ = ["Chain", "Region", "regions"]


@dataclass
class Region:
    """An obstacle: a polygon with holes, or a circle (``circle`` = (cx, cy, r) [m])."""

    polygon: shapely.Polygon
    layer: str
    source: str
    circle: tuple[float, float, float] | None = None


@dataclass
class Chain:
    """Joined pieces that enclose nothing."""

    coords: np.ndarray  # (n, 2) [m]
    layer: str
    pieces: int
    why: str  # "open" | "encloses nothing"


@dataclass
class _Ring:
    polygon: shapely.Polygon
    layer: str
    source: str
    circle: tuple[float, float, float] | None = None
    children: list[int] = field(default_factory=list)


def _describe(kinds: Counter) -> str:
    return "chain of " + " + ".join(f"{n} {k}" for k, n in sorted(kinds.items()))


def _snap(pieces: list[Piece], tol: float) -> list[np.ndarray]:
    """The open pieces' points with every end moved to the mean of the ends within ``tol``
    of it (transitively)."""
    ends = np.array([p.points[i] for p in pieces for i in (0, -1)], dtype=float).reshape(-1, 2)
    parent = np.arange(len(ends))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in KDTree(ends).query_pairs(tol):
        ri, rj = find(i), find(j)
        if ri != rj:
            parent[max(ri, rj)] = min(ri, rj)
    roots = np.array([find(i) for i in range(len(ends))])
    sums = np.zeros((len(ends), 2))
    np.add.at(sums, roots, ends)
    counts = np.bincount(roots, minlength=len(ends))
    snapped = sums[roots] / counts[roots, None]
    out = []
    for k, p in enumerate(pieces):
        pts = p.points.copy()
        pts[0], pts[-1] = snapped[2 * k], snapped[2 * k + 1]
        out.append(pts)
    return out


def _join(pieces: list[Piece], tol: float) -> tuple[list[_Ring], list[Chain]]:
    """Outlines enclosed by the open pieces, and the chains left over."""
    if not pieces:
        return [], []
    pts = _snap(pieces, tol)
    rings: list[_Ring] = []
    lines, owners = [], []
    for p, q in zip(pieces, pts):
        if len(q) >= 4 and np.array_equal(q[0], q[-1]):  # closes by itself (an open polyline drawn round)
            poly = shapely.Polygon(q[:-1])
            if poly.area > 0:
                rings.append(_Ring(poly, p.layer, p.source))
                continue
        if len(q) == 2 and np.array_equal(q[0], q[1]):
            continue  # shorter than the join tolerance
        lines.append(shapely.LineString(q))
        owners.append(p)
    if not lines:
        return rings, []
    noded = shapely.get_parts(shapely.union_all(lines))
    polys, cuts, dangles, invalid = shapely.polygonize_full(noded)
    mids = shapely.line_interpolate_point(np.array(lines, dtype=object), 0.5, normalized=True)
    tree = shapely.STRtree(mids)
    for face in shapely.get_parts(polys):
        hit = tree.query(face.exterior, predicate="dwithin", distance=max(tol, 1e-12))
        used = [owners[i] for i in hit]
        layer = Counter(p.layer for p in used).most_common(1)[0][0] if used else "0"
        rings.append(_Ring(shapely.Polygon(face.exterior), layer, _describe(Counter(p.source for p in used))))
    chains = []
    for geoms, why in ((dangles, "open"), (cuts, "encloses nothing"), (invalid, "encloses nothing")):
        parts = shapely.get_parts(geoms)
        if not len(parts):
            continue
        merged = shapely.get_parts(shapely.line_merge(shapely.union_all(parts)))
        for line in merged:
            if line.is_empty:
                continue
            hit = tree.query(line, predicate="dwithin", distance=max(tol, 1e-12))
            used = [owners[i] for i in hit]
            chains.append(Chain(np.asarray(line.coords)[:, :2], used[0].layer if used else "0", max(len(used), 1), why))
    return rings, chains


def _valid_rings(pieces: list[Piece]) -> list[_Ring]:
    """Closed pieces as rings; a self-crossing outline is split into its valid parts."""
    out = []
    for p in pieces:
        if len(p.points) < 3:
            continue
        poly = shapely.Polygon(p.points)
        if not poly.is_valid:
            parts = [g for g in shapely.get_parts(shapely.make_valid(poly)) if isinstance(g, shapely.Polygon)]
            out.extend(_Ring(shapely.Polygon(g.exterior), p.layer, p.source) for g in parts if g.area > 0)
        elif poly.area > 0:
            out.append(_Ring(poly, p.layer, p.source, p.circle))
    return out


def _dedupe(rings: list[_Ring], tol: float) -> list[_Ring]:
    """Drop outlines that repeat another within ``tol`` (a hatch over its own border)."""
    if len(rings) < 2:
        return rings
    polys = np.array([r.polygon for r in rings], dtype=object)
    area = shapely.area(polys)
    tree = shapely.STRtree(polys)
    keep = np.ones(len(rings), dtype=bool)
    for i, j in tree.query(polys, predicate="intersects").T:
        if i < j and keep[i] and keep[j]:
            slack = tol * float(rings[i].polygon.length) + 1e-18
            if abs(area[i] - area[j]) <= slack and float(shapely.area(
                    shapely.symmetric_difference(polys[i], polys[j]))) <= slack:
                # keep the more specific origin: an entity outline over a hatch boundary
                drop = j if rings[j].source == "HATCH" or rings[i].circle is not None else i
                keep[drop] = False
    return [r for r, k in zip(rings, keep) if k]


def regions(pieces: list[Piece], join_tol: float) -> tuple[list[Region], list[Chain]]:
    """The obstacles (even-odd nesting, holes subtracted) and the chains left open."""
    closed = [p for p in pieces if p.closed]
    loose = [p for p in pieces if not p.closed and len(p.points) >= 2]
    joined, chains = _join(loose, join_tol)
    rings = _dedupe(_valid_rings(closed) + joined, join_tol)
    if not rings:
        return [], chains
    polys = np.array([r.polygon for r in rings], dtype=object)
    area = shapely.area(polys)
    inner = shapely.point_on_surface(polys)
    tree = shapely.STRtree(polys)
    containers: list[list[int]] = [[] for _ in rings]
    for i, j in tree.query(inner, predicate="within").T:  # (point of ring i, ring j)
        if i != j and area[j] > area[i] and shapely.covers(polys[j], polys[i]):
            containers[int(i)].append(int(j))
    depth = [len(c) for c in containers]
    for i, c in enumerate(containers):
        if c:
            parent = min(c, key=lambda j: area[j])
            rings[parent].children.append(i)
    out = []
    for i, r in enumerate(rings):
        if depth[i] % 2:
            continue
        holes = [rings[k].polygon for k in r.children if depth[k] == depth[i] + 1]
        if not holes:
            out.append(Region(r.polygon, r.layer, r.source, r.circle))
            continue
        shape = shapely.difference(r.polygon, shapely.union_all(holes))
        for part in shapely.get_parts(shape):
            if isinstance(part, shapely.Polygon) and part.area > 0:
                out.append(Region(part, r.layer, r.source))
    return out, chains
