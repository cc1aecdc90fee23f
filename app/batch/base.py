"""What the batch runner needs of an engine (:mod:`app.batch.executors`,
:mod:`app.batch.cluster`): an executor of tasks, how many run at once, what a lost worker
looks like. No import of the engines themselves (they import this)."""

from __future__ import annotations

from concurrent.futures import Executor

__all__ = ["Engine"]


class Engine:
    """What the runner needs of an engine: an executor, how many tasks it runs at once, and
    what to do when it loses a worker."""

    name = "engine"
    #: True if the engine itself retries the tasks of a lost worker and knows which task
    #: killed it (Dask's scheduler); False if the runner must (a broken process pool)
    attributes_failures = False

    @property
    def executor(self) -> Executor:
        raise NotImplementedError

    @property
    def slots(self) -> int:
        """Tasks that run at once (workers x threads)."""
        return 1

    def is_lost_worker(self, exc: BaseException) -> bool:
        """Whether ``exc`` (a future's exception) means the worker died, not the item failed."""
        return False

    def restart(self) -> None:
        """Make the executor usable again after a lost worker."""

    def describe(self) -> str:
        return self.name

    def close(self, cancel: bool = False) -> None:
        """Stop the workers (``cancel``: now, dropping running tasks)."""
