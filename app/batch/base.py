"""What the batch runner needs of an engine (:mod:`app.batch.executors`,
:mod:`app.batch.cluster`): the service's executor it submits chunks to, how many run at once,
each item's memory cap, whether the executor retries lost work itself. No import of the
engines themselves (they import this)."""

from __future__ import annotations

from app.executors import JobExecutor

__all__ = ["Engine"]


class Engine:
    """A batch's view of one of the service's executors (:class:`app.executors.JobExecutor`):
    the runner submits :class:`app.batch.engine.BatchChunkJob` s to :attr:`executor`, keeps
    about twice :attr:`slots` in flight and caps each item at :attr:`item_memory_mb` MiB."""

    name = "engine"
    #: True if the executor itself retries the jobs of a lost worker (Dask's scheduler: a lost
    #: job reaching the runner was either given up, ``JobKilledWorkers``, or lost with the
    #: connection); False if a lost job is the runner's to retry and its items are suspects (a
    #: local pool: the chunk's process died, one of its items is the likely cause)
    attributes_failures = False
    #: each item's memory cap [MiB] (the planning process it runs in), None: none
    item_memory_mb: int | None = None

    def __init__(self, executor: JobExecutor):
        self._executor = executor

    @property
    def executor(self) -> JobExecutor:
        return self._executor

    @property
    def slots(self) -> int:
        """Chunks that run at once (workers x threads)."""
        return 1

    def describe(self) -> str:
        return self.name

    def pids(self) -> list[int]:
        """The processes the chunks run in, where this machine has them (a local pool's workers)."""
        return []

    def close(self, cancel: bool = False) -> None:
        """Stop the workers (``cancel``: now, dropping running chunks)."""
        self._executor.close()
