"""The one executor every job of the service goes through: :class:`JobService`.

The HTTP API (``app.routers``), the editor (``app.editor._planning``) and the service's
batches submit typed jobs (:data:`app.jobs.Job`) and get a typed outcome
(:data:`app.jobs.Outcome`) back. The service does, once for all of them:

1. **estimate**: a job that plans is refused (``too_much_work``, in microseconds) when the
   planner's work estimate exceeds the time limit;
2. **bound and run on an executor** (:class:`app.executors.JobExecutor`): the local
   :class:`app.workers.PlanPool` (worker processes with a time limit, a memory cap and a bounded
   queue; or inline threads), a Dask cluster (:class:`app.cluster.DaskExecutor`) or the calling
   thread (:class:`app.executors.InProcessExecutor`, no time limit);
3. **map errors once**: the pool's exceptions become :class:`app.jobs.Failed` with the HTTP
   status they answer (``timeout`` and ``too_much_memory`` 422, ``busy`` 503, a dead worker
   500), as the worker maps the planner's;
4. **keep synchronous requests apart from jobs** (issue 33): a *job* (``background=True``: a
   contour or a plan answered 202, up to the job limit ``RANGEPLAN_JOB_TIMEOUT_S``) runs on
   a share of the workers, at most :attr:`JobService.job_workers` at once
   (``RANGEPLAN_JOB_WORKERS``, default one fewer than the workers); more jobs wait their turn
   here, holding no worker and no thread of the synchronous requests. A synchronous request
   never waits behind a job: on a local pool it takes a free worker before any waiting job
   (:class:`app.workers.PlanPool`), and with jobs on every worker (a share of all of them) it
   is answered ``busy`` (503) at once; the synchronous requests on the workers are kept with
   their estimates (:meth:`JobService.sync_left`) so that a busy answer can say when a slot
   is expected to free.

Batch items on a local process pool or a Dask cluster run :func:`app.executors.run_bounded`,
the same estimate, limit and mapping, in a planning process of the process that runs them
(a time limit is always enforced by killing a process: :mod:`app.executors`).
"""

from __future__ import annotations

import asyncio
import dataclasses
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from app.executors import InProcessExecutor, JobExecutor, describe_failure, on_reference
from app.jobs import ExportJob, Job, Outcome, bounded, check_estimate, estimate
from app.workers import JobTimeout, PlanPool, PoolBusy, WorkerCrashed

__all__ = ["JobService", "KernelCompile", "describe_failure"]


class KernelCompile:
    """The service's view of the background compile of the kernels (issue 24;
    :mod:`planner.orchestrator.background`): :meth:`running` is the compile while it runs
    (its done-marker is looked for at most every ``poll_s`` seconds: one ``stat``; a compile
    that ended unfinished leaves the service on the reference, ``ended``), None once the
    kernels are compiled, when ``on_done`` is called once (from a watch thread too, so it
    happens without traffic)."""

    def __init__(self, running: Any, on_done: Any = None, poll_s: float = 0.5):
        self._running = running
        self._on_done = on_done
        self._poll_s = poll_s
        self.ended = False  #: the compile ended without finishing
        self._checked = time.monotonic()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        threading.Thread(target=self._watch, name="rangeplan-kernel-compile", daemon=True).start()

    def running(self) -> Any:
        """The background compile (a :class:`~planner.orchestrator.background.BackgroundCompile`), or None."""
        done = False
        with self._lock:
            if self._running is None or time.monotonic() - self._checked < self._poll_s:
                return self._running
            self._checked = time.monotonic()
            from planner._jit import kernel_cache_dir
            from planner.orchestrator.background import MARKER, running_compile

            if (kernel_cache_dir() / MARKER).exists():
                self._running, done = None, True
            elif running_compile() is None:  # ended without finishing (killed, or an error: its log says)
                if not self.ended:
                    print(f"rangeplan: the background compile ended without finishing (log {self._running.log}); "
                          "plans keep running on the numpy reference", file=sys.stderr, flush=True)
                self.ended = True
        if done:
            print("rangeplan: kernels compiled: new workers plan on them", file=sys.stderr, flush=True)
            if self._on_done is not None:
                self._on_done()
        return self._running

    def _watch(self) -> None:
        while not self._stop.wait(self._poll_s):
            if self.running() is None or self.ended:
                return

    def close(self) -> None:
        self._stop.set()


#: threads of :meth:`JobService.arun` started with the service (at most)
PRESTARTED_THREADS = 256


class JobService:
    """Runs jobs on ``pool``, any :class:`app.executors.JobExecutor`: a :class:`PlanPool` (local
    planning processes), a :class:`app.cluster.DaskExecutor` (a Dask cluster) or None: an
    :class:`~app.executors.InProcessExecutor` (the calling thread, the editor started on its own:
    the work estimate is checked against ``timeout_s``, but a thread cannot be stopped, so no
    time limit is armed; a time limit needs a process). :meth:`run` blocks; :meth:`arun` awaits
    it from an event loop on a thread pool sized to the executor's capacity."""

    def __init__(self, pool: JobExecutor | None = None, *, timeout_s: float = 30.0, memory_mb: int | None = None,
                 export_timeout_s: float | None = None, compiling: Any = None, job_workers: int | None = None):
        #: where jobs run (named ``pool`` since the local pool was the only one)
        self.pool: JobExecutor = pool if pool is not None else InProcessExecutor(timeout_s, memory_mb)
        self.inline = pool is None
        #: the background compile of the kernels while it runs (``compiling``: a
        #: :class:`~planner.orchestrator.background.BackgroundCompile`): jobs then plan on the
        #: numpy reference, estimated at its costs; once it is done the pool's workers are renewed
        self.kernels: KernelCompile | None = None
        if compiling is not None:
            self.kernels = KernelCompile(compiling, self._kernels_compiled)
        self.timeout_s = self.pool.timeout_s
        self.memory_mb = self.pool.memory_mb if pool is not None else memory_mb
        #: the time limit of an export (a stored plan is bounded by its size, not its work)
        self.export_timeout_s = max(self.timeout_s, export_timeout_s or 0.0)
        self._threads: ThreadPoolExecutor | None = None
        self._threads_lock = threading.Lock()
        #: jobs (``background``) that may run at once: the jobs' share of the workers
        self.job_workers = max(1, int(job_workers)) if job_workers else max(1, self.workers - 1)
        self._job_threads: ThreadPoolExecutor | None = None  # one per job slot: the share itself
        self.jobs_queued = 0  #: jobs waiting for a slot of the share
        self.jobs_running = 0  #: jobs holding a slot (on a worker, or taking the next free one)
        #: synchronous requests handed to the executor: when each was, and its work estimate [s]
        #: (None: not estimated before it runs), for :meth:`sync_left`
        self._sync: dict[int, tuple[float, float | None]] = {}
        self._sync_seq = 0

    @property
    def workers(self) -> int:
        """The executor's workers (a local pool's processes, a cluster's threads; 1 inline)."""
        return max(1, int(getattr(self.pool, "n", 1) or 1))

    @classmethod
    def start(cls, workers: int, timeout_s: float, max_queue: int, mode: str = "process",
              memory_mb: int | None = None, export_timeout_s: float | None = None,
              start: str | None = None, reference_while_compiling: bool = False,
              scheduler: str | None = None, job_workers: int | None = None) -> JobService:
        """A service with a new executor of its own (:meth:`close` ends it): ``mode``
        ``"process"`` or ``"thread"`` (a :class:`PlanPool` of ``workers``; ``start``: how its
        worker processes start, :data:`app.workers.START_METHODS`) or ``"dask"`` (the cluster at
        ``scheduler``, default ``RANGEPLAN_DASK_SCHEDULER``; ``OSError`` when it cannot be
        reached, ``ValueError`` when none is given). ``reference_while_compiling``: when the
        kernels are not compiled, compile them in the background
        (:func:`planner.orchestrator.background.while_compiling`) and plan on the numpy
        reference meanwhile (the workers start at once, on the reference; not on Dask, whose
        workers load or compile their own). ``job_workers``: the jobs' share (default one fewer than
        the workers)."""
        if mode == "dask":
            from app.cluster import DaskExecutor
            from app.settings import settings

            address = scheduler or settings().dask_scheduler
            if not address:
                raise ValueError("RANGEPLAN_EXECUTOR=dask needs the scheduler's address in RANGEPLAN_DASK_SCHEDULER "
                                 "(tcp://host:8786)")
            return cls(DaskExecutor(address, timeout_s, max_queue, memory_mb), export_timeout_s=export_timeout_s,
                       job_workers=job_workers)
        compiling = None
        if reference_while_compiling:
            from planner.orchestrator.background import while_compiling

            compiling = while_compiling("compiled", None)
        return cls(PlanPool(workers, timeout_s, max_queue, mode=mode, memory_mb=memory_mb, start=start),
                   export_timeout_s=export_timeout_s, compiling=compiling, job_workers=job_workers)

    def _kernels_compiled(self) -> None:
        threading.Thread(target=self.pool.renew, name="rangeplan-pool-renew", daemon=True).start()

    def run(self, job: Job, limit_s: float | None = None, background: bool = False) -> Outcome:
        """Estimate, bound, run ``job`` on a worker; never raises for the input's fault, a
        limit, a full queue or a dead worker: those are :class:`Failed`. While the kernels
        compile in the background a planning job runs on the numpy reference
        (:func:`app.executors.on_reference`, the rule the CLI applies too). ``limit_s``: the
        time limit of this job instead of the service's (an HTTP job's, ``RANGEPLAN_JOB_TIMEOUT_S``);
        ``background``: a job, which yields free workers to synchronous requests (its share is
        bounded by :meth:`arun`)."""
        running = self.kernels.running() if self.kernels is not None else None
        if running is not None:
            job = on_reference(job)
        timeout_s = self.timeout_s if limit_s is None else float(limit_s)
        work = estimate(job)
        refused = check_estimate(job, timeout_s, work)
        if refused is not None:
            if running is not None and refused.error.code == "too_much_work":
                when = ("are not compiled (the background compile ended without finishing)"
                        if self.kernels is not None and self.kernels.ended
                        else f"are compiling in the background, ready in {running.ready_in()}: retry then")
                error = refused.error.model_copy(update={"message": (
                    f"{refused.error.message}; the compiled kernels (~100x faster than the numpy reference this "
                    f"server plans on until then) {when}")})
                return dataclasses.replace(refused, error=error)
            return refused
        limit = self.export_timeout_s if isinstance(job, ExportJob) else timeout_s
        job = bounded(job, limit)
        if background:  # (a job's time left is its row's: app.routers.jobs)
            try:
                return self.pool.run(job, limit, background=True)
            except (JobTimeout, PoolBusy, WorkerCrashed) as exc:
                return describe_failure(exc, job, limit, self.memory_mb)
        with self._threads_lock:
            self._sync_seq = key = self._sync_seq + 1
            self._sync[key] = (time.monotonic(), None if work is None else float(work.seconds))
        try:
            return self.pool.run(job, limit)
        except (JobTimeout, PoolBusy, WorkerCrashed) as exc:
            return describe_failure(exc, job, limit, self.memory_mb)
        finally:
            with self._threads_lock:
                del self._sync[key]

    def sync_left(self) -> list[float]:
        """The expected time left [s] of each synchronous request handed to the executor with a
        work estimate: the estimate less the time since (waiting for a worker counts as run: a
        lower bound), not below 0. What a busy answer's ``Retry-After`` is made of with the
        jobs' time left (:func:`app.job_progress.first_free`)."""
        now = time.monotonic()
        with self._threads_lock:
            sync = list(self._sync.values())
        return [max(0.0, est - (now - t0)) for t0, est in sync if est is not None]

    def start_threads(self) -> None:
        """Start the threads :meth:`arun` waits on, before the first request (the API's and
        the editor's start-up). Started in a burst of requests instead, each new thread held
        the event loop until the scheduler first ran it: ~10 ms each on a loaded 2-core
        machine, 0.7 s for the 67 plans of 200 clients' first requests (tests/test_load.py)."""
        with self._threads_lock:
            if self._threads is not None:
                return
            capacity = self.pool.capacity + 4
            self._threads = ex = ThreadPoolExecutor(max_workers=capacity, thread_name_prefix="rangeplan-wait")
        # each task waits at the barrier, so every submit starts a thread of its own; beyond
        # PRESTARTED_THREADS (a queue configured huge) the executor starts them when needed
        n = min(capacity, PRESTARTED_THREADS)
        barrier = threading.Barrier(n + 1)
        for _ in range(n):
            ex.submit(barrier.wait, 30)
        try:
            barrier.wait(30)
        except threading.BrokenBarrierError:  # a thread that did not start in 30 s: it starts later
            pass

    async def arun(self, job: Job, limit_s: float | None = None, background: bool = False) -> Outcome:
        """:meth:`run` from an event loop (on a thread: the pool blocks). ``background``: a job,
        on one of :attr:`job_workers` threads of its own (the jobs' share; more wait for one
        without holding a worker or a thread of the synchronous requests)."""
        loop = asyncio.get_running_loop()
        if background:
            with self._threads_lock:
                if self._job_threads is None:
                    self._job_threads = ThreadPoolExecutor(self.job_workers, thread_name_prefix="rangeplan-job")
                threads = self._job_threads
                self.jobs_queued += 1
            return await loop.run_in_executor(threads, self._run_job, job, limit_s)
        if self._threads is None:
            self.start_threads()
        return await loop.run_in_executor(self._threads, self.run, job, limit_s)

    def _run_job(self, job: Job, limit_s: float | None) -> Outcome:
        with self._threads_lock:
            self.jobs_queued -= 1
            self.jobs_running += 1
        try:
            return self.run(job, limit_s, background=True)
        finally:
            with self._threads_lock:
                self.jobs_running -= 1

    def jobs(self) -> dict[str, int]:
        """The jobs' share: ``{"workers", "running", "queued"}`` (/ready, /metrics)."""
        return {"workers": self.job_workers, "running": self.jobs_running, "queued": self.jobs_queued}

    def stats(self) -> dict[str, Any]:
        return self.pool.stats()

    def readiness(self) -> dict[str, Any]:
        state = self.pool.readiness()
        running = self.kernels.running() if self.kernels is not None else None
        if running is None:
            state["kernels"] = "compiled"
        elif self.kernels is not None and self.kernels.ended:
            state["kernels"] = (f"not compiled: the background compile ended without finishing (log {running.log}); "
                                "plans run on the numpy reference")
        else:
            state["kernels"] = (f"compiling in the background, {running.ready_in()} left (pid {running.pid}); plans "
                                "run on the numpy reference meanwhile")
        return state

    def close(self, pool: bool = True) -> None:
        """Stop the waiting threads and (``pool``) the pool's workers."""
        if self.kernels is not None:
            self.kernels.close()
        if self._threads is not None:
            self._threads.shutdown(wait=False, cancel_futures=True)
            self._threads = None
        with self._threads_lock:
            jobs, self._job_threads = self._job_threads, None
        if jobs is not None:
            jobs.shutdown(wait=False, cancel_futures=True)
        if pool:
            self.pool.close()
