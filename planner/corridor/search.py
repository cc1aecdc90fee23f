"""The path through the cells: among all chains of free cells (sharing edges) from a cell
holding the start to a cell holding the end, the one with the fewest cells, and among those
the one with the fewest turns.

Breadth-first distances from both ends give the DAG of all shortest paths; a dynamic
programme over it, one layer at a time, with state = (cell, what the turn count must
remember) finds the fewest turns. A *turn* (:func:`count_turns`) is a change of direction
for squares; for triangles a straight run through a strip of triangles crosses edges of two
alternating orientations, so a turn is a crossing whose edge orientation differs from the
one two crossings back.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .cells import Grid

__all__ = ["count_turns", "fewest_turns_path"]


def fewest_turns_path(grid: Grid, free: np.ndarray, sources: np.ndarray,
                      targets: np.ndarray) -> tuple[list[int], int] | None:
    """Fewest cells, then fewest turns, from any of the cell ids ``sources`` to any of
    ``targets`` over the cells where ``free`` (C,) bool. Returns ``(path ids, turns)``, or
    None when no chain of free cells joins them."""
    common = np.intersect1d(sources, targets)
    if common.size:
        return [int(common[0])], 0
    C = len(free)
    e = grid.edges
    e = e[free[e[:, 0]] & free[e[:, 1]]]
    from scipy.sparse import csr_matrix  # loaded on first use: plans of given segments never need it
    from scipy.sparse.csgraph import dijkstra

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


def count_turns(seg_or_shape: Any, path: Sequence[int] | None = None, polygons: np.ndarray | None = None) -> int:
    """Turns along a path of cells (the search's definition), from the cell polygons: of a
    :class:`~planner.corridor.Segmentation`, or of ``shape`` ("square" | "triangle"), ``path``
    (cell ids) and ``polygons`` ((C, k, 2) [m]). Squares: the direction between consecutive
    centres changes; triangles: the orientation of the crossed edge differs from the one two
    crossings back."""
    if isinstance(seg_or_shape, str):
        shape = seg_or_shape
    else:
        shape, path, polygons = seg_or_shape.shape, seg_or_shape.path, seg_or_shape.polygons
    P = np.asarray(polygons, dtype=float)[np.asarray(path, dtype=np.int64)]  # (m, k, 2) along the path
    if len(P) < 2:
        return 0
    if shape == "square":
        labels = np.sign(np.diff(P.mean(axis=1), axis=0))  # direction of each move
        lag = 1
    else:  # the orientation of each crossed edge [deg, mod 180]: the two vertices both cells share
        A, B = P[:-1], P[1:]
        shared = np.linalg.norm(A[:, :, None, :] - B[:, None, :, :], axis=-1).min(axis=2) < 1e-9  # (m-1, 3)
        first, second = np.argsort(~shared, axis=1, kind="stable")[:, :2].T
        rows = np.arange(len(A))
        d = A[rows, second] - A[rows, first]
        labels = (np.round(np.degrees(np.arctan2(d[:, 1], d[:, 0]))) % 180)[:, None]
        lag = 2
    return int(np.count_nonzero(np.any(labels[lag:] != labels[:-lag], axis=1)))
