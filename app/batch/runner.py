"""The dispatcher: submits items in chunks (:class:`app.batch.engine.BatchChunkJob`) to an
engine's executor, the service's :class:`app.executors.JobExecutor` (``submit``), a bounded
number at a time, and reports each item's outcome as its chunk finishes
(``concurrent.futures.wait``, the same for this process, a local pool and a Dask cluster).

* **Bounded**: at most ``2 x slots`` tasks are in flight (each worker has one task queued
  behind the running one), so memory and the scheduler's queue stay small however large
  the batch, and a cancellation takes effect at once.
* **Chunks**: small plans are grouped so one task takes ~``target_task_s`` (0.5 s, at most
  ``max_chunk`` = 64 plans): a task costs a Dask scheduler and its client ~1-2.5 ms of CPU
  and its worker ~1-2 ms (docs/batch-scale.md), a Table I plan ~5 ms. Never more
  than ``remaining / (2 x slots)`` items per task, so the last tasks still spread over the
  workers. Every item keeps its own outcome and time limit.
* **No item lost**: a worker that dies takes its chunk with it (the executor's
  :class:`~app.workers.WorkerCrashed`). Dask's scheduler retries it itself (and gives up on
  the task that kept killing workers: :class:`~app.workers.JobKilledWorkers`); a local pool
  replaces its worker, and the items of the lost chunk run again, one at a time until each
  has passed or failed alone (so an item that kills its worker is found and reported after
  ``max_attempts``, and the others are not charged for it).
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, CancelledError, Future, wait
from dataclasses import dataclass, field
from typing import Any

from app.jobs import Failed
from app.workers import JobKilledWorkers, WorkerCrashed

from .engine import BatchChunkJob, chunk_outcomes
from .executors import Engine

__all__ = ["Item", "Runner", "failed_outcome"]


@dataclass
class Item:
    """One request of a batch. ``request`` is JSON text, a dict or a ``PlanRequest``;
    ``error`` is set for an item that cannot be planned at all (an unreadable file): it is
    reported without being sent anywhere."""

    index: int
    key: str
    request: Any = None
    error: dict[str, Any] | None = None
    attempts: int = 0
    tag: Any = None


def failed_outcome(code: str, message: str, field_: str | None = None, status: str = "error") -> dict[str, Any]:
    return {"status": status, "name": None, "payload": None, "summary": None,
            "error": {"code": code, "message": message, "field": field_}}


@dataclass
class _Stats:
    submitted_tasks: int = 0
    lost_workers: int = 0
    resubmitted_items: int = 0
    item_s: float | None = None  # running mean of one item's planning time
    chunk: int = 1
    extra: dict[str, Any] = field(default_factory=dict)


class Runner:
    """Runs items on ``engine`` and calls ``on_done(item, outcome)`` for each (in the
    thread that calls :meth:`run`). ``outcome`` is :func:`app.batch.engine.plan_item`'s
    dict plus ``attempts``; ``status`` is ``ok``, ``error`` (the request's fault: a planner
    error code), ``failed`` (it kept losing its worker) or ``cancelled``. ``timeout_s`` is each
    item's time limit (and work estimate); the engine's ``item_memory_mb`` its memory cap. With
    ``stage`` (a staging directory, see :func:`app.batch.engine.plan_chunk`), a worker that sees it writes
    each result there and the outcome has ``staged`` (the file's name in ``stage``) and
    ``bytes`` instead of ``payload``; ``on_done`` moves the file into place. A staged file
    whose outcome never arrives (its worker died, its item was cancelled) is never reported:
    the caller removes the staging directory at the end."""

    def __init__(self, engine: Engine, on_done: Callable[[Item, dict[str, Any]], None], *, fmt: str = "json",
                 timeout_s: float | None = None, max_attempts: int = 3, target_task_s: float = 0.5,
                 max_chunk: int = 64, poll_s: float = 0.25, stage: str | None = None):
        self.engine = engine
        self.stage = stage
        self.on_done = on_done
        self.fmt = fmt
        self.timeout_s = timeout_s
        self.max_attempts = max(1, int(max_attempts))
        self.target_task_s = target_task_s
        self.max_chunk = max(1, int(max_chunk))
        self.poll_s = poll_s
        self.stats = _Stats()
        self._inflight: dict[Future, list[Item]] = {}
        self._pending: deque[Item] = deque()
        self._suspects: deque[Item] = deque()
        self._lock = threading.Lock()
        self._cancel: list[Callable[[Item], bool]] = []
        self._dropped: set[int] = set()  # id() of cancelled items still inside a running chunk
        self._slots = 1
        self._slots_at = -math.inf

    # -- what the caller sees ---------------------------------------------------------------
    @property
    def running(self) -> int:
        """Items sent to the engine and not yet back."""
        return sum(len(v) for v in list(self._inflight.values()))

    def running_items(self) -> list[Item]:
        return [it for items in list(self._inflight.values()) for it in items]

    def cancel(self, predicate: Callable[[Item], bool]) -> None:
        """Drop the items for which ``predicate`` is true (thread-safe): those not started
        are cancelled, those running are forgotten (their outcome is ignored). Each is
        reported with status ``cancelled``."""
        with self._lock:
            self._cancel.append(predicate)

    # -- the loop ---------------------------------------------------------------------------
    def run(self, source: Iterable[Item] | Callable[[int], list[Item]], *,
            remaining: Callable[[], int] | None = None, idle: Callable[[], bool] | None = None,
            stop: threading.Event | None = None, tick: Callable[[], None] | None = None) -> None:
        """Run until ``source`` is exhausted and nothing is in flight (then ``idle()``, if
        given, may block for more work and return True to go on), or until ``stop`` is set.
        ``source`` is an iterable of items or ``take(n) -> up to n items``; ``remaining()``
        says how many are left (for the chunk size; an iterable that has ``len`` needs none).
        ``tick()`` is called on every turn of the loop (at least every ``poll_s``).
        On return, raise or Ctrl-C, whatever is still in flight is cancelled (not reported:
        a resumed batch runs it again)."""
        take: Callable[[int], list[Item]]
        if callable(source):
            take = source
        else:
            take, left = _taker(source)
            remaining = remaining or left
        try:
            while not (stop is not None and stop.is_set()):
                self._apply_cancellations()
                if tick is not None:
                    tick()
                self._fill(take, remaining)
                if not self._inflight:
                    if self._pending or self._suspects:
                        continue
                    if idle is None or not idle():
                        return
                    continue
                done, _ = wait(list(self._inflight), timeout=self.poll_s, return_when=FIRST_COMPLETED)
                for fut in done:
                    if fut in self._inflight:
                        self._collect(fut)
        finally:
            for fut in list(self._inflight):
                fut.cancel()
            self._inflight.clear()

    # -- internals ----------------------------------------------------------------------------
    def _report(self, item: Item, outcome: dict[str, Any]) -> None:
        outcome["attempts"] = item.attempts
        self.on_done(item, outcome)

    def _slots_now(self) -> int:
        now = time.monotonic()
        if now - self._slots_at > 1.0:  # a cluster grows and shrinks: ask at most once a second
            try:
                self._slots = max(1, self.engine.slots)
            except Exception:  # a cluster that went away: the slots it had
                pass
            self._slots_at = now
        return self._slots

    def _chunk_size(self, remaining: Callable[[], int] | None, slots: int) -> int:
        if self.stats.item_s is None:
            return 1
        n = int(self.target_task_s / max(self.stats.item_s, 1e-6))
        if remaining is not None:
            left = remaining() + len(self._pending)
            n = min(n, math.ceil(left / (2 * slots)))
        return max(1, min(self.max_chunk, n))

    def _fill(self, take: Callable[[int], list[Item]], remaining: Callable[[], int] | None) -> None:
        if self._suspects:  # after a lost chunk: one item at a time, alone, until all are cleared
            if not self._inflight:
                item = self._suspects.popleft()
                self._submit([item])
            return
        slots = self._slots_now()
        while len(self._inflight) < 2 * slots:
            size = self._chunk_size(remaining, slots)
            self.stats.chunk = size
            batch: list[Item] = []
            while self._pending and len(batch) < size:
                batch.append(self._pending.popleft())
            if len(batch) < size:
                batch.extend(take(size - len(batch)))
            ready = []
            for item in batch:
                if item.error is not None:
                    self._report(item, failed_outcome(**item.error))
                else:
                    ready.append(item)
            if not batch:
                return
            if ready:
                self._submit(ready)

    def _submit(self, items: list[Item]) -> None:
        for it in items:
            it.attempts += 1
        job = BatchChunkJob(tuple(it.request for it in items), self.fmt, self.timeout_s, self.engine.item_memory_mb,
                            self.stage, self.engine.name)
        fut = self.engine.executor.submit(job, 0.0)  # no limit on the chunk: each item has its own
        self.stats.submitted_tasks += 1
        self._inflight[fut] = items

    def _collect(self, fut: Future) -> None:
        items = self._inflight.pop(fut)
        try:
            done = fut.result()
            if isinstance(done, Failed):  # the chunk's own code failed (a bug): every item says so
                raise RuntimeError(done.error.message)
            outs = chunk_outcomes(done)
        except BaseException as exc:  # noqa: B036  (whatever a task raised: its items are reported)
            if isinstance(exc, KeyboardInterrupt):
                raise
            if isinstance(exc, (WorkerCrashed, CancelledError)):
                self._lost(items, exc)
            else:
                for it in items:
                    self._report(it, failed_outcome("internal_error", f"the task failed: {type(exc).__name__}: "
                                                    f"{exc}", status="failed"))
            return
        for it, out in zip(items, outs):
            if self._dropped and id(it) in self._dropped:
                self._dropped.discard(id(it))
                continue
            ms = out.get("wall_ms")
            if ms is not None:
                s = ms / 1e3
                self.stats.item_s = s if self.stats.item_s is None else 0.8 * self.stats.item_s + 0.2 * s
            self._report(it, out)

    def _give_up(self, item: Item, exc: BaseException) -> None:
        self._report(item, failed_outcome(
            "worker_died", f"the worker planning this item died {item.attempts} times "
            f"({type(exc).__name__}); the item is likely to crash its process (memory?)", status="failed"))

    def _lost(self, items: list[Item], exc: BaseException) -> None:
        self.stats.lost_workers += 1
        lost = [it for it in items if id(it) not in self._dropped]
        self._dropped.difference_update(id(it) for it in items)
        if self.engine.attributes_failures:  # the scheduler retried the chunk itself
            from_killed = isinstance(exc, JobKilledWorkers)
            for it in reversed(lost):
                if (from_killed and len(items) == 1) or it.attempts >= self.max_attempts:
                    self._give_up(it, exc)  # the scheduler already retried it on several workers
                else:
                    self.stats.resubmitted_items += 1
                    self._suspects.appendleft(it) if from_killed else self._pending.appendleft(it)
            return
        # the chunk's process died (the pool has replaced it; the other chunks run on): each item
        # is charged this attempt; from now on they run alone, so a further death is theirs
        for it in sorted(lost, key=lambda i: i.index, reverse=True):
            if it.attempts >= self.max_attempts:
                self._give_up(it, exc)
            else:
                self.stats.resubmitted_items += 1
                self._suspects.appendleft(it)

    def _apply_cancellations(self) -> None:
        with self._lock:
            preds, self._cancel = self._cancel, []
        if not preds:
            return

        def hit(it: Item) -> bool:
            return any(p(it) for p in preds)

        for fut, items in list(self._inflight.items()):
            gone = [it for it in items if hit(it)]
            if not gone:
                continue
            if len(gone) == len(items):
                fut.cancel()
                del self._inflight[fut]
            else:  # a chunk mixing batches: the others' outcomes are still wanted
                self._dropped.update(id(it) for it in gone)
            for it in gone:
                self._report(it, failed_outcome("cancelled", "the batch was cancelled", status="cancelled"))
        for q in (self._pending, self._suspects):
            keep = [it for it in q if not hit(it)]
            for it in q:
                if hit(it):
                    self._report(it, failed_outcome("cancelled", "the batch was cancelled", status="cancelled"))
            q.clear()
            q.extend(keep)


def _taker(source: Iterable[Item]) -> tuple[Callable[[int], list[Item]], Callable[[], int] | None]:
    """``take(n)`` over an iterable, and ``remaining()`` if it has a length."""
    it = iter(source)
    total = len(source) if hasattr(source, "__len__") else None  # type: ignore[arg-type]
    given = 0

    def take(n: int) -> list[Item]:
        nonlocal given
        out = []
        for _ in range(n):
            try:
                out.append(next(it))
            except StopIteration:
                break
        given += len(out)
        return out

    if total is None:
        return take, None
    return take, lambda: total - given
