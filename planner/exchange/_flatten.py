"""Curves to polylines within a tolerance (in the curve's own units).

One rule for every smooth curve ``c(t)``: ``n`` chords of equal parameter step keep within
``tol`` of the curve when ``max|c''| h^2 / 8 <= tol`` (``h`` the step), so
``n = ceil(sqrt(M / (8 tol)))`` with ``M`` a bound on ``|c''|`` over ``t in [0, 1]``:

- circular arc of radius ``r`` and sweep ``a``: ``M = r a^2``; an ellipse (or elliptic arc)
  with the larger semi-axis in place of ``r`` (``|c''| = |c - center|`` is at most it);
- quadratic Bezier: ``M = 2 |P0 - 2 P1 + P2|``; cubic: ``M = 6 max(|P0 - 2 P1 + P2|,
  |P1 - 2 P2 + P3|)``.

Arcs also get at least one chord per 45 degrees (a coarse tolerance never turns a circle
into a line). The chords' vertices lie on the curve (inscribed). A curve that would need
more chords than a shape may have vertices (``MAX_POLYGON_POINTS``) is refused before any
point is made (``too_large``, field ``flatten_tolerance``), and so is a curve that would
take the drawing past its budget of vertices in all (:mod:`planner.exchange._budget`): the
work of a drawing is bounded by its size, not by how fine a tolerance is asked for.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import PlannerError
from ..schema import MAX_POLYGON_POINTS
from ._budget import charge

__all__ = ["arc", "bezier", "bulge_polyline", "chords", "ellipse", "too_many_vertices"]

MAX_CHORD_ANGLE = math.pi / 4  # [rad]


def chords(bound: float, tol: float, sweep: float = 0.0) -> int:
    """Chords of equal parameter step for a curve with ``|c''| <= bound`` (parameter in
    [0, 1]) to stay within ``tol``; an arc of ``sweep`` [rad] gets one per 45 degrees at least."""
    x = math.sqrt(max(bound, 0.0) / (8.0 * tol)) if bound > 0 else 1.0
    if not x <= MAX_POLYGON_POINTS:  # also inf and nan (a tolerance that underflowed)
        raise too_many_vertices()
    n = max(math.ceil(x), math.ceil(abs(sweep) / MAX_CHORD_ANGLE - 1e-9), 1)
    charge(n)  # the drawing's budget of vertices (all its curves together)
    return n


def too_many_vertices() -> PlannerError:
    """The error of a curve that needs more vertices than a shape may have."""
    return PlannerError("too_large", f"a curve of the drawing needs more than {MAX_POLYGON_POINTS} vertices (the "
                        "limit per shape) to stay within flatten_tolerance; use a larger flatten_tolerance",
                        "flatten_tolerance")


def arc(center, radius: float, start: float, sweep: float, tol: float) -> np.ndarray:
    """Points (n + 1, 2) along the circular arc from angle ``start`` [rad] through ``sweep``
    [rad] (negative: clockwise)."""
    n = chords(radius * sweep * sweep, tol, sweep)
    a = start + sweep * np.linspace(0.0, 1.0, n + 1)
    return np.column_stack((center[0] + radius * np.cos(a), center[1] + radius * np.sin(a)))


def ellipse(center, major, minor, start: float, sweep: float, tol: float) -> np.ndarray:
    """Points (n + 1, 2) along the ellipse ``center + cos(t) major + sin(t) minor`` for ``t``
    from ``start`` through ``sweep`` [rad]."""
    major, minor = np.asarray(major, float)[:2], np.asarray(minor, float)[:2]
    big = max(float(np.hypot(*major)), float(np.hypot(*minor)))
    n = chords(big * sweep * sweep, tol, sweep)
    t = start + sweep * np.linspace(0.0, 1.0, n + 1)
    return np.asarray(center, float)[:2] + np.cos(t)[:, None] * major + np.sin(t)[:, None] * minor


def bezier(points: np.ndarray, tol: float) -> np.ndarray:
    """Points (n + 1, 2) along a quadratic (3 control points) or cubic (4) Bezier curve."""
    P = np.asarray(points, float)[:, :2]
    if len(P) == 3:
        bound = 2.0 * float(np.hypot(*(P[0] - 2 * P[1] + P[2])))
    elif len(P) == 4:
        bound = 6.0 * max(float(np.hypot(*(P[0] - 2 * P[1] + P[2]))), float(np.hypot(*(P[1] - 2 * P[2] + P[3]))))
    else:
        raise ValueError("a Bezier curve needs 3 or 4 control points")
    n = chords(bound, tol)
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    s = 1.0 - t
    if len(P) == 3:
        return s * s * P[0] + 2 * s * t * P[1] + t * t * P[2]
    return s ** 3 * P[0] + 3 * s * s * t * P[1] + 3 * s * t * t * P[2] + t ** 3 * P[3]


def bulge_polyline(vertices: np.ndarray, bulges: np.ndarray, closed: bool, tol: float) -> np.ndarray:
    """A DXF polyline with bulges (``tan(sweep / 4)`` of the arc from each vertex to the next)
    as points; a closed one repeats its first point at the end."""
    V = np.asarray(vertices, float)[:, :2]
    B = np.asarray(bulges, float)
    n = len(V)
    out = [V[:1]]
    for i in range(n if closed else n - 1):
        p, q, b = V[i], V[(i + 1) % n], B[i]
        chord = float(np.hypot(*(q - p)))
        if abs(b) < 1e-12 or chord == 0.0:
            out.append(q[None])
            continue
        sweep = 4.0 * math.atan(b)  # signed: positive counter-clockwise
        radius = chord / (2.0 * abs(math.sin(sweep / 2.0)))
        mid = (p + q) / 2.0
        normal = np.array([-(q - p)[1], (q - p)[0]]) / chord  # left of p -> q
        # the centre lies left of the chord for a counter-clockwise arc of less than half a turn
        h = radius * math.cos(sweep / 2.0)
        centre = mid + normal * h * math.copysign(1.0, b)
        start = math.atan2(p[1] - centre[1], p[0] - centre[0])
        pts = arc(centre, radius, start, sweep, tol)
        pts[-1] = q  # exact end
        out.append(pts[1:])
    return np.concatenate(out)
