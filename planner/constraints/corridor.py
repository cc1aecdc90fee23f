"""The corridor as constraints: the convex set each predicted pose must lie in, and the
no-overshoot half-plane at the end.

**Corridor** (:class:`CorridorConstraint`): the predicted pose of sample ``j`` lies in that
sample's range of the range sequence (the time-indexed range, taper included), shrunk by
:data:`MARGIN_M` / :data:`MARGIN_RAD` on every side that is wide enough; for segments that
carry an exact convex ``polygon`` (triangles from the segmentation) the polygon's half-planes
replace the x/y box (mapped by the same per-axis affine taper as the box).

Why the time-indexed range and not the union of the current and the next segment: the union
of two cells is not convex in general (an L at a turn), while each time-indexed range is a
convex box (or polygon), and consecutive ranges share an edge, so the robot crosses from one
to the next between two samples. The taper out of the start and onto the end makes the range
sequence start and end at the points, so the same constraints give the terminal condition:
once the samples whose range is the end point enter the horizon, the predicted robot must be
there (to within :data:`END_TOL_M`) for ``samples_per_segment + 1`` samples, i.e. at rest.
A point range in x/y is a corner of its neighbouring cell in many corridors (Table I), so it
is constrained to the box ``end +- END_TOL_M`` intersected with the neighbouring cell shrunk
by the margin: the robot stops within a few micrometres of the end point, inside the cell.

Margins: the constraints hold for the linear prediction, the plant is the nonlinear model;
the one-step mismatch left after the refinement (:mod:`planner.constraints.controller`) is
below 1e-9 m on Table I, far inside the 1 micrometre margin, which therefore keeps the
actual samples inside. The rows of the samples after the first are :data:`RECOURSE_M` /
:data:`RECOURSE_RAD` tighter still at Ts 10 ms (less at finer sample times, :func:`recourse`;
where the range is wide enough): the model is
re-linearised every step, so a sample predicted two or more steps ahead moves by up to
~1e-7 m when it becomes the next step's first sample, and a plan that used a range to its
edge there (a vertex of its rows: on arrival, the stop box with the arrival speed) would
leave the next step's QP infeasible. The tighter rows leave that room (recourse).

**No overshoot** (:class:`EndApproachConstraint`): from the last segment before the end point
on, the predicted position never passes the end point along the approach direction
(:func:`planner.corridor.geometry.approach_direction`: from the last cell's centre, or the
cell's before it where the end point is the last cell's centre).

**Arrival at rest** (:class:`ArrivalConstraint`): from the sample after the first whose range
is the end point on, the predicted velocity is at most :data:`ARRIVAL_SPEED_M_S` (x, y; at
fine sample times :data:`ARRIVAL_STEP_M` a sample, :func:`arrival_speed`) and
:data:`ARRIVAL_RATE_RAD_S` (psi). Not from that first sample itself: there the position
(micrometre box) and the velocity would both be pinned, which leaves the last move no
freedom, and the two-step prediction error (the model is re-linearised every step; about
2 micrometres at arrival on Table I) made the next step's QP infeasible. One sample later,
each condition is met with a step of recourse. Without it the robot could enter the micrometre stop box
still moving at a few mm/s and then have to reverse within a sample, which made the forces
spike and alternate in sign on arrival. The psi rate is held only where the end point's angle
is (within the margins) one value: an end with a psi range has no stop box in psi, and the
criterion draws the angle to the range's middle (the end pose the robot settles at). Held at
1e-3 rad/s there too, the angle crept to the middle for up to the whole tail: 2.8x the work
estimate (certification seed 22, case 4731), and ``not_settled`` at the end point at rest
where the tail was too short (5 of 155 such corridors of seed 22; issue 20). The criterion
aims at the stop box's centre there (:meth:`CorridorConstraint.criterion_sequence`), not at
the end point itself, which lies on the box's edge or, at a cell corner, a margin outside it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ..corridor import RangeSequence
from ..corridor.geometry import approach_direction, clip_halfplanes, halfplanes
from ..model import RobotModel
from ..schema import Segment, Settings
from . import kernels as ck
from .rows import RowBlock, RowConstraint, RowKind, StepContext

__all__ = ["ARRIVAL_RATE_RAD_S", "ARRIVAL_SPEED_MAX_M_S", "ARRIVAL_SPEED_M_S", "ARRIVAL_STEP_M", "END_TOL_M",
           "END_TOL_RAD", "MARGIN_M", "MARGIN_RAD", "RECOURSE_M", "RECOURSE_MIN", "RECOURSE_RAD", "RECOURSE_TS",
           "ArrivalConstraint", "CorridorConstraint", "EndApproachConstraint", "arrival_speed", "recourse"]

#: corridor margin [m]: constraints use each range shrunk by this on every side
MARGIN_M = 1e-6
#: angle margin [rad]
MARGIN_RAD = 1e-6
#: half-size of the box about a point range (end point) in x/y [m]
END_TOL_M = 3e-6
#: half-size of the angle box about a point angle range at the end [rad]
END_TOL_RAD = 3e-6
#: the rows of the horizon's samples after the first are this much tighter [m] ...
RECOURSE_M = 2e-7
#: ... and [rad], at the sample time :data:`RECOURSE_TS` and above; less at finer sample times
#: (:func:`recourse`)
RECOURSE_RAD = 2e-7
#: the sample time [s] the recourse was sized at (Table I with the Moving Slide)
RECOURSE_TS = 0.01
#: the least recourse [m, rad] at fine sample times: the one-step mismatch the refinement leaves
#: (``controller.REFINE_TOL_M``)
RECOURSE_MIN = 1e-8
#: largest speed of the tool point (per axis) once the range is the end point [m/s] ...
ARRIVAL_SPEED_M_S = 1e-4
#: ... or at fine sample times this distance a sample [m] (the corridor margin), at most
#: :data:`ARRIVAL_SPEED_MAX_M_S`: a velocity predicted to 2e-7 m a sample (the recourse) is
#: known to 2e-4 m/s at Ts 1 ms, twice 0.1 mm/s, so at Ts 1 and 2 ms the last 4-26 steps before
#: the end point were infeasible by less than a nanometre a second and done on the Python path
#: (DAQP and its slack problem, ~1 s a step: 8.7x the work estimate at Ts 2 ms, 24x at 1 ms, and
#: 3 of 8 short corridors refused at 1 ms; issue 31). 0.1 mm/s at Ts 10 ms, as before.
ARRIVAL_STEP_M = 1e-6
#: the largest arrival speed [m/s]: the default settling speed (settings.settle_speed_m_s)
ARRIVAL_SPEED_MAX_M_S = 1e-3
#: largest angular speed there [rad/s]
ARRIVAL_RATE_RAD_S = 1e-3


def recourse(Ts: float | None) -> tuple[float, float]:
    """How much tighter the rows of the horizon's samples after the first are ([m], [rad]) at
    the sample time ``Ts`` [s] (None: :data:`RECOURSE_TS`): the prediction error they leave room
    for, the change of a sample's prediction when the model is re-linearised one step later, is
    a sample's frozen linearisation ``~ a v Ts^3 / L`` (the drives' acceleration ``a``, the speed
    ``v``, the geometry's length ``L``): :data:`RECOURSE_M` at :data:`RECOURSE_TS` scaled by
    ``(Ts / RECOURSE_TS)^3``, at least :data:`RECOURSE_MIN`, at most the constant. Issue 31: at
    Ts 1 ms the plant left the 2- and 3-step predictions by at most 1.4e-10 / 6.6e-10 m (6 legs,
    49 kg, N 100; Table I at 10 ms 1.2e-7 / 6.1e-7 m), yet the rows of the later samples were
    2e-7 m tighter: a robot at rest at the edge of the first sample's rows cannot move 2e-7 m in
    one sample with its force rising at the rate limit, so 276 of the 600 steps (every step from
    the end point's approach on, at rest too) were infeasible by 3-5e-7 m and solved relaxed,
    at 15.6x the work estimate."""
    if Ts is None or Ts >= RECOURSE_TS:
        return RECOURSE_M, RECOURSE_RAD
    scale = (Ts / RECOURSE_TS) ** 3
    return max(RECOURSE_M * scale, RECOURSE_MIN), max(RECOURSE_RAD * scale, RECOURSE_MIN)


#: half-planes of recently seen cell polygons, by their vertices' bytes: the candidate timings of
#: one corridor (``fastest``, contouring) map the same cells to the same polygons at most samples
_HP_CACHE: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
_HP_CACHE_MAX = 1 << 14


def _halfplanes(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~planner.corridor.geometry.halfplanes` of ``V``, remembered (read-only arrays)."""
    key = V.tobytes()
    hit = _HP_CACHE.get(key)
    if hit is None:
        if len(_HP_CACHE) >= _HP_CACHE_MAX:
            _HP_CACHE.clear()
        A, b = halfplanes(V)
        A.flags.writeable = False
        b.flags.writeable = False
        hit = _HP_CACHE[key] = (A, b)
    return hit


class CorridorConstraint(RowConstraint):
    """``lo_s <= pose_j <= hi_s`` (boxes) or ``A_s (x, y)_j <= b_s`` (half-planes, with the
    angle row of the box) for every sample ``j`` of the horizon, ``s`` its sequence index:
    the pose sets (see the module docstring). Compiled twin: ``kernels.corridor_fill``.

    ``lo``/``hi`` (K, 3): the shrunk box per sample 1..K [m, m, rad], for the horizon's first
    sample; ``lo_deep``/``hi_deep`` the same shrunk by the recourse (:func:`recourse` at the
    sample time ``Ts``: :data:`RECOURSE_M` / :data:`RECOURSE_RAD` at 10 ms) more (at most to the
    centre), for the later samples; ``hp[s]``: ``(A (h, 2), b (h,))`` or ``None``, half-planes
    replacing the x/y box rows of sequence index ``s`` [m] (``b`` lowered by the recourse for
    the later samples)."""

    kind = RowKind.CORRIDOR

    @classmethod
    def of(cls, model: RobotModel, seq: RangeSequence, segments: Sequence[Segment] | None,
           st: Settings) -> CorridorConstraint:
        return cls(seq, segments, st.Ts)

    def __init__(self, seq: RangeSequence, segments: Sequence[Segment] | None, Ts: float | None = None):
        K = seq.K
        #: the later samples' rows this much tighter [m], [rad] (:func:`recourse`)
        self.recourse_m, self.recourse_rad = recourse(Ts)
        lo, hi = seq.lower.copy(), seq.upper.copy()
        w = hi - lo
        marg = np.array([MARGIN_M, MARGIN_M, MARGIN_RAD])
        shrink = np.minimum(marg, 0.5 * w)
        lo += shrink
        hi -= shrink
        self.hp: list[tuple[np.ndarray, np.ndarray] | None] = [None] * K
        #: the samples whose point range became the stop box
        self.stop = np.zeros(K, bool)
        if segments is not None:
            n = len(segments)
            boxes = [(s.lower[:2], s.upper[:2]) for s in segments]
            # the no-overshoot half-plane (EndApproachConstraint's): the stop box is cut to it too
            approach = None
            cuts: dict[tuple[int, bytes], tuple | None] = {}
            if n >= 2 and segments[-1].is_xy_point:
                d = approach_direction(segments)
                if d is not None:
                    approach = (d, float(d @ segments[-1].centre[:2]))
            for j in range(K):
                si = int(seq.segment[j])
                seg = segments[si]
                # x/y point range near the end: tiny box intersected with a neighbouring cell
                if np.all(w[j, :2] <= 2 * MARGIN_M) and si >= n - 2:
                    p = 0.5 * (seq.lower[j, :2] + seq.upper[j, :2])
                    for h in (si, si - 1, si + 1, n - 2):
                        # a cell with room inside its margins in x and y (not the end point
                        # itself, also where that has a psi range: cut to it, the box was
                        # inverted, lo = p + margin > hi = p - margin, rows no pose meets)
                        if 0 <= h < n and not segments[h].is_xy_point:
                            blo, bhi = boxes[h][0] + MARGIN_M, boxes[h][1] - MARGIN_M
                            if np.all(blo < bhi) and np.all(blo - END_TOL_M <= p) and np.all(p <= bhi + END_TOL_M):
                                lo[j, :2] = np.maximum(p - END_TOL_M, blo)
                                hi[j, :2] = np.minimum(p + END_TOL_M, bhi)
                                self.stop[j] = True
                                key = (h, p.tobytes())  # the same for every sample at the end point
                                if key not in cuts:
                                    cuts[key] = _stop_in_cell(segments[h], p, blo, bhi, approach, self.recourse_m)
                                cut = cuts[key]
                                if cut is not None:  # the box cut to the exact cell
                                    A, b, lo[j, :2], hi[j, :2] = cut
                                    self.hp[j] = (A, b)
                                # a point angle too: an equality on psi at every sample
                                # cannot damp a residual rotation (with one constant move per
                                # sample the rate only flips sign), so give it the same kind
                                # of box inside the cell's angle range where there is room
                                q = seq.lower[j, 2]
                                plo = segments[h].lower[2] + MARGIN_RAD
                                phi_ = segments[h].upper[2] - MARGIN_RAD
                                if w[j, 2] <= 2 * MARGIN_RAD and phi_ > plo and \
                                        plo - END_TOL_RAD <= q <= phi_ + END_TOL_RAD:
                                    lo[j, 2] = max(q - END_TOL_RAD, plo)
                                    hi[j, 2] = min(q + END_TOL_RAD, phi_)
                                break
                poly = seg.polygon
                if poly is not None and not seg.is_point:
                    sw = seg.upper[:2] - seg.lower[:2]
                    if np.all(sw > 0) and np.all(w[j, :2] > 4 * MARGIN_M):
                        # the same per-axis affine map that tapers the box
                        V = seq.lower[j, :2] + (np.asarray(poly, float) - seg.lower[:2]) * (w[j, :2] / sw)
                        A, b = _halfplanes(V)
                        self.hp[j] = (A, b - MARGIN_M)
        extra = np.minimum(np.array([self.recourse_m, self.recourse_m, self.recourse_rad]), 0.5 * (hi - lo))
        lo_deep, hi_deep = lo + extra, hi - extra
        if segments is not None:
            # a range spreading out of a point (the start) keeps that point inside its rows: shrunk
            # by the margin, the first spread samples of a start at a corner of its cell excluded
            # it, so a robot at rest there had to move a margin (1 um) within one sample, which a
            # force rising at its rate limit cannot at a fine Ts (0.05 um at Ts 1 ms: every
            # default request refused, issue 31). Being at the point is inside the corridor (the
            # point is a segment); away from it the rows are the shrunk range's.
            for i in range(1, len(segments)):
                if segments[i - 1].is_point and not segments[i].is_point:
                    p = segments[i - 1].centre
                    # the samples whose range holds the point (the spreading ones; not those
                    # narrowing onto the end point when the segment is between two points)
                    spread = (seq.segment == i) & np.all((seq.lower <= p + 1e-12) & (p <= seq.upper + 1e-12), axis=1)
                    for a, b in ((lo, hi), (lo_deep, hi_deep)):
                        a[spread] = np.minimum(a[spread], p)
                        b[spread] = np.maximum(b[spread], p)
        self.lo, self.hi = lo, hi
        self.lo_deep, self.hi_deep = lo_deep, hi_deep
        self.has_hp = np.array([h is not None for h in self.hp], bool)
        # the half-planes flattened for the compiled rows: those of sequence index s are
        # hp_A[hp_ptr[s]:hp_ptr[s + 1]]
        counts = [0 if h is None else len(h[1]) for h in self.hp]
        self.hp_ptr = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
        self.hp_A = np.ascontiguousarray(np.vstack([h[0] for h in self.hp if h is not None] or [np.zeros((0, 2))]),
                                         dtype=float)
        self.hp_b = np.concatenate([h[1] for h in self.hp if h is not None] or [np.zeros(0)]).astype(float)

    def criterion_sequence(self, seq: RangeSequence) -> RangeSequence:
        """The range sequence the criterion reads: ``seq`` with each stop box (module
        docstring) as the range of its sample, so that the criterion's target there (the
        range's centre) lies inside the box."""
        if not self.stop.any():
            return seq
        lower, upper = seq.lower.copy(), seq.upper.copy()
        lower[self.stop], upper[self.stop] = self.lo[self.stop], self.hi[self.stop]
        return replace(seq, lower=lower, upper=upper)

    def rows(self, step: StepContext) -> RowBlock:
        """Box rows sorted by axis, then sample (x and y only where the sample has no
        half-planes), then the half-planes sample by sample."""
        idx = step.idx
        samples = np.arange(len(idx))
        lo, hi, has_hp = self.lo_deep[idx], self.hi_deep[idx], self.has_hp[idx]
        lo[0], hi[0] = self.lo[idx[0]], self.hi[idx[0]]
        cols, vals, lower, upper = [], [], [], []
        for ax in range(3):
            sel = samples if ax == 2 else samples[~has_hp]
            cols.append(np.column_stack((6 * sel + ax, np.full(sel.size, -1))))
            vals.append(np.column_stack((np.ones(sel.size), np.zeros(sel.size))))
            lower.append(lo[sel, ax])
            upper.append(hi[sel, ax])
        for j in samples[has_hp]:
            A, b = self._halfplanes(int(idx[j]))
            cols.append(6 * j + np.tile(np.arange(2), (len(b), 1)))
            vals.append(A)
            lower.append(np.full(len(b), -np.inf))
            upper.append(b - (self.recourse_m if j > 0 else 0.0))
        return RowBlock(np.vstack(cols), np.vstack(vals), np.concatenate(lower), np.concatenate(upper), self.kind)

    def _halfplanes(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        hp = self.hp[s]
        assert hp is not None
        return hp

    @property
    def kernel_args(self) -> ck.CorridorArgs:
        return ck.CorridorArgs(self.lo, self.hi, self.lo_deep, self.hi_deep, self.has_hp, self.hp_ptr, self.hp_A,
                               self.hp_b, float(self.recourse_m))


def _stop_in_cell(cell: Segment, p: np.ndarray, blo: np.ndarray, bhi: np.ndarray,
                  approach: tuple[np.ndarray, float] | None, room: float = RECOURSE_M
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The stop box about the end point ``p`` (x, y), ``p +- END_TOL_M`` within the cell's box
    shrunk by the margin ``[blo, bhi]``, cut to the cell's exact polygon shrunk by the margin
    (an end point near a triangle's slanted edge or acute corner: the box alone let the robot
    settle up to a few tenths of a micrometre outside the corridor) and to the no-overshoot
    half-plane ``approach = (d, b)``, ``d . x <= b`` (an approach direction taken from a cell
    before the last one can cut the whole box off: the end point on the last cell's edge, the
    direction across it; every step at the end was then infeasible by ~0.5 um and solved
    relaxed, at 15x the work, issue 20): ``(A, b, lo, hi)``, the half-planes and those of the cut
    box's bounding box, and that box. Where the cut leaves no room for the later samples'
    recourse, the box about ``p`` is doubled (up to 16 times; the robot then stops within
    that of the end point, still short of it along ``d``). None where the box is inside every
    half-plane, or none leaves room. ``room``: the later samples' recourse [m]."""
    eye = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])

    def corners(r: float) -> np.ndarray:
        lo, hi = np.maximum(p - r, blo), np.minimum(p + r, bhi)
        return np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])

    def roomy(P: np.ndarray) -> bool:  # room for the later samples' recourse
        return len(P) >= 3 and bool(np.all(P.max(axis=0) - P.min(axis=0) > 2 * room))

    box = corners(END_TOL_M)
    out = None
    region = box
    if cell.polygon is not None:  # the box cut to the exact cell
        A, b = halfplanes(np.asarray(cell.polygon, float))
        b = b - MARGIN_M
        if not np.all(box @ A.T <= b[None, :]):
            cut = clip_halfplanes(box, A, b)
            if len(cut) >= 3 and np.all(cut.max(axis=0) - cut.min(axis=0) > 2 * room):
                clo, chi = cut.min(axis=0), cut.max(axis=0)
                out = np.vstack((A, eye)), np.concatenate((b, chi, -clo)), clo, chi
                region = cut
    else:
        A, b = np.zeros((0, 2)), np.zeros(0)
    if approach is None or roomy(clip_halfplanes(region, approach[0][None, :], np.array([approach[1] - room]))):
        return out
    # the no-overshoot half-plane leaves no room in the box: cut to it too, the box doubled
    A, b = np.vstack((A, approach[0][None, :])), np.concatenate((b, [approach[1]]))
    r = END_TOL_M
    for _ in range(5):
        box = corners(r)
        if roomy(clip_halfplanes(box, A, b - room)):
            cut = clip_halfplanes(box, A, b)
            clo, chi = cut.min(axis=0), cut.max(axis=0)
            return np.vstack((A, eye)), np.concatenate((b, chi, -clo)), clo, chi
        r *= 2
    return out


class EndApproachConstraint(RowConstraint):
    """No overshoot: ``d . (x, y)_j <= d . end`` [m] (the recourse, :func:`recourse`, less after
    the horizon's first sample) with ``d`` the approach direction
    (:func:`~planner.corridor.geometry.approach_direction`), for the samples from sequence
    index :attr:`start_index` on (the sample before the last segment before the end point).
    Only for corridors that end in a point. Compiled twin: ``kernels.approach_fill``."""

    kind = RowKind.CORRIDOR

    @classmethod
    def of(cls, model: RobotModel, seq: RangeSequence, segments: Sequence[Segment] | None,
           st: Settings) -> EndApproachConstraint:
        return cls(seq, segments, st.Ts)

    def __init__(self, seq: RangeSequence, segments: Sequence[Segment] | None, Ts: float | None = None):
        #: the later samples' row this much tighter [m] (:func:`recourse`)
        self.recourse_m = recourse(Ts)[0]
        #: approach direction (2,) and bound [m], or None (no rows)
        self.half_plane: tuple[np.ndarray, float] | None = None
        #: first sequence index with the row
        self.start_index = seq.K
        n = 0 if segments is None else len(segments)
        if segments is not None and n >= 2 and segments[-1].is_xy_point:
            d = approach_direction(segments)
            if d is not None:
                self.half_plane = (d, float(d @ segments[-1].centre[:2]))
                self.start_index = max(int(np.argmax(seq.segment >= n - 2)) - 1, 0)

    def rows(self, step: StepContext) -> RowBlock:
        """One row per sample from :attr:`start_index` on (none without the half-plane)."""
        sel = np.zeros(0, int) if self.half_plane is None else np.nonzero(step.idx >= self.start_index)[0]
        d, b = self._half_plane()
        return RowBlock(6 * sel[:, None] + np.arange(2), np.tile(d, (sel.size, 1)), np.full(sel.size, -np.inf),
                        b - np.where(sel > 0, self.recourse_m, 0.0), self.kind)

    def _half_plane(self) -> tuple[np.ndarray, float]:
        return self.half_plane if self.half_plane is not None else (np.zeros(2), 0.0)

    @property
    def kernel_args(self) -> ck.ApproachArgs:
        d, b = self._half_plane()
        return ck.ApproachArgs(self.half_plane is not None, np.ascontiguousarray(d, dtype=float), float(b),
                               int(self.start_index), float(self.recourse_m))


def arrival_speed(Ts: float | None) -> float:
    """The arrival rows' speed bound [m/s] at the sample time ``Ts`` [s]:
    :data:`ARRIVAL_SPEED_M_S`, or :data:`ARRIVAL_STEP_M` a sample where that is more, at most
    :data:`ARRIVAL_SPEED_MAX_M_S` (0.1 mm/s at Ts 10 ms and above, 0.5 at 2 ms, 1 at 1 ms)."""
    if Ts is None or Ts <= 0:
        return ARRIVAL_SPEED_M_S
    return min(max(ARRIVAL_SPEED_M_S, ARRIVAL_STEP_M / Ts), max(ARRIVAL_SPEED_MAX_M_S, ARRIVAL_SPEED_M_S))


class ArrivalConstraint(RowConstraint):
    """Arrival at rest: ``|x_dot_j|, |y_dot_j| <=`` :func:`arrival_speed` and ``|psi_dot_j| <=
    ARRIVAL_RATE_RAD_S`` (the psi rate only where the end's angle is one value; an infinite
    bound, a row never active, where it is a range) for the samples from sequence index
    :attr:`start_index` on: the one after the first whose x/y range is the end point (the end
    of the taper). Only for corridors that end in a point. Compiled twin: ``kernels.arrival_fill``."""

    kind = RowKind.SPEED

    @classmethod
    def of(cls, model: RobotModel, seq: RangeSequence, segments: Sequence[Segment] | None,
           st: Settings) -> ArrivalConstraint:
        return cls(seq, segments, st.Ts)

    def __init__(self, seq: RangeSequence, segments: Sequence[Segment] | None, Ts: float | None = None):
        #: first sequence index with the rows (``K``: none)
        self.start_index = seq.K
        #: the bounds [m/s, m/s, rad/s] (``Ts`` [s]: the sample time, None: 10 ms)
        v = arrival_speed(Ts)
        self.limit = np.array([v, v, ARRIVAL_RATE_RAD_S])
        n = 0 if segments is None else len(segments)
        if segments is not None and n >= 2 and segments[-1].is_xy_point:
            w = seq.upper[:, :2] - seq.lower[:, :2]
            at_end = (seq.segment >= n - 2) & np.all(w <= 2 * MARGIN_M, axis=1)
            if at_end.any():
                self.start_index = min(int(np.argmax(at_end)) + 1, seq.K - 1)
            if float(segments[-1].upper[2] - segments[-1].lower[2]) > 2 * MARGIN_RAD:
                self.limit[2] = np.inf  # an angle range at the end: its rate free (module docstring)

    def rows(self, step: StepContext) -> RowBlock:
        """Three rows (x, y, psi rates) per sample from :attr:`start_index` on."""
        sel = np.nonzero(step.idx >= self.start_index)[0]
        cols = (6 * sel[:, None] + 3 + np.arange(3)).reshape(-1, 1)
        lim = np.tile(self.limit, sel.size)
        return RowBlock(cols, np.ones((cols.shape[0], 1)), -lim, lim, self.kind)

    @property
    def kernel_args(self) -> ck.ArrivalArgs:
        return ck.ArrivalArgs(int(self.start_index), self.limit)
