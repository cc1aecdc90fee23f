"""The one job model of the service: what a worker is asked to do (a typed job), what it
answers (a typed outcome), and the one place a failure becomes an :class:`ErrorDetail`.

Jobs (:data:`Job`) are frozen dataclasses, picklable to a worker process:

* :class:`PlanJob` plan a validated request, serialise it (and store it) in the worker;
* :class:`SegmentJob` cells and corridor of a layout, no planning;
* :class:`ImportJob` a DXF/SVG drawing as a layout and a report;
* :class:`EditorJob` the editor's re-plan (segmentation kept when the plan fails);
* :class:`ExportJob` a stored plan in an output format, written to a spool file the server
  streams (the server process never parses the stored plan; JSON, the stored form, is
  copied as it is: :func:`spool_plan_json`, which the server runs itself on its read threads);
* :class:`SleepJob` (tests of the time limit);
* a :class:`ChunkJob`: a job made of jobs that runs them itself, each under its own bounds (a
  batch's chunk, :class:`app.batch.engine.BatchChunkJob`: defined above the executors, whose
  :func:`app.executors.run_bounded` it calls per item; this module knows only its protocol).

A new kind (e.g. a contour job around ``planner.plan_contour``) is a dataclass here, a
branch of :func:`_execute`, and, if it can be estimated, one in :func:`estimate`.

Outcomes (:data:`Outcome`) are :class:`Done` (bytes ready to send, the stored plan id, the
plan's summary, or the spool file) or :class:`Failed` (an :class:`ErrorDetail` and the HTTP
status it answers). :func:`run_job` runs a job here and now, with no time limit; a time limit
is enforced only by running the job in a process that is killed at the limit (the executors
of :mod:`app.executors`, which :class:`app.service.JobService` and the batches use).

No web framework or editor import: workers import this module.
"""

from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable

from pydantic import BaseModel, Field

from app import job_progress
from app.failures import degenerate, out_of_memory, too_much_work
from app.result_json import dumps
from planner.errors import over_the_limit
from planner.schema import ContourRequest, ImportOptions, PlanRequest, PlanResult, SegmentationResult

__all__ = ["ChunkJob", "ContourJob", "ContourWork", "Done", "EditorJob", "EditorPlan", "ErrorDetail", "ExportJob",
           "Failed", "ImportJob", "Job", "Outcome", "PlanJob", "SegmentJob", "SleepJob", "admitted_s", "bounded",
           "ESTIMATE_MARGIN", "check_estimate", "clean_spool", "crashed", "estimate", "failed", "run_job",
           "segmentation_module", "spool_dir", "spool_plan_json"]


class ErrorDetail(BaseModel):
    code: str = Field(description="Stable machine-readable cause: invalid_input, unreachable, singular, "
                      "not_settled, diverged, no_path, infeasible, too_large, too_much_work, too_much_memory, "
                      "timeout, not_found, name_taken, storage_full, unauthorized, busy, unavailable, "
                      "internal_error, ...")
    message: str = Field(description="Plain-language explanation")
    field: str | None = Field(None, description="Path of the request field at fault, e.g. 'segments[3].lower'")
    details: list[dict[str, Any]] | None = Field(None, description="All validation failures "
                                                 "[{field, message}] when there are several")

    def to_dict(self) -> dict[str, Any]:
        """``{code, message, field}`` (the planner's error dict)."""
        return {"code": self.code, "message": self.message, "field": self.field}


class EditorPlan(BaseModel):
    """What an :class:`EditorJob` answers (its JSON payload, parsed once by the editor):
    the layout's segmentation (kept when the plan then fails; null for a segment list or
    when segmenting failed), the plan result and the error (each may be null)."""

    segmentation: SegmentationResult | None = None
    result: PlanResult | None = None
    error: ErrorDetail | None = None


# ---------------------------------------------------------------------------------------
# jobs

@dataclass(frozen=True)
class PlanJob:
    """Plan ``request`` and answer it in ``format`` (:data:`app.formats.OUTPUT_FORMATS`, or
    ``none``: the summary only). With ``store`` (the SQLite file) the result is stored
    first; ``source`` names the plan's origin in machine-format headers."""

    request: PlanRequest
    format: str = "json"
    forces: bool = False
    source: str | None = None
    store: str | None = None
    corridor_id: str | None = None
    #: a layout's corridor, once segmented, is estimated again and refused over this [s]
    #: (:func:`planner.plan`'s ``work_limit_s``; set from the time limit by :func:`bounded`)
    work_limit_s: float | None = None
    #: the HTTP job this runs as (a row of the store's ``jobs``, marked running by the worker)
    job_id: str | None = None
    kind: ClassVar[str] = "plan"


@dataclass(frozen=True)
class SegmentJob:
    request: PlanRequest
    kind: ClassVar[str] = "segment"


@dataclass(frozen=True)
class ImportJob:
    data: bytes
    options: ImportOptions
    filename: str | None = None
    content_type: str | None = None
    #: refuse a drawing whose estimated work is over this many seconds before any curve is
    #: flattened (:func:`planner.exchange.import_drawing`'s ``work_limit_s``; set by :func:`bounded`)
    work_limit_s: float | None = None
    kind: ClassVar[str] = "import"


@dataclass(frozen=True)
class EditorJob:
    """The editor's re-plan: JSON of an :class:`EditorPlan` ``{"segmentation", "result", "error"}``."""

    request: PlanRequest
    kind: ClassVar[str] = "editor"


@dataclass(frozen=True)
class ExportJob:
    """The stored plan ``plan_id`` of ``store`` in ``format``, written to a new file in
    ``spool`` (a directory; None: answered as bytes). Done with ``path`` set, or a Failed
    ``not_found`` (404) when the plan is gone."""

    plan_id: str
    store: str
    format: str
    forces: bool = False
    spool: str | None = None
    kind: ClassVar[str] = "export"


@dataclass(frozen=True)
class ContourJob:
    """Contour a G-code program (:func:`planner.contour.plan_contour`; ``POST /v1/contour``),
    stored and answered like a :class:`PlanJob`. Estimated where it runs: the worker reads the
    program once (a program of tens of thousands of lines takes seconds and ~90 MB to read, never
    in the server process), refuses it over ``work_limit_s`` (``too_much_work``) and plans it.
    With ``sync_within_s`` (``POST /v1/contour`` on a synchronous worker, before any job is
    queued: :func:`app.routers.jobs.run_as_job`) it plans only a program estimated at most that
    long; a longer one ends after its estimate, :class:`Done` with ``deferred`` set, and is run
    again as an HTTP job (its program read again there: cheaper than shipping the read program
    back and forth, ``benchmarks/README.md``)."""

    request: ContourRequest
    format: str = "json"
    forces: bool = False
    source: str | None = None
    store: str | None = None
    #: refused over this estimate [s] (set from the time limit by :func:`bounded`)
    work_limit_s: float | None = None
    #: the HTTP job this runs as (a row of the store's ``jobs``): the worker writes its
    #: estimate and its progress (cut passes done) there (:func:`app.job_progress.job_progress`)
    job_id: str | None = None
    #: plan it only if its work estimate is at most this [s]; else end after the estimate
    #: (:class:`Done` with ``deferred``): the synchronous lane's test of ``POST /v1/contour``
    sync_within_s: float | None = None
    kind: ClassVar[str] = "contour"


@dataclass(frozen=True)
class SleepJob:
    seconds: float
    kind: ClassVar[str] = "sleep"


@runtime_checkable
class ChunkJob(Protocol):
    """A job made of jobs, which runs them itself (:func:`run_job` calls :meth:`run`): a batch's
    chunk of items, :class:`app.batch.engine.BatchChunkJob`, each item the service's typed job
    under its own work estimate, time limit and memory cap (:func:`app.executors.run_bounded`:
    a planning process of the process the chunk runs in, killed at the item's limit). So an
    executor runs a chunk with no limit of its own (its items have theirs), wherever it runs:
    this process (:class:`app.executors.InProcessExecutor`), a pool's worker
    (:class:`app.workers.PlanPool`) or a Dask worker (:class:`app.cluster.DaskExecutor`).
    :meth:`run` never raises for an item's fault: each item has its own outcome in the
    :class:`Done` it answers."""

    kind: ClassVar[str]

    def run(self) -> Done: ...


Job = PlanJob | SegmentJob | ImportJob | EditorJob | ExportJob | ContourJob | SleepJob | ChunkJob


# ---------------------------------------------------------------------------------------
# outcomes

@dataclass(frozen=True)
class Done:
    """A job that ran to the end: ``payload`` (bytes ready to send; empty when ``path``
    holds them), the stored plan's id, a plan's metrics summary, the spool file; ``deferred``:
    a :class:`ContourJob` with ``sync_within_s`` that stopped after its estimate (over it: no
    plan, no payload), to be run as an HTTP job."""

    payload: bytes | None = b""
    plan_id: str | None = None
    summary: dict[str, Any] | None = None
    path: str | None = None
    deferred: ContourWork | None = None
    ok: ClassVar[bool] = True


@dataclass(frozen=True)
class Failed:
    """A job that did not: the error and the HTTP status it answers (422: the input's
    fault; 404, 503 busy, 500 a planner bug or a dead worker)."""

    error: ErrorDetail
    status: int = 422
    #: the traceback of an unexpected exception (:func:`crashed`): logged, never sent
    trace: str | None = dataclasses.field(default=None, compare=False, repr=False)
    ok: ClassVar[bool] = False


Outcome = Done | Failed


def failed(error: dict[str, Any], status: int = 422) -> Failed:
    """A :class:`Failed` from a ``{code, message, field}`` dict."""
    return Failed(ErrorDetail(code=error["code"], message=error["message"], field=error.get("field"), details=None),
                  status)


def crashed(exc: BaseException) -> Failed:
    """An unexpected exception in the planner: 500, its type and first line (the traceback
    rides along for the server's error log)."""
    import traceback

    first = f"{type(exc).__name__}: {exc}".splitlines()[0]
    out = failed({"code": "internal_error", "message": f"the planner failed unexpectedly: {first}"}, 500)
    return dataclasses.replace(out, trace="".join(traceback.format_exception(exc)))


# ---------------------------------------------------------------------------------------
# running a job (in a worker process, or inline)

def estimate(job: Job):
    """The planner's work estimate (:func:`planner.estimate_work`) of a job that plans, else
    None (compared with the time limit before the job is queued; a :class:`ContourJob` is
    estimated by the worker that reads its program: :func:`_contour`)."""
    if isinstance(job, (PlanJob, EditorJob)):
        from planner import estimate_work

        return estimate_work(job.request)
    return None


@dataclass(frozen=True)
class ContourWork:
    """The work estimate of a :class:`ContourJob` (:func:`planner.contour.estimate_contour`)."""

    seconds: float
    detail: str
    field: str = "program"

    def message(self, limit_s: float, time_limit_s: float | None = None) -> str:
        return (f"this program needs an estimated {self.seconds:.3g} s of planning ({self.detail}), more than "
                f"{over_the_limit(limit_s, time_limit_s)}; split the program, give a larger tolerance_m or "
                "settings.Ts, or feed 'program'")


def run_job(job: Job, memory_mb: int | None = None) -> Outcome:
    """Run one job here and now; never raises for the input's fault nor for a planner bug
    (``memory_mb``: this process's memory cap, named by a memory error)."""
    import numpy as np

    from planner.errors import PlannerError

    try:
        return _execute(job)
    except PlannerError as exc:
        return failed(exc.to_dict())
    except (ArithmeticError, np.linalg.LinAlgError) as exc:
        # singular or non-finite model matrices: a degenerate robot description or pose the
        # planner's own checks let through; the input's fault, not the server's
        request = getattr(job, "request", None)
        return failed(degenerate(exc, custom_robot=not isinstance(getattr(request, "robot", None), str)))
    except MemoryError:
        return failed(out_of_memory(memory_mb, job.kind))
    except _NotFound as exc:
        return failed({"code": "not_found", "message": str(exc)}, 404)
    except Exception as exc:  # a planner bug: reported, the worker keeps serving
        return crashed(exc)


def _execute(job: Job) -> Done:
    if isinstance(job, PlanJob):
        return _plan(job)
    if isinstance(job, ExportJob):
        return _export(job)
    if isinstance(job, ContourJob):
        return _contour(job)
    if isinstance(job, ImportJob):
        from planner.exchange import import_drawing

        res = import_drawing(job.data, job.options, filename=job.filename, content_type=job.content_type,
                             work_limit_s=job.work_limit_s)
        return Done(dumps(res.to_json_dict()))
    if isinstance(job, SegmentJob):
        from planner import segment

        return Done(dumps(segment(job.request).to_dict()))
    if isinstance(job, EditorJob):
        return Done(_editor_plan(job.request))
    if isinstance(job, SleepJob):
        time.sleep(float(job.seconds))
        return Done(b"{}")
    if isinstance(job, ChunkJob):
        return job.run()
    raise ValueError(f"unknown job {type(job).__name__}")


def _plan(job: PlanJob) -> Done:
    from app.storage import new_id
    from planner import plan

    req = job.request
    if job.job_id:
        job_progress.job_progress(_store(job.store), job.job_id)(0, 1)
    result = plan(req, work_limit_s=job.work_limit_s)
    plan_id = new_id() if job.store else None
    result.plan_id = plan_id
    data = result.to_json()
    store = _store(job.store)
    if plan_id and store is not None and store.save_plan_json(
            data.decode(), req.to_json_dict(), job.corridor_id, id=plan_id) is None:
        plan_id = result.plan_id = None  # too large to keep (storage quotas): sent, not stored
        data = result.to_json()
    if job.format == "json":
        payload: bytes | None = data
    elif job.format == "none":
        payload = None
    else:
        from app.formats import write  # (imports the machine formats' writers: loaded by the workers at start)

        payload = write(result, job.format, layout=req.layout, forces=job.forces, source=job.source)
    return Done(payload, plan_id, _summary(result))


def _contour(job: ContourJob) -> Done:
    """Read a G-code program once, refuse it over ``work_limit_s`` (``too_much_work``), contour
    it: stored and answered like a plan (the stored request is the contour request)."""
    from app.storage import new_id
    from planner.contour import estimate_contour, plan_contour
    from planner.errors import PlannerError
    from planner.exchange import read_gcode

    req = job.request
    program = read_gcode(req.program, cut_below=req.cut_below_m, z_rapid_m_s=req.z_rapid_m_s)
    progress = None
    here = job_progress.here()
    if job.work_limit_s or job.job_id or here is not None or job.sync_within_s is not None:
        work = ContourWork(*estimate_contour(req, program))
        if job.sync_within_s is not None and work.seconds > job.sync_within_s:
            return Done(None, deferred=work)  # too long to answer synchronously: a job (before any limit's refusal)
        if job.work_limit_s and work.seconds > job.work_limit_s:
            raise PlannerError(**too_much_work(work, job.work_limit_s))
        if job.job_id:
            progress = job_progress.job_progress(_store(job.store), job.job_id, work.seconds)
        elif here is not None:
            progress = job_progress.with_estimate(here, work.seconds)
        if progress is not None:
            progress(0, len(program.passes))
    result = plan_contour(req, program=program, work_limit_s=job.work_limit_s, progress=progress)
    del program
    plan_id = new_id() if job.store else None
    result.plan_id = plan_id
    data = result.to_json()
    store = _store(job.store)
    if plan_id and store is not None and store.save_plan_json(
            data.decode(), req.model_dump(mode="json"), None, id=plan_id) is None:
        plan_id = result.plan_id = None
        data = result.to_json()
    if job.format == "json":
        payload: bytes | None = data
    elif job.format == "none":
        payload = None
    else:
        from app.formats import write

        payload = write(result, job.format, layout=None, forces=job.forces, source=job.source)
    return Done(payload, plan_id, _summary(result))


def _summary(result) -> dict[str, Any]:
    """A plan's figures (a batch's summary row); a contour plan's adds its two-sided deviation,
    the tolerance and the cycle and cut times."""
    m = result.metrics
    out = {"duration_s": m.duration_s, "energy": m.energy, "max_force_ratio": m.max_force_ratio,
           "contained": m.contained, "settled": m.settled, "end_error_m": m.end_error_m,
           "max_corridor_violation_m": m.max_corridor_violation_m, "steps": m.steps, "compute_ms": m.compute_ms,
           "max_drive_force_n": m.max_drive_force_n}
    c = getattr(result, "contour", None)
    if c is not None:  # (the CLI's summary line says these of a contour)
        out.update(max_deviation_m=c.max_deviation_m, tolerance_m=c.tolerance_m, cycle_time_s=c.cycle_time_s,
                   cut_time_s=c.cut_time_s, passes=len(c.passes), origin=list(c.origin), warnings=list(c.warnings))
    return out


def _export(job: ExportJob) -> Done:
    """Read the stored plan (in this worker: the server process never holds it), write it in
    the format to a spool file, answer its path."""
    from app.formats import write
    from planner.schema import PlanResult

    store = _store(job.store)
    if job.format == "json" and store is not None:
        out = spool_plan_json(store, job.plan_id, job.spool)
        if isinstance(out, Failed):
            raise _NotFound(out.error.message)
        return out
    text = store.get_plan_json(job.plan_id) if store is not None else None
    if text is None:
        raise _NotFound(f"no plan with id {job.plan_id!r}")
    result = PlanResult.model_validate_json(text)
    del text
    layout = None  # the layout of the plan's request (a DXF draws its obstacles)
    info = store.plan_info(job.plan_id) if store is not None else None
    try:
        layout = PlanRequest.model_validate(info["request"]).layout if info and info.get("request") else None
    except ValueError:  # a request stored by an older version: the DXF has no obstacles then
        layout = None
    body = write(result, job.format, layout=layout, forces=job.forces, source=f"plan {job.plan_id}")
    del result
    if job.spool is None:
        return Done(body)
    fd, path = _spool_file(job.spool)
    with os.fdopen(fd, "wb") as f:
        f.write(body)
    return Done(None, path=path)


class _NotFound(LookupError):
    pass


def spool_plan_json(store, plan_id: str, spool: str | None) -> Outcome:
    """The stored plan ``plan_id`` of ``store`` (a :class:`app.storage.Store`) as its stored
    JSON, copied without parsing in bounded chunks (:meth:`~app.storage.Store.copy_plan_json`)
    to a new file in ``spool`` (None: as bytes); Failed ``not_found`` (404) when it is gone.
    Only the copy's chunk is ever in memory: a download of any size is bounded like an export."""
    import io

    if spool is None:
        buf = io.BytesIO()
        found = store.copy_plan_json(plan_id, buf)
        return Done(buf.getvalue()) if found else _gone(plan_id)
    fd, path = _spool_file(spool)
    try:
        with os.fdopen(fd, "wb") as f:
            found = store.copy_plan_json(plan_id, f)
    except BaseException:
        os.unlink(path)
        raise
    if not found:
        os.unlink(path)
        return _gone(plan_id)
    return Done(None, path=path)


def _gone(plan_id: str) -> Failed:
    return failed({"code": "not_found", "message": f"no plan with id {plan_id!r}"}, 404)


def spool_dir(store_path: str | os.PathLike) -> str:
    """Where export jobs of the store at ``store_path`` write their files: ``exports/``
    beside the database (the server streams each file, then deletes it)."""
    return os.path.join(os.path.dirname(os.fspath(store_path)), "exports")


def clean_spool(spool: str, older_than_s: float = 3600.0) -> int:
    """Delete export files left by a response that never finished (a client that went away
    mid-stream, a server that was killed); returns how many."""
    n = 0
    try:
        entries = list(os.scandir(spool))
    except OSError:
        return 0
    for e in entries:
        try:
            if e.name.startswith("export-") and time.time() - e.stat().st_mtime > older_than_s:
                os.unlink(e.path)
                n += 1
        except OSError:
            pass
    return n


def _spool_file(spool: str) -> tuple[int, str]:
    import tempfile

    os.makedirs(spool, exist_ok=True)
    return tempfile.mkstemp(prefix="export-", suffix=".part", dir=spool)


_stores: dict = {}


def _store(path):
    if path is None:
        return None
    st = _stores.get(path)
    if st is None:
        from app.storage import Store
        st = _stores[path] = Store(path)
    return st


def segmentation_module():
    """``planner.corridor`` (its ``segment``), which the editor's re-plan segments with.
    Tests replace this function to control the segmentation's timing (inline runs)."""
    from planner import corridor

    return corridor


def _editor_plan(req) -> bytes:
    """The editor's re-plan: the segmentation of a layout (kept when the plan then fails)
    and the plan, as JSON ``{"segmentation", "result", "error"}`` (each may be null)."""
    from planner import PlannerError, load_robot, plan

    seg = None
    try:
        robot = load_robot(req.robot)
        segments = None
        if req.layout is not None:
            seg = segmentation_module().segment(req.layout, robot, req.settings)
            segments = seg.segments
        result = plan(req, robot=robot, segments=segments).to_json_dict()
        return dumps({"segmentation": seg.to_dict() if seg else None, "result": result, "error": None})
    except PlannerError as exc:
        return dumps({"segmentation": seg.to_dict() if seg else None, "result": None, "error": exc.to_dict()})


# ---------------------------------------------------------------------------------------
# bounds every executor applies before a job runs (app.executors, app.service)

#: how much longer than its work estimate a run may take: the estimates are fitted to hold within
#: it (``benchmarks/certify.py``, ``bench_contour_estimate.py``, ``bench_import_estimate.py``), so a
#: job is admitted only if its estimate times this fits in its time limit, and an admitted job
#: does not end by the limit (issue 33 goal 2)
ESTIMATE_MARGIN = 1.5


def admitted_s(timeout_s: float) -> float:
    """The work estimate [s] a job may have to be admitted under the time limit ``timeout_s`` [s]."""
    return float(timeout_s) / ESTIMATE_MARGIN


def check_estimate(job: Job, timeout_s: float | None, work: Any = None) -> Failed | None:
    """A :class:`Failed` ``too_much_work`` if the job's work estimate (``work``, the caller's
    :func:`estimate` if it has it) exceeds what the time limit ``timeout_s`` admits
    (:func:`admitted_s`)."""
    if not timeout_s or timeout_s <= 0:
        return None
    est = estimate(job) if work is None else work
    if est is not None and est.seconds > admitted_s(timeout_s):
        return failed(too_much_work(est, admitted_s(timeout_s), float(timeout_s)))
    return None


def bounded(job: Job, timeout_s: float | None) -> Job:
    """``job`` with the work its time limit admits (:func:`admitted_s`) as its work limit (a
    plan job whose layout, once segmented, is estimated again before it is simulated: issue 20;
    a contour job, estimated once its program is read; a drawing import, estimated once its
    file is parsed)."""
    if isinstance(job, (PlanJob, ContourJob, ImportJob)) and job.work_limit_s is None and timeout_s and timeout_s > 0:
        return dataclasses.replace(job, work_limit_s=admitted_s(timeout_s))
    return job
