"""Speed profiles along a piece's tube turned into sample counts per cell (issue 22): the
timings :mod:`planner.contour.search` scales.

- :func:`profile_counts`: the heuristic profile (a cell speed, the curvature and corner limits
  ``sqrt(a R)``, an acceleration forwards and backwards, a bounded jerk at the ends);
- :class:`OptimalProfiles`, :func:`optimal_counts`: the exact path's time-optimal profile under
  the drive forces and leg speeds (:func:`planner.contour.timing.time_optimal`), bounded at the
  corners and on the arcs by what the tube allows, as times at the cells' ends, and the counts
  of a time scale of it;
- :func:`arrival_run`, :func:`with_arrival`: the ``program`` feed's arrival at a piece's end
  (issue 35 goal 2): the controller trails its cells' centres while it cruises and catches up
  before the end, faster than F; a sample more in each of the last cells lets it arrive at F.
"""

from __future__ import annotations

import math
from functools import partial
from typing import Any, NamedTuple

import numpy as np

from ..model import RobotModel
from ..schema import PathElement, Settings
from .timing import PathSamples, time_optimal
from .tube import Tube

#: the time-optimal profile's grid spacing: the pass's length over this many points, within
#: [GRID_H_MIN, GRID_H_MAX] [m], and at least GRID_POINTS_MIN points (a move from rest to rest
#: on two points would never move)
GRID_POINTS = 400
GRID_H_MIN, GRID_H_MAX = 2e-5, 2e-4
GRID_POINTS_MIN = 16


def corner_radius(turn: np.ndarray, rho: float) -> np.ndarray:
    """The largest circle that turns a corner of angle ``turn`` [rad] within ``rho`` of its
    vertex: ``rho sin(h) / (1 - sin(h))``, ``h = (pi - turn) / 2`` [m]."""
    half = np.clip((math.pi - turn) / 2, 1e-6, math.pi / 2)
    return rho * np.sin(half) / np.maximum(1 - np.sin(half), 1e-12)


def profile_counts(t: Tube, v_cap: np.ndarray, a: float, Ts: float, a_turn: float | None = None,
                   jerk: float | None = None, start: int | None = None) -> np.ndarray:
    """Sample counts per segment of the tube from a speed profile: cell speed at most
    ``v_cap`` (per segment), ``sqrt(a_turn R)`` on arcs, ``sqrt(a_turn R_corner)`` at junctions
    (``a_turn``: ``a`` if not given), reached with acceleration ``a`` from rest and back to rest;
    ``jerk``: within ``(jerk / 2)^(1/3) (3 d)^(2/3)`` at a distance ``d`` from the rest at either
    end (the speed of a start from rest at that jerk: the drive forces rise at a bounded rate).
    ``start``: the samples the start point is held (:func:`start_free`)."""
    n = len(t.segments)
    a_turn = a if a_turn is None else a_turn
    v = v_cap.astype(float).copy()
    finite = np.isfinite(t.radius)
    v[finite] = np.minimum(v[finite], np.sqrt(a_turn * t.radius[finite]))
    j = t.turn > 0
    v[j] = np.minimum(v[j], np.sqrt(a_turn * corner_radius(t.turn[j], t.rho)))
    if jerk is not None:
        d = np.concatenate(([0.0], np.cumsum(t.length)))
        d = np.minimum(d[:-1] + t.length, d[-1] - d[:-1])  # the cell's far end from the nearer rest
        v = np.minimum(v, np.cbrt(jerk / 2) * np.cbrt(3 * d) ** 2)
    # speeds at the nodes between segments, from rest to rest
    node = np.empty(n + 1)
    node[0] = 0.0
    for k in range(n):
        node[k + 1] = min(v[k], math.sqrt(node[k] ** 2 + 2 * a * t.length[k]))
    node[n] = 0.0
    for k in range(n - 1, -1, -1):
        node[k] = min(node[k], math.sqrt(node[k + 1] ** 2 + 2 * a * t.length[k]))
    counts = np.ones(n, np.int64)
    cells = t.length > 0
    mean = np.maximum(0.5 * (node[:-1] + node[1:]), 1e-9)
    speed = np.minimum(v, np.maximum(mean, 0.25 * v))[cells]
    counts[cells] = np.maximum(1, np.ceil(t.length[cells] / np.maximum(speed, 1e-12) / Ts - 1e-9)).astype(np.int64)
    counts[t.lead] = 1  # the lead cells at the pass's ends (planner.contour.tube)
    return start_free(t, counts, start)


def start_free(t: Tube, counts: np.ndarray, start: int | None = None) -> np.ndarray:
    """``counts`` with the tube's start point (its first segment) held ``start`` samples
    (None: :data:`START_POINT_SAMPLES`): the robot at rest there is sample 0 (the range
    sequence's start), and a count of one pinned sample 1 there too, so the drives' first force
    (which the force-rate limit lets rise in the first sample) had to wait a sample: every piece
    lost one sample at its start (issue 35: dxf2gcode's first force 0.2 N, then 9 N a sample
    later; the third-order peer's starts at once). Sample 1 is then the lead cell's, which
    holds the start point (:mod:`planner.contour.tube`). One sample (``start`` 1, as before)
    where the Z axis, which starts from rest within its acceleration, needs it to follow a
    ramp that the tool starts on (:func:`planner.contour.plan.plan_cut`)."""
    if len(counts) > 1 and t.length[0] == 0 and t.segments[0].is_point:
        counts[0] = START_POINT_SAMPLES if start is None else start
    return counts


#: the samples a piece's start point is held beyond sample 0 (:func:`start_free`)
START_POINT_SAMPLES = 0


def optimal_caps(path: PathSamples, a_all: np.ndarray, rho: float, chord: np.ndarray, Ts: float,
                 zcap: np.ndarray | None = None, zcap_at: Any = None) -> np.ndarray:
    """The time-optimal profile's bounds on the squared speed beyond the drives' (the ``caps``
    of :func:`planner.contour.timing.time_optimal`): at a corner ``a_all r``, ``r`` the
    :func:`corner_radius` of the turn within ``rho``; on an arc, one of its tube chords per sample
    time ``Ts`` (``chord``: the longest chord of each element, 0 where it is no arc); on a move
    whose Z changes, the XY speed that keeps Z within its axis speed (``zcap`` per element) and
    its acceleration (``zcap_at``: :class:`planner.contour.zaxis.ZCaps`, by path position)."""
    cap = np.where(path.corner > 0, a_all * corner_radius(path.corner, rho), np.inf)
    c = chord[path.element]
    cap = np.minimum(cap, np.where(c > 0, (c / Ts) ** 2, np.inf))
    if zcap_at is not None:
        cap = np.minimum(cap, zcap_at.at_s(path.s) ** 2)
    return cap if zcap is None else np.minimum(cap, zcap[path.element] ** 2)


class OptimalProfiles:
    """The time-optimal profile of a piece (:func:`planner.contour.timing.time_optimal`) for a
    tube of it (:class:`Optimal`): ``OptimalProfiles(...)(t)``. Bounds on the speed beyond the
    drives' (:func:`optimal_caps`): at a corner (a tangent jump of angle ``theta``) ``sqrt(a r)``,
    ``a`` the acceleration the drives give in every direction, ``r = rho sin(h) / (1 - sin(h))``,
    ``h = (pi - theta) / 2`` (the largest circle that turns there within the cells' radius
    ``rho``); on an arc, one of its chords per sample (a cell holds at least one sample).
    ``memo``: profiles by the piece's geometry and bounds (the depth passes of a program are
    alike: one profile)."""

    def __init__(self, model: RobotModel, st: Settings, chunk: list[int], els: list[PathElement],
                 origin: np.ndarray, psi: float, memo: dict | None, zcap: np.ndarray | None = None,
                 zcap_at: Any = None) -> None:
        self.model, self.st, self.els, self.origin, self.psi = model, st, els, origin, psi
        self.memo = {} if memo is None else memo
        self.geo = tuple((e.kind, *e.start, *e.end, *(e.centre if e.centre is not None else (0.0, 0.0)),
                          e.sweep_rad or 0.0) for e in els)
        self.lengths = np.array([e.length_m for e in els])
        self.start = np.concatenate(([0.0], np.cumsum(self.lengths)))
        total = float(self.start[-1])
        self.h = min(max(total / GRID_POINTS, GRID_H_MIN), GRID_H_MAX, total / GRID_POINTS_MIN)
        self.chunk = np.asarray(chunk)
        #: per element the XY speed bound of its Z (:func:`planner.contour.search.z_caps`), None: none
        self.zcap = zcap if zcap is not None and np.isfinite(zcap).any() else None
        #: the Z axis acceleration's XY speed bound by path position (:class:`planner.contour.zaxis.ZCaps`)
        self.zcap_at = zcap_at

    def __call__(self, t: Tube) -> Optimal:
        """The profile for the tube ``t``: its time at the end of each of ``t``'s segments."""
        els, origin, st, memo = self.els, self.origin, self.st, self.memo
        loc = np.searchsorted(self.chunk, t.element)
        arc = np.isfinite(t.radius) & (t.length > 0)
        chord = np.zeros(len(els))
        np.maximum.at(chord, loc[arc], t.length[arc])
        key = (self.geo, float(origin[0]), float(origin[1]), self.psi, st.Ts, t.rho, tuple(np.round(chord, 12)),
               None if self.zcap is None else tuple(self.zcap), None if self.zcap_at is None else self.zcap_at.key)
        if key not in memo:
            caps = partial(optimal_caps, rho=t.rho, chord=chord, Ts=st.Ts, zcap=self.zcap, zcap_at=self.zcap_at)
            path, w, T = time_optimal(self.model, els, origin, self.psi, self.h, caps)
            memo[key] = (path.s, T, float(np.sqrt(w.max())))
        s_grid, T, v_peak = memo[key]
        ds, dt = np.diff(s_grid), np.diff(T)
        step = np.flatnonzero(ds > 0)
        rest = (float(ds[step[0]]), float(dt[step[0]]), float(ds[step[-1]]), float(dt[step[-1]])) if step.size else None
        # the path length at the end of every segment: its element's start plus its share of the
        # element's cells (points and junctions: at the boundary)
        total = np.bincount(loc, weights=t.length, minlength=len(els))
        before = np.concatenate(([0.0], np.cumsum(total)))[loc]
        frac = (np.cumsum(t.length) - before) / np.maximum(total[loc], 1e-300)
        s_end = self.start[loc] + np.clip(frac, 0.0, 1.0) * self.lengths[loc]
        return Optimal(np.interp(s_end, s_grid, T), v_peak, rest, s_end)


class Optimal(NamedTuple):
    """The time-optimal profile for one tube."""

    times: np.ndarray  #: the profile's time at the end of each of the tube's segments [s]
    v_peak: float  #: its top speed [m/s]
    #: the grid's first and last step: (length [m], time [s]) from rest, then to rest (:func:`rest_ends`)
    rest: tuple[float, float, float, float] | None = None
    s_end: np.ndarray | None = None  #: the path length at the end of each of the tube's segments [m]


def rest_ends(opt: Optimal, jerk: float | None) -> np.ndarray:
    """``opt.times`` with the profile's first step from rest and last step to rest as drives
    whose acceleration rises at ``jerk`` [m/s^3] take them (``program`` feed, issue 35 goal 2).
    The grid's profile takes a step of length ``h`` from rest to the speed ``v`` at a constant
    acceleration, ``2 h / v``; capped at F (``v`` = F at the grid's second point) that is a
    sample's travel or more at a slow F (dxf2gcode's circle at F400: ``h`` 63 um, 0.94 samples'
    travel at 10 ms; freecad's 34 mm at F300: 1.7). Drives whose acceleration rises at ``jerk`` reach
    ``v`` in ``2 sqrt(v / j)`` over ``v sqrt(v / j)``: the step takes ``h / v + sqrt(v / j)`` (at
    least ``(6 h / j)^(1/3)``, the step's length at that jerk from rest), so the times after the
    first step come earlier by the difference (none where it is not positive), and those within
    the last step by the same at the end, in proportion across each step. Unchanged without the
    grid's steps (``opt.rest``) or a jerk bound."""
    times = opt.times
    if opt.rest is None or opt.s_end is None or jerk is None or not jerk > 0:
        return times

    def gain(h: float, dt: float) -> float:
        if not (h > 0 and dt > 0):
            return 0.0
        v = 2 * h / dt
        return max(dt - max(h / v + math.sqrt(v / jerk), (6 * h / jerk) ** (1 / 3)), 0.0)

    h0, dt0, h1, dt1 = opt.rest
    g0, g1 = gain(h0, dt0), gain(h1, dt1)
    s = opt.s_end
    total = float(s[-1])
    out = times - g0 * np.clip(s / h0, 0.0, 1.0) - g1 * np.clip((s - (total - h1)) / h1, 0.0, 1.0)
    return np.maximum(np.maximum.accumulate(out), 0.0)


def optimal_counts(t: Tube, times: np.ndarray, step: float, start: int | None = None) -> np.ndarray:
    """Sample counts per segment of the tube from the profile's times at the segments' ends
    (``step``: the sample time over the scale): the samples up to each end, rounded. A sample
    of a segment the profile crosses in no time is taken from the cell before where that has
    two: a junction cell's (it lies inside both its neighbours) and the end's lead cell's (the
    range sequence narrows it onto the end point: its sample is the one that arrives there).
    Every segment at least one sample, the lead cells one, the start point ``start``
    (:func:`start_free`)."""
    b = np.round(times / step).astype(np.int64)
    counts = np.diff(np.concatenate(([0], b)))
    take = (t.length == 0) & (t.turn > 0)
    if len(take) > 2 and t.lead[-2]:
        take[-2] = True
    j = np.flatnonzero(take & (counts <= 0))
    j = j[(j > 0) & (counts[np.maximum(j - 1, 0)] >= 2)]
    counts[j - 1] -= 1
    counts[j] = 1
    counts = np.maximum(counts, 1)
    counts[t.lead] = 1
    return start_free(t, counts, start)


#: program feed: at most this many samples added before a piece's end (:func:`with_arrival`)
ARRIVAL_MAX = 3
#: program feed: a run of segments faster than F ending at most this many samples before the
#: piece's last sample is the arrival's catch-up (:func:`arrival_run`); the controller brakes
#: from F to rest in 5-8 samples at Ts 10 ms (measured on the CAM samples)
ARRIVAL_BRAKE_SAMPLES = 10
#: ... and starting at least this many samples into the last move (:func:`arrival_run`)
ARRIVAL_CRUISE_SAMPLES = 20


def arrival_run(over: np.ndarray, counts: np.ndarray, move: np.ndarray) -> np.ndarray:
    """Per segment of a plan (``over``: its largest speed over F, :func:`planner.contour.search.overspeed_of`;
    ``counts``: its samples; ``move``: its move), True on the run of consecutive segments faster
    than F that ends within :data:`ARRIVAL_BRAKE_SAMPLES` samples of the piece's end, inside the
    last move and at least :data:`ARRIVAL_CRUISE_SAMPLES` samples after that move's first: the
    controller, which trails its cells' centres while it cruises, catching up with them before
    it stops. All False where there is no such run (a run that starts near a junction is the
    catch-up after the junction's slowdown, which a sample more at the end does not remove)."""
    out = np.zeros(len(over), bool)
    k = len(over) - 1
    tail = 0
    while k >= 0 and over[k] <= 1.0:
        tail += int(counts[k])
        k -= 1
    if k < 0 or tail > ARRIVAL_BRAKE_SAMPLES:
        return out
    last = move[k]
    while k >= 0 and over[k] > 1.0 and move[k] == last:
        out[k] = True
        k -= 1
    before = int(counts[(move == last) & ~out & (np.arange(len(over)) <= k)].sum())
    if (k >= 0 and over[k] > 1.0) or before < ARRIVAL_CRUISE_SAMPLES:
        out[:] = False
    return out


def with_arrival(t: Tube, counts: np.ndarray, extra: int) -> np.ndarray:
    """``counts`` with a sample more in each of the last ``extra`` cells of positive length
    before the end's lead cell: time for the controller to catch up with its cells before it
    stops, at F rather than faster (:func:`arrival_run`)."""
    if extra <= 0:
        return counts
    out = counts.copy()
    cells = np.flatnonzero((t.length > 0) & ~t.lead)
    out[cells[-extra:]] += 1
    return out


#: program feed: rounds of a sample more in each run of segments faster than F
#: (:func:`run_samples`) before the moves' cells are shortened instead
RUN_FIXES = 3


#: program feed: a run faster than F within this many segments of a junction that turns the
#: path back by more than :data:`REVERSAL_RAD` gets no samples (:func:`run_samples`)
REVERSAL_NEAR = 4
REVERSAL_RAD = math.radians(150.0)


def near_reversal(turn: np.ndarray) -> np.ndarray:
    """Per segment of a tube (``turn``: its junctions' turn angles) whether it lies within
    :data:`REVERSAL_NEAR` segments of a reversal (a turn over :data:`REVERSAL_RAD`: a line
    retraced, a tab's flank): samples added there slow the robot's turn-back, which then
    crawls back along the line it came on (``tests/test_contour_retrace.py`` follows the
    path and lost it)."""
    out = np.zeros(len(turn), bool)
    for j in np.flatnonzero(turn > REVERSAL_RAD):
        out[max(j - REVERSAL_NEAR, 0):j + REVERSAL_NEAR + 1] = True
    return out


def run_samples(over: np.ndarray, counts: np.ndarray, lead: np.ndarray,
                avoid: np.ndarray | None = None) -> np.ndarray:
    """The samples to add per segment of a plan (``over``: each segment's largest speed over F,
    :func:`planner.contour.search.overspeed_of`; ``counts``: its samples; ``lead``: the lead
    cells, never raised) for its runs of consecutive segments faster than F: the controller
    trails its cells after a start or a corner's slowdown and runs ahead of them before a
    corner or the end, and catches up faster than F over a run of cells. A run's excess
    travel, ``sum(counts (over - 1))`` samples' travel at F, rounded up, is added one sample
    each to its fastest segments: time for the catch-up at F, where shortening every cell of
    the move (the cells' margin) costs a sample every few cells on the whole move. A run with a
    segment in ``avoid`` (:func:`near_reversal`) gets none."""
    add = np.zeros(len(counts), np.int64)
    bad = (over > 1.0) & ~lead
    k = 0
    n = len(over)
    while k < n:
        if not bad[k]:
            k += 1
            continue
        j = k
        while j < n and bad[j]:
            j += 1
        idx = np.arange(k, j)
        if avoid is not None and avoid[idx].any():
            k = j
            continue
        need = max(1, math.ceil(float(np.sum(counts[idx] * (over[idx] - 1.0))) - 1e-9))
        order = idx[np.argsort(-over[idx], kind="stable")]
        for q in range(need):
            add[order[q % len(order)]] += 1
        k = j
    return add
