"""How much work a request is, before any of it is done: the estimate a server compares with
its time limit to reject, in microseconds, what could not finish anyway (issue 15).

The estimate follows what :func:`~planner.orchestrator.plan` will do, stage by stage, from
the validated request alone (no robot model, no segmentation, no simulation):

* the corridor's length: ``n`` segments (given; or, for a layout, the start point, the
  cells of the shortest possible path between start and end, and the end point; or one per
  reference pose) held ``S`` samples each (``samples_per_segment``, or what ``speed_m_s`` /
  ``total_time_s`` resolve to), plus the whole settling tail the request allows
  (``tail_max_s``: its own bound on the work the model cannot predict, issue 20);
* the cost of one receding-horizon step for the mode, backend, solver and horizon ``N``
  (``a + b N + c N^2 + d N^3``; the compiled constrained step about linearly in N, its numpy
  reference with DAQP about ``N^2.2``) and the RK4 substeps;
* the range sequence, the corridor metrics and the result, per sample (linear in the
  samples; more with exact cell polygons);
* a layout's segmentation (per cell, per obstacle and a fixed part);
* the ``fastest`` timing search (:func:`fastest_steps`): the uniform count ``S`` it will find
  estimated from the longest move between two segment centres and the robot's dynamics
  (:func:`fastest_count`: a move from rest to rest at :data:`FASTEST_A_M_S2`, or
  :data:`FASTEST_SLOW_S` a segment where the horizon ``N Ts`` covers fewer than
  :data:`FASTEST_RAMPS` force ramps, where the search ends at ~10-25x the counts); the uniform
  phase's doubling and bisection at up to ``2 S``, and the per-segment bisections, each of
  ``log2(S) + 1`` candidates planned from the segment to the end (issue 33: Table I at Ts 2 ms
  ran 121 candidates, ~1 200 samples a segment, 46 CPU s against 1.2 s estimated); the move
  at most the legs' speed limit, a ``[point, box, point]`` corridor's from start to end, and its
  steps dearer with the horizon beyond 30 samples (:data:`FASTEST_HORIZON_COST`, issue 31);
* the advice an error may carry, checked before it is given (issue 20), bounded by its own
  parameters and estimated apart (``advice_seconds``): a layout without a path is segmented
  again with smaller cells, a narrower psi range and less clearance (at most
  :func:`planner.corridor.remedy_cells`); an infeasible constrained plan is planned again with
  :data:`MORE_TIME` times the samples (each at most that multiple of the plan);
* a constrained plan with ``require_settled: false``: the infeasible steps and slack-problem
  iterations it may take (:func:`slack_allowance`: :data:`~planner.schema.SLACK_BUDGET_S` of
  them, or the plan's own loop time if more; :func:`slack_costs`); the controller stops the plan
  with ``infeasible`` where either runs out, so this bound holds too.

Unit costs are :data:`planner.schema.WORK_COSTS` (seconds on the reference machine,
``benchmarks/bench_work.py``). The settling is counted in full (``tail_max_s``), so the
estimate bounds the work of a request whose corridor it knows: measured <= 1.5x the estimate
(``benchmarks/certify.py``), and an error's with its advice checks <= 1.5x the estimate plus
``advice_seconds``. A server admits a request by ``seconds`` and stops the advice checks at its
time limit. A layout's path is unknown until it is segmented: the estimate
takes the shortest possible one, and :func:`~planner.orchestrator.plan` with ``work_limit_s``
estimates again from the segmented corridor before simulating (:func:`check_work`), so a long
serpentine corridor is refused before its simulation starts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from ..corridor import cell_size_rule, remedy_cells
from ..errors import PlannerError, over_the_limit
from ..schema import (
    DEFAULT_FORCE_RISE_S,
    MAX_SAMPLES_PER_SEGMENT,
    MAX_TOTAL_STEPS,
    SLACK_BUDGET_S,
    SQRT3_2,
    WORK_COSTS,
    PlanRequest,
    Settings,
    cell_count,
    parse_request,
)
from .timing import centre_path_length, method_of, moving_segments

__all__ = ["FASTEST_A_M_S2", "FASTEST_BISECTION", "FASTEST_FRICTION_COST", "FASTEST_HORIZON_COST", "FASTEST_RAMPS",
           "FASTEST_SLOW_S", "FASTEST_V_SHARE", "MORE_TIME", "RATE_FRICTION_V_M_S", "REFUSAL_WORK", "RATE_RAMPS_MAX",
           "RATE_STEP_S",
           "WorkEstimate", "robot_motion",
           "check_work", "estimate_work", "fastest_count", "fastest_steps", "rate_step_cost", "slack_allowance",
           "slack_costs"]

#: a plan that stops at its first infeasible step (``require_settled``) may take this many times
#: its estimate in CPU seconds before the refused step's DAQP solves are cut
#: (:class:`planner.constraints.controller.WorkBound`; issue 33 goal 2: a refusal's own work
#: within 1.5x its estimate, like a plan's; at N 100 one refused step's slack problem took 2-6
#: CPU s against estimates of 0.18-1.2 s). Below 1.5: the bound is counted in this machine's
#: CPU seconds (the estimate's are the reference machine's) and the work after the cut (the
#: message, the plan's result) is not
REFUSAL_WORK = 1.3
#: the time factors the advice of an infeasible constrained plan tries, in this order (each
#: planned until its first infeasible step; the first that plans is advised), as far as the
#: limits on samples allow (issue 31: a speed of 5 m/s on Table I planned at 1/32 of it)
MORE_TIME = (2, 4, 8, 16, 32, 64, 128, 256)

#: ``fastest``: the acceleration [m/s^2] of the move from rest to rest over the longest step
#: between two segment centres that sets the uniform count the search finds (Table I, 2 cm
#: steps: ~0.1 s a segment measured, at Ts 5 and 10 ms; this takes 0.13 s)
FASTEST_A_M_S2 = 5.0
#: ``fastest``: the share of the speed at which the legs' friction takes the drives' whole force
#: that the estimated move reaches (Table I with 2000 N s/m: 0.075 m/s, the search found ~0.67 s
#: a 2.8 cm step, 0.6 s at half that speed)
FASTEST_V_SHARE = 0.5
#: ``fastest``: horizons ``N Ts`` of fewer force ramps (``force_max / force_rate``) than this
#: leave the robot too little preview to brake within the force-rate limit: the search ends at
#: 10-25x the counts (Table I: 1.5 ramps as usual, 1.2 ramps ~1 200 samples a segment at Ts
#: 2 ms, ~110 at Ts 10 ms with N = 6)
FASTEST_RAMPS = 1.4
#: ``fastest``: the time a segment takes [s] with such a short horizon (measured 1.2-2.5 s)
FASTEST_SLOW_S = 3.0
#: ``fastest``: the search's steps cost this much more per sample of horizon beyond the
#: default 30 (``1 + FASTEST_HORIZON_COST (N - 30) / 70``): its candidates run at the drives'
#: limits, where a step's active set grows with the horizon (Table I, CPU per simulated step of
#: the search: 0.22 / 0.65 / 1.27 ms at N 30 / 51 / 100, against 0.09 / 0.14 / 0.25 ms a plain
#: step; the search's steps are overcounted ~3x, so Table I at Ts 2 ms took 1.6x its estimate)
FASTEST_HORIZON_COST = 0.3
#: ``fastest``: its steps cost up to this much more where the legs' friction sets the estimated
#: move's speed (the drives' force over the friction below the legs' speed limit; whole at
#: :data:`RATE_FRICTION_V_M_S`, in proportion to the friction above it): the candidates then
#: run at the friction's limit, where every change of speed is a change of force, and the search
#: plans about the steps :func:`fastest_steps` counts (elsewhere ~1.4-3.4x fewer, which covers
#: the dearer steps). Measured per simulated step against the estimate's, issue 31: Table I with
#: a leg friction of 2000 N s/m 1.8x (the plan 1.28-1.42x its estimate), certification seed 31
#: case 78 (5 legs, 2000 N s/m, 251 N/s, N 100) 2.5x (the plan 1.68-1.82x); 500 N s/m 2.6x with
#: 3x fewer steps than counted
FASTEST_FRICTION_COST = 2.0
#: a constrained step's cost grows with the force-rate limit's ramps over the horizon
#: (``x = force_max / force_rate / (N Ts)``, at most :data:`RATE_RAMPS_MAX`): ``RATE_STEP_S x^2``
#: a leg and a sample of the horizon [s]. Where a ramp is longer than the horizon the rate rows
#: bind over all of it and each step takes more active-set changes: certification seed 31 case
#: 181 (3 legs, N 100, 2000 N s/m) 1.9 / 4.9 / 7.9 / 11.2 changes a leg and step at 0.5 / 1.5 /
#: 2.1 / 2.7 ramps (300 / 100 / 70 / 56 N/s), its steps 193 / 213 / 280 / 399 / 583 us (off, ...):
#: 2.2x the estimate's at 56 N/s; case 67 (3 legs, 500 N s/m, 37 N/s, 4.1 ramps) 17.8 changes,
#: 1.4x. Scaled by ``(v_f /`` :data:`RATE_FRICTION_V_M_S` ``)^-0.3`` (at most 1), ``v_f`` the speed at
#: which the legs' friction takes the drives' whole force: with less friction a speed is held
#: without force and the rate rows bind less (measured per leg, sample and ramp^2: 1.6e-7 s at
#: 2000 N s/m, 1.05e-7 at 500, 6.3e-8 at 50, 1.8-2.5e-8 at 5; the rule gives 1.6 / 1.05 / 0.53 /
#: 0.27e-7)
RATE_STEP_S = 1.6e-7
#: the friction speed [m/s] at which :data:`RATE_STEP_S` holds whole (legs of 150 N at 2000 N s/m)
RATE_FRICTION_V_M_S = 0.075
#: the ramps over the horizon beyond which :data:`RATE_STEP_S` grows no more (the measured range)
RATE_RAMPS_MAX = 4.0
#: ``fastest``: the mean share of a per-segment bisection candidate's steps it plans (half of
#: them feasible, to the end; half abandoned at ~a quarter: Table I at Ts 2 ms, 0.15-0.2 s
#: against 0.8 s)
FASTEST_BISECTION = 0.65


@dataclass(frozen=True)
class WorkEstimate:
    """The estimated compute time of a request and what it is made of."""

    seconds: float  #: estimated compute time on the reference machine [s]
    steps: int  #: receding-horizon steps over all plans of the request
    plans: int  #: plans the request runs (more than one for ``fastest``)
    field: str  #: the request field that contributes most
    detail: str  #: the arithmetic, in words
    #: the most that checking an error's advice adds (a layout's remedies segmented, an
    #: infeasible plan's :data:`MORE_TIME`), on the reference machine [s]; not part of ``seconds``
    advice_seconds: float = 0.0
    #: what to change, where the request's own options decide it (None: the general advice)
    advice: str | None = None

    def message(self, limit_s: float, time_limit_s: float | None = None) -> str:
        """Why a server that admits work estimated up to ``limit_s`` [s] rejects this request;
        ``time_limit_s``: its time limit, when the admitted work is less (the estimate's margin)."""
        advice = self.advice or ("make it smaller: fewer segments or samples per segment, a larger settings.Ts, a "
                                 "shorter horizon settings.N, or the paper mode")
        return (f"this request needs an estimated {self.seconds:.3g} s of planning ({self.detail}), more than "
                f"{over_the_limit(limit_s, time_limit_s)}; {advice}")


def _step_cost(mode: str, backend: str, solver: str, N: int, substeps: int) -> float:
    """Seconds of one receding-horizon step."""
    key = f"{mode}_{backend}"
    if mode == "paper" and backend == "reference" and solver != "riccati":
        key = f"paper_{solver}"
    c = WORK_COSTS
    step = c[f"{key}_a"] + c[f"{key}_b"] * N + c[f"{key}_c"] * N ** 2 + c[f"{key}_d"] * N ** 3
    return step + (substeps - 1) * c[f"substep_{backend}"]


def slack_costs(N: int) -> tuple[float, float]:
    """Seconds of one infeasible constrained step besides its slack problem's iterations (the
    hard QP on the Python path by DAQP, relaxed, the slack problem formed; about ``N^3``) and of
    one DAQP iteration of the slack problem (about ``N^2``): ``WORK_COSTS`` ``slack_*``."""
    c = WORK_COSTS
    return c["slack_step_a"] + c["slack_step_d"] * N ** 3, c["slack_iteration_a"] + c["slack_iteration_c"] * N ** 2


def slack_allowance(st: Settings, steps: int) -> tuple[int, int]:
    """``(infeasible steps, slack-problem iterations)`` a constrained plan with
    ``require_settled: false`` may take ((0, 0) otherwise: it stops at the first): half of
    :data:`~planner.schema.SLACK_BUDGET_S`, or of the plan's own estimated loop time (``steps``
    receding-horizon steps, the settling tail included) if more, pays for each at
    :func:`slack_costs` (at least one step). The estimate counts both; the controller stops the
    plan with ``infeasible`` where either runs out (the last slack problem's iteration limit is
    what is left)."""
    if st.mode != "constrained" or st.require_settled:
        return 0, 0
    budget = max(SLACK_BUDGET_S, steps * _step_cost(st.mode, st.backend, st.solver, st.N, st.plant_substeps))
    step_s, iteration_s = slack_costs(st.N)
    return max(1, int(0.5 * budget / step_s)), int(0.5 * budget / iteration_s)


def _layout_corridor(req: PlanRequest, S: int) -> tuple[int, int, int]:
    """(segments of the shortest possible corridor, cells of the grid, obstacles) of a layout."""
    lay = req.layout
    assert lay is not None
    st = req.settings.model_copy(update={"samples_per_segment": S})
    lower, upper = lay.bounds.lower, lay.bounds.upper
    shape = lay.cell.shape
    size = lay.cell.size if lay.cell.size is not None else cell_size_rule(lower, upper, lay.start_pose,
                                                                          lay.end_pose, shape, st)
    cells = cell_count(lower, upper, shape, size)[0]
    dx, dy = np.abs(lay.end_pose[:2] - lay.start_pose[:2]).tolist()
    # fewest edge-adjacent cells from a cell holding the start to one holding the end (a point
    # on a cell edge may take either cell): a square path steps in x and y separately; a
    # triangle advances half an edge in x per cell and a row (s sqrt(3)/2) per row crossing
    if shape == "square":
        path = max(0, math.ceil(dx / size) - 1) + max(0, math.ceil(dy / size) - 1) + 1
    else:
        path = max(0, math.ceil(2.0 * dx / size) - 2) + max(0, math.ceil(dy / (size * SQRT3_2)) - 1) + 1
    return path + 2, cells, len(lay.obstacles)


def _samples_per_segment(req: PlanRequest, n: int) -> int:
    st = req.settings
    if st.speed_m_s is not None and req.segments is not None:
        length = centre_path_length(req.segments)
        return max(1, round(length / (st.speed_m_s * st.Ts * moving_segments(n)))) if length > 0 else 1
    if st.total_time_s is not None:
        return max(1, round(st.total_time_s / (n * st.Ts)))
    if st.fastest:
        return st.N
    return st.samples_per_segment


def _longest_step(centres: np.ndarray) -> float:
    """The longest move between two consecutive centres [m] (psi at 5 cm a radian); a corridor
    of one segment between a start and an end point (``[point, box, point]``) moves from the
    start to the end within that segment (issue 31: the box's centre is half way, and the
    search found 1.6-5x the count estimated from it)."""
    if len(centres) < 2:
        return 0.0
    if len(centres) == 3:
        centres = centres[[0, 2]]
    d = np.diff(centres, axis=0)
    return float(np.max(np.hypot(d[:, 0], d[:, 1]) + 0.05 * np.abs(d[:, 2])))


def _ramp_s(req: PlanRequest) -> float | None:
    """The time a drive force takes to rise to its limit at the force-rate limit [s] (None: off)."""
    rate = req.settings.force_rate_n_s
    if isinstance(rate, str):
        return None
    if rate is None:
        return DEFAULT_FORCE_RISE_S
    from ..model import load_robot  # a given rate: the drives' force limits

    force = np.asarray(load_robot(req.robot).force_max, float)
    return float(np.max(force / np.broadcast_to(np.asarray(rate, float), force.shape)))


@lru_cache(maxsize=64)
def _builtin_substeps(robot: str, Ts: float) -> int:
    from ..model import load_robot
    from ..model.plant import plant_substeps

    return plant_substeps(load_robot(robot), Ts)


def _substeps(req: PlanRequest) -> int:
    """The plant's RK4 steps a sample the plan will take: the request's ``plant_substeps``, or
    those the robot's stiffness needs (:func:`planner.model.plant.plant_substeps`, at the home
    pose: the stiffness hardly changes over the workspace)."""
    st = req.settings
    if "plant_substeps" in st.model_fields_set:
        return st.plant_substeps
    if isinstance(req.robot, str):
        return _builtin_substeps(req.robot, st.Ts)
    from ..model import load_robot
    from ..model.plant import plant_substeps

    return plant_substeps(load_robot(req.robot), st.Ts)


def _motion(desc: Any) -> tuple[float, float]:
    """``(a, v)`` of a robot description: the acceleration of its whole mass under the sum of
    its drives' force limits [m/s^2] and the speed at which the sum of its leg frictions takes
    that force [m/s] (inf without friction), at most the slowest leg's speed limit (a leg along
    the move moves as fast as the tool; issue 31: with 0.028 m/s legs the search took 2.4x)."""
    legs = desc.leg_list()
    force = sum(g.force_max for g in legs)
    mass = desc.platform.mass + sum(g.cylinder.mass + g.rod.mass for g in legs)
    friction = sum(g.friction for g in legs)
    return force / mass, min(force / friction if friction > 0 else math.inf, min(g.speed_max for g in legs))


@lru_cache(maxsize=16)
def _builtin_motion(name: str) -> tuple[float, float]:
    from ..schema import builtin_description

    return _motion(builtin_description(name))


def robot_motion(req: PlanRequest) -> tuple[float, float]:
    """The ``fastest`` estimate's move: :data:`FASTEST_A_M_S2` scaled by the request's robot's
    acceleration over the Moving Slide's, and :data:`FASTEST_V_SHARE` of the speed its leg
    friction allows (issue 31: 0.433 s estimated for Table I whatever the robot; measured 3.5x
    with a 150 kg platform, 6x with a leg friction of 2000 N s/m), at most the request's
    ``tool_speed_max_m_s``."""
    a_ref = _builtin_motion("moving-slide")[0]
    a, v = _builtin_motion(req.robot) if isinstance(req.robot, str) else _motion(req.robot)
    limit = req.settings.tool_speed_max_m_s
    return FASTEST_A_M_S2 * a / a_ref, min(FASTEST_V_SHARE * v, limit if limit is not None else math.inf)


def _legs_and_friction(desc: Any) -> tuple[int, bool, float]:
    """The leg count of a robot description, whether its legs' friction, not their speed
    limit, bounds the speed of a move (:func:`_motion`), and the speed at which the friction
    takes the drives' whole force [m/s] (inf without friction)."""
    legs = desc.leg_list()
    force = sum(g.force_max for g in legs)
    friction = sum(g.friction for g in legs)
    v_f = force / friction if friction > 0 else math.inf
    return len(legs), v_f < min(g.speed_max for g in legs), v_f


@lru_cache(maxsize=16)
def _builtin_legs(name: str) -> tuple[int, bool, float]:
    from ..schema import builtin_description

    return _legs_and_friction(builtin_description(name))


def _robot_legs(req: PlanRequest) -> tuple[int, bool, float]:
    return _builtin_legs(req.robot) if isinstance(req.robot, str) else _legs_and_friction(req.robot)


def rate_step_cost(req: PlanRequest) -> float:
    """The seconds a constrained step costs more under the request's force-rate limit
    (:data:`RATE_STEP_S`; 0 without a limit or in the paper mode)."""
    st = req.settings
    ramp = _ramp_s(req)
    if st.mode != "constrained" or ramp is None:
        return 0.0
    x = min(ramp / (st.N * st.Ts), RATE_RAMPS_MAX)
    n_legs, _, v_f = _robot_legs(req)
    share = min(1.0, (v_f / RATE_FRICTION_V_M_S) ** -0.3) if math.isfinite(v_f) else 0.0
    return RATE_STEP_S * share * x * x * n_legs * st.N


def fastest_count(step_m: float, Ts: float, N: int, ramp_s: float | None,
                  motion: tuple[float, float] = (FASTEST_A_M_S2, math.inf)) -> int:
    """The uniform samples per segment the ``fastest`` search is estimated to end at: a move
    of ``step_m`` from rest to rest at the acceleration ``a`` and at most the speed ``v`` of
    ``motion`` (:func:`robot_motion`; ``2 sqrt(d / a)``, or ``d / v + v / a`` where the move
    reaches ``v``), or :data:`FASTEST_SLOW_S` a segment where the horizon ``N Ts`` covers
    fewer than :data:`FASTEST_RAMPS` force ramps of ``ramp_s`` (None: no force-rate limit)."""
    a, v = motion
    d = max(step_m, 0.0)
    t = 2.0 * math.sqrt(d / a) if d <= v * v / a else d / v + v / a
    if ramp_s is not None and N * Ts < FASTEST_RAMPS * ramp_s:
        t = max(t, FASTEST_SLOW_S)
    return max(1, min(math.ceil(t / Ts), MAX_SAMPLES_PER_SEGMENT))


def fastest_steps(n: int, S: int, N: int, tail_steps: int) -> tuple[int, int]:
    """``(candidates, receding-horizon steps)`` of the ``fastest`` search
    (:mod:`.fastest`) on ``n`` segments ending at the uniform count ``S``: the uniform phase
    (from ``N / 2`` doubled or halved to ``S``: its candidates ``2 n S_hi`` together, ``S_hi =
    max(N / 2, 2 S)``, then ``log2(S_hi)`` bisection candidates of ``n S_hi`` steps and the whole
    settling tail each), the ends (one plan) and, for each of the ``n - 2`` moving segments,
    ``log2(S)`` bisection candidates planned from the segment's start (less a horizon) to the end
    (``(n - i) S + N`` steps: a feasible candidate arrives at rest), :data:`FASTEST_BISECTION` of
    them on average (the infeasible half is abandoned early)."""
    S_hi = max(N // 2, 2 * S, 1)
    bisect = max(1, math.ceil(math.log2(max(S_hi, 2))))
    uniform = 2 * n * S_hi + bisect * (n * S_hi + tail_steps)
    ends = n * S + tail_steps
    per_segment = max(1, math.ceil(math.log2(max(S, 2))))
    moving = max(n - 2, 0)
    # segment i (1..n-2) resumed at its start less N: (n - i) S + N steps a feasible candidate,
    # about a quarter of it an infeasible one (abandoned): half of each
    segment_steps = math.ceil(FASTEST_BISECTION * per_segment * (S * (moving * (moving + 3) // 2) + moving * N))
    candidates = 2 + bisect + 1 + per_segment * moving
    return candidates, uniform + ends + segment_steps


def estimate_work(request: Any, segments: Sequence[Any] | None = None) -> WorkEstimate:
    """The estimated compute time of planning ``request`` (a validated
    :class:`~planner.schema.PlanRequest` or a dict in the one JSON shape); see the module
    docstring. Costs microseconds (a layout: its cell count; ``speed_m_s``: one pass over
    the segments). ``segments``: a layout's corridor once segmented (its length is then
    known: the estimate :func:`check_work` bounds the simulation with)."""
    req = parse_request(request)
    st = req.settings
    c = WORK_COSTS
    cells = obstacles = 0
    method = method_of(st)
    timing_field = f"settings.{method}"
    if req.reference is not None:
        n, S = len(req.reference.pose), 1
        corridor_field = "reference.pose"
    elif req.segments is not None:
        n = len(req.segments)
        S = _samples_per_segment(req, n)
        corridor_field = "segments"
    elif segments is not None:  # a layout, segmented
        n = len(segments)
        S = _samples_per_segment(req.model_copy(update={"segments": list(segments)}), n)
        cells, obstacles = _layout_corridor(req, S)[1:]
        corridor_field = "layout.cell.size"
    else:
        S = _samples_per_segment(req, 0) if method != "speed_m_s" else st.N
        n, cells, obstacles = _layout_corridor(req, S if method != "total_time_s" else st.N)
        if method == "total_time_s":
            S = _samples_per_segment(req, n)
        elif method == "speed_m_s":  # (the default tool speed too): the straight line from start to
            # end is no longer than the corridor's centre path, so this count is a lower one
            assert req.layout is not None and st.speed_m_s is not None
            line = float(np.linalg.norm(req.layout.end_pose[:2] - req.layout.start_pose[:2]))
            S = max(1, math.floor(line / (st.speed_m_s * st.Ts * moving_segments(n))))
        corridor_field = "layout.cell.size"
    polygons = req.layout is not None or any(s.polygon is not None for s in (req.segments or ()))
    steps_one = n * S + st.tail_steps
    plans, steps = 1, steps_one
    advice: str | None = None
    if st.fastest:
        seg_list = req.segments if req.segments is not None else segments
        if seg_list is not None:
            step_m = _longest_step(np.array([s.centre for s in seg_list], float))
        else:  # a layout not yet segmented: a cell's diagonal
            assert req.layout is not None
            step_m = math.sqrt(2.0) * (req.layout.cell.size or cell_size_rule(
                req.layout.bounds.lower, req.layout.bounds.upper, req.layout.start_pose, req.layout.end_pose,
                req.layout.cell.shape, st))
        S = fastest_count(step_m, st.Ts, st.N, _ramp_s(req), robot_motion(req))
        steps_one = n * S + st.tail_steps
        plans, steps = fastest_steps(n, S, st.N, st.tail_steps)
        ramp = _ramp_s(req)
        advice = ("a timing other than settings.fastest (speed_m_s, total_time_s or samples_per_segment: one plan "
                  "instead of a search of candidates), or fewer segments")
        if ramp is not None and st.N * st.Ts < FASTEST_RAMPS * ramp:
            advice = (f"a horizon settings.N of at least {math.ceil(FASTEST_RAMPS * ramp / st.Ts)} samples at Ts = "
                      f"{st.Ts:g} s (N Ts covering {FASTEST_RAMPS:g} force ramps of {ramp:g} s: with less the "
                      "fastest timing found is ~10-25x slower and takes as many more candidates), a larger "
                      "settings.Ts, or " + advice)
    step_s = _step_cost(st.mode, st.backend, st.solver, st.N, _substeps(req))
    rate_s = 0.0
    if st.fastest:
        step_s *= 1.0 + FASTEST_HORIZON_COST * max(0, st.N - 30) / 70
        n_legs, friction_bound, v_f = _robot_legs(req)
        if friction_bound:  # in proportion to the friction, whole at RATE_FRICTION_V_M_S
            step_s *= 1.0 + (FASTEST_FRICTION_COST - 1.0) * min(1.0, RATE_FRICTION_V_M_S / v_f)
    else:  # (the fastest search's steps have their own costs above, fitted with the rate limit on)
        rate_s = rate_step_cost(req)
        step_s += rate_s
    loop_s = steps * step_s
    metrics_s = steps * (c["sample"] + (c["sample_polygon"] if polygons else 0.0))
    segment_s = (c["segmentation"] if req.layout is not None else 0.0) + cells * c["cell"] + obstacles * c["obstacle"]
    seconds = c["fixed"] + loop_s + metrics_s + segment_s
    plan_s = seconds  # without the slack steps (the advice's candidates take none)
    # the fastest search's candidates plan with require_settled (abandoned at their first slack step)
    slack_n, slack_it = slack_allowance(st, steps_one) if not st.fastest else (0, 0)
    slack_s = float(np.dot((slack_n, slack_it), slack_costs(st.N)))
    seconds += plans * slack_s
    # the field to change: the horizon if a step costs more than at the mode's default N,
    # else what makes the corridor long (its segments, or its samples per segment)
    default_step = _step_cost(st.mode, st.backend, st.solver, 20 if st.mode == "paper" else 30, st.plant_substeps)
    if loop_s >= metrics_s and step_s > 2.0 * default_step and "N" in st.model_fields_set:
        field = "settings.N"
    elif req.reference is None and S > max(n, 20) and method != "fastest":
        field = timing_field
    else:
        field = corridor_field if not st.fastest else "settings.fastest"
    what = ("reference poses" if req.reference is not None else "segments" if req.segments is not None
            else f"segments (the path through {cells} cells)" if segments is not None
            else f"segments (shortest path through {cells} cells)")
    search = f"; the fastest-timing search at ~{S} samples a segment: {plans} candidates, {steps} steps"
    detail = (f"{n} {what} x {S} samples + settling (at most {st.tail_max_s:g} s) = {steps_one} steps"
              f"{search if plans > 1 else ''}, "
              f"~{step_s * 1e6:.0f} us per step in {st.mode} mode at N = {st.N}"
              f"{f' ({rate_s * 1e6:.0f} us of it for the force-rate limit)' if rate_s >= 0.1 * step_s else ''}"
              f"{'' if st.backend == 'compiled' else f' ({st.backend} backend, {st.solver} solver)'}, "
              f"{metrics_s:.2g} s of corridor metrics")
    if segment_s > 0.01:
        detail += f", {segment_s:.2g} s of segmentation"
    if slack_n:
        detail += (f", {slack_s:.3g} s for up to {slack_n} infeasible steps and {slack_it} slack-problem iterations "
                   "(settings.require_settled false)")
    advice_s = 0.0
    if req.layout is not None and segments is None:  # no path: the remedies segmented
        lay = req.layout
        size = lay.cell.size if lay.cell.size is not None else cell_size_rule(
            lay.bounds.lower, lay.bounds.upper, lay.start_pose, lay.end_pose, lay.cell.shape, st)
        psi_narrows = lay.psi_range is not None and bool(
            np.any(np.abs(np.asarray(lay.psi_range) - np.sort([lay.start_pose[2], lay.end_pose[2]])) > 1e-12))
        r_cells, r_runs = remedy_cells(lay.bounds.lower, lay.bounds.upper, lay.cell.shape, size, lay.clearance,
                                       psi_narrows)
        advice_s = r_cells * c["cell"] + r_runs * (obstacles * c["obstacle"] + c["segmentation"])
    if st.mode == "constrained" and not st.fastest and req.reference is None:  # infeasible: more time
        more = [f for f in MORE_TIME
                if S * f <= MAX_SAMPLES_PER_SEGMENT and n * S * f + st.tail_steps <= MAX_TOTAL_STEPS]
        # then a longer horizon (at most MAX_HORIZON: the step's cost about linear in N) and
        # settings.fastest (orchestrator.plan._other_advice)
        from ..schema import MAX_HORIZON, TIMING_FIELDS

        fast = req.model_copy(update={"settings": Settings.model_validate(
            {**st.model_dump(mode="json", exclude_unset=True, exclude={*TIMING_FIELDS}), "fastest": True})})
        other = plan_s * MAX_HORIZON / st.N + estimate_work(fast, segments).seconds
        advice_s = max(advice_s, sum(more) * plan_s + other)
    return WorkEstimate(seconds=seconds, steps=steps, plans=plans, field=field, detail=detail,
                        advice_seconds=advice_s, advice=advice)


def check_work(request: Any, segments: Any, limit_s: float | None) -> None:
    """Raise ``PlannerError("too_much_work")`` if planning ``request`` on the corridor
    ``segments`` (a layout's, once segmented) is estimated over ``limit_s`` [s] (None: no limit)."""
    if limit_s is None or limit_s <= 0:
        return
    est = estimate_work(request, segments)
    if est.seconds > limit_s:
        raise PlannerError("too_much_work", f"the segmented layout's corridor ({len(segments)} segments): "
                           + est.message(limit_s), est.field)
