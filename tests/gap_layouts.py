"""Layouts with narrow passages (issue 31 goal 2): 0.5-3 mm gaps in walls (straight or
slanted), slots (long narrow channels through thick walls), holed obstacles (a part outline
whose hole is two rooms joined by a narrow passage) and clearances, for the Moving Slide's
workspace. Used by ``tests/test_narrow_gaps.py`` (a fixed-seed slice) and
``benchmarks/bench_gaps.py`` (the run of >= 100).

``gap_layout(seed, i)`` is a plan request (the one JSON shape) with a layout whose start and
end lie on either side of the passage; ``free_width`` in its ``"name"`` is the passage's
width after the clearance (m). The layouts leave the cell size and shape to the planner.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

KINDS = ("wall", "slanted", "slot", "holed")


def _wall(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray, gap: float, thick: float,
          angle: float) -> tuple[list[dict], np.ndarray, np.ndarray]:
    """A wall of thickness ``thick`` through the middle of the bounds at ``angle`` [rad] from the
    y axis, with one gap of ``gap`` [m] somewhere along it: two polygons (reaching past the
    bounds), and a unit normal and a point of the wall's centre line."""
    W, H = hi - lo
    c = lo + np.array([W * rng.uniform(0.35, 0.65), H / 2])
    along = np.array([math.sin(angle), math.cos(angle)])  # the wall's direction
    normal = np.array([along[1], -along[0]])
    L = float(np.hypot(W, H))  # past the bounds either way
    # where the gap is along the wall: inside the bounds, away from their edges
    t_max = 0.5 * H / max(abs(along[1]), 1e-9) - 0.012
    t0 = rng.uniform(-0.6, 0.6) * max(t_max, 0.0)

    def piece(a: float, b: float) -> list[list[float]]:
        pts = [c + along * a - normal * thick / 2, c + along * b - normal * thick / 2,
               c + along * b + normal * thick / 2, c + along * a + normal * thick / 2]
        return [[float(x), float(y)] for x, y in pts]

    obs = [{"type": "polygon", "points": piece(-L, t0 - gap / 2)},
           {"type": "polygon", "points": piece(t0 + gap / 2, L)}]
    return obs, normal, c


def _holed(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray, gap: float,
           length: float) -> tuple[list[dict], np.ndarray, np.ndarray]:
    """A part outline past the bounds with one hole: two rooms joined by a passage ``gap``
    [m] wide and ``length`` long; the start room left, the end room right."""
    W, H = hi - lo
    xm = lo[0] + W * rng.uniform(0.4, 0.6)
    yp = lo[1] + H * rng.uniform(0.3, 0.7)  # the passage's centre line
    left = shapely.box(lo[0] + 0.004, lo[1] + 0.004, xm - length / 2, hi[1] - 0.004)
    right = shapely.box(xm + length / 2, lo[1] + 0.004, hi[0] - 0.004, hi[1] - 0.004)
    # the passage reaches 10 mm into both rooms, so that it is ``gap`` wide where it meets them
    passage = shapely.box(xm - length / 2 - 0.01, yp - gap / 2, xm + length / 2 + 0.01, yp + gap / 2)
    if rng.uniform() < 0.5:  # a slanted passage
        passage = shapely.affinity.rotate(passage, rng.uniform(-35, 35), origin=(xm, yp))
    passage = shapely.intersection(passage, shapely.box(lo[0] + 0.004, lo[1] + 0.004, hi[0] - 0.004, hi[1] - 0.004))
    hole = shapely.union_all([left, right, passage]).simplify(0.0)
    assert isinstance(hole, shapely.Polygon)  # the rooms and the passage overlap: one piece
    outline = shapely.box(lo[0] - 0.01, lo[1] - 0.01, hi[0] + 0.01, hi[1] + 0.01)
    ring = [[float(x), float(y)] for x, y in np.asarray(hole.exterior.coords)[:-1]]
    obs = [{"type": "polygon", "points": [[float(x), float(y)] for x, y in np.asarray(outline.exterior.coords)[:-1]],
            "holes": [ring]}]
    return obs, np.array([1.0, 0.0]), np.array([xm, yp])


def gap_layout(seed: int, i: int) -> dict:
    """The ``i``-th request of the generator with ``seed`` (see the module docstring)."""
    rng = np.random.default_rng([seed, i])
    kind = KINDS[i % len(KINDS)]
    W, H = rng.uniform(0.09, 0.13), rng.uniform(0.07, 0.10)
    off = rng.uniform(-0.01, 0.01, 2)
    lo, hi = off - np.array([W, H]) / 2, off + np.array([W, H]) / 2
    free = float(rng.uniform(0.5e-3, 3e-3))  # the passage after the clearance [m]
    clearance = 0.0 if rng.uniform() < 0.4 else float(rng.uniform(0.1e-3, 1.5e-3))
    gap = free + 2 * clearance
    if kind == "wall":
        obs, normal, c = _wall(rng, lo, hi, gap, rng.uniform(0.002, 0.012), 0.0)
    elif kind == "slanted":
        obs, normal, c = _wall(rng, lo, hi, gap, rng.uniform(0.002, 0.012),
                               math.radians(rng.choice([-1, 1]) * rng.uniform(10, 50)))
    elif kind == "slot":
        obs, normal, c = _wall(rng, lo, hi, gap, rng.uniform(0.015, 0.035),
                               math.radians(rng.uniform(-30, 30)))
    else:
        obs, normal, c = _holed(rng, lo, hi, gap, rng.uniform(0.003, 0.03))
    # start and end: either side of the wall, inside the bounds, clear of the obstacles
    pieces = [shapely.Polygon(o["points"], o.get("holes") or None) for o in obs]
    blocked = shapely.union_all(pieces).buffer(clearance + 0.002)
    ends = []
    for side in (-1.0, 1.0):
        for _ in range(200):
            p = np.array([rng.uniform(lo[0] + 0.005, hi[0] - 0.005), rng.uniform(lo[1] + 0.005, hi[1] - 0.005)])
            if np.sign(np.dot(p - c, normal)) == side and not blocked.contains(shapely.Point(p)) \
                    and abs(np.dot(p - c, normal)) > 0.015:
                break
        ends.append([float(p[0]), float(p[1]), 0.0])
    if ends[0][0] > ends[1][0]:
        ends.reverse()
    return {"name": f"gaps seed {seed} #{i}: {kind}, free_width {free:.6g} m, clearance {clearance:.6g} m",
            "robot": "moving-slide",
            "layout": {"bounds": {"lower": lo.tolist(), "upper": hi.tolist()}, "obstacles": obs,
                       "clearance": clearance, "start": ends[0], "end": ends[1]}}
