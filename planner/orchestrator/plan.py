"""The orchestrator: :func:`plan` turns a request into a :class:`~planner.schema.PlanResult`.

validate (:func:`planner.schema.parse_request`) -> robot model -> corridor (the request's
segments, or a layout segmented into cells) -> reach check -> timing -> range sequence ->
controller (the paper's, or the constrained mode's) -> receding-horizon simulation ->
result. This is the only place that composes the layers; the CLI, the HTTP workers and
the editor all call it.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._jit import numpy_only
from ..constraints import MARGIN_M, MARGIN_RAD, ConstrainedController, WorkBound
from ..corridor import RangeSequence, Segmentation, range_sequence, reference_sequence
from ..corridor import segment as segment_layout
from ..corridor.geometry import corridor_gaps
from ..errors import PlannerError, invalid
from ..model import RobotModel, load_robot
from ..model.plant import plant_substeps
from ..model.reach import check_pose, check_segments
from ..schema import (
    DEFAULT_FORCE_RISE_S,
    MAX_HORIZON,
    MAX_SAMPLES_PER_SEGMENT,
    MAX_TOTAL_STEPS,
    TIMING_FIELDS,
    PlanRequest,
    PlanResult,
    Reference,
    Segment,
    Settings,
    default_horizon,
    parse_request,
)
from .fastest import search as search_fastest
from .result import build_result
from .simulate import Resume, Simulation, simulate
from .timing import method_of, resolve_timing, timing_info
from .work import MORE_TIME, REFUSAL_WORK, check_work, estimate_work, slack_allowance

__all__ = ["AdviceBudget", "plan", "plan_timed", "segment", "warm_up"]


def _robot(req: PlanRequest, robot: RobotModel | None) -> RobotModel:
    model = load_robot(robot if robot is not None else req.robot)
    st = req.settings
    if st.q_u is not None and len(st.q_u) != model.n_legs:
        raise invalid("settings.q_u", f"must have one entry per drive ({model.n_legs}), got {len(st.q_u)}")
    rate = st.force_rate_n_s
    if isinstance(rate, np.ndarray) and len(rate) != model.n_legs:
        raise invalid("settings.force_rate_n_s", f"must be one number or one per drive ({model.n_legs}), "
                      f"got {len(rate)}")
    return model


def segment(request: Any, *, robot: RobotModel | None = None) -> Segmentation:
    """Segment a request's ``layout`` into cells and a corridor (no planning)."""
    req = parse_request(request)
    if req.layout is None:
        raise invalid("layout", "the request has no layout to segment")
    with numpy_only(req.settings.backend == "reference"):
        return segment_layout(req.layout, _robot(req, robot), req.settings)


def plan(request: Any, *, robot: RobotModel | None = None, segments: Sequence[Segment] | None = None,
         work_limit_s: float | None = None, start_force: np.ndarray | None = None) -> PlanResult:
    """Plan a trajectory for ``request`` (a dict in the one JSON shape or a validated
    :class:`~planner.schema.PlanRequest`). ``robot`` overrides the request's robot model,
    ``segments`` its corridor. ``work_limit_s``: a layout's corridor, once segmented, is
    estimated again (:func:`~planner.orchestrator.work.check_work`) and refused with
    ``too_much_work`` over this many seconds. Raises :class:`~planner.errors.PlannerError`
    naming the cause. ``settings.backend = "reference"`` runs numpy only (no kernel is
    compiled or loaded: :func:`planner._jit.numpy_only`). ``start_force``: the drive forces [N]
    held before the first sample (a plan that continues another, :mod:`planner.contour`): the
    first step's force-rate rows start from them, and the result's force rates count the first
    force's step from them; default zero (the robot at rest)."""
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    req = parse_request(request)
    with numpy_only(req.settings.backend == "reference"):
        return _plan(req, t0, robot, segments, work_limit_s, start_force, cpu0)


def _plan(req: PlanRequest, t0: float, robot: RobotModel | None, segments: Sequence[Segment] | None,
          work_limit_s: float | None, start_force: np.ndarray | None = None,
          cpu0: float | None = None) -> PlanResult:
    model = _robot(req, robot)
    st = _with_substeps(req, model)
    if segments is None:
        segments = req.segments
    cells: tuple[str, float] | None = None  # a layout's cells where the request leaves their size out
    if segments is None and req.layout is not None:
        seg = segment_layout(req.layout, model, st)
        segments = seg.segments
        if req.layout.cell.size is None:
            cells = (seg.shape, seg.size)
        check_work(req, segments, work_limit_s)
    if segments is not None:
        check_segments(model, segments)
        if st.fastest:
            result = _fastest(req.name, model, st, segments, start_force)
            result.metrics.compute_ms = (time.perf_counter() - t0) * 1e3
            return result
    method = method_of(st)
    given = st
    st = resolve_timing(st, segments)  # speed_m_s / total_time_s -> samples_per_segment
    bound = None  # a refused plan's own work within REFUSAL_WORK x its estimate, as a plan's
    if st.mode == "constrained" and st.require_settled and cpu0 is not None:
        bound = WorkBound.of(estimate_work(req, segments).seconds, REFUSAL_WORK, cpu0)
    try:
        result = _plan_once(req.name, model, st, segments, req.reference, start_force, bound, method=method)
    except PlannerError as exc:
        if exc.code == "infeasible" and exc.field == "settings" and segments is not None:
            estimate_s = bound.estimate_s if bound is not None else estimate_work(req, segments).seconds
            budget = _advice_budget(work_limit_s, estimate_s, t0)
            advised = _more_time_advice(exc, req.name, model, given, st, segments, budget, estimate_s, cells)
            if "the time plans" not in advised.message:
                advised = _other_advice(advised, req, model, st, segments, budget, estimate_s, given, cells)
            raise advised from None
        raise
    result.metrics.compute_ms = (time.perf_counter() - t0) * 1e3  # everything, result arrays included
    mt = result.metrics
    if not mt.settled and st.require_settled:
        raise PlannerError("not_settled", f"the robot did not settle at the end point within "
                           f"{st.tail_max_s:g} s after the corridor (end error {mt.end_error_m * 1e3:.3f} mm, "
                           f"speed {mt.end_speed_m_s * 1e3:.3f} mm/s); lengthen settings.tail_max_s, "
                           "add samples per segment or raise k_r", "settings.tail_max_s")
    return result


def _with_substeps(req: PlanRequest, model: RobotModel) -> Settings:
    """The request's settings with ``plant_substeps`` following the robot's stiffness and
    ``Ts`` (:func:`planner.model.plant.plant_substeps`, at the corridor's start) where the
    request leaves it out: a given ``plant_substeps`` overrides (issue 31)."""
    st = req.settings
    if "plant_substeps" in st.model_fields_set:
        return st
    start = (req.segments[0].centre if req.segments is not None else
             req.reference.pose[0] if req.reference is not None else None)
    n = plant_substeps(model, st.Ts, start)
    return st if n == st.plant_substeps else st.model_copy(update={"plant_substeps": n})


def _rest_to_rest_s(d: float, a: float, j: float | None) -> float:
    """The shortest time [s] a point mass takes over ``d`` [m] from rest to rest with its
    acceleration at most ``a`` [m/s^2] and its jerk at most ``j`` [m/s^3] (None: no bound)."""
    if d <= 0.0:
        return 0.0
    if j is None:
        return 2.0 * float(np.sqrt(d / a))
    if d <= 2.0 * a ** 3 / j ** 2:  # the acceleration never reaches a: four jerk phases
        return 4.0 * float(np.cbrt(d / (2.0 * j)))
    t1 = a / j  # ramps of the acceleration, then phases at a
    t2 = 0.5 * (-3.0 * t1 + float(np.sqrt(t1 * t1 + 4.0 * d / a)))
    return 4.0 * t1 + 2.0 * t2


def _time_needed(model: RobotModel, st: Settings, segments: Sequence[Segment]) -> tuple[float, str] | None:
    """A lower bound [s] on the time the robot takes from the corridor's start point to its end
    point, and the limit that sets it, in words (issue 31: a request that asks less time than
    this is impossible as asked, and no other horizon or solver helps): each leg changes its
    length from the start's to the end's at most at its ``speed_max``; and, where the platform
    keeps its angle, the platform alone (without the legs' masses and friction, which only slow
    it) pushed by all drives together at their ``force_max`` and, with a force-rate limit,
    changing that push at most at the sum of the drives' rates, from rest to rest along the
    straight line; and the tool at most at ``settings.tool_speed_max_m_s`` along that line (from
    rest to rest at the drives' acceleration where the platform keeps its angle). None if the
    corridor does not start and end at a point."""
    first, last = segments[0], segments[-1]
    if not (np.array_equal(first.lower, first.upper) and np.array_equal(last.lower, last.upper)):
        return None
    a, b = np.asarray(first.lower, float), np.asarray(last.lower, float)
    from ..model.kinematics import leg_lengths

    change = np.abs(np.diff(leg_lengths(model, np.array([a, b])), axis=0)[0])
    legs = change / model.speed_max
    i = int(np.argmax(legs))
    out = [(float(legs[i]), f"leg {i}'s speed limit of {model.speed_max[i]:g} m/s (the leg changes by "
            f"{change[i] * 1e3:.4g} mm)")]
    if all(float(s.lower[2]) == float(s.upper[2]) == float(a[2]) for s in segments):
        d = float(np.hypot(*(b[:2] - a[:2])))
        force = float(np.sum(model.force_max))
        rate = st.force_rate_n_s
        if isinstance(rate, str):
            j = None
        else:
            rates = (model.force_max / DEFAULT_FORCE_RISE_S if rate is None
                     else np.broadcast_to(np.asarray(rate, float), model.force_max.shape))
            j = float(np.sum(rates)) / model.platform_mass
        t = _rest_to_rest_s(d, force / model.platform_mass, j)
        words = (f"the drive forces ({force:g} N together on the {model.platform_mass:g} kg platform alone, from "
                 f"rest to rest over the {d * 1e3:.4g} mm from the start to the end")
        if j is not None and t > 1.001 * _rest_to_rest_s(d, force / model.platform_mass, None):
            words += f", their force rates at most {j * model.platform_mass:g} N/s together (settings.force_rate_n_s)"
        out.append((t, words + ")"))
    v = st.tool_speed_max_m_s
    d = float(np.hypot(*(b[:2] - a[:2])))
    if v is not None and d > 0.0:
        # the tool covers at least the straight line from the start to the end at most at v; where
        # the platform keeps its angle, from rest to rest pushed by all drives at their force
        # limits (the platform alone): 2 sqrt(d / a) below v, d / v + v / a where it reaches v
        t = d / v
        words = (f"the tool-speed limit of {v:g} m/s (settings.tool_speed_max_m_s) over the {d * 1e3:.4g} mm "
                 "from the start to the end")
        if all(float(s.lower[2]) == float(s.upper[2]) == float(a[2]) for s in segments):
            acc = float(np.sum(model.force_max)) / model.platform_mass
            t = _rest_to_rest_s(d, acc, None) if d <= v * v / acc else d / v + v / acc
            words += f", from rest to rest (the drive forces' {acc:.4g} m/s^2 on the platform alone)"
        out.append((t, words))
    return max(out)


def _moving_time(st: Settings, segments: Sequence[Segment]) -> float:
    """The time [s] a resolved timing gives the robot from leaving the start point to being
    at the end point: the moving segments' samples and one more."""
    counts = (np.asarray(st.segment_samples, float) if st.segment_samples is not None
              else np.full(len(segments), float(st.samples_per_segment)))
    return float((counts[1:-1].sum() + 1.0) * st.Ts)


def _with_more_time(given: Settings, st: Settings, segments: Sequence[Segment], factor: int,
                    cells: tuple[str, float] | None) -> tuple[Settings, str] | None:
    """The settings of a plan with ``factor`` times the time (``st`` resolved from the request's
    ``given`` settings), resolved as a request would be, with ``require_settled``, and how the
    advice names them in the timing field the request used; None over the limits on samples.
    ``cells``: see :func:`_more_time_advice`."""
    counts = np.asarray(st.segment_samples if st.segment_samples is not None
                        else [st.samples_per_segment] * len(segments), dtype=np.int64)
    new = counts * factor
    if int(new.max()) > MAX_SAMPLES_PER_SEGMENT or int(new.sum()) + st.tail_steps > MAX_TOTAL_STEPS:
        return None
    if given.speed_m_s is not None:
        advised = given.model_copy(update={"speed_m_s": given.speed_m_s / factor})
        how = f"settings.speed_m_s = {given.speed_m_s / factor:.6g} m/s"
    elif given.total_time_s is not None:
        advised = given.model_copy(update={"total_time_s": given.total_time_s * factor})
        how = f"settings.total_time_s = {given.total_time_s * factor:.6g} s"
    elif given.segment_samples is not None:
        advised = st.model_copy(update={"segment_samples": [int(c) for c in new],
                                        "samples_per_segment": int(new.max())})
        how = f"settings.segment_samples x {factor}"
    else:
        advised = st.model_copy(update={"samples_per_segment": int(st.samples_per_segment * factor)})
        how = f"settings.samples_per_segment = {st.samples_per_segment * factor}"
        if cells is not None:
            how += f" with layout.cell.size = {float(cells[1])!r} m, the cell size it has now"
            if cells[0] != "square":
                how += f" (layout.cell.shape = {cells[0]})"
    try:
        return resolve_timing(advised, segments).model_copy(update={"require_settled": True}), how
    except PlannerError:
        return None


@dataclass
class AdviceBudget:
    """What the advice search behind a refusal may still take (issue 31 goal 2, issue 33 goal 2):
    ``seconds`` of work estimate (reference seconds, as :func:`~.work.estimate_work` counts
    them; None: no bound), from which each candidate's estimate is taken before it is tried,
    so the same request gets the same advice on a quiet machine and a loaded one (the wall time
    a candidate took, counted before, stopped the search at another candidate under load);
    ``deadline``: the :func:`time.perf_counter` value at the server's limit, a safety stop
    only (a machine so slow that the limit passes: no candidate is started after it)."""

    seconds: float | None = None
    deadline: float | None = None

    def take(self, cost_s: float, bound_s: float | None = None) -> bool:
        """Whether a candidate estimated at ``cost_s`` fits what is left (or ``bound_s`` where
        there is no bound); if it does, it is taken from what is left."""
        if self.deadline is not None and time.perf_counter() >= self.deadline:
            return False
        left = self.seconds if self.seconds is not None else bound_s
        if left is not None and cost_s > left:
            return False
        if self.seconds is not None:
            self.seconds -= cost_s
        return True


def _advice_budget(work_limit_s: float | None, estimate_s: float, t0: float) -> AdviceBudget:
    """The advice search's budget under the compute limit ``work_limit_s`` [s] (None or <= 0:
    no bound): the limit less the refused plan's own estimate (``estimate_s``), and the
    limit's wall time from ``t0`` (the request's start) as the safety stop."""
    if work_limit_s is None or work_limit_s <= 0:
        return AdviceBudget()
    return AdviceBudget(work_limit_s - estimate_s, t0 + work_limit_s)


def _more_time_advice(exc: PlannerError, name: str | None, model: RobotModel, given: Settings, st: Settings,
                      segments: Sequence[Segment], budget: AdviceBudget | None = None,
                      estimate_s: float = 0.0, cells: tuple[str, float] | None = None) -> PlannerError:
    """``exc`` (an infeasible constrained plan) with advice that was checked: the corridor
    planned again with :data:`MORE_TIME` times the samples of every segment (each candidate
    abandoned at its first infeasible step; a factor that gives less time than
    :func:`_time_needed` is not planned: it cannot plan), as far as the limits on samples and
    the budget allow; the first that plans is named in the timing field the request used. If
    the request's time is under that bound, the error says so, with the limit and the amount.
    If none plans, the error says that more time does not help.
    ``budget``: the work the checks may take (None: no bound); a candidate whose estimate
    (``estimate_s`` of the request times the factor) does not fit is not planned, one that fits
    is taken from it before it is planned.
    ``cells``: the shape and size [m] of the cells the request's layout was segmented into where
    it left their size out; more samples a segment give another default
    (:func:`~planner.corridor.cell_size_rule`), so advice in samples names these cells too,
    which keeps the corridor the check planned."""
    tried: list[int] = []
    stop = ""  # why the search stopped early
    needed = _time_needed(model, st, segments)
    moving_s = _moving_time(st, segments)
    below: list[int] = []  # factors that give less time than the bound: not planned
    head = exc.message
    if needed is not None and moving_s < needed[0]:
        head += (f"; the request is impossible as asked: with {needed[1]}, the robot needs at least {needed[0]:.3g} s "
                 f"from the start to the end, its timing gives {moving_s:.3g} s "
                 f"({needed[0] / moving_s:.3g}x too little)")
    exc = PlannerError(exc.code, head, exc.field)
    for factor in MORE_TIME:
        if needed is not None and moving_s * factor < needed[0]:
            below.append(factor)
            continue
        timed = _with_more_time(given, st, segments, factor, cells)
        if timed is None:
            stop = "more time exceeds the limits on samples"
            break
        sub, how = timed
        if budget is not None and not budget.take(estimate_s * factor):
            stop = "more was not tried within the work limit"
            break
        tried.append(factor)
        try:
            settled = _run(name, model, sub, segments, None, abandon=True)[0].metrics.settled
        except PlannerError as again:
            if again.code == "infeasible":
                continue
            stop = f"{factor}x the time fails otherwise ({again.code})"
            break
        if not settled:
            stop = f"{factor}x the time keeps the corridor but does not settle within settings.tail_max_s"
            break
        return PlannerError("infeasible", f"{exc.message}; {factor}x the time plans ({how}, checked)", exc.field)
    if not tried:
        more = f"up to {below[-1]}x the time cannot plan (under that bound); more" if below else "more time"
        return PlannerError("infeasible", f"{exc.message}; {more} was not tried ({stop or 'no factor left'})",
                            exc.field)
    times = ", ".join(f"{f}x" for f in tried)
    if stop:
        return PlannerError("infeasible", f"{exc.message}; {times} the time do not help either (checked; {stop})",
                            exc.field)
    return PlannerError("infeasible", f"{exc.message}; {times} the time do not help either (checked): the "
                        "corridor is too narrow there for the robot's drive limits", exc.field)


#: the compute time [s] the advice of a longer horizon with more time may take where the request
#: has no work limit of its own (a server's limit bounds it otherwise)
COMBINED_ADVICE_S = 60.0


def _other_advice(exc: PlannerError, req: PlanRequest, model: RobotModel, st: Settings,
                  segments: Sequence[Segment], budget: AdviceBudget | None, estimate_s: float,
                  given: Settings | None = None, cells: tuple[str, float] | None = None) -> PlannerError:
    """``exc`` (an infeasible plan that more time did not cure, or more time was not tried)
    with the first of these remedies that plans, checked (issue 31: at Ts 2 ms a third of the
    short corridors were refused with "2x ... 16x the time do not help" while a longer horizon
    or ``fastest`` planned): a longer horizon ``N`` (the robot's default horizon where the
    request gave a shorter one, else twice the horizon, at most MAX_HORIZON) at the timing the
    request asked for; a horizon that previews as much of the corridor as the request's did with
    more time (``f N`` samples, at most MAX_HORIZON, at ``f`` times the time, ``f`` the first of
    :data:`MORE_TIME` at least twice what :func:`_time_needed` asks and at least 2; issue 31: a
    leg speed of 0.01 m/s planned Table I with N 200 and 16x the time, not with either alone;
    within :data:`COMBINED_ADVICE_S` where the request has no work limit; ``given`` and
    ``cells`` as :func:`_more_time_advice` takes them); then ``settings.fastest``, then more
    plant sub-steps (the robot's own
    count where the request gave fewer, else twice, at most 50); each within ``budget`` (its
    estimate, from ``estimate_s`` of the request, must fit, and is taken from it before it is
    planned). Unchanged if none plans."""
    tried: list[str] = []
    budget = budget if budget is not None else AdviceBudget()

    def plans(sub: Settings) -> bool:
        """Whether ``sub`` plans the corridor and settles (checked)."""
        try:
            return bool(_run(req.name, model, sub, segments, None, abandon=True)[0].metrics.settled)
        except PlannerError:
            return False

    # a remedy found: the time factors did not help, but the corridor is not too narrow
    head = exc.message.replace(": the corridor is too narrow there for the robot's drive limits", "")
    default_N = default_horizon(st.Ts, req.robot_description, st.force_rate_n_s)
    N = default_N if "N" in st.model_fields_set and st.N < default_N else min(2 * st.N, MAX_HORIZON)
    if N > st.N:
        cost = estimate_s * N / st.N
        if budget.take(cost):
            if plans(st.model_copy(update={"N": N, "require_settled": True})):
                return PlannerError("infeasible", f"{head}; settings.N = {N} plans (a longer horizon at "
                                    "the same timing, checked)", "settings.N")
            tried.append(f"settings.N = {N}")
    needed = _time_needed(model, st, segments)
    ratio = max(1.0, needed[0] / _moving_time(st, segments)) if needed is not None else 1.0
    factor = next((f for f in MORE_TIME if f >= 2.0 * ratio), None)
    timed = _with_more_time(given, st, segments, factor, cells) if factor is not None and given is not None else None
    if timed is not None and factor is not None:
        sub, how = timed
        N_far = min(MAX_HORIZON, st.N * factor)
        cost = estimate_s * factor * N_far / st.N
        if N_far > st.N and budget.take(cost, COMBINED_ADVICE_S):
            if plans(sub.model_copy(update={"N": N_far})):
                return PlannerError("infeasible", f"{head}; settings.N = {N_far} with {factor}x the time ({how}) "
                                    "plans (checked)", "settings.N")
            tried.append(f"settings.N = {N_far} with {factor}x the time")
    if not st.fastest:
        fast = req.model_copy(update={"settings": Settings.model_validate(
            {**req.settings.model_dump(mode="json", exclude_unset=True, exclude={*TIMING_FIELDS}), "fastest": True})})
        cost = estimate_work(fast, segments).seconds
        if budget.take(cost):
            fst = st.model_copy(update={"fastest": True, "speed_m_s": None, "total_time_s": None,
                                        "segment_samples": None})
            try:
                res = _fastest(req.name, model, fst, segments)
                return PlannerError("infeasible", f"{head}; settings.fastest plans it in "
                                    f"{res.metrics.duration_s:.3g} s (checked)", "settings.fastest")
            except PlannerError:
                tried.append("settings.fastest")
    # finer plant integration (issue 31: stiff legs, friction 2000 N s/m, planned with 8 RK4 steps a
    # sample): the robot's own count where the request gave fewer, else twice the steps
    auto = plant_substeps(model, st.Ts, np.asarray(segments[0].centre, float))
    steps = auto if st.plant_substeps < auto else min(2 * st.plant_substeps, 50)
    if steps > st.plant_substeps and auto > 1:  # (a robot whose stiffness one step a sample suits: no)
        cost = estimate_s * steps / st.plant_substeps
        if budget.take(cost):
            if plans(st.model_copy(update={"plant_substeps": steps, "require_settled": True})):
                return PlannerError("infeasible", f"{head}; settings.plant_substeps = {steps} plans (a finer "
                                    "integration of the robot at the same timing, checked)",
                                    "settings.plant_substeps")
            tried.append(f"settings.plant_substeps = {steps}")
    if tried:
        return PlannerError("infeasible", f"{exc.message}; {' and '.join(tried)} do not plan either (checked)",
                            exc.field)
    return exc


def _plan_once(name: str | None, model: RobotModel, st: Settings, segments: Sequence[Segment] | None,
               reference: Reference | None, start_force: np.ndarray | None = None, bound: WorkBound | None = None,
               **timing: object) -> PlanResult:
    """One run of the loop at fixed timing; raises ``infeasible`` for a constrained plan that
    needed slack when ``require_settled`` asks for a guaranteed plan (``bound``: the work its
    refused step may take, :class:`~planner.constraints.controller.WorkBound`)."""
    return _run(name, model, st, segments, reference, timing=timing, start_force=start_force, bound=bound)[0]


def _run(name: str | None, model: RobotModel, st: Settings, segments: Sequence[Segment] | None,
         reference: Reference | None,
         resume: Resume | None = None, keep: Sequence[int] = (), timing: dict | None = None,
         abandon: bool = False, start_force: np.ndarray | None = None,
         bound: WorkBound | None = None) -> tuple[PlanResult, Simulation]:
    """:func:`_plan_once` from ``resume`` (or the start), remembering the states at ``keep``;
    returns the simulation too. ``abandon``: stop at the first infeasible step (a candidate
    of the ``fastest`` search). ``start_force``: the forces held before the first sample [N]
    (:func:`plan`; zero if None). ``bound``: the work a refused step may take (:func:`_plan_once`)."""
    seq: RangeSequence
    if segments is not None:
        seq = range_sequence(list(segments), st, model.n_legs)
    else:
        assert reference is not None
        for i, pose in enumerate(reference.pose):
            check_pose(model, pose, f"reference.pose[{i}]")
        seq = reference_sequence(reference.pose, st, model.n_legs)
    check_pose(model, seq.start, "segments[0]" if segments is not None else "reference.pose[0]")
    controller: ConstrainedController | None = None
    if st.mode == "constrained":
        controller = ConstrainedController(model, seq, st, segments, abandon=abandon,
                                           slack=slack_allowance(st, seq.K + st.tail_steps), bound=bound)
        if start_force is not None:  # the first step's force-rate rows from the forces held before it
            controller.memory.u_prev[:] = start_force
    sim = simulate(model, seq, st, controller, resume, keep)
    report = controller.report() if controller is not None else {}
    result = build_result(model, name, st, seq, segments, sim, report, timing_info(st, segments, **(timing or {})),
                          start_force)
    mt = result.metrics
    if controller is not None and (mt.infeasible_steps or 0) > 0 and st.require_settled:
        raise controller.infeasible_error(
            f"the constrained plan cannot keep the robot in the corridor within the drive limits: "
            f"{mt.infeasible_steps} of {mt.steps} steps needed slack (up to "
            f"{(mt.constraint_slack_max_m or 0.0) * 1e3:.4f} mm)")
    return result, sim


def plan_timed(name: str | None, model: RobotModel, st: Settings, segments: Sequence[Segment],
               counts: Sequence[int], *, abandon: bool = True, start_force: np.ndarray | None = None) -> PlanResult:
    """One constrained plan of ``segments`` held ``counts`` samples each (a caller's own
    timing search, e.g. :mod:`planner.contour`). ``abandon``: raise ``infeasible`` at the first
    step that needs slack instead of planning on. The segments' reach is the caller's check.
    ``start_force``: the forces held before the first sample [N] (:func:`plan`)."""
    t0 = time.perf_counter()
    sub = st.model_copy(update={"fastest": False, "segment_samples": [int(c) for c in counts],
                                "samples_per_segment": int(max(counts)), "require_settled": True})
    with numpy_only(st.backend == "reference"):
        result = _run(name, model, sub, segments, None, abandon=abandon,
                      timing={"method": "segment_samples"}, start_force=start_force)[0]
    result.metrics.compute_ms = (time.perf_counter() - t0) * 1e3
    return result


def _fastest(name: str | None, model: RobotModel, st: Settings, segments: Sequence[Segment],
             start_force: np.ndarray | None = None) -> PlanResult:
    """The plan at the fastest feasible timing (:mod:`.fastest`; ``start_force``: :func:`plan`)."""
    gaps = corridor_gaps(segments, 2 * MARGIN_M, 2 * MARGIN_RAD)

    def plan_at(counts: np.ndarray, resume: Resume | None, keep: Sequence[int]) -> tuple[PlanResult, Simulation]:
        # require_settled: a candidate is abandoned at its first infeasible step
        sub = st.model_copy(update={"fastest": False, "segment_samples": [int(c) for c in counts],
                                    "samples_per_segment": int(counts.max()), "require_settled": True})
        return _run(name, model, sub, segments, None, resume, keep, abandon=True, start_force=start_force)

    best, evaluations = search_fastest(plan_at, st, segments)
    if best is None or best.result is None:
        why = (f"{gaps[0].describe()}; the robot would have to jump between them within one sample, which no "
               "timing allows: connect or widen the segments") if gaps else \
            "no timing up to the limits keeps the corridor within the drive limits"
        raise PlannerError("infeasible", why, f"segments[{gaps[0].index + 1}]" if gaps else "settings.fastest")
    res = best.result
    counts = [int(c) for c in best.counts]
    final = st.model_copy(update={"fastest": False, "segment_samples": counts, "samples_per_segment": max(counts)})
    res.settings = final
    res.timing = timing_info(final, segments, method="fastest", evaluations=evaluations, feasible=True,
                             one_fewer_sample_infeasible=True)
    return res


def warm_up(backend: str = "compiled") -> float:
    """Compile (first run after installing) or load (afterwards, from numba's on-disk cache)
    the compiled kernels of every path by planning tiny corridors: the paper mode; the
    constrained mode with equalities eliminated (psi fixed), with the QP in the inputs (a
    psi range) and the slack problem (too little time); and segments a small layout in both
    cell shapes. Returns the seconds taken, and marks the cache compiled (:func:`.background.mark_compiled`). Servers
    call it before taking jobs, ``make`` after installing (``python -m planner``). Compiling is
    reported on stderr with an estimate of the time left (:mod:`.compiling`).
    ``backend="reference"``: the same on the numpy reference (imports and first calls; nothing
    compiles, no marker): a service's workers while the kernels compile in the background
    (:mod:`.background`)."""
    from .background import mark_compiled
    from .compiling import compile_progress

    t0 = time.perf_counter()
    fixed = [{"lower": [0.0, 0.0, 0.0], "upper": [0.0, 0.0, 0.0]},
             {"lower": [0.0, 0.0, 0.0], "upper": [0.01, 0.01, 0.0]},
             {"lower": [0.01, 0.01, 0.0], "upper": [0.01, 0.01, 0.0]}]
    turning = [{"lower": [0.0, 0.0, 0.0], "upper": [0.0, 0.0, 0.0]},
               {"lower": [0.0, 0.0, 0.0], "upper": [0.04, 0.01, 0.02]},
               {"lower": [0.04, 0.01, 0.02], "upper": [0.04, 0.01, 0.02]}]
    base = {"N": 5, "require_settled": False, "tail_max_s": 0.05, "backend": backend}
    runs: list[tuple[list, dict]] = [
        (fixed, {"mode": "paper"}), (fixed, {"mode": "constrained"}),
        (turning, {"mode": "constrained", "samples_per_segment": 30}),
        (turning, {"mode": "constrained", "samples_per_segment": 2})]
    with compile_progress():
        for segs, extra in runs:
            plan({"robot": "moving-slide", "segments": segs, "settings": {**base, **extra}})
        # and a layout's segmentation in both cell shapes: the first layout a process planned
        # took ~80 ms more (shapely and the grid's modules loading), 5x its estimate (issue 20)
        for shape in ("square", "triangle"):
            segment({"robot": "moving-slide", "layout": {
                "bounds": {"lower": [-0.02, -0.02], "upper": [0.02, 0.02]},
                "obstacles": [{"type": "rectangle", "lower": [-0.005, -0.005], "upper": [0.005, 0.005]},
                              {"type": "circle", "center": [0.01, -0.01], "radius": 0.003}],
                "cell": {"shape": shape, "size": 0.005}, "start": [-0.015, -0.015, 0.0], "end": [0.015, 0.015, 0.0]},
                "settings": {"backend": backend}})
    if backend == "compiled":
        mark_compiled()  # every kernel is in the cache now: the done-marker (.background.kernels_ready)
    return time.perf_counter() - t0
