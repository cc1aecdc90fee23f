"""The one executor every job of the service goes through: :class:`JobService`.

The HTTP API (``app.routers``), the editor (``app.editor._planning``) and the service's
batches submit typed jobs (:data:`app.jobs.Job`) and get a typed outcome
(:data:`app.jobs.Outcome`) back. The service does, once for all of them:

1. **estimate**: a job that plans is refused (``too_much_work``, in microseconds) when the
   planner's work estimate exceeds the time limit;
2. **bound and run on a worker**: :class:`app.workers.PlanPool` (worker processes with a time
   limit, a memory cap and a bounded queue; or inline threads);
3. **map errors once**: the pool's exceptions become :class:`app.jobs.Failed` with the HTTP
   status they answer (``timeout`` and ``too_much_memory`` 422, ``busy`` 503, a dead worker
   500), as the worker maps the planner's.

Batch items on a local process pool or a Dask cluster run :func:`app.jobs.run_bounded`, the
same estimate, limit and mapping in the process that runs them.
"""

from __future__ import annotations

import asyncio
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from app.failures import import_timeout, out_of_memory, timeout
from app.jobs import ExportJob, Failed, ImportJob, Job, Outcome, bounded, check_estimate, failed, run_bounded
from app.workers import JobTimeout, PlanPool, PoolBusy, WorkerCrashed, WorkerOutOfMemory

__all__ = ["JobService", "describe_failure"]


def describe_failure(exc: Exception, job: Job, timeout_s: float, memory_mb: int | None = None) -> Failed:
    """The outcome of a job the pool did not run to the end (the one wording of a time
    limit, a memory limit, a full queue or a dead worker)."""
    if isinstance(exc, WorkerOutOfMemory):
        return failed({"code": "too_much_memory", "message": str(exc) or out_of_memory(memory_mb)["message"]})
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


class JobService:
    """Runs jobs on ``pool`` (a :class:`PlanPool`; None: inline in the calling thread under
    ``timeout_s``, the editor started on its own). :meth:`run` blocks; :meth:`arun` awaits
    it from an event loop on a thread pool sized to the pool's capacity."""

    def __init__(self, pool: PlanPool | None = None, *, timeout_s: float = 30.0, memory_mb: int | None = None,
                 export_timeout_s: float | None = None):
        self.pool = pool
        self.timeout_s = pool.timeout_s if pool is not None else float(timeout_s)
        self.memory_mb = pool.memory_mb if pool is not None else memory_mb
        #: the time limit of an export (a stored plan is bounded by its size, not its work)
        self.export_timeout_s = max(self.timeout_s, export_timeout_s or 0.0)
        self._threads: ThreadPoolExecutor | None = None

    @classmethod
    def start(cls, workers: int, timeout_s: float, max_queue: int, mode: str = "process",
              memory_mb: int | None = None, export_timeout_s: float | None = None,
              start: str | None = None) -> JobService:
        """A service with a new pool of its own (:meth:`close` ends it); ``start``: how its
        worker processes start (:data:`app.workers.START_METHODS`)."""
        return cls(PlanPool(workers, timeout_s, max_queue, mode=mode, memory_mb=memory_mb, start=start),
                   export_timeout_s=export_timeout_s)

    def run(self, job: Job) -> Outcome:
        """Estimate, bound, run ``job`` on a worker; never raises for the input's fault, a
        limit, a full queue or a dead worker: those are :class:`Failed`."""
        refused = check_estimate(job, self.timeout_s)
        if refused is not None:
            return refused
        limit = self.export_timeout_s if isinstance(job, ExportJob) else self.timeout_s
        job = bounded(job, limit)
        if self.pool is None:
            return run_bounded(job, limit, self.memory_mb)
        try:
            return self.pool.run(job, limit)
        except (JobTimeout, PoolBusy, WorkerCrashed) as exc:
            return describe_failure(exc, job, limit, self.memory_mb)

    async def arun(self, job: Job) -> Outcome:
        """:meth:`run` from an event loop (on a thread: the pool blocks)."""
        if self._threads is None:
            capacity = self.pool.capacity if self.pool is not None else 4
            self._threads = ThreadPoolExecutor(max_workers=capacity + 4, thread_name_prefix="rangeplan-wait")
        return await asyncio.get_running_loop().run_in_executor(self._threads, self.run, job)

    def stats(self) -> dict[str, Any]:
        return self.pool.stats() if self.pool is not None else {}

    def readiness(self) -> dict[str, Any]:
        if self.pool is None:
            return {"ready": True, "workers_ready": 1, "workers": 1, "failures": []}
        return self.pool.readiness()

    def close(self, pool: bool = True) -> None:
        """Stop the waiting threads and (``pool``) the pool's workers."""
        if self._threads is not None:
            self._threads.shutdown(wait=False, cancel_futures=True)
            self._threads = None
        if pool and self.pool is not None:
            self.pool.close()
