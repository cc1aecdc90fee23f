"""Where each sample of a cut piece is along its programmed path (issue 35): the one
implementation of "which move a sample is on" and "how far along it".

- :func:`move_of`: per sample the move (index in the pass) whose tube cell the timing held it in
  (the range sequence's cell: :func:`~planner.contour.passes.segment_of`); monotone along the
  piece by construction, whatever the path's shape in the plane (a ramp down a line and back
  along it, a tab, a full circle that ends where it starts);
- :func:`progress`: per sample the share of its move it has reached (the point of the move it
  projects onto; on an arc the angle followed from sample to sample, so the seam of a full
  circle, where its start and end are one point, is its start for the samples that begin it
  and its end for those that end it), that point and the sample's XY distance from it, and its
  path length from the pass's start, made monotone (the robot's progress);
- :func:`move_speeds`: per move the top speed the path was run at (the samples' own speeds and
  the progress between two samples over their time, so a move passed between two samples has
  its speed too).

Never the nearest point of the whole path: on a retraced path that is another move's.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..schema import PathElement, PlanResult
from .passes import counts_of, segment_of
from .tube import Tube

__all__ = ["Progress", "move_of", "move_speeds", "moves_at", "progress"]


def move_of(result: PlanResult, t: Tube) -> np.ndarray:
    """Per sample of a piece's plan ``result`` in its tube ``t`` the index (in the pass) of
    the move whose cell holds it (K,), non-decreasing."""
    return moves_at(t, counts_of(result, len(t.segments)), len(result.time))


def moves_at(t: Tube, counts: np.ndarray, K: int) -> np.ndarray:
    """:func:`move_of` of the first ``K`` samples of a timing (``counts`` per tube segment),
    planned or not (where a candidate stopped)."""
    return np.asarray(t.element)[segment_of(np.asarray(counts), K)]


class Progress(NamedTuple):
    """:func:`progress`' outcome, per sample: ``share`` of its move reached (0..1), ``foot`` the
    point of the move it projects onto (program frame, (K, 2)) [m], ``distance`` its XY distance
    from that point [m], ``s`` its path length from the pass's start, non-decreasing [m]."""

    share: np.ndarray
    foot: np.ndarray
    distance: np.ndarray
    s: np.ndarray


def progress(pose: np.ndarray, elem: np.ndarray, elements: list[PathElement], origin: np.ndarray) -> Progress:
    """Per sample (``pose`` (K, 2+) robot frame, ``elem`` its move in ``elements``,
    :func:`move_of`) how far along the path it is (module docstring)."""
    p_all = np.asarray(pose, float)[:, :2] - origin
    elem = np.asarray(elem, np.int64)
    K = len(p_all)
    share, foot = np.zeros(K), np.zeros((K, 2))
    # each run of samples on one move (one run per move where elem is monotone)
    starts = np.flatnonzero(np.r_[True, elem[1:] != elem[:-1]]) if K else np.zeros(0, np.int64)
    for a, b in zip(starts, np.r_[starts[1:], K]):
        e = elements[int(elem[a])]
        p = p_all[a:b]
        if e.kind == "arc" and e.centre is not None and e.sweep_rad and e.start_angle_rad is not None:
            f = _arc_share(p, e)
            share[a:b] = f
            foot[a:b] = e.point_at(f * e.length_m)
        else:
            s0, v = np.asarray(e.start, float), np.asarray(e.end, float) - np.asarray(e.start, float)
            f = np.clip((p - s0) @ v / max(float(v @ v), 1e-24), 0.0, 1.0)
            share[a:b] = f
            foot[a:b] = s0 + f[:, None] * v
    lengths = np.array([max(e.length_m, 0.0) for e in elements])
    begin = np.concatenate(([0.0], np.cumsum(lengths)))[:-1]
    s = np.maximum.accumulate(begin[elem] + share * lengths[elem]) if K else np.zeros(0)
    return Progress(share, foot, np.hypot(*(p_all - foot).T), s)


def _arc_share(p: np.ndarray, e: PathElement) -> np.ndarray:
    """The share of the arc ``e`` reached by the consecutive samples ``p`` (program frame) of
    one run: each sample's angle from the arc's start, followed from one sample to the next
    (consecutive samples are in the same or consecutive cells, less than half a turn apart),
    the run's whole turns chosen so that it lies on the arc as far as it can (a sample just
    before the start of a full circle is at its start, not its end)."""
    assert e.centre is not None and e.sweep_rad is not None and e.start_angle_rad is not None
    c = np.asarray(e.centre, float)
    sweep = abs(e.sweep_rad)
    rel = (np.arctan2(p[:, 1] - c[1], p[:, 0] - c[0]) - e.start_angle_rad) * math.copysign(1.0, e.sweep_rad)
    rel = np.unwrap(rel)
    rel -= 2 * math.pi * math.floor(rel[0] / (2 * math.pi))  # the first in [0, 2 pi)
    out_of = [float(np.sum(np.maximum(-(rel + k), 0.0) + np.maximum(rel + k - sweep, 0.0)))
              for k in (0.0, -2 * math.pi)]
    if out_of[1] < out_of[0]:
        rel = rel - 2 * math.pi
    return np.clip(rel / sweep, 0.0, 1.0)


def move_speeds(time: np.ndarray, speed: np.ndarray, elem: np.ndarray, s: np.ndarray, moves: list[int],
                elements: list[PathElement]) -> np.ndarray:
    """Per move of ``moves`` (indices in ``elements``, the piece's) the top speed the path was
    run at on it [m/s]: its samples' ``speed`` and, for each step between two samples whose
    progress ``s`` (:func:`progress`) overlaps the move, that progress over the step's time (a
    move passed between two samples, or cut by samples its cell did not hold, has its speed)."""
    lengths = np.array([max(e.length_m, 0.0) for e in elements])
    begin = np.concatenate(([0.0], np.cumsum(lengths)))
    dt = np.maximum(np.diff(time), 1e-12)
    step = np.diff(s) / dt
    out = np.zeros(len(moves))
    for j, k in enumerate(moves):
        lo, hi = begin[k], begin[k + 1]
        own = speed[elem == k]
        over = step[(s[1:] > lo) & (s[:-1] < hi)] if len(s) > 1 else np.zeros(0)
        out[j] = max(float(own.max(initial=0.0)), float(over.max(initial=0.0)))
    return out
