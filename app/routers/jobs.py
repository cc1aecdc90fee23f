"""Long contours and plans as jobs (issue 35 goal 6): ``202 Accepted``, ``GET /v1/jobs/{id}``.

``POST /v1/contour`` and ``POST /v1/plan`` answer synchronously (200 and the plan) when the
work is short, and ``202 Accepted`` with a job (``Location: /v1/jobs/{id}``) when

* the request asks for it: ``Prefer: respond-async`` (RFC 7240; the answer says
  ``Preference-Applied: respond-async``), or
* the work estimate is over the threshold: ``RANGEPLAN_ASYNC_AFTER_S`` (10 s), or the request's
  ``Prefer: wait=N`` (RFC 7240: "I will wait N seconds"), never above the synchronous limit
  ``RANGEPLAN_PLAN_TIMEOUT_S``. Both are estimated before anything is queued, off the event
  loop: a plan by the server (microseconds to milliseconds, on a thread), a contour by a
  worker of the synchronous lane, which reads its program (seconds for a long one, and ~90 MB:
  never in the server process), estimates it and, when the estimate is within the threshold,
  plans it right there (the program read once); over it, the worker ends after the estimate
  and the contour is queued as a job with that estimate (its program read again by the job's
  worker: cheaper than shipping the read program, 29 MB of pickle for 100 000 lines, through
  the server). So a short contour never waits behind long jobs, as a short plan does not.
  Only when jobs hold every worker (``RANGEPLAN_JOB_WORKERS`` >= ``RANGEPLAN_WORKERS``) is a
  contour queued unestimated, its worker's estimate awaited (a row of the store), or
* a synchronous contour queued so is still running at the synchronous limit: it becomes a
  job then, rather than a timeout.

A job runs under ``RANGEPLAN_JOB_TIMEOUT_S`` (600 s; a contour always does, as it may become
one), on the jobs' share of the workers (``RANGEPLAN_JOB_WORKERS``: at most that many at once,
the others wait ``queued``; :class:`app.service.JobService`), so that synchronous requests
always find a worker; a synchronous contour waits for its turn there too, and becomes a job
when it is still waiting or running at the synchronous limit. ``GET /v1/jobs/{id}`` says
``state`` (queued | running | done | failed), ``progress`` ``{done, total, unit}`` (a
contour's cut passes, written by the worker after each pass), the work estimate, ``eta_s``
and, once done, ``result``: the stored plan's URL (``/v1/plans/{id}``, any ``?format=``), or
``error`` (the error the synchronous call would have answered).

``Retry-After`` (a 202, and ``GET /v1/jobs/{id}`` while the job is queued or running) says when
the job is expected to end, within 1-60 s (:func:`app.job_progress.job_wait`): a running job's
time left (``eta_s``); a queued one's estimate plus the work ahead of it (the running jobs'
time left and the estimates of the jobs queued before it) shared by the jobs' workers. A
client that follows it polls a 30 s job about once, not 30 times; a job that overruns its
estimate is told again from its measured progress. A busy answer (503) says when the first
slot is expected to free (:func:`app.routers.deps.busy_retry_after`).

Progress crosses the process boundary through the SQLite store the worker already opens to
store its plan (:func:`app.job_progress.job_progress`): the same for a local planning process, the
in-process executor and a Dask worker sharing the data directory, and readable by any thread
of the server; a pipe message would have needed every executor to carry a second kind of
message. Jobs are bounded: ``RANGEPLAN_MAX_JOBS`` kept (503 when that many are unfinished),
finished ones dropped after ``RANGEPLAN_JOB_MAX_AGE_S``; unfinished ones of a server that
stopped are ended ``failed`` when the next one starts jobs. The token and Host rules cover
``/v1/jobs`` as every ``/v1`` path.
"""

from __future__ import annotations

import asyncio
import dataclasses
import threading
import time
from dataclasses import dataclass
from typing import Any, Literal

from fastapi import APIRouter, FastAPI, Header, Request
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, Field
from starlette.exceptions import HTTPException as StarletteHTTPException

from app import storage_io
from app.errors import error_response, errors_doc
from app.failures import too_much_work
from app.job_progress import RETRY_MAX_S, RETRY_MIN_S, job_wait, retry_after, time_left
from app.jobs import (
    ContourJob,
    Done,
    ErrorDetail,
    Failed,
    Job,
    Outcome,
    PlanJob,
    admitted_s,
    check_estimate,
    crashed,
    estimate,
    failed,
)
from app.observability import observe_job
from app.routers.deps import busy_retry_after, outcome_response, respond, service, store, submit
from app.storage import Store, new_id

__all__ = ["ACCEPTED_DOC", "JobStatus", "PREFER", "job_limits", "job_status", "parse_prefer", "router", "run_as_job"]

router = APIRouter(tags=["jobs"])

#: how often a handler looks at a contour's row for its estimate while it waits [s]
POLL_S = 0.05
class JobProgress(BaseModel):
    done: int = Field(description="Units done (count)")
    total: int | None = Field(description="Units in all (count); null until the worker has read the request")
    unit: Literal["passes", "plans"] = Field(description="What is counted: a contour's cut passes, or one plan")


class JobStatus(BaseModel):
    id: str = Field(description="Job id (GET /v1/jobs/{id})")
    kind: Literal["contour", "plan"] = Field(description="What the job computes")
    state: Literal["queued", "running", "done", "failed"] = Field(description="queued (waiting for a worker), "
                                                                  "running, done (result) or failed (error)")
    created: float = Field(description="When it was accepted, s since the Unix epoch")
    progress: JobProgress
    estimate_s: float | None = Field(description="The planner's work estimate (CPU s); null until it is known")
    elapsed_s: float | None = Field(description="Time since it started running (until it ended), s")
    updated: float = Field(description="When its row last changed (progress), s since the Unix epoch")
    eta_s: float | None = Field(description="Estimated time left, s: the work estimate less the time run until the "
                                "first unit is done (not below a tenth of it), then the measured time per unit "
                                "times the units left and the join after them (0.3 units per unit), not below a "
                                "tenth of a unit's time while it runs; 0 once ended, null when unknown")
    result: str | None = Field(description="Once done: the stored plan's URL (GET it, with ?format= if you like)")
    plan_id: str | None = Field(description="Once done: the stored plan's id")
    error: ErrorDetail | None = Field(description="Once failed: the error the synchronous call would have answered")


PREFER = Header(None, description="RFC 7240. `respond-async`: answer 202 Accepted with a job at once; `wait=N`: "
                "answer synchronously only if the work estimate is at most N s (else 202; default "
                "RANGEPLAN_ASYNC_AFTER_S)")

#: the OpenAPI description of a job's ``Retry-After`` (a 202, GET /v1/jobs/{id} while it runs)
RETRY_AFTER_JOB = (f"Seconds before polling it ({RETRY_MIN_S}-{RETRY_MAX_S}): when the job is expected to end, its "
                   "time left (its work estimate less what it has run, or its measured time per unit) and, while it "
                   "is queued, the work ahead of it (the running jobs' time left and the estimates of the jobs "
                   "queued before it) shared by the jobs' workers (RANGEPLAN_JOB_WORKERS)")

ACCEPTED_DOC: dict[int | str, dict[str, Any]] = {202: {
    "model": JobStatus, "description": "Accepted as a job (asked by `Prefer: respond-async`, or the work "
    "estimate is over the threshold): poll `Location` (GET /v1/jobs/{id}) until `state` is done, then GET its "
    "`result`", "headers": {
        "Location": {"description": "The job: GET /v1/jobs/{id}", "schema": {"type": "string"}},
        "Retry-After": {"description": RETRY_AFTER_JOB, "schema": {"type": "integer", "minimum": RETRY_MIN_S,
                                                                   "maximum": RETRY_MAX_S}},
        "Preference-Applied": {"description": "respond-async when the request asked for it",
                               "schema": {"type": "string"}}},
    "links": {"GetJob": {"operationId": "get_job", "parameters": {"job_id": "$response.body#/id"}}}}}


@dataclass(frozen=True)
class JobLimits:
    async_after_s: float  #: work estimate [s] over which a request is answered 202
    sync_limit_s: float  #: the synchronous limit: no synchronous answer waits longer [s]
    job_timeout_s: float  #: compute limit of a job [s]
    max_jobs: int
    max_age_s: float


_LOCK = threading.Lock()


def job_limits(app: FastAPI) -> JobLimits:
    """The app's job bounds (``app.state.job_limits``; from the settings on first use, when the
    unfinished jobs of a server before this one are ended ``failed``)."""
    with _LOCK:
        limits = getattr(app.state, "job_limits", None)
        if limits is None:
            from app.settings import settings

            cfg = settings()
            sync = float((getattr(app.state, "plan_limits", None) or {}).get("timeout_s") or cfg.plan_timeout_s)
            limits = app.state.job_limits = JobLimits(min(cfg.async_after_s, sync), sync,
                                                      max(cfg.job_timeout_s, sync), cfg.max_jobs, cfg.job_max_age_s)
        if not getattr(app.state, "jobs_recovered", False):
            app.state.jobs_recovered = True
            app.state.store.abandon_jobs("the server stopped while this job ran; submit it again")
        return limits


@dataclass(frozen=True)
class Preference:
    respond_async: bool = False
    wait_s: float | None = None


def parse_prefer(values: list[str]) -> Preference:
    """The ``Prefer`` headers' ``respond-async`` and ``wait=N`` (RFC 7240: comma-separated
    preferences, each ``token[=value]`` with optional ``;`` parameters; unknown ones ignored)."""
    respond_async, wait = False, None
    for value in values:
        for item in value.split(","):
            name, _, arg = item.split(";")[0].strip().partition("=")
            name = name.strip().lower()
            if name == "respond-async":
                respond_async = True
            elif name == "wait":
                try:
                    wait = max(0.0, float(arg.strip().strip('"')))
                except ValueError:
                    pass
    return Preference(respond_async, wait)


def _unit(job: Job) -> str:
    return "passes" if isinstance(job, ContourJob) else "plans"


async def job_retry_after(request: Request, job_id: str) -> int:
    """The ``Retry-After`` [s] of the job ``job_id`` (module docstring; its rows read off the loop)."""
    rows = await storage_io.read(store(request).unfinished_jobs)
    return retry_after(job_wait(rows, job_id, service(request).job_workers, time.time()))


async def _accepted(request: Request, row: dict, applied: bool) -> JSONResponse:
    headers = {"Location": f"/v1/jobs/{row['id']}", "Retry-After": str(await job_retry_after(request, row["id"]))}
    if applied:
        headers["Preference-Applied"] = "respond-async"
    return JSONResponse(job_status(row), status_code=202, headers=headers)


@dataclass(frozen=True)
class _ToJob:
    """A contour the synchronous lane did not answer: run it as a job, with its estimate [s] if
    known; ``now``: answer 202 at once (else the handler waits for its worker's estimate)."""

    estimate_s: float | None
    now: bool


async def _estimated_contour(request: Request, job: ContourJob, threshold: float,
                             limits: JobLimits) -> Response | _ToJob:
    """A contour estimated on a synchronous worker before it is queued (module docstring): its
    answer when that worker planned it (its estimate within ``threshold``) or refused it, else
    a job: with its estimate (over ``threshold``); at once, unestimated, when the synchronous
    limit ran out first (a large program read on a loaded machine, or an estimate that was
    low: a job then rather than a timeout, as the job lane's synchronous contour does); or
    unestimated, its worker's estimate awaited, when jobs hold every worker."""
    svc = service(request)
    t0 = time.perf_counter()
    outcome = await svc.arun(dataclasses.replace(job, sync_within_s=threshold))
    if isinstance(outcome, Done) and outcome.deferred is not None:
        work = outcome.deferred
        if work.seconds > admitted_s(limits.job_timeout_s):  # over the jobs' limit too: refused now
            return outcome_response(failed(too_much_work(work, admitted_s(limits.job_timeout_s),
                                                         limits.job_timeout_s)), "json")
        return _ToJob(work.seconds, True)
    if isinstance(outcome, Failed) and outcome.error.code == "timeout" and limits.job_timeout_s > limits.sync_limit_s:
        return _ToJob(None, True)
    if (isinstance(outcome, Failed) and outcome.status == 503 and outcome.error.code == "busy"
            and svc.job_workers >= svc.workers):  # jobs may hold every worker: the job lane estimates it
        return _ToJob(None, False)
    observe_job(request.app, job, time.perf_counter() - t0, outcome)
    return await respond(request, outcome, job.format)


async def run_as_job(request: Request, job: ContourJob | PlanJob, fmt: str) -> Response:
    """Answer ``job`` synchronously (the plan) or as a job (202), as the module docstring says."""
    app = request.app
    limits = job_limits(app)
    pref = parse_prefer(request.headers.getlist("prefer"))
    threshold = min(pref.wait_s if pref.wait_s is not None else limits.async_after_s, admitted_s(limits.sync_limit_s))
    est_s: float | None = None
    accept_now = pref.respond_async
    if isinstance(job, PlanJob):  # estimated here, before it is queued (as the service does)
        est = await asyncio.get_running_loop().run_in_executor(None, estimate, job)
        est_s = est.seconds if est is not None else None
        if est_s is not None and est_s > admitted_s(limits.job_timeout_s):  # over every limit: refused now
            refused = check_estimate(job, limits.job_timeout_s)
            if refused is not None:
                return outcome_response(refused, fmt)
        if not pref.respond_async and (est_s is None or est_s <= threshold):
            return await submit(request, job, fmt)  # short: synchronous, under the synchronous limit
    elif not pref.respond_async:  # a contour: estimated (and, if short, planned) on a synchronous worker
        lane = await _estimated_contour(request, job, threshold, limits)
        if isinstance(lane, Response):
            return lane
        est_s, accept_now = lane.estimate_s, lane.now
    st = store(request)
    job_id = new_id()
    if not await storage_io.write(st.create_job, job_id, job.kind, _unit(job), total=1 if isinstance(job, PlanJob)
                                  else None, estimate_s=est_s, max_jobs=limits.max_jobs,
                                  max_age_s=limits.max_age_s):
        return error_response(503, "busy", f"{limits.max_jobs} jobs are unfinished (RANGEPLAN_MAX_JOBS); retry when "
                              "one has ended", headers={"Retry-After": str(await busy_retry_after(request))})
    job = dataclasses.replace(job, job_id=job_id)
    task = asyncio.ensure_future(_run(app, job, fmt, limits.job_timeout_s))
    tasks = _tasks(app)  # held until it ends (the loop keeps only weak references to tasks)
    tasks.add(task)
    task.add_done_callback(tasks.discard)
    if accept_now or (est_s is not None and est_s > threshold):
        row = await storage_io.read(st.get_job, job_id)
        if row is not None:  # (a job that ended already and was dropped: never within max_jobs)
            return await _accepted(request, row, pref.respond_async)
    t0 = time.monotonic()
    while True:  # a contour: synchronous unless its worker's estimate is over the threshold
        await asyncio.wait({task}, timeout=POLL_S)
        if task.done():
            outcome = task.result()
            await storage_io.write(st.delete_job, job_id)  # answered here: nothing to poll
            return await respond(request, outcome, fmt)
        row = await storage_io.read(st.get_job, job_id)
        if row is None:
            raise RuntimeError(f"job {job_id} vanished")
        est_s = row["estimate_s"]
        if (est_s is not None and est_s > threshold) or time.monotonic() - t0 > limits.sync_limit_s:
            return await _accepted(request, row, False)


def _tasks(app: FastAPI) -> set:
    with _LOCK:
        tasks = getattr(app.state, "job_tasks", None)
        if tasks is None:
            tasks = app.state.job_tasks = set()
        return tasks


async def _run(app: FastAPI, job: ContourJob | PlanJob, fmt: str, limit_s: float) -> Outcome:
    """Run ``job`` on the app's job service under the job limit; end its row with the outcome."""
    t0 = time.perf_counter()
    try:
        outcome = await app.state.ensure_service().arun(job, limit_s, background=True)  # on the jobs' share
    except Exception as exc:  # the service closing under it (the server stopping): the job failed
        outcome = crashed(exc)
    observe_job(app, job, time.perf_counter() - t0, outcome)
    try:
        await _finish(app.state.store, job, outcome)
    except Exception:  # the store's threads stopped with the server: the next one ends the row
        pass
    return outcome


async def _finish(st: Store, job: ContourJob | PlanJob, outcome: Outcome) -> None:
    """End the job's row with its outcome."""
    assert job.job_id is not None
    if isinstance(outcome, Done):
        if outcome.plan_id is None:
            await storage_io.write(st.job_finished, job.job_id, error={
                "code": "too_large", "field": None, "status": 422, "message": "the plan is larger than this server "
                "stores (RANGEPLAN_MAX_PLAN_BYTES, RANGEPLAN_MAX_STORE_BYTES): ask for it synchronously "
                "(Prefer: wait=...) or split the program"})
        else:
            await storage_io.write(st.job_finished, job.job_id, plan_id=outcome.plan_id)
    else:
        await storage_io.write(st.job_finished, job.job_id, error={**outcome.error.to_dict(), "status": outcome.status})


def job_status(row: dict) -> dict[str, Any]:
    """A job's row as :class:`JobStatus` (JSON)."""
    now = time.time()
    state, done, total, est = row["state"], int(row["done"]), row["total"], row["estimate_s"]
    started, finished = row["started"], row["finished"]
    elapsed = None if started is None else max(0.0, (finished or now) - started)
    eta = 0.0 if state in ("done", "failed") else time_left(done, total, started, row["updated"], now, est)
    err = row["error"]
    plan_id = row["plan_id"]
    return {"id": row["id"], "kind": row["kind"], "state": state, "created": row["created"],
            "progress": {"done": done, "total": total, "unit": row["unit"]}, "estimate_s": est,
            "elapsed_s": elapsed, "updated": row["updated"], "eta_s": eta,
            "result": f"/v1/plans/{plan_id}" if plan_id else None, "plan_id": plan_id,
            "error": None if err is None else {k: err.get(k) for k in ("code", "message", "field")}}


@router.get("/v1/jobs/{job_id}", response_model=JobStatus, operation_id="get_job",
            responses={200: {"description": "The job's status; `Retry-After` while it is queued or running",
                             "headers": {"Retry-After": {"description": RETRY_AFTER_JOB, "schema": {
                                 "type": "integer", "minimum": RETRY_MIN_S, "maximum": RETRY_MAX_S}}}},
                       **errors_doc(404, descriptions={404: "Unknown job id (or a finished job dropped: "
                                                       "RANGEPLAN_MAX_JOBS, RANGEPLAN_JOB_MAX_AGE_S)"})})
async def get_job(job_id: str, request: Request):
    """A job's state, progress (units done of total), work estimate, time left and, once done,
    its result's URL (the stored plan) or its error. ``Retry-After`` while it is queued or runs:
    when it is expected to end (1-60 s; the work ahead of it counted while it is queued)."""
    row = await storage_io.read(store(request).get_job, job_id)
    if row is None:
        raise StarletteHTTPException(404, f"no job with id {job_id!r}")
    headers = None
    if row["state"] in ("queued", "running"):
        headers = {"Retry-After": str(await job_retry_after(request, job_id))}
    return JSONResponse(job_status(row), headers=headers)

