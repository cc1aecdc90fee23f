"""The ``jobs`` table of the store (``GET /v1/jobs/{id}``, app/routers/jobs.py): a long
request's state and progress, written by the worker that runs it and by the server, read by
any server process of the same store. A mixin of :class:`app.storage.Store` (its table is made
with the store's schema); standard library only."""

from __future__ import annotations

import json
import time
from contextlib import AbstractContextManager
from sqlite3 import Connection

__all__ = ["JobRows"]


class JobRows:
    """The ``jobs`` rows of a store: what :class:`app.storage.Store` gives them is its two
    connection helpers (a write transaction, a read connection)."""

    def _write(self, synchronous: str = "FULL") -> AbstractContextManager[Connection]:
        raise NotImplementedError

    def _connect(self, synchronous: str = "FULL") -> AbstractContextManager[Connection]:
        raise NotImplementedError

    _JOB_COLUMNS = ("id", "kind", "state", "created", "started", "updated", "finished", "done", "total", "unit",
                    "estimate_s", "plan_id", "error")

    def create_job(self, id: str, kind: str, unit: str, *, total: int | None = None, estimate_s: float | None = None,
                   max_jobs: int = 100, max_age_s: float = 86400.0) -> bool:
        """A new ``queued`` job. Finished jobs older than ``max_age_s`` are dropped, then the
        oldest finished ones beyond ``max_jobs - 1``; False (nothing created) when ``max_jobs``
        unfinished jobs remain."""
        now = time.time()
        with self._write("NORMAL") as con:
            con.execute("DELETE FROM jobs WHERE state IN ('done', 'failed') AND finished < ?", (now - max_age_s,))
            n = con.execute("SELECT count(*) FROM jobs").fetchone()[0]
            if n >= max_jobs:
                con.execute("DELETE FROM jobs WHERE seq IN (SELECT seq FROM jobs WHERE state IN ('done', 'failed') "
                            "ORDER BY seq LIMIT ?)", (n - max_jobs + 1,))
                if con.execute("SELECT count(*) FROM jobs").fetchone()[0] >= max_jobs:
                    return False
            con.execute("INSERT INTO jobs (id, kind, state, created, updated, total, unit, estimate_s) "
                        "VALUES (?, ?, 'queued', ?, ?, ?, ?, ?)", (id, kind, now, now, total, unit, estimate_s))
        return True

    def job_started(self, id: str, total: int | None = None, estimate_s: float | None = None) -> None:
        """The job ``id`` runs (its worker has estimated it: ``total`` units of progress, the
        work estimate [s])."""
        now = time.time()
        with self._write("NORMAL") as con:
            con.execute("UPDATE jobs SET state = 'running', started = ?, updated = ?, total = coalesce(?, total), "
                        "estimate_s = coalesce(?, estimate_s) WHERE id = ? AND state IN ('queued', 'running')",
                        (now, now, total, estimate_s, id))

    def job_progress(self, id: str, done: int, total: int | None = None) -> None:
        """``done`` units of the job ``id`` are done (never lowered: a row only moves forwards)."""
        with self._write("NORMAL") as con:
            con.execute("UPDATE jobs SET done = max(done, ?), total = coalesce(?, total), updated = ? "
                        "WHERE id = ? AND state IN ('queued', 'running')", (done, total, time.time(), id))

    def job_finished(self, id: str, plan_id: str | None = None, error: dict | None = None) -> None:
        """The job ``id`` ended: ``done`` with its stored plan, or ``failed`` with ``error``
        (``{code, message, field, status}``)."""
        now = time.time()
        with self._write("NORMAL") as con:
            if error is None:
                con.execute("UPDATE jobs SET state = 'done', finished = ?, updated = ?, plan_id = ?, "
                            "done = coalesce(total, done) WHERE id = ?", (now, now, plan_id, id))
            else:
                con.execute("UPDATE jobs SET state = 'failed', finished = ?, updated = ?, error = ? WHERE id = ?",
                            (now, now, json.dumps(error), id))

    def get_job(self, id: str) -> dict | None:
        """A job's row (``error`` parsed), or None."""
        with self._connect() as con:
            row = con.execute(f"SELECT {', '.join(self._JOB_COLUMNS)} FROM jobs WHERE id = ?", (id,)).fetchone()
        if row is None:
            return None
        out = dict(zip(self._JOB_COLUMNS, row, strict=True))
        out["error"] = None if out["error"] is None else json.loads(out["error"])
        return out

    def unfinished_jobs(self) -> list[dict]:
        """The ``queued`` and ``running`` jobs' rows in the order they were created (the order the
        jobs' share takes them: :func:`app.job_progress.job_wait`), without their errors."""
        cols = [c for c in self._JOB_COLUMNS if c != "error"]
        with self._connect() as con:
            rows = con.execute(f"SELECT {', '.join(cols)} FROM jobs WHERE state IN ('queued', 'running') "
                               "ORDER BY seq").fetchall()
        return [dict(zip(cols, row, strict=True)) for row in rows]

    def delete_job(self, id: str) -> bool:
        with self._write("NORMAL") as con:
            return con.execute("DELETE FROM jobs WHERE id = ?", (id,)).rowcount > 0

    def abandon_jobs(self, message: str) -> int:
        """End every unfinished job as ``failed`` with ``message`` (a server starting: the jobs of
        the one before it are no longer running); returns how many."""
        now = time.time()
        error = json.dumps({"code": "internal_error", "message": message, "field": None, "status": 500})
        with self._write("NORMAL") as con:
            return con.execute("UPDATE jobs SET state = 'failed', finished = ?, updated = ?, error = ? "
                               "WHERE state IN ('queued', 'running')", (now, now, error)).rowcount
