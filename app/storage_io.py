"""Storage calls off the event loop, on executors of their own (issue 21: latency under load).

With 200 concurrent clients mixing plans, saves and list pages (``benchmarks/bench_load.py``)
corridor lists reached a p99 of 9-15 s. The storage endpoints were plain ``def`` endpoints,
run on Starlette's shared thread pool (40 threads). A save holds its thread while it waits
for SQLite's one writer lock and its ``fsync`` (corridors are durable: ``synchronous=FULL``),
and so does every save queued behind it: with ~70 saves in flight every thread of the pool
can be waiting on the writer, and a list page, a read that WAL mode never blocks, then waits
for a free thread behind them. (On the shared machine of the measurement in
benchmarks/README.md the CPU queue dominated both trees; see there.)

Here reads and writes have executors of their own: writes run one at a time on a single
thread (SQLite serialises writers anyway, so more threads only wait), reads on a few threads
that never wait behind a write. The endpoints are ``async`` and await them
(:func:`read`, :func:`write`), so a waiting save holds no thread a read needs.
"""

from __future__ import annotations

import asyncio
import functools
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

__all__ = ["READ_THREADS", "read", "shutdown", "write"]

T = TypeVar("T")

#: threads that read the store at once (reads in WAL mode run in parallel, in C: SQLite
#: releases the GIL; more would compete with the event loop for the GIL)
READ_THREADS = 4

_lock = threading.Lock()
_executors: dict[str, ThreadPoolExecutor] = {}


def _executor(kind: str) -> ThreadPoolExecutor:
    with _lock:
        ex = _executors.get(kind)
        if ex is None:
            ex = _executors[kind] = ThreadPoolExecutor(READ_THREADS if kind == "read" else 1,
                                                       thread_name_prefix=f"rangeplan-store-{kind}")
        return ex


async def read(fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """``fn(*args, **kwargs)`` (a store read) on the read threads."""
    return await asyncio.get_running_loop().run_in_executor(_executor("read"), functools.partial(fn, *args, **kwargs))


async def write(fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """``fn(*args, **kwargs)`` (a store write) on the one write thread."""
    return await asyncio.get_running_loop().run_in_executor(_executor("write"),
                                                            functools.partial(fn, *args, **kwargs))


def shutdown() -> None:
    """Stop the executors (they start again on next use)."""
    with _lock:
        exs = list(_executors.values())
        _executors.clear()
    for ex in exs:
        ex.shutdown(wait=False)
