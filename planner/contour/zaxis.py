"""The Z of a cut whose Z moves (issue 32, goal 3: ramps, helices, tabs planned with the XY
motion) within the Z axis speed and acceleration.

The programmed Z is a function of the path position (:func:`programmed_z`: per sample, the Z of
its move where the sample projects onto it), so where the slope ``dZ/ds`` changes (a ramp's
start and end, a tab's flanks) it turns a corner in time: its velocity jumps by the slope's
change times the XY speed there, an unbounded acceleration. The Z planned instead
(:func:`plan_z`) is the sample sequence nearest the programmed Z that keeps

* ``|z[k+1] - z[k]| <= v_max Ts`` (the axis speed, between samples),
* ``|z[k+1] - 2 z[k] + z[k-1]| <= a_max Ts^2`` (the axis acceleration, the exported samples'
  second differences; at rest before the first sample and after the last),
* ``|z[k] - zp[k]| <= sqrt(tol^2 - d[k]^2)``: the tool point (X, Y, Z) within the tolerance of
  the programmed 3-D path, ``d[k]`` the sample's XY distance from the point of its move it
  projects onto (at most 0.95 tol in the tube); the first and the last sample at the programmed Z,

a linear programme (scipy's HiGHS) in units of ``a_max Ts^2``. Where no such sequence exists
(the XY motion too fast where the slope changes, or accelerating along a slope faster than Z
may), the samples it misses name their moves, and :func:`planner.contour.plan.plan_cut` plans
the piece again with those moves slower. :class:`ZCaps` gives the XY speed bounds a first plan
starts with: a slope change ``dg`` blended within ``tol_z`` at the axis acceleration turns at an
XY speed of at most ``sqrt(8 a tol_z) / dg`` (a parabola's deviation from the corner it rounds,
``(dg v)^2 / (8 a)``), ``tol_z`` half the 3-D budget's worst case; along a slope ``g`` the XY
speed then rises at most at ``a / |g|``.

Units: m, s.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..schema import PathElement
from .path import progress

__all__ = ["SLOPE_STOP_M_S", "Z_EASE", "Z_SLACK", "Z_TRIES", "ZCaps", "ZPlan", "accel_dwell", "blend_speed", "plan_z",
           "programmed_z", "slope_stops", "slopes"]

#: a sample whose Z misses its budget by more than this share of ``a_max Ts^2`` fails (the LP's
#: own feasibility tolerance is 1e-7 of that unit)
Z_SLACK = 1e-4
#: the share of the tolerance a slope change's blend may use in the first caps (the 3-D budget
#: at the tube's widest, sqrt(1 - 0.95^2) = 0.31 of it, halved)
FIRST_BUDGET = 0.15
#: ``fastest``: a piece whose first timing Z misses is searched again as ``fastest`` with the XY
#: acceleration along the slopes it missed on (:class:`ZCaps`' ``gentle``) this share of the one
#: before, once, before the ``program`` feed's slower re-plans: a 2 mm ramp of slope 1 at Ts 10 ms
#: missed by 0.38 um at the full share took 0.200 s re-planned as a program feed, 0.120 s at 0.9
#: (Z's own shortest move 0.089 s); at the full share every time (not 0.9 from the first) fusion360's
#: first pass took 0.405 s against 0.426 s
Z_EASE = 0.9
#: points per cell on which :meth:`ZCaps.seconds` integrates the time at the bound
CROSS_POINTS = 9


def slopes(els: list[PathElement]) -> np.ndarray:
    """Per move its Z slope ``dZ/ds`` over its XY length (0 where Z stays or it has none)."""
    return np.array([(e.z_end_m - e.z_start_m) / e.length_m if e.length_m > 0 else 0.0 for e in els])


def blend_speed(dg: float | np.ndarray, tol: float, a_max: float) -> Any:
    """The XY speed [m/s] at which a slope change ``dg`` is blended within :data:`FIRST_BUDGET`
    of the tolerance ``tol`` at the Z acceleration ``a_max``: ``sqrt(8 a_max FIRST_BUDGET tol) / dg``
    (module docstring)."""
    return math.sqrt(8.0 * a_max * FIRST_BUDGET * tol) / dg


class ZCaps:
    """The XY speed [m/s] along a piece (its moves ``els`` in order) under which its Z can follow
    (module docstring), by path position ``s`` from the piece's start:

    * on a move of slope ``g``: the axis speed's ``v_max / |g|``, and ``slow`` (per move, inf
      unless a plan before missed there);
    * at a slope change ``dg`` at ``s_j`` (a junction of two moves; at the piece's ends the robot
      is at rest): the blend's ``v_j = sqrt(8 a_max FIRST_BUDGET tol) / dg``, and away from it
      along a sloped move the speed reached from ``v_j`` at the XY acceleration that keeps Z's
      ``g s''`` within ``a_max``: ``sqrt(v_j^2 + 2 (a_max / |g|) |s - s_j|)`` (a move whose Z
      stays is bounded only at the junction itself).

    :meth:`at_s` by position (the time-optimal profile's grid), :meth:`__call__` per segment of
    a tube (the lowest over the segment's extent: the heuristic profile's cells); ``key`` for
    memos."""

    def __init__(self, els: list[PathElement], chunk: list[int], tol: float, v_max: float, a_max: float,
                 slow: np.ndarray | None = None, gentle: np.ndarray | None = None) -> None:
        self.g = slopes(els)
        self.chunk = np.asarray(chunk)
        self.lengths = np.array([max(e.length_m, 0.0) for e in els])
        self.start = np.concatenate(([0.0], np.cumsum(self.lengths)))
        move = np.where(self.g != 0.0, v_max / np.maximum(np.abs(self.g), 1e-300), np.inf)
        self.move = move if slow is None else np.minimum(move, slow)
        # the slope changes, the piece's ends included (at rest there: the slope "changes" from none)
        g_ext = np.r_[0.0, self.g, 0.0]
        dg = np.abs(np.diff(g_ext))
        j = np.flatnonzero(dg > 0)
        self.s_j = self.start[j]
        self.v_j = blend_speed(dg[j], tol, a_max)
        #: per move the XY acceleration's share of a_max / |g| (lowered where a plan before missed)
        self.acc = a_max * (np.ones(len(els)) if gentle is None else np.asarray(gentle, float))
        self.key = (tuple(self.move), tuple(self.s_j), tuple(self.v_j), tuple(self.acc))

    def junction_cap(self, k: int) -> float:
        """The lowest blend speed at the ends of the piece's move ``k`` [m/s] (inf: no slope
        change there)."""
        at = (self.s_j >= self.start[k] - 1e-12) & (self.s_j <= self.start[k + 1] + 1e-12)
        return float(self.v_j[at].min()) if at.any() else math.inf

    @property
    def active(self) -> bool:
        """Whether any move's Z changes (else every bound is inf)."""
        return bool(np.any(self.g != 0.0))

    def _at(self, k: np.ndarray, s: np.ndarray) -> np.ndarray:
        """The bound at positions ``s`` on the piece's moves ``k``."""
        g = np.abs(self.g[k])
        cap = self.move[k].astype(float)
        acc = np.where(g > 0, self.acc[k] / np.maximum(g, 1e-300), np.inf)
        for sj, vj in zip(self.s_j, self.v_j):
            d = np.abs(s - sj)
            with np.errstate(invalid="ignore"):
                c = np.where(d <= 1e-12, vj, np.sqrt(vj * vj + 2.0 * acc * d))
            cap = np.minimum(cap, np.where(np.isnan(c), np.inf, c))
        return cap

    def at_s(self, s: np.ndarray) -> np.ndarray:
        """The bound [m/s] at path positions ``s`` [m] from the piece's start (at a junction the
        lower of its two moves')."""
        s = np.asarray(s, float)
        k0 = np.clip(np.searchsorted(self.start[1:], s, side="left"), 0, len(self.g) - 1)
        k1 = np.clip(np.searchsorted(self.start[1:], s, side="right"), 0, len(self.g) - 1)
        return np.minimum(self._at(k0, s), self._at(k1, s))

    def _extent(self, t: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per segment of the tube ``t``: its move (in the piece) and its extent ``[s0, s1]``
        along the piece [m]."""
        loc = np.searchsorted(self.chunk, t.element)
        total = np.bincount(loc, weights=t.length, minlength=len(self.g))
        before = np.concatenate(([0.0], np.cumsum(total)))[loc]
        share = self.lengths[loc] / np.maximum(total[loc], 1e-300)
        s1 = self.start[loc] + np.clip((np.cumsum(t.length) - before) * share, 0.0, self.lengths[loc])
        s0 = np.maximum(s1 - t.length * share, self.start[loc])
        return loc, s0, s1

    def __call__(self, t: Any) -> np.ndarray:
        """Per segment of the tube ``t`` the lowest bound over its extent [m/s]: at the point of
        it nearest each slope change, and the move's own."""
        loc, s0, s1 = self._extent(t)
        cap = self.move[loc].astype(float)
        for sj in self.s_j:
            cap = np.minimum(cap, self._at(loc, np.clip(sj, s0, s1)))
        return cap

    def seconds(self, t: Any, points: int = CROSS_POINTS) -> np.ndarray:
        """Per segment of the tube ``t`` the time [s] to cross it at the bound (its extent over
        the bound's harmonic mean on ``points`` points, each end included): a cell at a slope
        change is slow only at its end there (the bound rises as ``sqrt(v_j^2 + 2 a d / |g|)``
        away from it), where :meth:`__call__`'s lowest bound over the whole cell counts it slow
        throughout (fusion360's ramps: the cells on both sides of the slope change took 4
        samples each at 6 ms for about 1.6 and 1)."""
        loc, s0, s1 = self._extent(t)
        f = np.linspace(0.0, 1.0, points)
        s = s0[:, None] + (s1 - s0)[:, None] * f
        inv = 1.0 / np.maximum(self._at(np.repeat(loc[:, None], points, axis=1), s), 1e-300)
        mean = (inv[:, :-1] + inv[:, 1:]).sum(axis=1) / (2 * (points - 1))  # the trapezoid rule
        return (s1 - s0) * mean


#: a piece whose Z cannot follow is planned at most this many times in all
#: (:func:`planner.contour.plan.plan_cut`; the work estimate counts them for a piece with a slope)
Z_TRIES = 8


def programmed_z(pose: np.ndarray, elem: np.ndarray, elements: list[PathElement],
                 origin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per sample (``pose`` (K, 2) robot frame, ``elem`` the index of its move in ``elements``)
    the programmed Z where it projects onto its move and its XY distance from that point [m]
    (:func:`planner.contour.path.progress`: on a full circle's seam, its start or its end by
    the samples' order)."""
    got = progress(pose, elem, elements, origin)
    z0 = np.array([e.z_start_m for e in elements])[elem]
    z1 = np.array([e.z_end_m for e in elements])[elem]
    return z0 + got.share * (z1 - z0), got.distance


class ZPlan:
    """:func:`plan_z`'s outcome: ``z`` the planned Z per sample [m]; ``miss`` per sample by how
    much it misses its 3-D budget [m] (0 everywhere: the plan holds)."""

    def __init__(self, z: np.ndarray, miss: np.ndarray) -> None:
        self.z, self.miss = z, miss

    @property
    def ok(self) -> bool:
        return bool(np.all(self.miss <= 0.0))


def plan_z(zp: np.ndarray, budget: np.ndarray, Ts: float, v_max: float, a_max: float,
           before: float | None = None) -> ZPlan:
    """The Z per sample nearest ``zp`` (the programmed Z, module docstring) within ``budget`` of
    it (per sample [m]; the first and last samples held at ``zp``), its steps within ``v_max Ts``
    and its second differences within ``a_max Ts^2``, the robot at rest before and after (the
    first and last steps within ``a_max Ts^2``). ``before``: the Z of the sample before the
    first [m] where Z goes on from a piece planned before (the first sample then shared with that
    piece's last): the first second difference is taken with it, so Z's acceleration holds across
    the two pieces, not only within each. Where no sequence keeps every budget, the one
    that misses it least (in sum) and by how much each sample misses it."""
    from scipy.optimize import linprog
    from scipy.sparse import coo_matrix, csr_matrix, vstack

    K = len(zp)
    unit = a_max * Ts * Ts
    if K < 3 or (float(np.ptp(zp)) == 0.0 and (before is None or before == zp[0])):  # Z stays: the programmed Z
        return ZPlan(np.asarray(zp, float).copy(), np.zeros(K))
    base = float(zp[0])
    w = (np.asarray(zp, float) - base) / unit  # the programmed Z in units of a_max Ts^2 from its start
    b = np.maximum(np.asarray(budget, float), 0.0) / unit
    b[0] = b[-1] = 0.0
    vs = v_max * Ts / unit
    # variables: x (K), e (K) >= |x - w|, u (K) >= 0 the miss beyond the budget
    k = np.arange(K)
    eye = coo_matrix((np.ones(K), (k, k)), shape=(K, K))
    zero = csr_matrix((K, K))
    rows: list = []
    rhs: list[np.ndarray] = []
    # x - e <= w, -x - e <= -w
    rows += [vstack([eye, -eye, zero]).T, vstack([-eye, -eye, zero]).T]
    rhs += [w, -w]
    # x - u <= w + b, -x - u <= -w + b
    rows += [vstack([eye, zero, -eye]).T, vstack([-eye, zero, -eye]).T]
    rhs += [w + b, b - w]
    # steps: |x[k+1] - x[k]| <= vs
    n1 = K - 1
    r1 = np.arange(n1)
    d1 = coo_matrix((np.r_[-np.ones(n1), np.ones(n1)], (np.r_[r1, r1], np.r_[r1, r1 + 1])), shape=(n1, 3 * K))
    rows += [d1, -d1]
    rhs += [np.full(n1, vs), np.full(n1, vs)]
    # second differences, at rest before and after: the padded sequence x[0], x[0..K-1], x[K-1]
    n2 = K
    r2 = np.arange(n2)
    # row j: x[j+1] - 2 x[j] + x[j-1], with x[-1] = x[0] and x[K] = x[K-1]
    # (or with x[-1] = before, a constant, where Z goes on from the piece before)
    ii = np.r_[r2, r2, r2]
    jj = np.r_[np.minimum(r2 + 1, K - 1), r2, np.maximum(r2 - 1, 0)]
    vv = np.r_[np.ones(n2), -2 * np.ones(n2), np.ones(n2)]
    shift = np.zeros(n2)
    if before is not None:
        vv[2 * n2] = 0.0  # row 0's x[-1] term: the constant below, not x[0]
        shift[0] = (float(before) - base) / unit
    d2 = coo_matrix((vv, (ii, jj)), shape=(n2, 3 * K)).tocsr()
    rows += [d2, -d2]
    rhs += [np.ones(n2) - shift, np.ones(n2) + shift]
    A = vstack([r.tocsr() if hasattr(r, "tocsr") else r for r in rows]).tocsr()
    scale_u = 1e3 * K  # missing the budget costs far more than any distance inside it
    c = np.r_[np.zeros(K), np.ones(K), np.full(K, scale_u)]
    bounds = [(None, None)] * K + [(0, None)] * (2 * K)
    res = linprog(c, A_ub=A, b_ub=np.concatenate(rhs), bounds=bounds, method="highs")
    if res.status != 0 or res.x is None:  # pragma: no cover - the LP is always feasible (x = w[0] throughout)
        return ZPlan(np.asarray(zp, float), np.full(K, np.inf))
    x = res.x[:K]
    z = base + x * unit
    miss = np.maximum(np.abs(x - w) - b - Z_SLACK, 0.0) * unit
    return ZPlan(z, miss)


def _trapezoid(dz: float, v: float, a: float) -> tuple[float, float]:
    """A move of ``|dz|`` from rest to rest at most at speed ``v`` and acceleration ``a``: its
    time and top speed."""
    d = abs(dz)
    if d * a >= v * v:
        return d / v + v / a, v
    return 2.0 * math.sqrt(d / a), math.sqrt(d * a)


def _trapezoid_at(t: np.ndarray, dz: float, a: float, v: float, T: float) -> np.ndarray:
    """The distance covered (signed as ``dz``) at times ``t`` in [0, T] of :func:`_trapezoid`'s move."""
    ta = v / a
    t = np.clip(t, 0.0, T)
    s = np.where(t < ta, 0.5 * a * t * t, np.where(t > T - ta, abs(dz) - 0.5 * a * (T - t) ** 2,
                                                     0.5 * a * ta * ta + v * (t - ta)))
    return math.copysign(1.0, dz) * np.clip(s, 0.0, abs(dz))


def accel_dwell(block: Any, z: float, a_max: float) -> tuple[Any, Any]:
    """A plunge's or retract's Z moves (``block.z_moves``, each at its programmed speed
    ``|dZ| / seconds``) within the Z acceleration: each from rest to rest at most at its speed
    and at ``a_max`` (its time grows by ``v / a_max``, or to ``2 sqrt(|dZ| / a_max)`` for a
    short one). The block with those times and its Z as a function of the time from its start
    [s] -> [m]; the block as it is and None where it moves no Z."""
    moves = list(block.z_moves)
    z0 = block.z_start_m if block.z_start_m is not None else z
    if not moves or all(abs(m[1] - (moves[k - 1][1] if k else z0)) == 0.0 for k, m in enumerate(moves)):
        return block, None
    pieces: list[tuple[float, float, float, float, float]] = []  # start time, z0, dz, top speed, duration
    new_moves: list[tuple[float, float, int]] = []
    t, zs = 0.0, float(z0)
    for secs, z_end, line in moves:
        dz = float(z_end) - zs
        if dz != 0.0 and secs > 0:
            T, v = _trapezoid(dz, abs(dz) / secs, a_max)
        else:
            T, v = float(secs), 0.0
        pieces.append((t, zs, dz, v, T))
        new_moves.append((T, float(z_end), line))
        t, zs = t + T, float(z_end)
    out = block.model_copy(update={"z_moves": new_moves, "duration_s": t})

    def z_at(times: np.ndarray) -> np.ndarray:
        times = np.asarray(times, float)
        zz = np.full(len(times), float(z0))
        for t0, zs0, dz, v, T in pieces:
            on = times >= t0
            if dz != 0.0 and v > 0:
                zz[on] = zs0 + _trapezoid_at(times[on] - t0, dz, a_max, v, T)
            else:
                zz[on] = zs0 + dz
        return zz

    return out, z_at


#: fastest: a pass's pieces end where Z lets the tool pass a slope change no faster than this [m/s]
#: (:func:`slope_stops`)
SLOPE_STOP_M_S = 0.05


def slope_stops(feed: str, els: list[PathElement], tol: float, a_max: float) -> list[int]:
    """``fastest``: the moves of a pass after which its pieces end (:func:`planner.contour.passes.chunks`,
    each piece planned rest to rest) because Z's slope changes there so sharply that Z lets the
    tool pass no faster than :data:`SLOPE_STOP_M_S` (the blend's speed within the tolerance at
    the Z acceleration ``a_max``, :func:`planner.contour.zaxis.blend_speed`; a ramp's start and
    end). Its own timing per piece (a ramp's within the Z axis, the level cut's at the drives')
    instead of one scale and Z caps over the whole pass; the exact path stops there as well (with
    a Z acceleration limit Z's velocity, slope times speed, is continuous). Measured on
    fusion360's first pass (ramps of slope 1 in and out, a blend of 4.9 mm/s): 0.711 s as one
    piece (its first timing missed Z by 0.10 mm and was planned again slower), 0.405 s in three.
    A gentle slope change is passed: freecad's helix (slope 0.04) into its circle, a blend of
    0.18 m/s, took 0.344 s as two pieces, 0.292 s as one. Not in ``program`` feed (at F the blend
    is near F and a stop costs the pieces' ends)."""
    if feed != "fastest":
        return []
    g = slopes(els)
    return [k for k in range(len(els) - 1)
            if g[k] != g[k + 1] and blend_speed(abs(g[k + 1] - g[k]), tol, a_max) < SLOPE_STOP_M_S]
