"""Where a job runs, and the one way its time limit is enforced: a process killed at the limit.

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

No web framework or editor import.
"""

from __future__ import annotations

import atexit
import threading

from app.failures import import_timeout, out_of_memory, timeout
from app.jobs import ExportJob, Failed, ImportJob, Job, Outcome, bounded, check_estimate, failed, run_job
from app.workers import JobTimeout, PlanPool, PoolBusy, WorkerCrashed, WorkerOutOfMemory

__all__ = ["child_pool", "close_child_pool", "describe_failure", "run_bounded"]


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
        return failed(import_timeout(timeout_s) if isinstance(job, ImportJob) else timeout(timeout_s))
    if isinstance(exc, PoolBusy):
        return failed({"code": "busy", "message": f"too many plans in progress ({exc}); retry shortly"}, 503)
    if isinstance(exc, WorkerCrashed):
        return failed({"code": "internal_error", "message": f"the planning process died: {exc}"}, 500)
    raise exc


# ---------------------------------------------------------------------------------------
# this process's own planning processes

_CHILD: dict[str, PlanPool | None] = {"pool": None}
_CHILD_LOCK = threading.Lock()


def _threads_here() -> int:
    """How many threads of this process may run jobs at once: a Dask worker's thread count
    inside a Dask worker, else 1 (a local pool's worker, a command)."""
    import sys

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
    runs in the calling thread. Never raises for the input's fault, a limit or a dead process."""
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
