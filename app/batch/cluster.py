"""The Dask batch engine: a distributed cluster behind ``Client.get_executor()`` (the
``concurrent.futures`` interface the local pool also speaks).

The connection, the worker plugin that warms every worker (:class:`app.cluster.WarmUp`, which
also relaxes the nanny's malloc trim) and the test for a lost worker are the service's
(:mod:`app.cluster`): batches and the service's jobs (``RANGEPLAN_EXECUTOR=dask``) reach a
cluster the same way. Tasks refer to :func:`app.batch.engine.plan_chunk` by name: workers need
the same rangeplan version as the client.
"""

from __future__ import annotations

from concurrent.futures import Executor

from app.cluster import MALLOC_ENV, STATE, WarmUp, connect, lost_worker, relax_malloc_trim, slots

from .base import Engine

__all__ = ["DaskEngine", "WarmUp", "MALLOC_ENV", "STATE", "relax_malloc_trim"]


class DaskEngine(Engine):
    name = "dask"
    attributes_failures = True

    def __init__(self, address: str, connect_timeout_s: float = 10.0):
        self.address = address
        self.client = connect(address, connect_timeout_s)
        self._executor = self.client.get_executor(pure=False)

    @property
    def executor(self) -> Executor:
        return self._executor

    @property
    def slots(self) -> int:
        return slots(self.client)

    def is_lost_worker(self, exc: BaseException) -> bool:
        return lost_worker(exc)

    def describe(self) -> str:
        return f"dask: {self.address} ({self.slots} worker threads)"

    def close(self, cancel: bool = False) -> None:
        try:
            self._executor.shutdown(wait=not cancel)
        finally:
            self.client.close()
