"""Where a batch runs: the service's executors (:class:`app.executors.JobExecutor`), to which
the runner submits chunks of items as typed jobs (:class:`app.batch.engine.BatchChunkJob`).

* :class:`InlineEngine`: :class:`app.executors.InProcessExecutor`, the calling process, one
  item after another (the 1-process baseline of ``benchmarks/bench_batch.py``).
* :class:`LocalEngine`: a local pool of planning processes, :class:`app.workers.PlanPool`
  (fresh interpreters, ``start="exec"``: independent of the interactive pool's fork server,
  which is renewed after a background compile); each loads the compiled kernels once when
  it starts. A worker that dies is replaced by the pool; the runner runs the items of its
  chunk again, one at a time.
* :class:`app.batch.cluster.DaskEngine`: :class:`app.cluster.DaskExecutor`, a Dask cluster
  (imported only when a scheduler address is given).

:class:`app.batch.base.Engine` is what the runner needs of each. Every item runs as the
service's typed job under the service's bounds wherever it runs (:func:`app.executors.run_bounded`).

:func:`open_engine` picks one: a scheduler address (argument or ``RANGEPLAN_DASK_SCHEDULER``)
means Dask, else a local pool of ``workers`` (default: the CPU count).
"""

from __future__ import annotations

import os

from app.executors import InProcessExecutor
from app.workers import PlanPool

from .base import Engine
from .config import SCHEDULER_ENV

__all__ = ["Engine", "InlineEngine", "LocalEngine", "open_engine", "SCHEDULER_ENV"]


class InlineEngine(Engine):
    name = "inline"

    def __init__(self, memory_mb: int | None = None):
        super().__init__(InProcessExecutor(timeout_s=0.0))
        self.item_memory_mb = memory_mb

    def describe(self) -> str:
        return "inline: this process, one item at a time"


class LocalEngine(Engine):
    """``workers`` local planning processes (``nice``: their CPU priority below this process;
    the command's own by default, the service's batch pool below its interactive one, which
    runs :data:`~app.workers.WORKER_NICE` below it; ``memory_mb``: each item's address-space
    cap [MiB], None: none)."""

    name = "local"

    def __init__(self, workers: int | None = None, nice: int = 0, memory_mb: int | None = None):
        self.workers = max(1, int(workers or os.cpu_count() or 1))
        self.nice = int(nice)
        self.item_memory_mb = memory_mb
        # no limit of the pool's own (the items have theirs) and no cap on the worker (its items'
        # planning processes have theirs); the runner keeps at most 2 x slots chunks in flight
        self.pool = PlanPool(self.workers, timeout_s=0.0, max_queue=2 * self.workers, memory_mb=0, start="exec",
                             nice=self.nice)
        super().__init__(self.pool)

    @property
    def slots(self) -> int:
        return self.workers

    def pids(self) -> list[int]:
        """The worker processes' ids (started with the engine; None while one starts)."""
        return [p for p in (w.pid for w in self.pool._workers) if p is not None]

    def describe(self) -> str:
        return f"local: {self.workers} worker process{'es' if self.workers > 1 else ''}"

    def close(self, cancel: bool = False) -> None:
        self.pool.close(cancel=cancel)


def open_engine(workers: int | None = None, scheduler: str | None = None, *, nice: int = 0,
                inline: bool = False, connect_timeout_s: float = 10.0, memory_mb: int | None = None) -> Engine:
    """The engine for these settings: ``inline``; a Dask cluster at ``scheduler`` (or
    ``$RANGEPLAN_DASK_SCHEDULER``; its workers have the cluster's own memory limits); else a
    local pool of ``workers``, each item capped at ``memory_mb`` MiB. Raises ``OSError`` when
    the scheduler cannot be reached within ``connect_timeout_s``."""
    if inline:
        return InlineEngine(memory_mb)
    if not scheduler:
        from app.settings import settings

        scheduler = settings().dask_scheduler or None
    if scheduler:
        from .cluster import DaskEngine

        return DaskEngine(scheduler, connect_timeout_s=connect_timeout_s)
    return LocalEngine(workers, nice=nice, memory_mb=memory_mb)
