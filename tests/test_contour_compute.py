"""The contour's deviation measures made cheaper (issue 35 goal 4) measure what they measured:
the distance to a pass's path against a brute-force one (every point against every element,
each by its own closed form), the candidate pruning against the unpruned minimum at every point
of every move, and the path-to-cut bound within its gap of a dense brute-force maximum."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.contour.passes import _nearest_only
from planner.contour.tube import PathGeometry, path_to_cut
from planner.exchange import read_gcode


def _program(rng: np.random.Generator) -> str:
    """A random closed-ish pass of lines and arcs (radius 0.5-5 mm), some moves tiny."""
    out = ["G21 G90", "G0 X0 Y0", "G1 Z-1 F600"]
    x = y = 0.0
    for _ in range(int(rng.integers(4, 12))):
        if rng.random() < 0.5:
            L = float(rng.choice([0.01, 0.2, 3.0])) * float(rng.uniform(0.5, 2))
            a = float(rng.uniform(0, 2 * math.pi))
            x, y = x + L * math.cos(a), y + L * math.sin(a)
            out.append(f"G1 X{x:.4f} Y{y:.4f}")
        else:
            r = float(rng.uniform(0.5, 5))
            a = float(rng.uniform(0, 2 * math.pi))
            cx, cy = x + r * math.cos(a), y + r * math.sin(a)
            b = a + math.pi + float(rng.uniform(-2.5, 2.5))
            x2, y2 = cx + r * math.cos(b), cy + r * math.sin(b)
            out.append(f"{'G2' if rng.random() < 0.5 else 'G3'} X{x2:.4f} Y{y2:.4f} I{cx - x:.4f} J{cy - y:.4f}")
            x, y = x2, y2
    return "\n".join(out) + "\n"


def _brute(geo: PathGeometry, pts: np.ndarray) -> np.ndarray:
    """Distance of each point to the whole path, every element by its closed form."""
    best = np.full(len(pts), np.inf)
    for k in range(geo.n):
        if geo.arc[k]:
            v = pts - geo.c[k]
            ang = np.arctan2(v[:, 1], v[:, 0])
            sw = geo.sweep[k]
            off = np.mod((ang - geo.a0[k]) * np.sign(sw), 2 * np.pi)
            inside = (off <= abs(sw) + 1e-12) | (abs(sw) >= 2 * np.pi - 1e-12)
            ends = np.minimum(np.hypot(*(pts - geo.p0[k]).T), np.hypot(*(pts - geo.p1[k]).T))
            d = np.where(inside, np.abs(np.hypot(*v.T) - geo.r[k]), ends)
        else:
            a, b = geo.p0[k], geo.p1[k]
            ab = b - a
            t = np.clip((pts - a) @ ab / max(ab @ ab, 1e-300), 0, 1)
            d = np.hypot(*(pts - a - t[:, None] * ab).T)
        best = np.minimum(best, d)
    return best


@pytest.mark.parametrize("seed", range(6))
def test_distance_and_pruning_against_brute_force(seed):
    rng = np.random.default_rng(seed)
    els = read_gcode(_program(rng)).passes[0].elements
    geo = PathGeometry(els, np.zeros(2))
    # moves near the path: from points on it, displaced up to 0.3 mm, up to 0.5 mm long
    k = rng.integers(0, geo.n, 300)
    s = rng.random(300) * geo.length[k]
    a = geo.point_at(k, s) + rng.normal(0, 1e-4, (300, 2))
    b = a + rng.normal(0, 2e-4, (300, 2))
    every = np.tile(np.arange(geo.n), (300, 1))
    pruned = _nearest_only(a, b, every, geo)
    assert pruned.shape == every.shape and (np.diff(pruned, axis=1) >= 0).all()
    frac = np.linspace(0, 1, 41)
    pts = (a[:, None, :] + frac[None, :, None] * (b - a)[:, None, :]).reshape(-1, 2)
    rows = np.repeat(np.arange(300), len(frac))
    exact = _brute(geo, pts)
    np.testing.assert_allclose(geo.distance(pts, every[rows]), exact, rtol=0, atol=1e-15)
    np.testing.assert_allclose(geo.distance(pts, pruned[rows]), exact, rtol=0, atol=1e-15)
    # pruning drops something where elements are far apart (the test would pass without it otherwise)
    kept = np.array([np.unique(r).size for r in pruned])
    if geo.n >= 4:
        assert kept.mean() < geo.n - 1


@pytest.mark.parametrize("seed", range(4))
def test_path_to_cut_within_its_gap_of_a_dense_maximum(seed):
    rng = np.random.default_rng(100 + seed)
    els = read_gcode(_program(rng)).passes[0].elements
    geo = PathGeometry(els, np.zeros(2))
    tol = 2e-5
    # a cut: points along the path every ~0.15 mm, displaced up to tol / 2
    k = np.concatenate([np.full(max(int(geo.length[i] / 1.5e-4), 1) + 1, i) for i in range(geo.n)])
    s = np.concatenate([np.linspace(0, geo.length[i], max(int(geo.length[i] / 1.5e-4), 1) + 1)
                        for i in range(geo.n)])
    cut = geo.point_at(k, s) + rng.uniform(-tol / 3, tol / 3, (len(k), 2))
    got = path_to_cut(geo, cut, tol)
    # brute force: dense path points against every cut segment
    kk = np.concatenate([np.full(2000, i) for i in range(geo.n)])
    ss = np.concatenate([np.linspace(0, geo.length[i], 2000) for i in range(geo.n)])
    p = geo.point_at(kk, ss)
    A, B = cut[:-1], cut[1:]
    best = np.full(len(p), np.inf)
    for j in range(0, len(A), 256):
        a, b = A[j:j + 256][None], B[j:j + 256][None]
        ab = b - a
        t = np.clip(np.einsum("mcj,mcj->mc", p[:, None] - a, ab) / np.maximum(np.einsum("mcj,mcj->mc", ab, ab),
                                                                                 1e-300), 0, 1)
        best = np.minimum(best, np.hypot(*(p[:, None] - a - t[..., None] * ab).transpose(2, 0, 1)).min(axis=1))
    dense = float(best.max())
    assert dense - 1e-12 <= got <= dense + 1e-9 + geo.length.max() / 1999 / 2
