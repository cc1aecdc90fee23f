"""A Dask distributed cluster, for the service's jobs and for batches: the connection, the
worker plugin that warms every worker, and :class:`DaskExecutor` (the service's jobs on it).

Workers need rangeplan installed (the same version as the client: tasks refer to
:func:`app.executors.run_bounded` and :func:`app.batch.engine.plan_chunk` by name).
:class:`WarmUp`, a worker plugin registered once per client (:func:`connect`), loads the
compiled kernels on every worker, including workers that join or are restarted later; items
then never compile or import anything. A job with a time limit runs in a planning process of
the worker (:func:`app.executors.child_pool`), killed at the limit: the worker lives on. The
scheduler retries the tasks of a worker that dies (``distributed.scheduler.allowed-failures``,
3 by default) and gives up with ``KilledWorker`` on a task that killed that many workers.

**Memory reuse.** Dask's nanny starts every worker with ``MALLOC_TRIM_THRESHOLD_=65536``
(``distributed.nanny.pre-spawn-environ``): glibc hands freed heap memory back to the system
as soon as 64 kB are free at its top, and with the variable set its thresholds no longer
adapt. The planner allocates and frees arrays at every step, so the pages are returned and
faulted in again all the time: a constrained Table I plan took 93 ms of CPU in a Dask worker
against 80 ms in a pool worker before issue 17 (2-5 % more since the constrained loop is
compiled; benchmarks/README.md). :class:`WarmUp` therefore sets, in each worker it warms and
only where a lower trim threshold is set, glibc's own adaptive limits (trim 64 MiB, mmap
32 MiB: what a process without the variable reaches); memory above that is still returned.
``RANGEPLAN_DASK_MALLOC=keep`` leaves the workers' settings alone.

**The service on Dask** (``RANGEPLAN_EXECUTOR=dask``, ``RANGEPLAN_DASK_SCHEDULER``): each job
is one task running :func:`app.executors.run_bounded` on a worker, under the service's time
limit and memory cap. A job that stores its plan (``POST /v1/plan``, ``POST /v1/contour``) or
reads a stored one (an export) opens the server's SQLite store by its path on the worker: the
workers must see the server's data directory at the same path (the same host, or a shared
filesystem that supports SQLite's locks).
"""

from __future__ import annotations

import asyncio
import math
import sys
import threading
import time
from concurrent.futures import Future
from typing import Any

from distributed import Client
from distributed.diagnostics.plugin import WorkerPlugin

from app.executors import run_bounded, warm_worker
from app.jobs import Job, Outcome
from app.workers import Admission, JobKilledWorkers, WorkerCrashed

__all__ = ["DaskExecutor", "WarmUp", "MALLOC_ENV", "STATE", "connect", "lost_worker", "relax_malloc_trim"]

#: ``keep``: leave the Dask workers' malloc settings as the cluster set them
MALLOC_ENV = "RANGEPLAN_DASK_MALLOC"
#: glibc's ``mallopt`` parameters (malloc.h) and the limits its adaptive thresholds reach on
#: 64-bit systems (``DEFAULT_MMAP_THRESHOLD_MAX`` and twice that)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
TRIM_BYTES, MMAP_BYTES = 64 << 20, 32 << 20
#: what :class:`WarmUp` did in this worker process (``malloc``: whether it relaxed the trim)
STATE: dict[str, bool | None] = {"malloc": None}


def relax_malloc_trim() -> bool:
    """In this process: if ``MALLOC_TRIM_THRESHOLD_`` is below :data:`TRIM_BYTES` (Dask's
    nanny sets 65536), set glibc's trim and mmap thresholds to :data:`TRIM_BYTES` and
    :data:`MMAP_BYTES`. True if it did; False where there is nothing to do or no glibc."""
    from app.settings import SettingsError, settings

    try:
        wanted = settings().malloc_trim_threshold
    except SettingsError:  # not a number: glibc ignores it too
        return False
    if wanted is None or wanted >= TRIM_BYTES or not sys.platform.startswith("linux"):
        return False
    import ctypes

    try:
        libc = ctypes.CDLL("libc.so.6")
        return bool(libc.mallopt(_M_TRIM_THRESHOLD, TRIM_BYTES)) and bool(libc.mallopt(_M_MMAP_THRESHOLD, MMAP_BYTES))
    except (OSError, AttributeError):  # not glibc (musl has no such library name, no mallopt)
        return False


class WarmUp(WorkerPlugin):
    """Load the planner's compiled kernels when a worker starts (off its event loop, so
    heartbeats go on during a first compilation) and, unless ``malloc == "keep"``, let glibc
    reuse freed memory (:func:`relax_malloc_trim`)."""

    idempotent = True
    name = "rangeplan-warm-up"

    def __init__(self, malloc: str = "relax"):
        self.malloc = malloc

    async def setup(self, worker) -> None:
        STATE["malloc"] = relax_malloc_trim() if self.malloc != "keep" else False
        await asyncio.get_running_loop().run_in_executor(None, warm_worker, "dask")


def connect(address: str, connect_timeout_s: float = 10.0) -> Client:
    """A client of the scheduler at ``address`` with :class:`WarmUp` registered on its
    workers; ``OSError`` naming the cause when the scheduler cannot be reached within
    ``connect_timeout_s`` or its workers cannot load rangeplan."""
    try:
        client = Client(address, timeout=f"{connect_timeout_s}s", set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise OSError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
    try:
        from app.settings import settings

        client.register_plugin(WarmUp(settings().dask_malloc), name=WarmUp.name)
    except Exception as exc:  # a worker without rangeplan cannot even load the plugin
        client.close()
        raise OSError(f"the Dask workers at {address} cannot load rangeplan ({type(exc).__name__}: {exc}); "
                      "install the same rangeplan version on every worker") from None
    return client


def lost_worker(exc: BaseException) -> bool:
    """Whether ``exc`` (a Dask future's exception) means a worker died or the scheduler
    dropped the task, not that the task failed."""
    from concurrent.futures import CancelledError

    from distributed.comm.core import CommClosedError
    from distributed.scheduler import KilledWorker

    # a future the scheduler dropped (it lost its data or restarted) arrives cancelled
    return isinstance(exc, (KilledWorker, CommClosedError, CancelledError))


def slots(client: Client) -> int:
    """Tasks the cluster runs at once (its workers' threads; at least 1)."""
    nthreads: dict = client.nthreads()  # type: ignore[assignment]  (synchronous client)
    return max(1, sum(nthreads.values()))


class DaskExecutor(Admission):
    """The service's jobs on a Dask cluster (:class:`app.executors.JobExecutor`): each
    :meth:`run` is one task, :func:`app.executors.run_bounded` on a worker (the estimate,
    the time limit as a killed planning process, the memory cap ``memory_mb`` MiB). At most
    the cluster's threads plus ``max_queue`` jobs at once (more: :class:`PoolBusy`); a worker
    that dies under a job is :class:`WorkerCrashed` after the scheduler's retries."""

    mode = "dask"

    def __init__(self, address: str, timeout_s: float = 30.0, max_queue: int = 64, memory_mb: int | None = None,
                 connect_timeout_s: float = 10.0, client: Client | None = None):
        self.address = address
        self.timeout_s = float(timeout_s)
        self.max_queue = int(max_queue)
        self.memory_mb = int(memory_mb or 0)
        self.client = client if client is not None else connect(address, connect_timeout_s)
        self._lock = threading.Lock()
        self._inflight = 0
        self._closed = False
        self._executor: Any = None  # Client.get_executor(), made by the first submit()
        self._n, self._n_at = 1, -math.inf  # the worker threads, when last asked (n)
        self.jobs_run = 0  #: jobs handed to the cluster

    @property
    def n(self) -> int:
        """The cluster's worker threads (it grows and shrinks): asked of the scheduler at most
        once a second (every job's admission reads it; each question is a round trip to the
        scheduler, which a batch's chunks would otherwise pay one by one)."""
        now = time.monotonic()
        if now - self._n_at > 1.0:
            try:
                self._n = slots(self.client)
            except Exception:
                self._n = 1
            self._n_at = now
        return self._n

    @property
    def capacity(self) -> int:
        return self.n + self.max_queue

    def run(self, job: Job, timeout_s: float | None = None, background: bool = False) -> Outcome:
        """One task (``background``: at a lower priority than the synchronous requests' tasks,
        which the scheduler starts first)."""
        limit = self.timeout_s if timeout_s is None else float(timeout_s)
        with self._admitted():
            fut = self.client.submit(run_bounded, job, limit, self.memory_mb or None, pure=False,
                                     priority=-1 if background else 0)
            try:
                return fut.result()
            except Exception as exc:
                raise _crashed(exc) from None

    def submit(self, job: Job, timeout_s: float | None = None) -> Future:
        """:meth:`run` without blocking: one task, its outcome in a ``concurrent.futures.Future``
        (``Client.get_executor()``'s, which :meth:`Future.cancel` withdraws from the scheduler);
        a lost worker is :class:`~app.workers.WorkerCrashed` as in :meth:`run`."""
        limit = self.timeout_s if timeout_s is None else float(timeout_s)
        self._admit()
        try:
            with self._lock:
                if self._executor is None:
                    self._executor = self.client.get_executor(pure=False)
                executor = self._executor
            task = executor.submit(run_bounded, job, limit, self.memory_mb or None)
        except BaseException:
            self._release()
            raise
        out: Future = Future()

        def settle(done: Future) -> None:
            self._release()
            if done.cancelled():
                out.cancel()
                out.set_running_or_notify_cancel()
                return
            if not out.set_running_or_notify_cancel():
                return
            exc = done.exception()
            if exc is None:
                out.set_result(done.result())
            else:
                out.set_exception(_crashed(exc))

        def withdraw(mine: Future) -> None:
            if mine.cancelled():
                task.cancel()

        task.add_done_callback(settle)
        out.add_done_callback(withdraw)
        return out

    def stats(self) -> dict[str, Any]:
        return {"mode": self.mode, "workers": self.n, "in_flight": self._inflight, "timeout_s": self.timeout_s,
                "replaced_workers": 0, "memory_mb": self.memory_mb, "scheduler": self.address}

    def readiness(self) -> dict[str, Any]:
        try:
            workers = len(self.client.scheduler_info().get("workers", {}))
            failures = [] if workers else [f"no Dask worker at {self.address}"]
        except Exception as exc:
            workers, failures = 0, [f"the Dask scheduler at {self.address} does not answer ({type(exc).__name__})"]
        return {"ready": workers > 0 and not self._closed, "workers_ready": workers, "workers": workers,
                "failures": failures}

    def renew(self) -> None:
        """Nothing to renew: each Dask worker loads its own kernels (:class:`WarmUp`)."""

    def close(self, cancel: bool = False) -> None:
        """Close the connection (``cancel``: the tasks sent are withdrawn first)."""
        with self._lock:
            self._closed = True
            executor, self._executor = self._executor, None
        try:
            if executor is not None:
                executor.shutdown(wait=not cancel)
        finally:
            self.client.close()


def _crashed(exc: BaseException) -> BaseException:
    """A Dask task's exception as :meth:`DaskExecutor.run` raises it: a lost worker or a dropped
    task is :class:`~app.workers.WorkerCrashed` (:class:`~app.workers.JobKilledWorkers` when the
    scheduler gave up after the task killed several workers), anything else as it is."""
    if not (lost_worker(exc) or isinstance(exc, OSError)):
        return exc
    kind = JobKilledWorkers if type(exc).__name__ == "KilledWorker" else WorkerCrashed
    return kind(f"the Dask worker was lost ({type(exc).__name__}: {exc})")
