"""Batches in the HTTP service: a dispatcher thread that runs the stored batches' items on
the batch engine and stores each outcome.

**A batch never starves single interactive plans.** Single plans run in the API's own
``PlanPool`` (``app.workers``); batches run on a *separate* engine: a local process pool of
``RANGEPLAN_BATCH_WORKERS`` processes (default: half the cores, at least one) whose
processes run at a lower CPU priority (``nice`` +10, the interactive workers +5: when an
interactive plan and a batch item compete for a core, the kernel gives the interactive one
~3/4 of it), or a Dask
cluster (``RANGEPLAN_DASK_SCHEDULER``), which takes no CPU from this machine at all. A
separate pool rather than a share of the same one: the ``PlanPool`` keeps its bounded queue
(``503 busy``) and latency for interactive users whatever the batches hold, and the batch
engine can be a cluster.

Items use the same request model and bounds as single plans: the same compute limit per
plan (``RANGEPLAN_PLAN_TIMEOUT_S``), the same work estimate before planning (``too_much_work``)
and, on the local pool, the same memory cap per worker process (``RANGEPLAN_WORKER_MEMORY_MB``,
``too_much_memory``). A batch holds at most ``RANGEPLAN_MAX_BATCH_ITEMS``
(10 000) items; at most ``RANGEPLAN_MAX_BATCH_QUEUE`` (100 000) items wait in all batches
together (more: ``503 busy``).

Results travel back from the workers to this process (the CLI's workers write their result
files themselves, :func:`app.batch.engine.plan_chunk`): here a result is stored in the
SQLite file with its item's status in one transaction, where ``GET .../results`` reads it,
retention prunes it with its batch and a restart finds it; a Dask cluster seldom shares the
server's data directory.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import orjson

from app.settings import settings

from .store import FINAL, BatchStore

__all__ = ["BatchService", "QueueFull"]


class QueueFull(Exception):
    """More items than the service's batch queue holds."""


class BatchService:
    def __init__(self, db_path: Path | str, *, workers: int | None = None, scheduler: str | None = None,
                 timeout_s: float | None = None, nice: int = 10, max_items: int | None = None,
                 max_queue: int | None = None, keep: int | None = None, memory_mb: int | None = None):
        cfg = settings()
        self.store = BatchStore(db_path, keep=keep or cfg.max_batches)
        self.workers = workers or cfg.batch_workers
        self.scheduler = scheduler or cfg.dask_scheduler or None
        self.timeout_s = timeout_s or cfg.plan_timeout_s
        self.memory_mb = memory_mb if memory_mb is not None else cfg.worker_memory_mb
        self.nice = nice
        self.max_items = max_items or cfg.max_batch_items
        self.max_queue = max_queue or cfg.max_batch_queue
        self.engine: Any = None
        self.engine_error: str | None = None
        self._runner: Any = None
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._buffer: list[tuple[int, int, dict[str, Any]]] = []
        self._flushed = time.monotonic()
        self._create_lock = threading.Lock()
        self._lost_before = 0  # lost workers of the runners before the current one

    # -- life -----------------------------------------------------------------------------------
    def start(self) -> None:
        """Put items that were running when the server stopped back in the queue, and start
        the dispatcher (the engine starts with the first item)."""
        if self._thread is not None:
            return
        self.store.recover()
        self._thread = threading.Thread(target=self._loop, name="rangeplan-batches", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop dispatching (running items run again after a restart) and stop the engine."""
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(30)
            self._thread = None
        if self.engine is not None:
            self.engine.close(cancel=True)
            self.engine = None
        self.store.close()

    def worker_restarts(self) -> int:
        """Batch worker processes lost and replaced since the service started (count)."""
        runner = self._runner
        return self._lost_before + (runner.stats.lost_workers if runner is not None else 0)

    def stats(self) -> dict[str, Any]:
        return {"engine": self.engine.describe() if self.engine is not None else None,
                "workers": self.workers if not self.scheduler else None, "scheduler": self.scheduler,
                "running": self._runner.running if self._runner is not None else 0, "engine_error": self.engine_error}

    # -- requests ---------------------------------------------------------------------------------
    def create(self, requests: list[str], name: str | None = None) -> dict[str, Any]:
        with self._create_lock:
            queued = self.store.pending_total()
            if queued + len(requests) > self.max_queue:
                raise QueueFull(f"{queued} batch items are waiting; at most {self.max_queue} may wait")
            out = self.store.create(requests, name)
        self._wake.set()
        return out

    def progress(self, id_: str) -> dict[str, Any] | None:
        """A batch's progress (:meth:`BatchStore.progress`) with ``running`` counting the items
        being planned on the workers now: at most the engine's slots (workers x threads). Items
        sent to the engine ahead of a free worker are waiting, so they count as ``pending``."""
        out = self.store.progress(id_)
        return None if out is None else self.at_workers(out)

    def at_workers(self, out: dict[str, Any]) -> dict[str, Any]:
        """``out`` (one batch's progress) with ``running`` capped at the engine's slots."""
        try:
            slots = int(self.engine.slots) if self.engine is not None else 0
        except Exception:  # a Dask cluster that went away: no worker plans anything
            slots = 0
        running = min(int(out["running"]), slots)
        return {**out, "running": running, "pending": int(out["pending"]) + int(out["running"]) - running}

    def cancel(self, id_: str) -> dict[str, Any] | None:
        seq = self.store.seq_of(id_)
        if seq is None or not self.store.cancel(id_):
            return None
        if self._runner is not None:
            self._runner.cancel(lambda it: it.tag == seq)
        return self.progress(id_)

    def delete(self, id_: str) -> bool:
        if self.cancel(id_) is None:
            return False
        return self.store.delete(id_)

    def results(self, id_: str, wait: bool = False, poll_s: float = 0.2) -> Iterator[bytes] | None:
        """JSON Lines, one per item in item order: ``{"item", "status", "kind", "name", "engine",
        "worker", "attempts", "summary" | "error", "result"}``. Without ``wait``, the items
        finished so far; with it, every item as it finishes (until the batch ends)."""
        seq = self.store.seq_of(id_)
        if seq is None:
            return None

        def lines() -> Iterator[bytes]:
            nxt = 0
            while True:
                rows = self.store.items(seq, nxt)
                if not rows:
                    return
                for item, status, outcome, result in rows:
                    if status not in FINAL:
                        if not wait:
                            nxt = item + 1
                            continue
                        while True:  # wait for this item, in order
                            time.sleep(poll_s)
                            got = self.store.items(seq, item, 1)
                            if not got:
                                return
                            item, status, outcome, result = got[0]
                            if status in FINAL:
                                break
                    yield _line(item, status, outcome, result)
                    nxt = item + 1
        return lines()

    def summary_rows(self, id_: str) -> Iterator[dict[str, str]] | None:
        from .summary import summary_row

        seq = self.store.seq_of(id_)
        if seq is None:
            return None

        def rows() -> Iterator[dict[str, str]]:
            nxt = 0
            while True:
                chunk = self.store.items(seq, nxt, 512, with_result=False)
                if not chunk:
                    return
                for item, status, outcome, _ in chunk:
                    oc = orjson.loads(outcome) if outcome else {"status": status}
                    yield summary_row(item, str(item), oc)
                    nxt = item + 1
        return rows()

    # -- the dispatcher ------------------------------------------------------------------------------
    def _open_engine(self) -> Any:
        from .executors import open_engine

        while not self._stop.is_set():
            try:
                engine = open_engine(self.workers if not self.scheduler else None, self.scheduler, nice=self.nice,
                                     memory_mb=self.memory_mb)
                self.engine_error = None
                return engine
            except OSError as exc:  # a cluster not reachable (yet): keep the items, try again
                self.engine_error = str(exc)
                self._stop.wait(5.0)
        return None

    def _loop(self) -> None:
        from .runner import Item, Runner

        while not self._stop.is_set():
            if self.store.pending_total() == 0:
                self._wake.wait(1.0)
                self._wake.clear()
                continue
            if self.engine is None:
                self.engine = self._open_engine()
                if self.engine is None:
                    return

            def take(n: int) -> list[Item]:
                return [Item(item, f"{bid}/{item}", request=req, tag=seq)
                        for seq, bid, item, req in self.store.claim(n)]

            def on_done(item: Item, outcome: dict[str, Any]) -> None:
                self._buffer.append((item.tag, item.index, outcome))
                if len(self._buffer) >= 64:
                    self._flush()

            def idle() -> bool:
                self._flush()
                self._wake.wait(0.5)
                self._wake.clear()
                return not self._stop.is_set()

            if self._runner is not None:
                self._lost_before += self._runner.stats.lost_workers
            self._runner = Runner(self.engine, on_done, fmt="json", timeout_s=self.timeout_s)
            try:
                self._runner.run(take, remaining=self.store.pending_total, idle=idle, stop=self._stop,
                                 tick=self._tick)
            except Exception as exc:  # the engine broke in a way the runner does not handle: start anew
                self.engine_error = f"{type(exc).__name__}: {exc}"
                try:
                    self.engine.close(cancel=True)
                finally:
                    self.engine = None
                self.store.recover()
            finally:
                self._flush()

    def _tick(self) -> None:
        if self._buffer and time.monotonic() - self._flushed > 0.2:
            self._flush()

    def _flush(self) -> None:
        buf, self._buffer = self._buffer, []
        self._flushed = time.monotonic()
        if buf:
            self.store.save(buf)


def _line(item: int, status: str, outcome: str | None, result: bytes | None) -> bytes:
    oc = orjson.loads(outcome) if outcome else {}
    head = {"item": item, "status": status, "kind": oc.get("kind"), "name": oc.get("name"), "engine": oc.get("engine"),
            "worker": oc.get("worker"), "attempts": oc.get("attempts")}
    if status == "ok":
        head["summary"] = oc.get("summary")
    else:
        head["error"] = oc.get("error") or {"code": status, "message": f"the item is {status}", "field": None}
    body = orjson.dumps(head)
    if status == "ok" and result is not None:
        return body[:-1] + b',"result":' + bytes(result) + b"}\n"
    return body + b"\n"
