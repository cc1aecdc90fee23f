"""The Dask batch engine: the service's :class:`app.cluster.DaskExecutor` on a distributed
cluster, to which the runner submits its chunks (:class:`app.batch.engine.BatchChunkJob`).

The connection, the worker plugin that warms every worker (:class:`app.cluster.WarmUp`, which
also relaxes the nanny's malloc trim) and the test for a lost worker are the service's
(:mod:`app.cluster`): batches and the service's jobs (``RANGEPLAN_EXECUTOR=dask``) reach a
cluster the same way. A chunk runs in a worker's thread (no limit of its own); each of its
items has the time limit and runs in a planning process of that worker. Tasks refer to
:func:`app.executors.run_bounded` and the chunk's class by name: workers need the same
rangeplan version as the client.
"""

from __future__ import annotations

from app.cluster import MALLOC_ENV, STATE, DaskExecutor, WarmUp, connect, relax_malloc_trim

from .base import Engine

__all__ = ["DaskEngine", "WarmUp", "MALLOC_ENV", "STATE", "relax_malloc_trim"]


class DaskEngine(Engine):
    name = "dask"
    attributes_failures = True

    def __init__(self, address: str, connect_timeout_s: float = 10.0):
        self.address = address
        self.client = connect(address, connect_timeout_s)
        # no limit and no memory cap on the chunk itself: its items have theirs (the runner keeps
        # at most 2 x slots chunks in flight, so the admission never refuses one)
        self.dask = DaskExecutor(address, timeout_s=0.0, max_queue=1 << 16, memory_mb=0, client=self.client)
        super().__init__(self.dask)

    @property
    def slots(self) -> int:
        return self.dask.n

    def describe(self) -> str:
        return f"dask: {self.address} ({self.slots} worker threads)"

    def close(self, cancel: bool = False) -> None:
        self.dask.close(cancel=cancel)
