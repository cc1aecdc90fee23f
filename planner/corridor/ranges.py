"""Segments to a per-sample range sequence (paper Section V.B, Table I, Fig. 4).

Each segment's range ``[r_a, r_b]`` is held for ``S`` samples (default ``N``: "the all
values are repeated in number equal length of horizon N"), or for its own count
(``settings.segment_samples``). Sample ``j = 1..K`` (``K`` = the counts' sum) belongs to
segment ``RangeSequence.segment[j - 1]``; sample 0 is the start. With
``taper`` (default), a segment that follows a point (the start) spreads linearly out of
that point over its samples, and a segment followed by a point (the end) narrows linearly
onto it (Fig. 4 a, c). Past sample ``K`` the end point is held. At each step the criterion
reads the next ``N`` samples of this sequence (:meth:`RangeSequence.window`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..schema import Segment, Settings


@dataclass
class RangeSequence:
    lower: np.ndarray  # (K, 3) r_a per sample 1..K [m, m, rad]
    upper: np.ndarray  # (K, 3) r_b per sample
    qa: np.ndarray  # (K, 3) diagonal of Q_ra per sample
    qb: np.ndarray  # (K, 3) diagonal of Q_rb per sample
    qu: np.ndarray  # (m,) diagonal of Q_u
    segment: np.ndarray  # (K,) segment index per sample (-1 for a reference trajectory)
    start: np.ndarray  # (3,) start pose
    end: np.ndarray  # (3,) end pose

    @property
    def K(self) -> int:
        return len(self.lower)

    def window(self, k: int, N: int):
        """Ranges and penalties for samples ``k+1..k+N``, the end held past ``K``."""
        if getattr(self, "_padded_N", None) != N:
            pad = lambda a: np.concatenate((a, np.repeat(a[-1:], N, axis=0)))  # noqa: E731
            self._padded = tuple(pad(a) for a in (self.lower, self.upper, self.qa, self.qb))
            self._qu = np.broadcast_to(self.qu, (N, len(self.qu)))
            self._padded_N = N
        k = min(k, self.K)
        lo, hi, qa, qb = self._padded
        return lo[k:k + N], hi[k:k + N], qa[k:k + N], qb[k:k + N], self._qu

    def at(self, k: int):
        """Range of sample ``k`` (0 = start point)."""
        if k == 0:
            return self.start, self.start
        i = min(k - 1, self.K - 1)
        return self.lower[i], self.upper[i]


def _penalties(settings: Settings, n_drives: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Diagonals of ``Q_ra``, ``Q_rb`` (3,) and ``Q_u`` (n_drives,) from the settings."""
    qa = np.array(settings.q_ra, float) if settings.q_ra is not None else np.full(3, settings.k_r)
    qb = np.array(settings.q_rb, float) if settings.q_rb is not None else np.full(3, settings.k_r)
    qu = np.array(settings.q_u, float) if settings.q_u is not None else np.full(n_drives, settings.k_u)
    return qa, qb, qu


def segment_counts(settings: Settings, n_segments: int) -> np.ndarray:
    """Samples each segment is held (n,): ``settings.segment_samples``, or
    ``samples_per_segment`` for every segment."""
    if settings.segment_samples is not None:
        return np.asarray(settings.segment_samples, dtype=np.int64)
    return np.full(n_segments, settings.samples_per_segment, dtype=np.int64)


def range_sequence(segments: list[Segment], settings: Settings, n_drives: int) -> RangeSequence:
    """Section V.B: expand the corridor's segments into per-sample ranges, segment ``i`` held
    for its count of :func:`segment_counts` samples (its taper over its own samples)."""
    n = len(segments)
    counts = segment_counts(settings, n)
    starts = np.concatenate(([0], np.cumsum(counts)))
    lo = np.repeat(np.array([s.lower for s in segments]), counts, axis=0)
    hi = np.repeat(np.array([s.upper for s in segments]), counts, axis=0)
    qa0, qb0, qu = _penalties(settings, n_drives)
    qa = np.repeat(np.array([s.q_ra if s.q_ra is not None else qa0 for s in segments]), counts, axis=0)
    qb = np.repeat(np.array([s.q_rb if s.q_rb is not None else qb0 for s in segments]), counts, axis=0)
    seg = np.repeat(np.arange(n), counts)
    if settings.taper:
        def between(i: int) -> bool:  # a single segment between two points
            return 0 < i < n - 1 and segments[i - 1].is_point and segments[i + 1].is_point

        for i in range(1, n):
            if segments[i - 1].is_point and not segments[i].is_point:  # spread out of a point
                p = segments[i - 1].centre
                sl = slice(starts[i], starts[i + 1])
                c = int(counts[i])
                # between two points: spread over the first half, narrow over the second (both at
                # once would pull the range off the start point from its first sample: a robot
                # at rest there, its force rising at a bounded rate, could not follow at a fine
                # sample time)
                span = (c + 1) // 2 if between(i) else c
                alpha = np.minimum(np.arange(1, c + 1) / span, 1.0)[:, None]
                lo[sl] = p + (segments[i].lower - p) * alpha
                hi[sl] = p + (segments[i].upper - p) * alpha
        for i in range(n - 1):
            if segments[i + 1].is_point and not segments[i].is_point:  # narrow onto a point
                p = segments[i + 1].centre
                sl = slice(starts[i], starts[i + 1])
                c = int(counts[i])
                skip = c // 2 if between(i) else 0
                alpha = (np.maximum(np.arange(1, c + 1) - skip, 0) / (c - skip))[:, None]
                lo[sl] = lo[sl] + (p - lo[sl]) * alpha
                hi[sl] = hi[sl] + (p - hi[sl]) * alpha
    return RangeSequence(lo, hi, qa, qb, qu, seg, segments[0].centre.copy(), segments[-1].centre.copy())


def reference_sequence(reference: np.ndarray, settings: Settings, n_drives: int) -> RangeSequence:
    """The tracking criterion (12) as a degenerate range: ``r_a = w``, ``Q_rb = 0``.

    ``reference[0]`` is the start pose (sample 0); ``reference[j]`` the desired pose at sample j.
    """
    qa0, _, qu = _penalties(settings, n_drives)
    w = reference[1:]
    K = len(w)
    return RangeSequence(w.copy(), w.copy(), np.tile(qa0, (K, 1)), np.zeros((K, 3)), qu,
                         np.full(K, -1), reference[0].copy(), reference[-1].copy())
