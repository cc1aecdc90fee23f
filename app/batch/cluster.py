"""The Dask engine: a distributed cluster behind ``Client.get_executor()`` (the
``concurrent.futures`` interface the local pool also speaks).

Workers need rangeplan installed (the same version as the client: tasks refer to
:func:`app.batch.engine.plan_chunk` by name). :class:`WarmUp`, a worker plugin registered
once per client, loads the compiled kernels on every worker, including workers that join
or are restarted later; items then never compile or import anything. The scheduler retries
the tasks of a worker that dies (``distributed.scheduler.allowed-failures``, 3 by default)
and gives up with ``KilledWorker`` on a task that killed that many workers.

**Memory reuse.** Dask's nanny starts every worker with ``MALLOC_TRIM_THRESHOLD_=65536``
(``distributed.nanny.pre-spawn-environ``): glibc hands freed heap memory back to the system
as soon as 64 kB are free at its top, and with the variable set its thresholds no longer
adapt. The planner allocates and frees arrays at every step, so the pages are returned and
faulted in again all the time: a constrained Table I plan took 93 ms of CPU in a Dask worker
against 80 ms in a pool worker before issue 17 (2-5 % more since the constrained loop is
compiled; benchmarks/README.md). :class:`WarmUp` therefore sets, in
each worker it warms and only where a lower trim threshold is set, glibc's own adaptive
limits (trim 64 MiB, mmap 32 MiB: what a process without the variable reaches); memory above
that is still returned. ``RANGEPLAN_DASK_MALLOC=keep`` leaves the workers' settings alone.
"""

from __future__ import annotations

import asyncio
import os
import sys
from concurrent.futures import Executor

from distributed import Client
from distributed.diagnostics.plugin import WorkerPlugin

from .engine import warm_worker
from .executors import Engine

__all__ = ["DaskEngine", "WarmUp", "MALLOC_ENV", "relax_malloc_trim"]

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
    try:
        wanted = int(os.environ.get("MALLOC_TRIM_THRESHOLD_", ""))
    except ValueError:
        return False
    if wanted >= TRIM_BYTES or not sys.platform.startswith("linux"):
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


class DaskEngine(Engine):
    name = "dask"
    attributes_failures = True

    def __init__(self, address: str, connect_timeout_s: float = 10.0):
        self.address = address
        try:
            self.client = Client(address, timeout=f"{connect_timeout_s}s", set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise OSError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
        try:
            from app.settings import settings

            self.client.register_plugin(WarmUp(settings().dask_malloc), name=WarmUp.name)
        except Exception as exc:  # a worker without rangeplan cannot even load the plugin
            self.client.close()
            raise OSError(f"the Dask workers at {address} cannot load rangeplan ({type(exc).__name__}: {exc}); "
                          "install the same rangeplan version on every worker") from None
        self._executor = self.client.get_executor(pure=False)

    @property
    def executor(self) -> Executor:
        return self._executor

    @property
    def slots(self) -> int:
        nthreads: dict = self.client.nthreads()  # type: ignore[assignment]  (synchronous client)
        return max(1, sum(nthreads.values()))

    def is_lost_worker(self, exc: BaseException) -> bool:
        from concurrent.futures import CancelledError

        from distributed.comm.core import CommClosedError
        from distributed.scheduler import KilledWorker

        # a future the scheduler dropped (it lost its data or restarted) arrives cancelled
        return isinstance(exc, (KilledWorker, CommClosedError, CancelledError))

    def describe(self) -> str:
        return f"dask: {self.address} ({self.slots} worker threads)"

    def close(self, cancel: bool = False) -> None:
        try:
            self._executor.shutdown(wait=not cancel)
        finally:
            self.client.close()

