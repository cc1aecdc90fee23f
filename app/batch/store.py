"""Batches and their items in the service's SQLite file (beside ``app.storage``'s corridors
and plans; same WAL mode, one connection per thread, ``BEGIN IMMEDIATE`` writes).

An item is ``pending`` -> ``running`` -> ``ok`` | ``error`` | ``failed`` (or ``cancelled``);
a batch is ``queued`` -> ``running`` -> ``done`` (or ``cancelled``). On start,
:meth:`BatchStore.recover` puts the items that were running when the server stopped back to
``pending``: they run again, nothing finished is lost. Results are the planner's JSON bytes
(~145 kB for Table I; see docs/batch-scale.md), stored once and streamed as they are. The
newest ``keep`` finished batches are kept (``RANGEPLAN_MAX_BATCHES``, default 100).
"""

from __future__ import annotations

import json
import sqlite3
import time
import uuid
from contextlib import AbstractContextManager
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from app.storage import DB_NAME, Connections

__all__ = ["BatchStore", "FINAL", "DB_NAME"]

#: item states that are final
FINAL = ("ok", "error", "failed", "cancelled")

_SCHEMA = """
CREATE TABLE IF NOT EXISTS batches (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    id TEXT NOT NULL UNIQUE,
    name TEXT,
    created TEXT NOT NULL,
    state TEXT NOT NULL,
    total INTEGER NOT NULL,
    format TEXT NOT NULL,
    started REAL,
    finished REAL,
    done_at_start INTEGER NOT NULL DEFAULT 0
);
-- small columns first: reading an item's status never touches its request or result pages
CREATE TABLE IF NOT EXISTS batch_items (
    id INTEGER PRIMARY KEY,
    batch_seq INTEGER NOT NULL,
    item INTEGER NOT NULL,
    status TEXT NOT NULL,
    finished REAL,
    outcome TEXT,
    request TEXT NOT NULL,
    result BLOB,
    UNIQUE (batch_seq, item)
);
CREATE INDEX IF NOT EXISTS batch_items_by_status ON batch_items (batch_seq, status, item);
"""


def _now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="microseconds").replace("+00:00", "Z")


class BatchStore:
    """Batch tables in the SQLite file at ``path`` (a file, or a directory holding
    ``rangeplan.sqlite3``)."""

    def __init__(self, path: Path | str, keep: int = 100):
        path = Path(path)
        if path.is_dir() or path.suffix == "":
            path = path / DB_NAME
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self.keep = max(1, int(keep))
        self._db = Connections(path)
        con = self._con()
        con.execute("PRAGMA journal_mode=WAL")
        con.executescript(_SCHEMA)

    # -- plumbing ---------------------------------------------------------------------------
    def _con(self) -> sqlite3.Connection:
        # results are recomputable (as app.storage's plans): synchronous NORMAL
        return self._db.get("NORMAL")

    def _write(self) -> AbstractContextManager[sqlite3.Connection]:
        return self._db.write("NORMAL")

    def close(self) -> None:
        self._db.close()

    # -- batches ----------------------------------------------------------------------------
    def create(self, requests: list[str], name: str | None = None, fmt: str = "json") -> dict[str, Any]:
        """A new queued batch of ``requests`` (JSON texts); returns its progress."""
        id_ = uuid.uuid4().hex
        with self._write() as con:
            cur = con.execute("INSERT INTO batches (id, name, created, state, total, format) VALUES (?, ?, ?, ?, ?, ?)",
                              (id_, name, _now_iso(), "queued", len(requests), fmt))
            seq = cur.lastrowid
            con.executemany("INSERT INTO batch_items (batch_seq, item, status, request) VALUES (?, ?, 'pending', ?)",
                            ((seq, i, r) for i, r in enumerate(requests)))
        out = self.progress(id_)
        assert out is not None
        return out

    def _batch(self, id_: str) -> tuple | None:
        return self._con().execute("SELECT seq, id, name, created, state, total, format, started, finished, "
                                   "done_at_start FROM batches WHERE id = ?", (id_,)).fetchone()

    def seq_of(self, id_: str) -> int | None:
        row = self._con().execute("SELECT seq FROM batches WHERE id = ?", (id_,)).fetchone()
        return row[0] if row else None

    def progress(self, id_: str) -> dict[str, Any] | None:
        """State and counts of a batch: ``total``, ``done`` (finished, any outcome), ``ok``,
        ``failed`` (error or failed), ``cancelled``, ``running`` (items handed to the engine),
        ``pending``, ``rate_per_s`` (items planned, not cancelled, per second since it started or
        resumed), ``eta_s``."""
        b = self._batch(id_)
        if b is None:
            return None
        seq, id_, name, created, state, total, fmt, started, finished, done_at_start = b
        counts = dict(self._con().execute("SELECT status, count(*) FROM batch_items WHERE batch_seq = ? "
                                          "GROUP BY status", (seq,)).fetchall())
        ok, error, failed = counts.get("ok", 0), counts.get("error", 0), counts.get("failed", 0)
        cancelled = counts.get("cancelled", 0)
        done = ok + error + failed + cancelled
        end = finished if finished is not None else time.time()
        rate = None
        planned = ok + error + failed  # cancelled items are not work done: not in the rate
        if started is not None and end > started and planned > done_at_start:
            rate = (planned - done_at_start) / (end - started)
        left = total - done
        return {"id": id_, "name": name, "state": state, "created": created, "format": fmt, "total": total,
                "done": done, "ok": ok, "failed": error + failed, "cancelled": cancelled,
                "running": counts.get("running", 0), "pending": counts.get("pending", 0),
                "rate_per_s": rate, "eta_s": (left / rate if rate and state in ("queued", "running") else None),
                "elapsed_s": (end - started) if started is not None else None}

    def list(self, limit: int = 100) -> list[dict[str, Any]]:
        ids = [r[0] for r in self._con().execute("SELECT id FROM batches ORDER BY seq DESC LIMIT ?", (limit,))]
        return [p for p in (self.progress(i) for i in ids) if p is not None]

    def pending_total(self) -> int:
        """Items waiting or running in every batch (the service's queue)."""
        return self._con().execute("SELECT count(*) FROM batch_items i JOIN batches b ON b.seq = i.batch_seq "
                                   "WHERE b.state IN ('queued', 'running') AND i.status IN ('pending', 'running')"
                                   ).fetchone()[0]

    def status_counts(self) -> dict[str, dict[str, int]]:
        """``{"items": {status: count}, "batches": {state: count}}`` over every stored batch
        (the service's metrics)."""
        con = self._con()
        items = dict(con.execute("SELECT status, count(*) FROM batch_items GROUP BY status").fetchall())
        batches = dict(con.execute("SELECT state, count(*) FROM batches GROUP BY state").fetchall())
        return {"items": items, "batches": batches}

    def cancel(self, id_: str) -> bool:
        """Mark a batch cancelled and its pending items cancelled (running ones are cancelled
        by the service). False if there is no such batch."""
        with self._write() as con:
            row = con.execute("SELECT seq, state FROM batches WHERE id = ?", (id_,)).fetchone()
            if row is None:
                return False
            seq, state = row
            if state in ("queued", "running"):
                con.execute("UPDATE batches SET state = 'cancelled', finished = ? WHERE seq = ?", (time.time(), seq))
                con.execute("UPDATE batch_items SET status = 'cancelled', finished = ? WHERE batch_seq = ? AND "
                            "status IN ('pending', 'running')", (time.time(), seq))
        return True

    def delete(self, id_: str) -> bool:
        with self._write() as con:
            row = con.execute("SELECT seq FROM batches WHERE id = ?", (id_,)).fetchone()
            if row is None:
                return False
            con.execute("DELETE FROM batch_items WHERE batch_seq = ?", (row[0],))
            con.execute("DELETE FROM batches WHERE seq = ?", (row[0],))
        return True

    def recover(self) -> int:
        """After a restart: items left running go back to pending, their batches to queued.
        Returns how many items will run again."""
        with self._write() as con:
            n = con.execute("UPDATE batch_items SET status = 'pending' WHERE status = 'running' AND batch_seq IN "
                            "(SELECT seq FROM batches WHERE state IN ('queued', 'running'))").rowcount
            con.execute("UPDATE batches SET state = 'queued', started = NULL WHERE state = 'running'")
        return n

    # -- the dispatcher's side ----------------------------------------------------------------
    def claim(self, n: int) -> list[tuple[int, str, int, str]]:
        """Up to ``n`` pending items, shared evenly between the active batches (oldest first),
        marked running: ``(batch_seq, batch_id, item, request)``."""
        if n <= 0:
            return []
        out: list[tuple[int, str, int, str]] = []
        with self._write() as con:
            active = con.execute("SELECT seq, id, state FROM batches WHERE state IN ('queued', 'running') "
                                 "ORDER BY seq").fetchall()
            if not active:
                return []
            share = max(1, -(-n // len(active)))
            now = time.time()
            for seq, id_, state in active:
                if len(out) >= n:
                    break
                rows = con.execute("SELECT item, request FROM batch_items WHERE batch_seq = ? AND status = 'pending' "
                                   "ORDER BY item LIMIT ?", (seq, min(share, n - len(out)))).fetchall()
                if not rows:
                    continue
                con.executemany("UPDATE batch_items SET status = 'running' WHERE batch_seq = ? AND item = ?",
                                ((seq, item) for item, _ in rows))
                if state == "queued":
                    done = con.execute("SELECT count(*) FROM batch_items WHERE batch_seq = ? AND status IN "
                                       "('ok', 'error', 'failed')", (seq,)).fetchone()[0]  # planned (rate_per_s)
                    con.execute("UPDATE batches SET state = 'running', started = ?, done_at_start = ? WHERE seq = ?",
                                (now, done, seq))
                out.extend((seq, id_, item, req) for item, req in rows)
        return out

    def save(self, outcomes: list[tuple[int, int, dict[str, Any]]]) -> None:
        """Store finished items ``(batch_seq, item, outcome)`` in one transaction and close
        the batches they complete. An outcome for an item no longer running (its batch was
        cancelled) is dropped."""
        if not outcomes:
            return
        now = time.time()
        with self._write() as con:
            seqs = set()
            for seq, item, oc in outcomes:
                payload = oc.get("payload")
                meta = {k: v for k, v in oc.items() if k != "payload"}
                con.execute("UPDATE batch_items SET status = ?, finished = ?, outcome = ?, result = ? WHERE "
                            "batch_seq = ? AND item = ? AND status = 'running'",
                            (oc["status"], now, json.dumps(meta, allow_nan=False, default=str), payload, seq, item))
                seqs.add(seq)
            for seq in seqs:
                open_items = con.execute("SELECT count(*) FROM batch_items WHERE batch_seq = ? AND status IN "
                                         "('pending', 'running')", (seq,)).fetchone()[0]
                if open_items == 0:
                    con.execute("UPDATE batches SET state = 'done', finished = ? WHERE seq = ? AND state = 'running'",
                                (now, seq))
            self._prune(con)

    def _prune(self, con: sqlite3.Connection) -> None:
        old = con.execute("SELECT seq FROM batches WHERE state IN ('done', 'cancelled') ORDER BY seq DESC "
                          "LIMIT -1 OFFSET ?", (self.keep,)).fetchall()
        for (seq,) in old:
            con.execute("DELETE FROM batch_items WHERE batch_seq = ?", (seq,))
            con.execute("DELETE FROM batches WHERE seq = ?", (seq,))

    # -- reading results ----------------------------------------------------------------------
    def items(self, seq: int, start: int = 0, limit: int = 64, with_result: bool = True) -> list[tuple]:
        """``(item, status, outcome_json, result_bytes)`` from item ``start`` on, in order."""
        col = "result" if with_result else "NULL"
        return self._con().execute(f"SELECT item, status, outcome, {col} FROM batch_items WHERE batch_seq = ? "
                                   "AND item >= ? ORDER BY item LIMIT ?", (seq, start, limit)).fetchall()

    def state(self, seq: int) -> str | None:
        row = self._con().execute("SELECT state FROM batches WHERE seq = ?", (seq,)).fetchone()
        return row[0] if row else None
