"""Where a batch runs: one ``concurrent.futures.Executor`` interface over three engines.

* :class:`InlineEngine`: the calling process, one item after another (the 1-process
  baseline of ``benchmarks/bench_batch.py``; no parallelism).
* :class:`LocalEngine`: a local process pool (``ProcessPoolExecutor``, ``spawn``: a fresh
  interpreter per worker, safe beside the server's threads); each worker loads the compiled
  kernels once in its initializer. A worker that dies breaks a ``ProcessPoolExecutor``;
  :meth:`LocalEngine.restart` starts a new pool and the runner resubmits what was in flight.
* :class:`app.batch.cluster.DaskEngine`: a Dask distributed cluster through
  ``Client.get_executor()`` (imported only when a scheduler address is given).

:class:`app.batch.base.Engine` is what the runner needs of each. Items run the service's jobs
under the service's bounds wherever they run (:func:`app.executors.run_bounded`).

:func:`open_engine` picks one: a scheduler address (argument or ``RANGEPLAN_DASK_SCHEDULER``)
means Dask, else a local pool of ``workers`` (default: the CPU count).
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

from app.executors import warm_worker

from .base import Engine
from .config import SCHEDULER_ENV

__all__ = ["Engine", "InlineEngine", "LocalEngine", "open_engine", "SCHEDULER_ENV"]


class _InlineExecutor(Executor):
    """Runs each call at submit, in the calling thread."""

    def submit(self, fn, /, *args, **kwargs):  # type: ignore[override]
        fut: Future = Future()
        fut.set_running_or_notify_cancel()
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # noqa: B036  (a Future carries any exception)
            if isinstance(exc, KeyboardInterrupt):
                raise
            fut.set_exception(exc)
        return fut


class InlineEngine(Engine):
    name = "inline"

    def __init__(self):
        self._executor = _InlineExecutor()

    @property
    def executor(self) -> Executor:
        return self._executor

    def describe(self) -> str:
        return "inline: this process, one item at a time"


class LocalEngine(Engine):
    """``workers`` local processes (``nice``: their CPU priority offset, > 0 yields to the
    interactive planning pool; ``memory_mb``: each one's address-space cap [MiB], None: none)."""

    name = "local"

    def __init__(self, workers: int | None = None, nice: int = 0, memory_mb: int | None = None):
        self.workers = max(1, int(workers or os.cpu_count() or 1))
        self.nice = nice
        self.memory_mb = memory_mb
        self._pool = self._start()

    def _start(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=warm_worker, initargs=("local", self.nice, self.memory_mb, os.getpid()))

    @property
    def executor(self) -> Executor:
        return self._pool

    @property
    def slots(self) -> int:
        return self.workers

    def is_lost_worker(self, exc: BaseException) -> bool:
        return isinstance(exc, BrokenProcessPool)

    def restart(self) -> None:
        self._shutdown(self._pool, cancel=True)
        self._pool = self._start()

    def pids(self) -> list[int]:
        """The worker processes' ids (started lazily: empty before the first task)."""
        return [p.pid for p in (self._pool._processes or {}).values() if p.pid is not None]

    @staticmethod
    def _shutdown(pool: ProcessPoolExecutor, cancel: bool) -> None:
        procs = list((pool._processes or {}).values())
        pool.shutdown(wait=not cancel, cancel_futures=cancel)
        if cancel:
            for p in procs:  # running tasks are not stopped by shutdown(): stop their processes
                if p.is_alive():
                    p.kill()
            for p in procs:
                p.join(5)

    def describe(self) -> str:
        return f"local: {self.workers} worker process{'es' if self.workers > 1 else ''}"

    def close(self, cancel: bool = False) -> None:
        self._shutdown(self._pool, cancel)


def open_engine(workers: int | None = None, scheduler: str | None = None, *, nice: int = 0,
                inline: bool = False, connect_timeout_s: float = 10.0, memory_mb: int | None = None) -> Engine:
    """The engine for these settings: ``inline``; a Dask cluster at ``scheduler`` (or
    ``$RANGEPLAN_DASK_SCHEDULER``; its workers have the cluster's own memory limits); else a
    local pool of ``workers``, each capped at ``memory_mb`` MiB. Raises ``OSError`` when the
    scheduler cannot be reached within ``connect_timeout_s``."""
    if inline:
        return InlineEngine()
    if not scheduler:
        from app.settings import settings

        scheduler = settings().dask_scheduler or None
    if scheduler:
        from .cluster import DaskEngine

        return DaskEngine(scheduler, connect_timeout_s=connect_timeout_s)
    return LocalEngine(workers, nice=nice, memory_mb=memory_mb)
