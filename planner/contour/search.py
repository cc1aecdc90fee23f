"""The timing search of a contour piece (issue 22): sample counts per tube cell planned in the
constrained mode from rest to rest, the fastest feasible kept.

``program`` feed: the heuristic profile with its cell speed capped at each move's F, lowered
until the plan is feasible and no sample is faster than F (:meth:`TimingSearch.program_loop`).
``fastest``: two timings, the faster kept (the passes after the first use the first's, from
its scale, :class:`Scale`): the heuristic profile scaled (``v = lambda v0``, ``a = lambda^2 a0``,
:meth:`TimingSearch.heuristic`), and the exact path's time-optimal profile slowed by a scale
(:meth:`TimingSearch.optimal_search`); each to the largest feasible scale
(:func:`largest_feasible`; each candidate abandoned at its first step that needs slack); an arc
whose chord per sample is faster than the drives turn the tool on it is cut in cells of one
sample's travel at their speed (:meth:`TimingSearch.arc_cells`). Where
a feed's own search finds no timing the other's is tried (:func:`search_timing`); an
``infeasible`` verdict's advice is checked before it is given (:func:`confirmed_infeasible`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from ..errors import PlannerError
from ..model import RobotModel
from ..orchestrator import feasible, plan_timed
from ..schema import MAX_CONTOUR_TOLERANCE_M, MAX_TOTAL_STEPS, MIN_TS, ContourRequest, PathElement, PlanResult, Settings
from .defaults import bound_arcs, drive_jerk
from .estimate import ADVICE_MIN_S, ADVICE_WORK, FEED_MARGIN, piece_estimate
from .passes import CELL_SAMPLES, PROGRAM_MARGIN, V0_M_S, TubeSizes, piece_tube, segment_of
from .path import moves_at
from .profiles import (
    ARRIVAL_MAX,
    RUN_FIXES,
    Optimal,
    arrival_run,
    near_reversal,
    optimal_counts,
    profile_counts,
    rest_ends,
    run_samples,
    with_arrival,
)
from .tube import Tube
from .zaxis import slopes

__all__ = ["SCALE_MAX", "SCALE_MIN", "SCALE_RESOLUTION", "Found", "Scale", "TimingSearch", "confirmed_infeasible",
           "largest_feasible", "overspeed", "overspeed_of", "piece_key", "search_timing",
           "z_caps"]

#: fastest: the reference acceleration the scale's square multiplies [m/s^2] (the reference
#: cell speed: :data:`planner.contour.passes.V0_M_S`)
A0_M_S2 = 1.0
#: fastest: the reference jerk of the start and stop [m/s^3] (the scale's cube multiplies it)
J0_M_S3 = 50.0
#: program feed: the acceleration of the profile [m/s^2]
A_PROGRAM_M_S2 = 2.0
#: fastest: the scale is found to this relative resolution: ``lam`` feasible, ``lam (1 + r)`` not
SCALE_RESOLUTION = 1 / 64
#: fastest: the range of scales searched
SCALE_MIN, SCALE_MAX = 1 / 64, 64.0
#: program feed: the profile's scales tried (from PROGRAM_MARGIN down by 0.7 each)
PROGRAM_TRIES = 8
#: program feed, the time-optimal timing (:meth:`TimingSearch.within_feed`): rounds of more
#: samples for the segments faster than F, each raising their count by their excess and this
PROGRAM_FIXES = 3
#: program feed, the time-optimal timing's tube (:meth:`TimingSearch.program_optimal`): its
#: the tubes tried, and the margin's step beyond the excess measured (the cells' first margin
#: under a sample's travel at F: :data:`planner.contour.estimate.FEED_MARGIN`)
FEED_MARGIN_TRIES = 5
FEED_MARGIN_STEP = 0.005
#: the sides of the tool-speed rows' polygon (``planner.constraints.motion.TOOL_SPEED_SIDES``,
#: which ``tests/test_contour_rest.py`` checks this against)
FEED_ROWS_SIDES = 32
#: program feed, the time-optimal timing (:meth:`TimingSearch.program_optimal`): its candidates
#: are planned with the tool-speed rows (``settings.tool_speed_max_m_s``) at the piece's top F
#: times this, ``1 / cos(pi / sides)``: the rows' polygon lies inside the circle of their limit,
#: and this puts its sides' middles on F (the sides face the axes: a line along one is held at
#: F; in the vertex directions up to 0.48 % over, which :meth:`TimingSearch.lowered_rows`
#: answers), so the controller's catch-ups after a start or a corner and before the end run at
#: F instead of over it; where that is infeasible, without them. On arcs too (issue 35 goal 2,
#: branch feedcap6): the min-force criterion brakes onto a piece's end gently and makes up for
#: it by running ahead over F (dxf2gcode's circle 1.03 F for 25 samples), which the samples
#: added for it only made gentler; with a 16-gon's rows (1.9 % below the limit at the sides'
#: middles) a circle's cells at 0.995 F could not be held under rows at F, so arcs went without
#: rows then (and the rows stood at 1.015 F)
FEED_SPEED_ROOM = 1.0 / math.cos(math.pi / FEED_ROWS_SIDES)
#: program feed: a plan under the speed rows faster than F by at most this (the catch-ups in the
#: rows' polygon's vertex directions) is planned again with the rows lowered
#: by its excess (:meth:`TimingSearch.lowered_rows`), at most this many times, before samples are
#: added to its runs (a sample a run: 1.3 % of fusion360's 2 mm lines at 6 ms)
FEED_ROWS_LOWER_MAX = 1.03
FEED_ROWS_LOWER_TRIES = 3
FEED_ROWS_LOWER_STEP = 0.001
#: program feed: a segment's excess over F beyond this is a spike (more samples in its cells),
#: not a move's cells too long (shorter cells on the whole move)
FEED_SPIKE = 1.03
PROGRAM_FIX_MARGIN = 0.0
#: program feed: the time-optimal timing's scale, where 1 does not plan, to this resolution
PROGRAM_RESOLUTION = 1 / 128
#: an infeasible piece's advice, checked: the tolerance times this, then the sample time times this
ADVICE_TOLERANCE = 2.0
ADVICE_TS = 0.5
#: fastest, the time-optimal timing (:func:`search_timing`): its cells hold this many samples at
#: the profile's top speed (shorter cells keep the robot nearer the profile's progress, longer
#: ones lose fewer samples to cells shorter than a sample's travel)
OPT_CELL_SAMPLES = 1.5
#: the time-optimal timing's scale is found to this relative resolution (its profile is near
#: the drives' limits everywhere: the scale found is near 1, and a finer step is worth its plans)
OPT_RESOLUTION = 1 / 256
#: the samples a tube plan takes beyond the profile's time (the lead cells, the end point; the
#: start point took one more before it was held no sample, :func:`~planner.contour.profiles.start_free`):
#: the time-optimal timing is tried where its profile's time plus these beats the other
OPT_END_SAMPLES = 3
#: fastest, an arc the drives bound below a chord per sample (:meth:`TimingSearch.arc_cells`):
#: its cells' speed, a factor ``kappa`` of the drives' turn speed, found to this resolution
#: within [ARC_KAPPA_MIN, ARC_KAPPA_MAX]
ARC_RESOLUTION = 1 / 128
ARC_KAPPA_MIN, ARC_KAPPA_MAX = 0.8, 1.25


class Scale(NamedTuple):
    """``fastest``: the timing a cut found, where the next cut's search starts: its family
    (``optimal``: the time-optimal profile scaled in time by ``lam``; ``profile``: the
    heuristic profile, ``lam`` the whole of it, ``mu`` its speeds) and scales."""

    family: str
    lam: float
    mu: float = 1.0


class Found:
    """A timing search's outcome: the plan (None: none found), the ``fastest`` scales, and
    where the candidates stopped (the source line of the first step that needed slack, the
    latest of them)."""

    def __init__(self, Ts: float) -> None:
        self.Ts = Ts
        self.result: PlanResult | None = None
        self.tube: Tube | None = None  #: the tube of the result
        self.scale: Scale | None = None
        self.stop_line: int | None = None
        self.plans = 0
        #: the plan found before :meth:`TimingSearch.end_trimmed` shortened it (None: not shortened)
        self.untrimmed: PlanResult | None = None
        #: the search that found it (:meth:`TimingSearch.start_held` replans it)
        self.search: TimingSearch | None = None

    def failed(self, err: PlannerError, t: Tube, counts: np.ndarray, els_line: Callable[[int], int]) -> None:
        """Note where a candidate stopped (``at t = ... s`` in the controller's message)."""
        self.plans += 1
        try:
            ts = float(err.message.split("at t = ")[1].split(" s")[0])
        except (IndexError, ValueError):
            return
        k = int(round(ts / self.Ts))
        self.stop_line = els_line(int(moves_at(t, counts, k + 1)[-1] if k > 0 else t.element[0]))


class TimingSearch:
    """The candidate timings of one piece, each planned in its tube (the closures of the search
    before issue 34, as methods): ``tube_at(v)``, the piece's tube with cells sized for the
    profile speed ``v`` (:class:`~planner.contour.passes.TubeSizes`); ``optimal``, its
    time-optimal profile for a tube (:class:`~planner.contour.profiles.OptimalProfiles`);
    ``deadline`` (``time.process_time``): candidates after it are not planned. ``found``
    collects where the failed candidates stopped."""

    def __init__(self, model: RobotModel, st: Settings, tube_at: Callable[[float], Tube], chunk: list[int],
                 els: list[PathElement], deadline: float | None, optimal: Callable[[Tube], Optimal] | None,
                 z_max_m_s: float | None = None, cell_caps: Callable[[Tube], np.ndarray] | None = None) -> None:
        self.model, self.st, self.tube_at, self.chunk, self.els = model, st, tube_at, chunk, els
        self.deadline, self.optimal = deadline, optimal
        self.feed = np.array([e.feed_m_s for e in els])
        self.zcap = z_caps(els, z_max_m_s)  # the XY speed that keeps each move's Z within the axis speed
        self.cell_caps = cell_caps  # per tube segment: the Z axis acceleration's (planner.contour.zaxis.ZCaps)
        self.z_capped = bool(np.isfinite(self.zcap).any())
        self.name = f"line {els[0].line}"
        self.found = Found(st.Ts)
        self.lines = dict(zip(chunk, (e.line for e in els)))
        self.run_counts = np.zeros(0, np.int64)  #: the counts :meth:`within_runs` found
        self.plan_st = st  #: the settings the candidates are planned with (:meth:`program_optimal`'s speed rows)
        #: program feed: the drives' jerk under the force-rate limit [m/s^3] (None: no limit), for
        #: the profile's steps from and to rest (:func:`~planner.contour.profiles.rest_ends`)
        self.jerk = drive_jerk(model, st)
        self.arc_tubes: dict[tuple[int, float], Tube] = {}  #: :meth:`arc_tube`'s, by size and kappa
        self.start_force: np.ndarray | None = None  #: the forces held before a candidate's first sample [N]
        #: the samples the start point is held (None: :data:`~planner.contour.profiles.START_POINT_SAMPLES`)
        self.start: int | None = None

    def feed_on(self, t: Tube) -> np.ndarray:
        """The programmed F [m/s] of the move each of the tube's segments belongs to."""
        return self.feed[np.searchsorted(self.chunk, t.element)]

    def zcap_on(self, t: Tube) -> np.ndarray:
        """The Z speed's bound on the XY speed [m/s] of each of the tube's segments (inf where
        its move keeps Z)."""
        return self.zcap[np.searchsorted(self.chunk, t.element)]

    def shape_on(self, t: Tube) -> np.ndarray:
        """:meth:`zcap_on` and, where given, the ``cell_caps``: the bound the profiles' speed
        keeps (not a check of the samples: the caller checks what they bound)."""
        out = self.zcap_on(t)
        return out if self.cell_caps is None else np.minimum(out, self.cell_caps(t))

    def attempt(self, t: Tube, counts: np.ndarray) -> PlanResult | None:
        """One candidate: the tube planned with these sample counts per segment
        (:func:`planner.orchestrator.plan_timed`); None where it is infeasible, does not settle
        or comes after the deadline (noted in :attr:`found`)."""
        if self.deadline is not None and time.process_time() > self.deadline:
            return None
        check_counts(counts, self.els[0].line)
        try:
            res = plan_timed(self.name, self.model, self.plan_st, t.segments, counts.tolist(),
                             start_force=self.start_force)
        except PlannerError as err:
            if err.code not in ("infeasible", "not_settled"):
                raise
            self.found.failed(err, t, counts, self.lines.__getitem__)
            return None
        self.found.plans += 1
        return res if feasible(res) else None

    def program_loop(self) -> tuple[PlanResult, Tube] | None:
        """The ``program`` feed's timing: the heuristic profile with the cell speed at the
        programmed F times a scale (from :data:`PROGRAM_MARGIN`, the cells sized for it),
        the scale lowered by 0.7 after an infeasible plan and to 0.95 F over the fastest sample
        after one that exceeds F, at most :data:`PROGRAM_TRIES` times."""
        scale = PROGRAM_MARGIN
        for _ in range(PROGRAM_TRIES):
            t = self.tube_at(float(self.feed.max()) * scale)
            feed_of = self.feed_on(t)
            counts = profile_counts(t, feed_of * scale, A_PROGRAM_M_S2 * scale * scale, self.st.Ts,
                                    start=self.start)
            res = self.attempt(t, counts)
            if res is None:
                scale *= 0.7
                continue
            over = overspeed(res, t, counts, feed_of)
            if over <= 1.0:
                return res, t
            scale *= min(0.95 / max(over, 1e-9), 0.9)
        return None

    def scaled_run(self, t: Tube, v_cap: np.ndarray, capped: bool, feed_of: np.ndarray,
                   tried: dict[bytes, PlanResult | None], lam: float, mu: float = 1.0) -> PlanResult | None:
        """The heuristic profile at the scale ``lam`` (speeds ``lam mu v_cap``, acceleration
        ``lam^2 A0``, turn acceleration ``(lam mu)^2 A0``, jerk ``lam^3 J0``) planned in ``t``;
        ``capped``: None where a sample exceeds the programmed F. ``tried``: the plans by their
        sample counts (scales often give the same)."""
        v = v_cap * lam * mu
        if self.z_capped:  # a ramp's or helix's Z within the axis speed, whatever the scale
            v = np.minimum(v, self.shape_on(t))
        counts = profile_counts(t, v, A0_M_S2 * lam * lam, self.st.Ts, A0_M_S2 * (lam * mu) ** 2, J0_M_S3 * lam ** 3,
                                self.start)
        key = counts.tobytes()
        if key not in tried:
            res = self.attempt(t, counts)
            if res is not None and capped and overspeed(res, t, counts, feed_of) > 1.0:
                res = None
            tried[key] = res
        return tried[key]

    def scaled(self, t: Tube, v_cap: np.ndarray, capped: bool, lam0: float, mu0: float, high: float,
               limit: np.ndarray | None = None) -> tuple[PlanResult, tuple[float, float]] | None:
        """The heuristic profile's fastest feasible scales (:meth:`scaled_run`), searched from
        ``lam0``, ``mu0`` up to ``high``: 1. the whole profile (speeds, accelerations); 2. the
        speeds alone (cell speed and the curvature and corner limits), the accelerations between
        them as found: where the start and the stop bound the first scale, the path between them
        can go faster. The plan and ``(lam, mu)``; None: no scale is feasible. ``capped``: no
        sample faster than ``limit`` (per segment; the programmed F if not given)."""
        feed_of = self.feed_on(t) if limit is None else limit
        tried: dict[bytes, PlanResult | None] = {}

        def run(lam: float, mu: float = 1.0) -> PlanResult | None:
            return self.scaled_run(t, v_cap, capped, feed_of, tried, lam, mu)

        lam = largest_feasible(lambda x: run(x) is not None, lam0, high=high)
        if lam is None:
            return None
        mu = largest_feasible(lambda x: run(lam, x) is not None, max(mu0, 1.0), low=1.0, high=max(high / lam, 1.0))
        assert mu is not None  # mu = 1 is lam's plan
        best = run(lam, mu)
        assert best is not None
        return best, (lam, mu)

    def heuristic(self, h: Scale | None) -> tuple[PlanResult, Tube, Scale] | None:
        """``fastest``'s heuristic timing: the profile of the reference speed :data:`V0_M_S`
        (cells sized for it) scaled (:meth:`scaled`), from the hint's scales if it is one of
        this family's."""
        h = h if h is not None and h.family == "profile" else None  # the other family's scale means nothing here
        t = self.tube_at(V0_M_S)
        got = self.scaled(t, np.full(len(t.segments), V0_M_S), self.z_capped, h.lam if h else 1.0,
                          h.mu if h else 1.0, SCALE_MAX, self.zcap_on(t))
        arc_t = self.arc_tube(V0_M_S, 1.0)
        if arc_t is not None:  # the arcs the drives bound in cells of one sample at their speed
            v0 = np.full(len(arc_t.segments), V0_M_S)
            got_a = self.scaled(arc_t, v0, self.z_capped, h.lam if h else 1.0, h.mu if h else 1.0, SCALE_MAX,
                                self.zcap_on(arc_t))
            if got_a is not None:  # the speeds' scale's search stops where cells of one sample and two
                lam = got_a[1][0]  # alternate: the cells' own speed (the speeds' top scale) tried too
                top = self.scaled_run(arc_t, v0, self.z_capped, self.zcap_on(arc_t), {}, lam, SCALE_MAX / lam)
                if top is not None and top.time[-1] < got_a[0].time[-1]:
                    got_a = (top, (lam, SCALE_MAX / lam))
            if got_a is not None and (got is None or got_a[0].time[-1] < got[0].time[-1]):
                got, t = got_a, arc_t
                lam, mu = got[1]
                faster = self.arc_cells(V0_M_S, got[0], lambda u: self.scaled_run(
                    u, np.full(len(u.segments), V0_M_S), self.z_capped, self.zcap_on(u), {}, lam, mu))
                if faster is not None:
                    got, t = (faster[0], got[1]), faster[1]
        return (got[0], t, Scale("profile", *got[1])) if got is not None else None

    def optimal_run(self, t: Tube, times: np.ndarray, tried: dict[bytes, PlanResult | None],
                    lam: float) -> PlanResult | None:
        """The time-optimal profile's ``times`` scaled in time by ``1 / lam`` planned in ``t``
        (``tried``: the plans by their sample counts)."""
        counts = optimal_counts(t, times, lam * self.st.Ts, self.start)
        key = counts.tobytes()
        if key not in tried:
            res = self.attempt(t, counts)
            if res is not None and self.z_capped and overspeed(res, t, counts, self.zcap_on(t)) > 1.0:
                res = None  # a ramp's Z faster than the axis
            tried[key] = res
        return tried[key]

    def optimal_search(self, h: Scale | None, beat: float | None = None) -> tuple[PlanResult, Tube, Scale] | None:
        """The time-optimal profile's timing (:class:`~planner.contour.profiles.OptimalProfiles`)
        scaled in time by ``1 / lam`` (speeds ``lam``, accelerations ``lam^2``), the largest
        feasible ``lam``. ``beat``: the time of a timing found already [s]: first the one scale
        at which this one would be as fast (the profile's time over it, a few samples for the
        ends); not feasible there, none slower can win (one plan to know it); else the search
        starts at the profile itself."""
        optimal = self.optimal
        assert optimal is not None
        ref = optimal(self.tube_at(V0_M_S))
        t = self.tube_at(OPT_CELL_SAMPLES * ref.v_peak / CELL_SAMPLES)
        times = optimal(t).times
        if not (np.all(np.isfinite(times)) and times[-1] > 0):  # pragma: no cover - a profile that never moves
            return None
        tried: dict[bytes, PlanResult | None] = {}

        def run(lam: float) -> PlanResult | None:
            return self.optimal_run(t, times, tried, lam)

        # where the Z axis acceleration shapes the profile (its speed along a slope rises at a_z / |g|),
        # the profile holds it at the scale 1 and a faster one breaks it (accelerations lam^2): at most 1
        high = 1.0 if self.cell_caps is not None else SCALE_MAX
        lam0, low = min(h.lam if h else 1.0, high), SCALE_MIN
        if beat is not None:
            room = beat - OPT_END_SAMPLES * self.st.Ts
            if room <= 0:
                return None
            low = min(max(float(times[-1]) / room, SCALE_MIN), high)
            if run(low) is None:
                return None
            lam0 = min(max(low, 1.0), high)
        lam = largest_feasible(lambda x: run(x) is not None, lam0, OPT_RESOLUTION, low=low, high=high)
        if lam is None:
            return None
        best = run(lam)
        assert best is not None
        if beat is not None and best.time[-1] >= beat:
            return None
        return best, t, Scale("optimal", lam)

    def arc_speeds(self) -> np.ndarray:
        """Per element of the piece: :func:`~planner.contour.defaults.bound_arcs` (the drives'
        turn speed on the arcs whose chord per sample is faster; 0 elsewhere) [m/s]."""
        sizes = self.tube_at
        if not isinstance(sizes, TubeSizes):
            return np.zeros(len(self.els))
        return bound_arcs(self.els, sizes.tol, self.model, self.st)

    def arc_tube(self, v_cells: float, kappa: float) -> Tube | None:
        """The piece's tube with cells sized for the speed ``v_cells`` (as ``tube_at``) and the
        arcs of :meth:`arc_speeds` cut in cells of one sample's travel at ``kappa`` times their
        speed (:func:`~planner.contour.tube.sample_split`); None where no arc is so bound."""
        v = self.arc_speeds()
        sizes = self.tube_at
        if not v.any() or not isinstance(sizes, TubeSizes):
            return None
        piece_max = max(v_cells * self.st.Ts * CELL_SAMPLES, 4 * sizes.tol)
        key = (round(math.log(piece_max) * 8), round(kappa, 9))
        if key not in self.arc_tubes:
            self.arc_tubes[key] = piece_tube(sizes.model, sizes.chunk, sizes.els, sizes.origin, sizes.tol, sizes.psi,
                                             sizes.pos, sizes.elements, piece_max, kappa * v * self.st.Ts)
        return self.arc_tubes[key]

    def arc_cells(self, v_cells: float, best: PlanResult,
                  plan: Callable[[Tube], PlanResult | None]) -> tuple[PlanResult, Tube] | None:
        """``fastest`` where the drives bound an arc below one chord per sample (:meth:`arc_speeds`;
        ``best``: the plan found in the tube of ``kappa`` 1, :meth:`heuristic`'s): the arc's cells
        re-cut to one sample's travel at ``kappa`` times the drives' turn speed each
        (:meth:`arc_tube`, ``v_cells`` the size of the other cells), each planned by ``plan``
        (the heuristic profile at the scales found), ``kappa`` the largest feasible within
        [:data:`ARC_KAPPA_MIN`, :data:`ARC_KAPPA_MAX`] (:data:`ARC_RESOLUTION`). On the chords of
        the sagitta a cell holds one sample or two, so the tool turns at ``chord / Ts`` or half of
        it, whichever the drives allow (issue 35 goal 1: dxf2gcode's circle at 1.093x the
        third-order optimum). The plan and its tube where faster than ``best``; else None."""
        if not self.arc_speeds().any():
            return None
        made: dict[float, tuple[Tube, PlanResult | None]] = {}

        def run(kappa: float) -> PlanResult | None:
            key = round(kappa, 9)
            if key not in made:
                t = self.arc_tube(v_cells, kappa)
                assert t is not None
                made[key] = (t, plan(t))
            return made[key][1]

        kappa = largest_feasible(lambda x: run(x) is not None, 1.0, ARC_RESOLUTION, low=ARC_KAPPA_MIN,
                                 high=ARC_KAPPA_MAX)
        if kappa is None:
            return None
        t, res = made[round(kappa, 9)]
        if res is None or res.time[-1] >= best.time[-1]:
            return None
        return res, t

    def feed_counts(self, t: Tube, counts: np.ndarray) -> np.ndarray:
        """``counts`` raised where a cell would be crossed faster than its move's F on average:
        at least its length over F Ts samples (the profile's rounding to whole samples would
        give a cell of 2.6 samples' travel 2 samples, 30 % over F); the lead cells stay one."""
        seconds = getattr(self.cell_caps, "seconds", None)
        if seconds is None:
            need = np.ceil(t.length / (np.minimum(self.feed_on(t), self.shape_on(t)) * self.st.Ts) - 1e-9)
        else:  # the Z axis acceleration's bound rises away from a slope change: its time across the cell
            at = t.length / np.minimum(self.feed_on(t), self.zcap_on(t))
            need = np.ceil(np.maximum(at, seconds(t)) / self.st.Ts - 1e-9)
        out = np.maximum(counts, need.astype(np.int64))
        out[t.lead] = counts[t.lead]
        return out

    def within_feed(self, t: Tube, counts: np.ndarray, feed_of: np.ndarray) -> PlanResult | None:
        """``counts`` planned in ``t`` and kept where no sample nor straight move between samples
        is faster than ``feed_of`` (per segment, :func:`overspeed_of`); where some are, only
        their segments get more samples (their count times their excess), at most
        :data:`PROGRAM_FIXES` times. None: infeasible, or still faster than F."""
        for _ in range(PROGRAM_FIXES + 1):
            res = self.attempt(t, counts)
            if res is None:
                return None
            over = overspeed_of(res, counts, feed_of)
            bad = (over > 1.0) & ~t.lead
            if over.max() <= 1.0:
                return res
            if not bad.any():
                return None  # a lead cell (one sample) too fast: not a count to raise
            counts = counts.copy()
            counts[bad] = np.maximum(np.ceil(counts[bad] * over[bad] * (1 + PROGRAM_FIX_MARGIN)), counts[bad] + 1)
        return None

    def within_runs(self, t: Tube, counts: np.ndarray, over: np.ndarray) -> PlanResult | None:
        """``counts`` (whose plan ran faster than F by ``over`` per segment) with samples added
        to its runs faster than F (:func:`~planner.contour.profiles.run_samples`), planned
        again, at most :data:`~planner.contour.profiles.RUN_FIXES` times; the plan where none
        is faster than F, else None."""
        feed_of = np.minimum(self.feed_on(t), self.zcap_on(t))
        avoid = near_reversal(t.turn)
        for _ in range(RUN_FIXES):
            add = run_samples(over, counts, t.lead, avoid)
            if not add.any():  # the excess is near a reversal only: the cells' margin instead
                return None
            counts = counts + add
            res = self.attempt(t, counts)
            if res is None:
                return None
            over = overspeed_of(res, counts, feed_of)
            if over.max() <= 1.0:
                self.run_counts = counts
                return res
        return None

    def lowered_rows(self, t: Tube, counts: np.ndarray, over: float) -> PlanResult | None:
        """``counts`` planned again with the tool-speed rows lowered by the plan's excess over F
        (``over``, at most :data:`FEED_ROWS_LOWER_MAX`) and a little more, at most
        :data:`FEED_ROWS_LOWER_TRIES` times: the plan where no sample is faster than F (the rows
        kept in :attr:`plan_st`), else None (the rows as they were)."""
        before = self.plan_st
        feed_of = np.minimum(self.feed_on(t), self.zcap_on(t))
        limit = before.tool_speed_max_m_s
        assert limit is not None
        for _ in range(FEED_ROWS_LOWER_TRIES):
            limit = limit / (over * (1 + FEED_ROWS_LOWER_STEP))
            self.plan_st = before.model_copy(update={"tool_speed_max_m_s": limit})
            res = self.attempt(t, counts)
            if res is None:
                break
            over = float(overspeed_of(res, counts, feed_of).max())
            if over <= 1.0:
                return res
            if over > FEED_ROWS_LOWER_MAX:
                break
        self.plan_st = before
        return None

    def rest_times(self, t: Tube, opt: Optimal) -> np.ndarray:
        """The profile's times for the ``program`` feed's counts: with its steps from and to rest
        as the drives take them (:func:`~planner.contour.profiles.rest_ends`) where that gives the
        tube fewer samples in all, else as the profile has them (shifted, a junction's rounding
        can cost the sample the ends gave: the benchmark part's passes, 470 against 469)."""
        fast = rest_ends(opt, self.jerk)
        if fast is opt.times:
            return fast
        n_fast = int(self.feed_counts(t, optimal_counts(t, fast, self.st.Ts, self.start)).sum())
        n = int(self.feed_counts(t, optimal_counts(t, opt.times, self.st.Ts, self.start)).sum())
        return fast if n_fast < n else opt.times

    def program_optimal(self) -> tuple[PlanResult, Tube] | None:
        """The ``program`` feed's timing: the exact path's time-optimal profile with each move's
        speed capped at its own F (``optimal``, built capped: :func:`~planner.contour.plan.plan_cut`),
        in cells of a whole number of samples at each move's F shortened by a margin
        (:meth:`~planner.contour.passes.TubeSizes.at_feed`), from :data:`FEED_MARGIN`, raised
        by the excess on the moves where a plan runs faster than F (at most
        :data:`FEED_MARGIN_TRIES` tubes);
        then at the scale 1 where that plans within F (:meth:`within_feed`: a segment faster
        than F gets more samples, not the whole pass), else the largest feasible slower scale."""
        optimal = self.optimal
        at_feed = getattr(self.tube_at, "at_feed", None)
        if optimal is None or at_feed is None:
            return None
        # the margins a pass of the same moves found (depth passes: one plan each after the first)
        memo, geo = getattr(optimal, "memo", None), getattr(optimal, "geo", None)
        key = ("feed margin", geo, self.st.Ts)
        first = np.full(len(self.els), FEED_MARGIN)
        margin, arrive, known, rows, limit = memo.get(key, (first, 0, None, True, None)) \
            if memo is not None and geo else (first, 0, None, True, None)
        # the tool-speed rows at the piece's top F (a little over it: the rows' polygon lies inside
        # the circle), unless the request sets its own: the controller's catch-ups then run at F
        rows = rows and self.st.tool_speed_max_m_s is None
        speed_st = self.st.model_copy(update={"tool_speed_max_m_s": float(self.feed.max()) * FEED_SPEED_ROOM
                                              if limit is None else limit})
        self.plan_st = speed_st if rows else self.st
        t: Tube | None = None
        counts = np.zeros(0, np.int64)
        for _ in range(FEED_MARGIN_TRIES):
            try:
                cur: Tube = at_feed(margin)
            except PlannerError as err:  # too many cells at that size: the heuristic profile's coarser ones
                if err.code != "too_large":
                    raise
                return None
            t = cur
            times = self.rest_times(cur, optimal(cur))
            if not (np.all(np.isfinite(times)) and times[-1] > 0):  # pragma: no cover - a profile that never moves
                return None
            counts = with_arrival(cur, self.feed_counts(cur, optimal_counts(cur, times, self.st.Ts, self.start)),
                                  arrive)
            if known is not None and len(known) == len(counts):  # a pass of the same moves' run samples
                counts, known = known, None
            res = self.attempt(cur, counts)
            if res is None and self.plan_st is speed_st:  # infeasible under the speed rows: without them
                self.plan_st, rows = self.st, False
                res = self.attempt(cur, counts)
            if res is None:
                break
            over_seg = overspeed_of(res, counts, np.minimum(self.feed_on(cur), self.zcap_on(cur)))
            if over_seg.max() <= 1.0:
                if memo is not None and geo:
                    memo[key] = (margin, arrive, counts, rows, self.plan_st.tool_speed_max_m_s if rows else None)
                return res, cur
            if self.plan_st is not self.st and over_seg.max() <= FEED_ROWS_LOWER_MAX:
                # a small excess under the speed rows (the catch-ups in the 16-gon's vertex
                # directions): the rows lowered by it, not a sample more per run
                lowered = self.lowered_rows(cur, counts, float(over_seg.max()))
                if lowered is not None:
                    if memo is not None and geo:
                        memo[key] = (margin, arrive, counts, rows, self.plan_st.tool_speed_max_m_s)
                    return lowered, cur
            got = self.within_runs(cur, counts, over_seg)  # the catch-ups: a sample more in each run
            if got is not None:
                if memo is not None and geo:
                    memo[key] = (margin, arrive, self.run_counts, rows,
                                 self.plan_st.tool_speed_max_m_s if rows else None)
                return got, cur
            # the catch-up before the end, where it is the only excess: a sample more there, not
            # shorter cells on the whole move (where there are others, shorter cells first)
            loc = np.searchsorted(self.chunk, cur.element)
            tail = arrival_run(over_seg, counts, loc)
            bumped = bool(tail.any()) and arrive < ARRIVAL_MAX and not (over_seg[~tail] > 1.0).any()
            if bumped:
                arrive += 1
                over_seg = np.where(tail, 0.0, over_seg)
            # a move whose cells run a little faster than F throughout: shorter cells (at least one
            # more); a spike (the robot speeding up into a faster move ahead of its first cell):
            # more samples in those cells only (below)
            loc = np.searchsorted(self.chunk, cur.element)
            over = np.zeros(len(self.els))  # per move, its cells' largest excess short of a spike
            np.maximum.at(over, loc, np.where(over_seg <= FEED_SPIKE, over_seg, 0.0))
            if not (over > 1.0).any():
                if bumped:
                    continue
                break
            cells = np.bincount(loc[cur.length > 0], minlength=len(self.els)).clip(1)
            raised = np.maximum((1 + margin) * over * (1 + FEED_MARGIN_STEP), (1 + margin) * (cells + 1) / cells)
            margin = np.where(over > 1.0, raised * (1 + 1e-6) - 1, margin)
        assert t is not None
        if len(counts) == len(t.segments):  # the spikes: more samples where the samples run faster than F
            got = self.within_feed(t, counts, np.minimum(self.feed_on(t), self.zcap_on(t)))
            if got is not None:
                return got, t
        assert t is not None
        times = self.rest_times(t, optimal(t))
        feed_of = np.minimum(self.feed_on(t), self.zcap_on(t))
        tried: dict[bytes, PlanResult | None] = {}

        def run(lam: float) -> PlanResult | None:
            counts = with_arrival(t, self.feed_counts(t, optimal_counts(t, times, lam * self.st.Ts, self.start)),
                                  arrive)
            key = counts.tobytes()
            if key not in tried:
                tried[key] = self.within_feed(t, counts, feed_of)
            return tried[key]

        lam = largest_feasible(lambda x: run(x) is not None, 1.0, PROGRAM_RESOLUTION, low=SCALE_MIN, high=1.0)
        if lam is None:
            return None
        best = run(lam)
        assert best is not None
        return best, t

    def program_feed(self) -> tuple[PlanResult, Tube] | None:
        """The ``program`` feed's search: :meth:`program_optimal`, else :meth:`program_loop`,
        else the ``fastest`` heuristic profile capped by F (cells sized for half of it), kept
        where no sample exceeds F."""
        got_p = self.program_optimal()
        if got_p is None:
            got_p = self.program_loop()
        if got_p is None:  # the fastest profile under F
            t = self.tube_at(float(self.feed.max()) * 0.5)
            got = self.scaled(t, self.feed_on(t) * PROGRAM_MARGIN, True, 0.5, 1.0, 1.0)
            got_p = (got[0], t) if got is not None else None
        return got_p

    def replanned(self, res: PlanResult, t: Tube, counts: np.ndarray) -> PlanResult | None:
        """``counts`` planned in ``t`` under the speed rows ``res`` (a plan found) was planned
        with; None where infeasible."""
        kept, self.plan_st = self.plan_st, self.plan_st.model_copy(
            update={"tool_speed_max_m_s": res.settings.tool_speed_max_m_s})
        try:
            return self.attempt(t, counts)
        finally:
            self.plan_st = kept

    def end_trimmed(self, res: PlanResult, t: Tube, limit: np.ndarray | None) -> PlanResult:
        """``res`` (the timing found in ``t``) planned once more with the end point held no
        sample beyond the end's lead cell, kept where that is feasible, shorter and (``limit``:
        per segment the speed no sample may exceed, the programmed F in ``program`` feed, the Z
        axis speed's bound) within ``limit``. The range sequence pins the lead cell's one sample
        onto the end point already (:mod:`planner.contour.tube`), and the end point's own sample
        pinned a second one there, after which the robot may settle: where it had settled at
        the first, a sample lost at every piece's end (issue 35: pcb_gcode's circle in
        ``program`` feed arrives within 4 um of the end at 0.69 mm/s, settled, a sample before
        its plan ended). Tried only where ``res`` had settled at the lead cell's sample (where
        the robot needs the end point's sample to arrive at rest, the tightest ``fastest``
        timings, the arrival rows at the sequence's last sample would not let it: one plan spent
        for nothing on each of the bench part's 15 passes)."""
        counts = np.asarray(res.settings.segment_samples, np.int64).copy()
        if len(counts) != len(t.segments) or counts[-1] != 1 or not t.segments[-1].is_point:
            return res
        k = int(counts[:-1].sum())  # the lead cell's sample
        if k >= len(res.time) or not (
                float(np.hypot(*(res.pose[k, :2] - t.segments[-1].centre[:2]))) < self.st.settle_position_m
                and float(np.hypot(*res.velocity[k, :2])) < self.st.settle_speed_m_s):
            return res
        counts[-1] = 0
        got = self.replanned(res, t, counts)
        if got is None or len(got.time) >= len(res.time):
            return res
        if limit is not None and overspeed(got, t, counts, limit) > 1.0:
            return res
        return got

    def remember_trim(self, before: PlanResult, after: PlanResult) -> None:
        """A pass of the same moves (depth passes) plans ``after``'s counts (the end trimmed,
        :meth:`end_trimmed`) at once where :meth:`program_optimal` kept ``before``'s for it: one
        plan a pass, not two (the bench part in ``program`` feed: 31 plans for 16, 4.1 -> 5.8
        CPU s, without it)."""
        memo, geo = getattr(self.optimal, "memo", None), getattr(self.optimal, "geo", None)
        key = ("feed margin", geo, self.st.Ts)
        if memo is None or not geo or key not in memo:
            return
        margin, arrive, known, rows, limit = memo[key]
        if known is not None and np.array_equal(known, np.asarray(before.settings.segment_samples, np.int64)):
            memo[key] = (margin, arrive, np.asarray(after.settings.segment_samples, np.int64), rows, limit)

    def start_held(self, res: PlanResult, t: Tube) -> PlanResult | None:
        """``res`` (the timing found in ``t``) planned again with its start point held one
        sample, the timing after it as it was (as every piece was planned before
        :func:`~planner.contour.profiles.start_free`): where the Z axis missed, it starts from
        rest a sample before the tool leaves (:func:`planner.contour.plan.plan_cut`). None
        where that is infeasible or the start point was held already."""
        counts = np.asarray(res.settings.segment_samples, np.int64).copy()
        if len(counts) != len(t.segments) or counts[0] != 0:
            return None
        counts[0] = 1
        return self.replanned(res, t, counts)

    def fastest(self, hint: Scale | None) -> tuple[PlanResult, Tube, Scale] | None:
        """The ``fastest`` feed's search: without a ``hint`` (or without the time-optimal
        profile) the heuristic timing, then the time-optimal one where it can beat it; with the
        first pass's ``hint``, its family first and the other where that finds none."""
        best: tuple[PlanResult, Tube, Scale] | None = None
        if self.arc_speeds().any():  # arcs the drives bound (:meth:`arc_cells`): both families, afresh
            hint = None
        if hint is None or self.optimal is None:  # the heuristic first, then the time-optimal one if it can beat it
            best = self.heuristic(hint)
            if self.optimal is not None:
                best = self.optimal_search(None, best[0].time[-1] if best is not None else None) or best
        elif hint.family == "optimal":  # the first pass's timing; the other where it finds none
            best = self.optimal_search(hint) or self.heuristic(None)
        else:
            best = self.heuristic(hint) or self.optimal_search(None)
        return best


def search_timing(feed_mode: str, model: RobotModel, st: Settings, tube_at: Callable[[float], Tube], chunk: list[int],
                  els: list[PathElement], hint: Scale | None, deadline: float | None = None,
                  optimal: Callable[[Tube], Optimal] | None = None, z_max_m_s: float | None = None,
                  cell_caps: Callable[[Tube], np.ndarray] | None = None,
                  start_force: np.ndarray | None = None, start_samples: int | None = None,
                  trim_end: bool = True) -> Found:
    """A timing of the piece for the feed mode, in the tube ``tube_at(v)`` with cells sized for
    the profile's speed ``v`` (``program``: the programmed F times the profile's scale, so that
    a slower profile has shorter cells: the criterion pulls the robot toward each cell's
    centre, and a cell of many samples let it run ahead of the profile, faster than F, at
    every scale; ``fastest``: :data:`V0_M_S` for the heuristic profile, the time-optimal
    profile's top speed for its timing ``optimal``; without a ``hint`` the heuristic one, then
    the time-optimal one where it can be faster, else the hint's first). If the mode's own
    search finds none, the other mode's (a timing under the programmed F is one ``fastest`` may
    use; ``program`` retries the ``fastest`` profile capped by F, kept where no sample exceeds
    F). ``deadline`` (``time.process_time``: compute time, as
    :func:`~planner.contour.estimate.estimate_contour` counts it): candidates after it are not
    planned. ``z_max_m_s``: the Z axis speed, which bounds the XY speed along a move whose Z
    changes (:func:`z_caps`), in both feeds (the program feed's F is capped by it already:
    :func:`planner.exchange._tabs.cap_z_speed`); ``cell_caps``: per segment of a tube a further
    bound on the XY speed [m/s] (the Z axis acceleration's, :class:`planner.contour.zaxis.ZCaps`).
    ``start_force``: the drive forces the part before left [N], every candidate planned from them
    (:func:`planner.orchestrator.plan_timed`; None: from zero, the robot at rest).
    ``start_samples``: the samples the start point is held (None: none beyond sample 0,
    :func:`~planner.contour.profiles.start_free`); ``trim_end``: the plan found tried once more
    without the end point's own sample (:meth:`TimingSearch.end_trimmed`; ``found.untrimmed``
    the plan before, where it is shorter)."""
    search = TimingSearch(model, st, tube_at, chunk, els, deadline, optimal, z_max_m_s, cell_caps)
    search.start_force = start_force
    search.start = start_samples
    found = search.found
    found.search = search
    capped = feed_mode == "program"
    if feed_mode == "program":
        got_p = search.program_feed()
        if got_p is not None:
            found.result, found.tube = got_p
    else:
        best = search.fastest(hint)
        if best is not None:
            found.result, found.tube, found.scale = best
        else:  # a timing under the programmed F
            got_p = search.program_loop()
            if got_p is not None:
                found.result, found.tube = got_p
                capped = True
    if trim_end and found.result is not None and found.tube is not None:
        t = found.tube
        limit = np.minimum(search.feed_on(t), search.zcap_on(t)) if capped else \
            search.zcap_on(t) if search.z_capped else None
        trimmed = search.end_trimmed(found.result, t, limit)
        if trimmed is not found.result:
            found.untrimmed, found.result = found.result, trimmed
            if feed_mode == "program":
                search.remember_trim(found.untrimmed, trimmed)
    return found


def confirmed_infeasible(req: ContourRequest, model: RobotModel, st: Settings, chunk: list[int],
                         els: list[PathElement], origin: np.ndarray, tol: float, psi: float, pos: np.ndarray,
                         elements: list[PathElement], found: Found, hint: Scale | None, passes: int,
                         limit_at: float | None = None) -> PlannerError:
    """The ``infeasible`` error of a piece no timing plans, its advice checked (issue 22, as
    :func:`planner.orchestrator.plan._more_time_advice` does for plans): the piece planned
    again, by the same search, at :data:`ADVICE_TOLERANCE` times the tolerance, then at
    :data:`ADVICE_TS` times the sample time; the first that plans is named ("tolerance_m
    0.02 plans, checked"), else the error says neither helps and where the plans stop.
    Bounded: the checks together take at most :data:`ADVICE_WORK` times the piece's own
    estimate, at least :data:`ADVICE_MIN_S` (the bound :func:`~planner.contour.estimate.estimate_contour`
    names), and end at ``limit_at`` (``time.process_time``: the caller's work limit); a
    candidate not planned within that is said so."""
    line = els[0].line
    where = f"line {found.stop_line}" if found.stop_line is not None else f"line {line}"
    head = (f"line {line}: no timing keeps the tool within {tol * 1e3:g} mm of the path within the drive limits "
            f"at a sample time of {st.Ts:g} s (the plans stop at {where})")
    budget = max(ADVICE_WORK * piece_estimate(req.feed, els, st.Ts, passes, tol), ADVICE_MIN_S)
    deadline = time.process_time() + budget
    if limit_at is not None:  # what the caller's work limit leaves
        deadline = min(deadline, limit_at)
        budget = max(deadline - time.process_time(), 0.0)
    candidates: list[tuple[str, float, float]] = []
    if tol * ADVICE_TOLERANCE <= MAX_CONTOUR_TOLERANCE_M:
        candidates.append((f"tolerance_m {tol * ADVICE_TOLERANCE:g} ({tol * ADVICE_TOLERANCE * 1e3:g} mm)",
                           tol * ADVICE_TOLERANCE, st.Ts))
    if st.Ts * ADVICE_TS >= MIN_TS:
        candidates.append((f"settings.Ts {st.Ts * ADVICE_TS:g} s", tol, st.Ts * ADVICE_TS))
    tried: list[str] = []
    for what, tol2, Ts2 in candidates:
        if time.process_time() > deadline:
            break
        st2 = st.model_copy(update={"Ts": Ts2})
        try:
            tubes = TubeSizes(model, st2, chunk, els, origin, tol2, psi, pos, elements)
            got = search_timing(req.feed, model, st2, tubes, chunk, els, hint, deadline, z_max_m_s=req.z_rapid_m_s)
        except PlannerError:
            got = None
        if got is not None and got.result is not None:
            before = "".join(f"{w} does not plan; " for w in tried)
            return PlannerError("infeasible", f"{head}; {before}{what} plans, checked",
                                "tolerance_m" if tol2 != tol else "settings.Ts")
        if time.process_time() <= deadline:
            tried.append(what)
    not_tried = [w for w, _, _ in candidates if w not in tried]
    if tried and not not_tried:
        return PlannerError("infeasible", f"{head}; neither {' nor '.join(tried)} plans either (checked): the "
                            f"path at {where} asks more of the drives than a tube of that width allows",
                            "tolerance_m")
    msg = f"{head}; {' and '.join(tried)} do not plan either (checked); " if tried else f"{head}; "
    return PlannerError("infeasible", msg + f"{' and '.join(not_tried)} not checked within the work bound "
                        f"({budget:.2g} s); give a larger tolerance_m or a smaller settings.Ts", "tolerance_m")


def piece_key(els: list[PathElement]) -> tuple[tuple, bool]:
    """A piece's shape (its moves' kinds, XY ends from the piece's start, sweeps and Z slopes, to
    1 nm: the same shape anywhere in the plane) and whether it is level (no move changes Z). The
    ``fastest`` scale a piece found is the next search's start (its ``hint``) for a piece of the
    same shape (depth passes, repeated features), else, for a level piece, the last level
    piece's (as before: 50 tiny passes of random shapes took 3.8 CPU s searched afresh each,
    2.2 s so); a piece with a slope has its own (the Z caps make its scale no guess for another,
    nor another's for it: measured on fusion360, the level middle of its first pass 0.252 s from
    the ramp's scale, 0.186 s searched afresh; its second pass 0.261 s from the ramp's, 0.195 s;
    a ramp from the level part's 0.345 s, 0.108 s afresh)."""
    o = np.asarray(els[0].start, float)
    g = slopes(els)
    key = tuple((e.kind, *np.round(np.asarray(e.start, float) - o, 9), *np.round(np.asarray(e.end, float) - o, 9),
                 round(e.sweep_rad or 0.0, 9), round(float(gk), 9)) for e, gk in zip(els, g))
    return key, not bool(np.any(g != 0.0))


def z_caps(els: list[PathElement], z_max_m_s: float | None) -> np.ndarray:
    """Per move, the XY speed [m/s] at which its Z moves at ``z_max_m_s`` (``z_max L / |dZ|``,
    ``L`` its XY length): inf where Z stays, or no limit is given."""
    out = np.full(len(els), np.inf)
    if z_max_m_s is None:
        return out
    for k, e in enumerate(els):
        dz = abs(e.z_end_m - e.z_start_m)
        if dz > 0 and e.length_m > 0:
            out[k] = z_max_m_s * e.length_m / dz
    return out


def largest_feasible(ok: Callable[[float], bool], start: float, resolution: float = SCALE_RESOLUTION,
                     low: float = SCALE_MIN, high: float = SCALE_MAX) -> float | None:
    """The largest scale ``lam`` in ``[low, high]`` with ``ok(lam)`` and not ``ok(lam (1 + resolution))``
    (or ``lam`` at ``high``), found from ``start``: steps growing geometrically (``resolution``,
    twice that, ...) up from a feasible start or down from an infeasible one bracket it, then
    bisection (in the logarithm) narrows the bracket to ``1 + resolution``. From the scale of
    the piece before (identical depth passes), that is two plans: ``start`` and the step above.
    ``None``: nothing from ``low`` up is feasible (assumes slower is never worse, as the
    bisection it replaces did)."""
    start = min(max(start, low), high)
    step = resolution
    if ok(start):
        lo = start
        while True:
            if lo >= high:
                return lo
            cand = min(lo * (1 + step), high)
            if not ok(cand):
                hi = cand
                break
            lo = cand
            step *= 2
    else:
        hi = start
        while True:
            if hi <= low:
                return None
            cand = max(hi / (1 + step), low)
            if ok(cand):
                lo = cand
                break
            hi = cand
            step *= 2
    while hi > lo * (1 + resolution) * (1 + 1e-12):
        mid = math.sqrt(lo * hi)
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return lo


def check_counts(counts: np.ndarray, line: int) -> None:
    if counts.sum() > MAX_TOTAL_STEPS // 2:
        raise PlannerError("too_large", f"line {line}: the pass needs {int(counts.sum())} samples, more than the "
                           f"limit of {MAX_TOTAL_STEPS // 2}; give a larger settings.Ts or split the program",
                           "program")


def overspeed(res: PlanResult, t: Tube, counts: np.ndarray, feed: np.ndarray) -> float:
    """Largest tool speed / the programmed F of the move being cut (:func:`overspeed_of`)."""
    return float(overspeed_of(res, counts, feed).max())


def overspeed_of(res: PlanResult, counts: np.ndarray, feed: np.ndarray) -> np.ndarray:
    """Per segment, the largest tool speed / the programmed F of the move being cut: the
    samples' speeds, and the straight moves between samples as the exported program runs them
    (chord / Ts), each against the smaller F of the segments at its two ends (a move that
    crosses into a slower move's cells runs at most that F); 0 where a segment has no sample."""
    K = len(res.time)
    seg = segment_of(counts, K)
    speed = np.hypot(*res.velocity[:, :2].T) / np.maximum(feed[seg], 1e-12)
    chord = np.hypot(*np.diff(res.pose[:, :2], axis=0).T) / res.settings.Ts
    chord = chord / np.maximum(np.minimum(feed[seg[:-1]], feed[seg[1:]]), 1e-12)
    out = np.zeros(len(counts))
    np.maximum.at(out, seg, speed)
    np.maximum.at(out, seg[:-1], chord)
    np.maximum.at(out, seg[1:], chord)
    return out
