"""Planning for the editor: the background re-plan worker and the one place the editor
imports from ``planner``.

Every other editor module gets the planner's functionality (plan, request parsing, the
segmentation, robots, ``MODE_DEFAULTS``, ``to_csv``, ``PlannerError``, ...) through the
names this module re-exports, so that a change of the planner's import paths touches this
file only.

Re-plans run on :class:`PlanWorker`, a thread with a debounce and a generation counter:
``schedule()`` returns at once (GUI callbacks never wait for a plan), the worker computes
only the newest generation, and the caller drops a result whose generation is no longer
current (a stale result never overwrites a newer one).

Where a plan is computed: every re-plan and drawing import is a typed job
(:class:`app.jobs.EditorJob`, :class:`app.jobs.ImportJob`; a G-code program's design, a
contour request, :class:`app.jobs.ContourJob` as ``POST /v1/contour`` runs it) submitted to the service's one
executor, :class:`app.service.JobService`. Under ``rangeplan serve`` that is the API's
service (:func:`use_service`): the same worker processes, work estimate, time limit, memory
limit and error codes as ``POST /v1/plan``, never in the server process. Without one (an
editor started on its own, tests) the job runs on the editor's worker thread under the same
estimate and limit (``RANGEPLAN_PLAN_TIMEOUT_S``).
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import ValidationError

from app.formats import MACHINE_FORMATS, OUTPUT_FORMATS, write
from app.jobs import ContourJob, EditorJob, EditorPlan, ErrorDetail, Failed, ImportJob
from app.service import JobService
from app.settings import settings
from planner import PlannerError, PlanRequest, PlanResult, RobotModel, load_robot
from planner.exchange import Toolpath, read_gcode, toolpath
from planner.model import SINGULAR_TOL, kinematics
from planner.model.placement import Placement, fit_shape, reach_extent, reachable_mask, reachable_points
from planner.schema import (
    DEFAULT_LAYOUT_SPEED_M_S,
    DEFAULT_MODE,
    DEFAULT_ROBOT,
    MAX_CONTOUR_TOLERANCE_M,
    MAX_LEGS,
    MIN_CONTOUR_TOLERANCE_M,
    MODE_DEFAULTS,
    PARTIAL_LAYOUT,
    Cell,
    ContourRequest,
    ImportOptions,
    ImportResult,
    Layout,
    RobotDescription,
    SegmentationResult,
    Settings,
    builtin_description,
    builtin_robot_names,
    default_horizon,
    format_validation_error,
    planner_error,
)

__all__ = [
    "DEFAULT_LAYOUT_SPEED_M_S",
    "DEFAULT_MODE",
    "DEFAULT_ROBOT",
    "ErrorDetail",
    "HAS_SPEED_SETTING",
    "MACHINE_FORMATS",
    "OUTPUT_FORMATS",
    "MAX_CONTOUR_TOLERANCE_M",
    "MAX_LEGS",
    "MIN_CONTOUR_TOLERANCE_M",
    "MODE_DEFAULTS",
    "SINGULAR_TOL",
    "ContourRequest",
    "PlanOutcome",
    "PlanRequest",
    "PlanResult",
    "PlanWorker",
    "PlannerError",
    "SegmentationResult",
    "Toolpath",
    "Robot",
    "RobotCache",
    "builtin_robot_names",
    "compute_plan",
    "is_contour",
    "program_toolpath",
    "tube_cells",
    "to_csv",
    "use_pool",
    "use_service",
    "validate_request",
    "editable",
    "field_bounds",
    "auto_horizon",
    "Placement",
    "fit_shape",
    "reachable_mask",
    "reachable_points",
    "reachable_region",
    "robot_geometry",
    "drawing_request",
    "export_result",
    "read_gcode",
    "toolpath",
]

log = logging.getLogger("rangeplan.editor")
#: the editor's name: the extent and centroid of the reach at one angle
reachable_region = reach_extent

#: the job service re-plans and imports are submitted to, or None: inline (:func:`_service`)
_shared: JobService | None = None


def use_service(service: JobService | None) -> None:
    """Submit re-plans and imports to ``service`` (the API's, under ``rangeplan serve``)
    from now on; None: run them on the editor's worker thread (same estimate and limit)."""
    global _shared
    _shared = service


def use_pool(pool: Any) -> None:
    """:func:`use_service` with a service around ``pool`` (an :class:`app.workers.PlanPool`)."""
    use_service(JobService(pool) if pool is not None else None)


def _service() -> JobService:
    return _shared if _shared is not None else JobService(None, timeout_s=settings().plan_timeout_s)

Robot = RobotModel
#: whether this planner's settings have a travel speed ``speed_m_s`` [m/s]
HAS_SPEED_SETTING = "speed_m_s" in Settings.model_fields


def is_contour(request: dict | None) -> bool:
    """Whether the design ``request`` is a G-code program to contour (a
    :class:`~planner.schema.ContourRequest`: it has a ``program``), not a plan request."""
    return isinstance(request, dict) and "program" in request


def validate_request(request: dict) -> tuple[PlanRequest | ContourRequest | None, str | None]:
    """The request validated as planning and storage validate it (a G-code program's design
    as ``POST /v1/contour`` validates it): ``(request, None)`` or ``(None, one line naming the
    field and the cause)``."""
    try:
        if is_contour(request):
            return ContourRequest.model_validate(request), None
        return PlanRequest.model_validate(request), None
    except ValidationError as exc:
        return None, format_validation_error(exc)


def field_bounds(model: str, field: str) -> dict[str, float]:
    """The numeric bounds (``gt``, ``ge``, ``lt``, ``le``) of a field of the request schema
    (``model`` one of "Settings", "Layout", "Cell"), so that the editor's fields check what
    validation checks; e.g. ``field_bounds("Settings", "Ts") == {"ge": 1e-4, "le": 1.0}``."""
    cls = {"Settings": Settings, "Layout": Layout, "Cell": Cell}[model]
    out: dict[str, float] = {}
    for meta in cls.model_fields[field].metadata:
        for key in ("gt", "ge", "lt", "le"):
            value = getattr(meta, key, None)
            if value is not None:
                out[key] = value  # as declared (1.0, 200): messages print it as the planner does
    return out


@functools.lru_cache(maxsize=32)
def _builtin_description(name: str) -> RobotDescription:
    return builtin_description(name)


def auto_horizon(request: dict) -> int | None:
    """The horizon ``N`` [samples] the planner uses for ``request`` when its settings give
    none: the paper mode's fixed default, or the constrained mode's from the sample time, the
    robot and the force-rate limit (:func:`planner.schema.default_horizon`). None when the
    settings or the robot do not validate (the planner then says what is wrong)."""
    given = request.get("settings") or {}
    try:
        st = Settings.model_validate({k: v for k, v in given.items() if k != "N"})
        if st.mode != "constrained":
            return int(st.N)
        robot = request.get("robot", DEFAULT_ROBOT)
        desc = _builtin_description(robot) if isinstance(robot, str) else RobotDescription.model_validate(robot)
        return default_horizon(st.Ts, desc, st.force_rate_n_s)
    except (ValidationError, PlannerError, KeyError, TypeError, ValueError):
        return None


def robot_geometry(robot: RobotModel, pose) -> dict:
    """The robot drawn at ``pose`` = [x, y, psi] (tool point, m, m, rad): base pivots (n, 2),
    platform pivots in the world frame (n, 2) and leg lengths (n,) [m]."""
    pose = np.asarray(pose, dtype=float)
    rx, ry, dx, dy = kinematics.leg_vectors(robot, pose[None])
    pivots = np.column_stack((pose[0] + rx[0], pose[1] + ry[0]))
    return {"base": robot.base.copy(), "pivots": pivots, "lengths": np.hypot(dx[0], dy[0])}


def editable(req: PlanRequest | ContourRequest) -> dict:
    """A validated request as the editor's state: what the client gave (settings the mode
    decides stay unset), with the layout complete (every field, top-level start/end merged
    in), in JSON types. A contour request: its fields in JSON types."""
    if isinstance(req, ContourRequest):
        return req.model_dump(mode="json", exclude_none=True)
    out = req.to_json_dict()
    if req.layout is not None:
        out["layout"] = req.layout.model_dump(mode="json", exclude_none=True)
        for key in ("start", "end", "psi_range"):
            out.pop(key, None)
    return out


def to_csv(result: PlanResult, header: tuple[str, ...] = ()) -> str:
    """The CSV of a plan result, ``header`` as its first comment lines."""
    return write(result, "csv", header=header).decode()


def drawing_request(data: bytes, filename: str, request: dict, options: dict) -> tuple[dict, str]:
    """``request`` with its layout's bounds and obstacles replaced by a drawing's
    (:func:`planner.exchange.import_drawing` with ``options``, on the pool of :func:`use_pool`
    when there is one: the API's workers, compute limit and memory cap); start, end, cell,
    clearance and psi range stay. Returns the new request and a one-line summary; raises
    :class:`PlannerError` naming the cause for a bad drawing (or too much work)."""
    res = _read_drawing(data, filename, options)
    layout = dict(request.get("layout") or {})
    imported = res.layout.model_dump(mode="json", include={"bounds", "obstacles"}, exclude_unset=True)
    layout.update(imported)  # the draft (a dict) takes the drawing's bounds and obstacles
    lo, hi = np.asarray(res.layout.bounds.lower), np.asarray(res.layout.bounds.upper)
    for key, corner in (("start", lo + 0.05 * (hi - lo)), ("end", hi - 0.05 * (hi - lo))):
        layout.setdefault(key, [float(corner[0]), float(corner[1]), 0.0])  # a design without a layout: corners
    request = {k: v for k, v in request.items() if k not in ("segments", "reference")}
    rep = res.report
    summary = (f"{len(rep.shapes)} obstacle(s), {rep.holes} hole(s) from layers {', '.join(rep.layers)}; units "
               f"{rep.units} ({rep.units_source}); {len(rep.open_chains)} open chain(s) left out")
    return {**request, "layout": layout}, summary


def _read_drawing(data: bytes, filename: str, options: dict) -> ImportResult:
    try:
        opts = ImportOptions.model_validate(options)
    except ValidationError as exc:
        raise planner_error(exc) from None
    out = _service().run(ImportJob(data, opts, filename))
    if isinstance(out, Failed):
        raise PlannerError(out.error.code, out.error.message, out.error.field)
    return ImportResult.model_validate_json(out.payload or b"", context=PARTIAL_LAYOUT)


def export_result(result: PlanResult, fmt: str, request: PlanRequest | ContourRequest | dict,
                  header: tuple[str, ...] = ()) -> str:
    """A plan result in a machine format (:data:`MACHINE_FORMATS`: G-code, leg lengths, DXF
    with the obstacles of ``request``'s layout: the validated request the result was planned
    for, or a draft dict, validated here), ``header`` lines (design, plan id, request hash)
    in its header."""
    model = request if isinstance(request, (PlanRequest, ContourRequest)) else validate_request(request)[0]
    layout = model.layout if isinstance(model, PlanRequest) else None  # a contour draws no obstacles
    return write(result, fmt, layout=layout, source="rangeplan editor", header=header).decode()


class RobotCache:
    """Robots loaded from their specs (a built-in name or a description dict), kept by
    spec; safe to use from the GUI threads and the worker at once."""

    def __init__(self) -> None:
        self._robots: dict[str, Robot] = {}
        self._lock = threading.Lock()

    def get(self, spec) -> Robot:
        """The robot of ``spec``; raises :class:`PlannerError` for a bad spec."""
        key = json.dumps(spec, sort_keys=True)
        with self._lock:
            robot = self._robots.get(key)
        if robot is None:
            robot = load_robot(spec)
            with self._lock:
                robot = self._robots.setdefault(key, robot)
        return robot

    def of_request(self, request: dict, *, fallback: bool = False) -> Robot | None:
        """The robot ``request`` names. For a bad spec: the default robot with
        ``fallback``, else None."""
        try:
            return self.get(request.get("robot", DEFAULT_ROBOT))
        except PlannerError:
            return self.get(DEFAULT_ROBOT) if fallback else None


@dataclass(frozen=True)
class PlanOutcome:
    """What one re-plan produced, typed: the segmentation (None for a request without a
    layout or when segmenting failed), the plan result (or None) and the error (or None);
    ``seconds`` is the wall time [s]; ``request`` the validated request it planned (None:
    the request was invalid)."""

    segmentation: SegmentationResult | None
    result: PlanResult | None
    error: ErrorDetail | None
    seconds: float
    request: PlanRequest | ContourRequest | None = None


def compute_plan(request: dict, robots: RobotCache) -> PlanOutcome:
    """Validate ``request`` (the one JSON shape), then segment (when it has a layout) and
    plan it as an :class:`app.jobs.EditorJob` of the job service. Never raises for a bad
    request, an impossible plan or too much work: those become ``PlanOutcome.error``.
    (``robots``: the editor's cache, for drawing; the job loads its own.)"""
    t0 = time.perf_counter()

    def outcome(plan: EditorPlan, req: PlanRequest | ContourRequest | None = None) -> PlanOutcome:
        return PlanOutcome(plan.segmentation, plan.result, plan.error, time.perf_counter() - t0, req)

    contour = is_contour(request)
    try:
        req = ContourRequest.model_validate(request) if contour else PlanRequest.model_validate(request)
    except ValidationError as exc:  # the first failing field names the error; the message lists up to three
        first = planner_error(exc)
        message = format_validation_error(exc).removeprefix(f"{first.field}: ")
        return outcome(EditorPlan(error=ErrorDetail(code=first.code, message=message, field=first.field, details=None)))
    if isinstance(req, ContourRequest):  # a G-code program: the contour job, as POST /v1/contour runs it
        done = _service().run(ContourJob(req, "json", source="rangeplan editor"))
        if isinstance(done, Failed):
            return outcome(EditorPlan(error=done.error), req)
        return outcome(EditorPlan(result=PlanResult.model_validate_json(done.payload or b"{}")), req)
    out = _service().run(EditorJob(req))
    if isinstance(out, Failed):
        return outcome(EditorPlan(error=out.error), req)
    # the worker's JSON parsed once into the result models (it crossed a process boundary)
    return outcome(EditorPlan.model_validate_json(out.payload or b"{}"), req)


#: programs read for drawing, by their text and reading options (the newest few)
_programs: dict[tuple, Toolpath] = {}
_programs_lock = threading.Lock()


def program_toolpath(request: dict) -> Toolpath:
    """The programmed path of a G-code program's design (``request``: a contour request dict)
    as :func:`planner.exchange.read_gcode` reads it (the reading the contour job plans from:
    the same ``cut_below_m`` and ``z_rapid_m_s``), as a polyline in the program frame
    (:func:`planner.exchange.toolpath`: arcs sampled 0.5 mm apart at most, rapids marked). The
    last few are kept (a re-plan after an edit of the origin or the tolerance reads nothing).
    Raises :class:`PlannerError` naming the line for a bad program."""
    cut_below = float(request.get("cut_below_m", 0.0))
    z_rapid = float(request.get("z_rapid_m_s", 0.05))
    text = str(request.get("program", ""))
    key = (hashlib.sha256(text.encode()).hexdigest(), cut_below, z_rapid)
    with _programs_lock:
        found = _programs.get(key)
    if found is not None:
        return found
    path = toolpath(read_gcode(text, cut_below=cut_below, z_rapid_m_s=z_rapid))
    with _programs_lock:
        if len(_programs) >= 4:
            _programs.pop(next(iter(_programs)))
        _programs[key] = path
    return path


def tube_cells(result: PlanResult) -> list[np.ndarray]:
    """The tolerance tube of a contour plan: the convex cells (each (m, 2) [m], robot frame) its
    cut passes were planned through, in order (the corridor's segments with a polygon; the
    boxes of the travel moves and the points at the passes' ends have none)."""
    return [np.asarray(s.polygon, float) for s in result.corridor.segments or [] if s.polygon is not None]


class PlanWorker(threading.Thread):
    """Runs re-plans off the GUI threads.

    ``schedule()`` bumps the generation and sets the time the plan may start (the
    debounce, [s]); the worker then calls ``run_generation(gen)`` for the newest
    generation only. ``run_generation`` checks :meth:`is_current` before it publishes.
    An exception in ``run_generation`` goes to ``on_crash`` and the worker keeps running.
    """

    def __init__(self, run_generation: Callable[[int], Any], on_crash: Callable[[Exception], Any],
                 debounce_s: float):
        super().__init__(name="rangeplan-editor-planner", daemon=True)
        self._run_generation = run_generation
        self._on_crash = on_crash
        self.debounce_s = debounce_s  #: quiet time after the last edit before a re-plan starts [s]
        self._cv = threading.Condition()
        self.requested = 0  #: newest generation asked for
        self.started = 0  #: generation being computed / last computed
        self.finished = 0  #: last generation whose computation ended (published or discarded)
        self._due = 0.0  # time.monotonic() [s] at which the newest generation may start
        self._stopping = False

    def schedule(self, immediate: bool = False) -> int:
        """Ask for a re-plan (after the debounce unless ``immediate``); returns its generation."""
        with self._cv:
            self.requested += 1
            self._due = time.monotonic() + (0.0 if immediate else self.debounce_s)
            self._cv.notify_all()
            return self.requested

    def is_current(self, gen: int) -> bool:
        """Whether ``gen`` is still the newest generation asked for."""
        with self._cv:
            return gen == self.requested

    def idle(self) -> bool:
        """Whether no re-plan is pending or running."""
        with self._cv:
            return self.finished == self.requested

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` [s] until idle; returns whether it is."""
        end = time.monotonic() + timeout_s
        with self._cv:
            while self.finished != self.requested:
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._cv.wait(min(left, 0.1))
            return True

    def stop(self) -> None:
        """Ask the thread to end (it finishes a plan it is computing first)."""
        with self._cv:
            self._stopping = True
            self._cv.notify_all()

    def run(self) -> None:
        while True:
            with self._cv:
                while not self._stopping:
                    if self.requested != self.finished:
                        wait = self._due - time.monotonic()
                        if wait <= 0:
                            break
                        self._cv.wait(wait)
                    else:
                        self._cv.wait()
                if self._stopping:
                    return
                gen = self.requested
                self.started = gen
            try:
                self._run_generation(gen)
            except Exception as exc:  # the page never dies: report, keep the worker alive
                log.exception("editor re-plan failed")
                self._on_crash(exc)
            with self._cv:
                self.finished = max(self.finished, gen)
                self._cv.notify_all()
