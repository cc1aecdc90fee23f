"""The Dask engine: a distributed cluster behind ``Client.get_executor()`` (the
``concurrent.futures`` interface the local pool also speaks).

Workers need rangeplan installed (the same version as the client: tasks refer to
:func:`app.batch.engine.plan_chunk` by name). :class:`WarmUp`, a worker plugin registered
once per client, loads the compiled kernels on every worker, including workers that join
or are restarted later; items then never compile or import anything. The scheduler retries
the tasks of a worker that dies (``distributed.scheduler.allowed-failures``, 3 by default)
and gives up with ``KilledWorker`` on a task that killed that many workers.
"""

from __future__ import annotations

import asyncio
from concurrent.futures import Executor

from distributed import Client
from distributed.diagnostics.plugin import WorkerPlugin

from .engine import warm_worker
from .executors import Engine

__all__ = ["DaskEngine", "WarmUp"]


class WarmUp(WorkerPlugin):
    """Load the planner's compiled kernels when a worker starts (off its event loop, so
    heartbeats go on during a first compilation)."""

    idempotent = True
    name = "rangeplan-warm-up"

    async def setup(self, worker) -> None:
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
            self.client.register_plugin(WarmUp(), name=WarmUp.name)
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

