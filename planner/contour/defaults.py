"""The contour's sample time and horizon chosen from the program (issue 35 goal 3) where the
request gives neither ``settings.Ts`` nor ``settings.N`` (:func:`contour_settings`): for the
``fastest`` feed from its arcs (:func:`contour_ts`), for the ``program`` feed from its short
moves at their F (:func:`feed_ts`).

**Why the sample time.** A tube cell holds at least one sample, and on an arc a cell is one
chord of sagitta ``s_a = 0.18 tol`` (:data:`~planner.contour.tube.SAGITTA_FRACTION`): the tool
moves at most one chord ``c = 2 sqrt(2 R s_a - s_a^2)`` per sample time, so on an arc of radius
``R`` the speed is at most ``c / Ts``. At the plan's default 10 ms that is 29 mm/s on a 3 mm arc
at 0.02 mm, where the drives allow about 0.1 m/s: measured on the benchmark part
(``benchmarks/bench_contour_optimum.py``), ``fastest`` spent 0.18 s on each 3 mm corner arc
against the exact path's third-order optimum's 0.08 s, 1.55x the optimum per pass, while it
was as fast or faster on the lines.

**The rule** (:func:`contour_ts`): per arc the speed it asks, ``v = min(sqrt(a R), (j
R^2)^(1/3), j^(1/3) (L / 2)^(2/3), v_leg)`` (``fastest``: the drives' turn speed on the circle;
the speed at which the force that turns the tool about the circle, ``m v^2 / R``, rotates with
it, ``v / R``, no faster than the force-rate limit lets it change, ``m v^3 / R^2 <= m j``; the
speed a start from rest reaches in half the arc's length ``L`` at that jerk; the legs' top
speed; :func:`arc_speed` in ``program`` feed also at most the move's F), ``a`` the acceleration the drives give the tool
in every direction at the centre of the base (:func:`drive_acceleration`), ``j = a / ramp``,
``ramp`` the slowest drive's rise from 0 to ``force_max``. The sample time is ``c / v`` of the
arc where that is smallest, rounded up to a whole :data:`TS_STEP_S` (a chord per sample at most
the speed the arc asks: rounded down, a chord would need just over one sample, so two, at half
the speed), within [:data:`TS_FLOOR_S`, the settings' default]. Measured on the three programs of
``bench_contour_optimum.py`` at 10, 5, 4 and 3 ms, the rule's choice (3, 4 and 3 ms) cut each
program fastest. The step, 0.25 ms (issue 35, was 1 ms): freecad's 1.5 mm circle asks 3.65 ms,
which a whole millisecond rounded to 4 ms (0.292 s, 1.016x the third-order optimum), 3.75 ms cuts
it in 0.270 s (0.94x); measured ``fastest`` cut time against the step (the CAM samples of
``tests/data/cam``, their need in brackets): freecad (3.65) 4 / 3.75 / 3.7 / 3.5 ms 0.644 /
0.608 / 0.599 / 0.627 s, estlcam (3.26) 4 / 3.5 / 3.3 / 3 ms 0.616 / 0.595 / 0.614 / 0.714 s,
dxf2gcode (3.10) 4 / 3.5 / 3.25 / 3.2 / 3 ms 0.264 / 0.249 / 0.257 / 0.259 / 0.330 s, pcb_gcode
(3.89) 4 / 3.9 ms 0.416 / 0.429 s: at a 0.25 ms step none is slower than at 1 ms (together 1.875
against 1.940 s), at 0.1 ms pcb_gcode is (1.901 s together), at 0.5 ms freecad stays at 4 ms.
A program without arcs, or whose arcs the default reaches, keeps the default.

**Arcs alone** (issue 35 goal 1, branch arccells). Rounded up, the chord per sample is at most
the speed the arc asks, and on an isolated circle that is the whole pass: dxf2gcode's circle (r
4 mm, ``c / v`` 3.105 ms) at 3.25 ms cruised at 0.165 m/s where the drives turn the tool at
0.1728 (1.093x the third-order optimum), pcb_gcode's (r 1 mm) 1.046x at 4 ms; 0.05 ms steps
(3.15 / 3.9 ms) gave 1.060x / 1.020x, and below the need the chords needed two samples each
(0.312 s at 3 ms). So ``fastest`` re-cuts an arc whose chord per sample is faster than its
speed into cells of one sample's travel at it (:meth:`planner.contour.search.TimingSearch.arc_cells`),
and a program whose passes do not mix lines and arcs takes :data:`ARC_CELL_TS_FRACTION` of the
need, rounded down, to give those cells room: dxf2gcode 3 ms (the floor), 0.207 s (1.039x),
pcb_gcode 3.5 ms, its circle 0.126 s (0.999x) and its lines' pass 0.252 -> 0.238 s. Where
lines and arcs share a pass the need stays rounded up: freecad (its pass 0 two 2 mm arcs between
lines) at 3.5 ms cut 0.336 + 0.248 s against 0.319 + 0.259 s at 3.75, estlcam at 3.25 ms
0.292 s a pass against 0.280 at 3.5 (measured with the re-cut cells).

**The program feed's sample time** (:func:`feed_ts`, issue 35 goal 2). The controller needs
6-15 samples to reach F from rest or after a corner and 5-8 to stop (measured on the CAM
samples at 10 ms), whatever the sample time: on a move of a dozen samples at F that is most of
it (fusion360's 2 mm lines at F1000, 12 samples: 1.15-1.20x the F-capped third-order optimum
per pass). A move that starts or ends a pass or meets a neighbour at a corner (its tangent turns
by more than :data:`FEED_CORNER_RAD`) gets at least :data:`FEED_MOVE_SAMPLES` samples at its F:
the sample time ``L / (F n)`` of the shortest such move, rounded down to a whole
:data:`TS_STEP_S`, within [:data:`TS_FLOOR_S`, the settings' default]. Moves shorter than
:data:`FEED_MOVE_MIN_TOL` tolerances do not count (a CAM program's tiny segments are cut
within the tolerance anyway, not at their own F). A program with an arc that asks less than
its F (:func:`arc_speed`: the drives' turn or the force-rate limit bound it) keeps the default:
``benchmarks/bench_estimates.py``'s 60 circles of 0.1 mm at F3000 (4.5 mm lines between rows)
cut in 5.73 s at 4.5 ms against 7.86 s at 10 ms, but for 2.2-3.7x the CPU and 7.8x under its
work estimate (at 5 ms 23 CPU s, 11x over: the feed's scale search near the edge of
feasibility on tiny arcs). Measured on fusion360 (``benchmarks/README.md``):
at 10 / 6 / 5 / 4 ms (N 30) its passes took 1.43 + 0.54 / 1.362 + 0.492 / 1.35 + 0.49 / 1.356 +
0.488 s; freecad's moves (62-160 samples at 10 ms) were not faster at 5 or 7.5 ms (7.2 + 5.83
against 7.215 + 6.05 and 7.305 + 5.85 s), and at 20 samples the benchmark part's 4 mm lines at
F1200 keep 10 ms (its compute unchanged). 19 samples (issue 35 goal 2, branch feedcap4): with
the rows lowered by a small excess (:mod:`planner.contour.search`) fusion360 at 6 / 6.25 ms cut
1.230 + 0.480 / 1.231 + 0.475 s (its third-order optimum at F 1.2298 + 0.4705 s); at 6 ms its
2 mm lines take 21 cells (20.1 samples' travel at F / 1.005), at 6.25 ms 20. The benchmark part
(4 mm at F1200: 10.5 ms) and freecad keep 10 ms.

**The horizon** with a chosen sample time: :data:`HORIZON_RAMPS` force ramps of the slowest
drive, at least the constrained mode's 30 samples (the default horizon's 0.25 s at 3 ms is 84
samples: the same cut, measured, for 40 % more compute).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from ..model import RobotModel
from ..schema import DEFAULT_FORCE_RISE_S, MODE_DEFAULTS, ContourRequest, PathElement, Program, Settings
from .timing import PathSamples, constraint_rows, turn
from .tube import SAGITTA_FRACTION

__all__ = ["ARC_CELL_TS_FRACTION",
           "FEED_CORNER_RAD", "FEED_MOVE_MIN_TOL", "FEED_MOVE_SAMPLES", "HORIZON_RAMPS", "TS_FLOOR_S", "TS_STEP_S",
           "arc_speed", "bound_arcs", "contour_settings", "contour_ts", "drive_acceleration", "drive_jerk", "feed_ts"]

#: the finest sample time chosen [s]: at 2 ms the benchmark pass took longer than at 3 ms
#: (1.154 s against 0.822 s, the search's scales) for 2.6x the compute
TS_FLOOR_S = 0.003
#: the sample time is chosen in whole steps of this [s] (module docstring: 1 ms left freecad's circle
#: 1.016x the optimum at 4 ms where it asks 3.65 ms)
TS_STEP_S = 0.00025
#: a program whose passes do not mix lines and arcs: the sample time at most this fraction of
#: the arcs' chord over their speed, rounded down (module docstring: their cells are re-cut at the
#: drives' speed, which needs a chord per sample faster than it)
ARC_CELL_TS_FRACTION = 0.9
#: the horizon with a chosen sample time: this many force ramps of the slowest drive
HORIZON_RAMPS = 3.0
#: program feed: a move that starts or ends a pass or turns a corner gets at least this many
#: samples at its F (:func:`feed_ts`; module docstring: 20 chose 6 ms for fusion360, whose 2 mm
#: lines then take 21 cells of one sample, 20.1 samples' travel at F / 1.005: 19 chooses 6.25 ms,
#: 20 cells each)
FEED_MOVE_SAMPLES = 19
#: program feed: a tangent jump larger than this between two moves is a corner [rad]
FEED_CORNER_RAD = math.radians(10.0)
#: program feed: moves shorter than this many tolerances do not choose the sample time
FEED_MOVE_MIN_TOL = 20.0


@lru_cache(maxsize=16)
def _acceleration(model: RobotModel) -> float:
    centre = np.asarray(model.base, float).mean(axis=0)
    q = np.array([[centre[0], centre[1], 0.0], [centre[0] + 1e-4, centre[1], 0.0]])
    dq = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    path = PathSamples(np.array([0.0, 1e-4]), q, dq, np.zeros((2, 3)), np.zeros(2, np.int64), np.zeros(2))
    return float(constraint_rows(model, path)[4].min())


def drive_acceleration(model: RobotModel) -> float:
    """The acceleration the drives give the tool in every direction of the plane from rest at
    the centre of the base pivots, psi 0 [m/s^2] (:func:`planner.contour.timing.constraint_rows`;
    16.1 m/s^2 for the moving-slide, 16.07-16.11 over the benchmark part)."""
    return _acceleration(model)


def drive_jerk(model: RobotModel, st: Settings) -> float | None:
    """The tool's acceleration's rate of change under the force-rate limit [m/s^3]:
    :func:`drive_acceleration` over the slowest drive's rise (320 m/s^3 for the moving-slide at
    the default limit); None: no limit."""
    ramp = _ramp(model, st)
    return None if ramp is None else drive_acceleration(model) / ramp


def arc_speed(e: PathElement, a: float, jerk: float | None, v_leg: float, feed: str) -> float:
    """The speed an arc asks [m/s] (module docstring): ``min(sqrt(a R), (j R^2)^(1/3),
    j^(1/3) (L/2)^(2/3), v_leg)``, and at most F in ``program`` feed."""
    assert e.radius_m is not None
    R = e.radius_m
    v = min(math.sqrt(a * R), v_leg)
    if jerk is not None:
        v = min(v, (jerk * R * R) ** (1 / 3), jerk ** (1 / 3) * (e.length_m / 2) ** (2 / 3))
    if feed == "program":
        v = min(v, e.feed_m_s)
    return v


def bound_arcs(elements: list[PathElement], tol: float, model: RobotModel, st: Settings) -> np.ndarray:
    """``fastest``: per element the speed the drives turn the tool at on its arc
    (:func:`arc_speed`) where one sample's travel at it, at ``st.Ts``, is shorter than the arc's
    chord of the sagitta (the drives, not the tube's chords, bound the arc: its cells are re-cut
    to one sample at that speed, :meth:`planner.contour.search.TimingSearch.arc_cells`); 0
    elsewhere [m/s]."""
    a, jerk = drive_acceleration(model), drive_jerk(model, st)
    v_leg = float(np.min(model.speed_max))
    s_a = SAGITTA_FRACTION * tol
    out = np.zeros(len(elements))
    for i, e in enumerate(elements):
        if e.kind != "arc" or not e.radius_m or e.length_m <= 1e-12:
            continue
        R = e.radius_m
        chord = 2 * math.sqrt(max(2 * R * s_a - s_a * s_a, 0.0)) if s_a < R else 2 * R
        v = arc_speed(e, a, jerk, v_leg, "fastest")
        if v * st.Ts < chord * (1 - 1e-9):
            out[i] = v
    return out


def contour_ts(program: Program, tol: float, feed: str, model: RobotModel, st: Settings) -> float:
    """The sample time [s] for the program's arcs (module docstring), at most ``st.Ts``."""
    a = drive_acceleration(model)
    ramp = _ramp(model, st)
    jerk = None if ramp is None else a / ramp  # "off": no jerk bound
    v_leg = float(np.min(model.speed_max))
    s_a = SAGITTA_FRACTION * tol
    need = st.Ts
    mixed = False  # a pass of lines and arcs
    for b in program.passes:
        kinds = {e.kind for e in b.elements if e.length_m > 1e-12}
        mixed = mixed or kinds >= {"arc", "line"}
        for e in b.elements:
            if e.kind != "arc" or not e.radius_m or e.length_m <= 1e-12:
                continue
            R = e.radius_m
            chord = 2 * math.sqrt(max(2 * R * s_a - s_a * s_a, 0.0)) if s_a < R else 2 * R
            v = arc_speed(e, a, jerk, v_leg, feed)
            if v > 0:
                need = min(need, chord / v)
    if need >= st.Ts:
        return st.Ts
    if mixed:
        steps = math.ceil(need / TS_STEP_S - 1e-9)
    else:  # arcs alone: their cells re-cut at the drives' speed (planner.contour.search.TimingSearch.arc_cells)
        steps = math.floor(ARC_CELL_TS_FRACTION * need / TS_STEP_S + 1e-9)
    return min(st.Ts, max(TS_FLOOR_S, round(steps * TS_STEP_S, 9)))  # 0.00325, not 0.0032500000000000003


def feed_ts(program: Program, tol: float, model: RobotModel, st: Settings) -> float:
    """The ``program`` feed's sample time [s] (module docstring): :data:`FEED_MOVE_SAMPLES`
    samples at F on the shortest move that starts or ends a pass or turns a corner, at most
    ``st.Ts``; ``st.Ts`` where an arc asks less than its F (:func:`arc_speed`)."""
    a = drive_acceleration(model)
    ramp = _ramp(model, st)
    jerk = None if ramp is None else a / ramp
    v_leg = float(np.min(model.speed_max))
    need = st.Ts
    for b in program.passes:
        els = [e for e in b.elements if e.length_m > 1e-12]
        if any(e.kind == "arc" and e.radius_m and arc_speed(e, a, jerk, v_leg, "program") < e.feed_m_s for e in els):
            return st.Ts  # tiny arcs: the feed's search near the edge of feasibility (module docstring)
        for k, e in enumerate(els):
            if e.length_m < FEED_MOVE_MIN_TOL * tol or e.feed_m_s <= 0:
                continue
            ends = k == 0 or k == len(els) - 1
            if ends or turn(els[k - 1], e) > FEED_CORNER_RAD or turn(e, els[k + 1]) > FEED_CORNER_RAD:
                need = min(need, e.length_m / (e.feed_m_s * FEED_MOVE_SAMPLES))
    if need >= st.Ts:
        return st.Ts
    steps = math.floor(need / TS_STEP_S + 1e-9)
    return min(st.Ts, max(TS_FLOOR_S, round(steps * TS_STEP_S, 9)))


def contour_settings(req: ContourRequest, st: Settings, program: Program, tol: float, model: RobotModel) -> Settings:
    """``st`` with the sample time and horizon chosen for the program (module docstring) where
    the request gives neither ``settings.Ts`` nor ``settings.N``: ``fastest`` from its arcs
    (:func:`contour_ts`), ``program`` from its short moves at F (:func:`feed_ts`; elsewhere it
    keeps the default: at 5 ms freecad's passes were no faster for 1.4-2.2x the compute);
    else ``st`` as given."""
    if req.settings.get("Ts") is not None or req.settings.get("N") is not None:
        return st
    Ts = contour_ts(program, tol, req.feed, model, st) if req.feed == "fastest" else feed_ts(program, tol, model, st)
    if Ts >= st.Ts:
        return st
    out = Settings.model_validate({**req.settings, "Ts": Ts})  # the defaults as if Ts were typed
    ramp = _ramp(model, st)
    if ramp is None:  # no force-rate limit: the mode's default horizon at that Ts
        return out
    low = int(MODE_DEFAULTS["constrained"]["N"])
    return out.model_copy(update={"N": max(low, min(out.N, math.ceil(HORIZON_RAMPS * ramp / Ts - 1e-9)))})


def _ramp(model: RobotModel, st: Settings) -> float | None:
    """The slowest drive's rise from 0 to ``force_max`` under the force-rate limit [s]; None:
    no limit."""
    rate = st.force_rate_n_s
    if isinstance(rate, str):
        return None
    fmax = np.asarray(model.force_max, float)
    r = fmax / DEFAULT_FORCE_RISE_S if rate is None else np.broadcast_to(np.asarray(rate, float), fmax.shape)
    return float(np.max(fmax / r))
