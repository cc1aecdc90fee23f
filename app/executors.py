"""Where a job runs: one executor interface, three implementations; and the one way a time
limit is enforced: a process killed at the limit.

:class:`JobExecutor` is what :class:`app.service.JobService` (the API, the editor, contour
plans) submits typed jobs to:

* :class:`InProcessExecutor`: the calling thread (a command, the editor on its own); it
  cannot stop a job, so it arms no time limit;
* :class:`app.workers.PlanPool`: a local pool of planning processes, each killed and replaced
  at the time limit (the server's default; ``RANGEPLAN_EXECUTOR=process``);
* :class:`app.cluster.DaskExecutor`: a Dask cluster (``RANGEPLAN_EXECUTOR=dask``,
  ``RANGEPLAN_DASK_SCHEDULER``); each job runs :func:`run_bounded` on a worker.

Batches submit their items to the same executors (:meth:`JobExecutor.submit`): a chunk of
items is one typed job (:class:`app.jobs.ChunkJob`, :class:`app.batch.engine.BatchChunkJob`)
that runs each item through :func:`run_bounded` where the chunk runs (:mod:`app.batch.executors`).

A job (:data:`app.jobs.Job`) never has its time limit enforced inside the thread that runs
it (an exception injected into a running thread can land anywhere, in numba's cache loader
included). It runs in a planning process of a :class:`app.workers.PlanPool`, which is
killed and replaced when the job passes its limit; the caller gets ``timeout``.

* :func:`run_bounded` runs a job under the service's bounds from any process: the work
  estimate (``too_much_work`` before it starts), then the job in a planning process of this
  process's own pool (:func:`child_pool`, started on first use: one process per thread that
  may call it; a batch's local worker or a Dask worker thus plans in a child of its own).
  Without a time limit or a memory cap the job runs in the calling thread (nothing to enforce).
* :func:`describe_failure`: the one wording of a time limit, a memory limit, a full queue or
  a dead worker (the pool's exceptions) as an outcome.
* :func:`on_reference`: the one rule of a job submitted while the kernels compile in the
  background: it plans on the numpy reference (the service and the CLI apply it).

No web framework or editor import.
"""

from __future__ import annotations

import atexit
import dataclasses
import os
import socket
import sys
import threading
from concurrent.futures import Future
from typing import Any, Protocol, runtime_checkable

from app.failures import import_timeout, out_of_memory, timeout
from app.jobs import (
    ChunkJob,
    ContourJob,
    EditorJob,
    ExportJob,
    Failed,
    ImportJob,
    Job,
    Outcome,
    PlanJob,
    SegmentJob,
    bounded,
    check_estimate,
    failed,
    run_job,
)
from app.workers import JobsHoldEveryWorker, JobTimeout, PlanPool, PoolBusy, WorkerCrashed, WorkerOutOfMemory

__all__ = ["InProcessExecutor", "JobExecutor", "WORKER", "child_pool", "close_child_pool", "describe_failure",
           "on_reference", "run_bounded", "warm_worker", "where"]


@runtime_checkable
class JobExecutor(Protocol):
    """Runs typed jobs (:data:`app.jobs.Job`). :meth:`run` blocks and returns the job's outcome
    (:func:`app.jobs.run_job`), or raises :class:`~app.workers.JobTimeout` (the job passed
    ``timeout_s``, default :attr:`timeout_s`; 0: none), :class:`~app.workers.PoolBusy` (more
    than :attr:`capacity` jobs at once) or :class:`~app.workers.WorkerCrashed` (the process
    running it died; :class:`~app.workers.JobKilledWorkers`: it died wherever the job was
    retried); :class:`app.service.JobService` maps these once (:func:`describe_failure`).
    :meth:`submit` is :meth:`run` without blocking (the batches' dispatcher keeps several jobs
    in flight): a ``concurrent.futures.Future`` of the outcome, or of one of those exceptions.
    ``background``: a job that may run up to the job limit (a contour, a plan answered 202),
    which yields free workers to synchronous requests (:class:`app.workers.PlanPool`; a lower
    priority on Dask; :class:`app.service.JobService` bounds how many run at once).
    The work estimate is the caller's."""

    mode: str
    timeout_s: float
    memory_mb: int

    @property
    def capacity(self) -> int: ...

    def run(self, job: Job, timeout_s: float | None = None, background: bool = False) -> Outcome: ...

    def submit(self, job: Job, timeout_s: float | None = None) -> Future: ...

    def stats(self) -> dict[str, Any]: ...

    def readiness(self) -> dict[str, Any]: ...

    def renew(self) -> None: ...

    def close(self) -> None: ...


class InProcessExecutor:
    """Jobs in the calling thread (:class:`JobExecutor`): no parallelism beyond the callers'
    threads and no time limit (a thread cannot be stopped; the caller's work estimate still
    refuses work over ``timeout_s``). ``memory_mb`` only names the cap in a memory error."""

    mode = "inline"

    def __init__(self, timeout_s: float = 30.0, memory_mb: int | None = None):
        self.timeout_s = float(timeout_s)
        self.memory_mb = int(memory_mb or 0)
        self.jobs_run = 0

    @property
    def capacity(self) -> int:
        return 0

    def run(self, job: Job, timeout_s: float | None = None, background: bool = False) -> Outcome:
        self.jobs_run += 1
        return run_job(job, self.memory_mb or None)

    def submit(self, job: Job, timeout_s: float | None = None) -> Future:
        """Runs the job now, in the calling thread; returns its finished future."""
        fut: Future = Future()
        fut.set_running_or_notify_cancel()
        try:
            fut.set_result(self.run(job, timeout_s))
        except Exception as exc:  # (run_job raises none for a job's fault)
            fut.set_exception(exc)
        return fut

    def stats(self) -> dict[str, Any]:
        return {}

    def readiness(self) -> dict[str, Any]:
        return {"ready": True, "workers_ready": 1, "workers": 1, "failures": []}

    def renew(self) -> None:
        """Nothing to renew: the next job loads what this process has."""

    def close(self) -> None:
        """Nothing to stop."""


def on_reference(job: Job) -> Job:
    """``job`` planning on the numpy reference (``settings.backend = "reference"``) where it
    would plan on the compiled kernels; other jobs as they are. The one rule of a job submitted
    while the kernels compile in the background (issue 24): :class:`app.service.JobService`
    applies it to every job while its :class:`~app.service.KernelCompile` runs, the CLI when
    :func:`planner.orchestrator.background.while_compiling` says so (``app.cli``)."""
    if isinstance(job, (PlanJob, EditorJob, SegmentJob)):
        st = job.request.settings
        if st.backend != "compiled":
            return job
        return dataclasses.replace(job, request=job.request.model_copy(
            update={"settings": st.model_copy(update={"backend": "reference"})}))
    if isinstance(job, ContourJob):
        given = job.request.settings
        if given.get("backend") not in (None, "compiled") or given.get("solver", "riccati") != "riccati":
            return job
        return dataclasses.replace(job, request=job.request.model_copy(
            update={"settings": {**given, "backend": "reference"}}))
    return job


def describe_failure(exc: Exception, job: Job, timeout_s: float, memory_mb: int | None = None) -> Failed:
    """The outcome of a job the pool did not run to the end (the one wording of a time
    limit, a memory limit, a full queue or a dead worker)."""
    if isinstance(exc, WorkerOutOfMemory):
        return failed({"code": "too_much_memory", "message": str(exc) or out_of_memory(memory_mb, job.kind)["message"],
                       "field": "drawing" if job.kind == "import" else None})
    if isinstance(exc, JobTimeout):
        if isinstance(job, ExportJob):
            return failed({"code": "timeout", "field": "format", "message": f"writing the plan as {job.format} took "
                           f"longer than the export limit of {timeout_s:g} s (RANGEPLAN_EXPORT_TIMEOUT_S)"})
        if job.kind == "contour":  # what lowers a contour's work, not a corridor's
            from app.failures import contour_timeout

            return failed(contour_timeout(timeout_s))
        return failed(import_timeout(timeout_s) if isinstance(job, ImportJob) else timeout(timeout_s))
    if isinstance(exc, JobsHoldEveryWorker):
        return failed({"code": "busy", "message": f"{exc}; retry shortly, or keep a worker for synchronous "
                       "requests (RANGEPLAN_JOB_WORKERS below RANGEPLAN_WORKERS)"}, 503)
    if isinstance(exc, PoolBusy):
        return failed({"code": "busy", "message": f"too many plans in progress ({exc}); retry shortly"}, 503)
    if isinstance(exc, WorkerCrashed):
        return failed({"code": "internal_error", "message": f"the planning process died: {exc}"}, 500)
    raise exc


# ---------------------------------------------------------------------------------------
# a process that runs jobs for others (a batch's local worker, a Dask worker)

#: ``name``: where this process runs jobs for others, set by :func:`warm_worker` (a Dask worker
#: is also recognised by ``distributed.get_worker()``; anything else is ``inline``; a batch's
#: chunk names its engine itself); ``jobs``: jobs run here through :func:`run_bounded` (count)
WORKER: dict[str, Any] = {"name": "inline"}
#: whether this process has loaded the compiled kernels (:func:`_load_kernels`)
_KERNELS = {"loaded": False}
_KERNELS_LOCK = threading.Lock()


def _load_kernels() -> float:
    """Load (or compile) the planner's kernels once per process; returns the seconds taken."""
    with _KERNELS_LOCK:
        if _KERNELS["loaded"]:
            return 0.0
        try:
            from planner import warm_up

            return warm_up()
        except Exception:  # the first plan compiles instead
            return 0.0
        finally:
            _KERNELS["loaded"] = True


def where() -> dict[str, Any]:
    """Where this call runs: ``{"engine", "worker", "host", "pid"}``; ``worker`` is the Dask
    worker's address, else ``host:pid``."""
    host, pid = socket.gethostname(), os.getpid()
    if "distributed" in sys.modules:  # only a Dask worker (or client) has imported it
        try:
            from distributed import get_worker

            return {"engine": "dask", "worker": get_worker().address, "host": host, "pid": pid}
        except (ImportError, ValueError):  # ValueError: not inside a Dask task
            pass
    return {"engine": WORKER["name"], "worker": f"{host}:{pid}", "host": host, "pid": pid}


def warm_worker(engine: str = "dask") -> float:
    """Load the compiled kernels (``planner.warm_up``) and mark this process as ``engine``
    (:func:`where`): a Dask worker's start (:class:`app.cluster.WarmUp`), once per worker
    process, never per item. Returns the seconds taken."""
    WORKER["name"] = engine
    return _load_kernels()


# ---------------------------------------------------------------------------------------
# this process's own planning processes

_CHILD: dict[str, PlanPool | None] = {"pool": None}
_CHILD_LOCK = threading.Lock()


def _threads_here() -> int:
    """How many threads of this process may run jobs at once: a Dask worker's thread count
    inside a Dask worker, else 1 (a local pool's worker, a command)."""
    if "distributed" in sys.modules:
        try:
            from distributed import get_worker

            return max(1, int(getattr(get_worker(), "nthreads", 1)))
        except (ImportError, ValueError, AttributeError):  # not inside a Dask task
            pass
    return 1


def child_pool(memory_mb: int | None = None, workers: int | None = None) -> PlanPool:
    """This process's planning processes (started on the first call; ``workers``: how many,
    default one per thread that may run jobs here), each capped at ``memory_mb`` MiB. They
    are fresh interpreters (``start="exec"``: a Dask worker is a daemonic process, which
    multiprocessing refuses children) that end with this process. A different memory cap
    replaces the pool."""
    mb = int(memory_mb or 0)
    with _CHILD_LOCK:
        pool = _CHILD["pool"]
        if pool is not None and pool.memory_mb != mb:
            pool.close()
            pool = None
        if pool is None:
            pool = _CHILD["pool"] = PlanPool(workers or _threads_here(), timeout_s=0.0, max_queue=1024,
                                             memory_mb=mb, start="exec")
        return pool


def close_child_pool() -> None:
    """End this process's planning processes (they are started again when needed)."""
    with _CHILD_LOCK:
        pool, _CHILD["pool"] = _CHILD["pool"], None
    if pool is not None:
        pool.close()


atexit.register(close_child_pool)


def run_bounded(job: Job, timeout_s: float | None = None, memory_mb: int | None = None) -> Outcome:
    """Run ``job`` under the service's bounds: refused before it starts if its work estimate
    exceeds ``timeout_s`` (``too_much_work``), else run in a planning process of
    :func:`child_pool` that is killed at ``timeout_s`` (``timeout``; the next job gets a new
    process) and capped at ``memory_mb`` MiB (``too_much_memory``). With neither bound the job
    runs in the calling thread, and so does a :class:`~app.jobs.ChunkJob` (each of its items is
    bounded on its own, here). Never raises for the input's fault, a limit or a dead process."""
    if isinstance(job, ChunkJob):
        return run_job(job)
    with _CHILD_LOCK:
        WORKER["jobs"] = WORKER.get("jobs", 0) + 1
    refused = check_estimate(job, timeout_s)
    if refused is not None:
        return refused
    limit = float(timeout_s) if timeout_s and timeout_s > 0 else 0.0
    job = bounded(job, limit)
    if not limit and not memory_mb:
        return run_job(job)
    try:
        return child_pool(memory_mb).run(job, limit)
    except (JobTimeout, PoolBusy, WorkerCrashed) as exc:
        return describe_failure(exc, job, limit, memory_mb)
