"""Saved corridors and plan results in one SQLite file (WAL mode).

The store is shared by the HTTP API, its planning worker processes and the editor, so it
must be safe under concurrent use from threads *and* processes:

* each thread has its own connection (SQLite connections are not shared between threads);
* the database runs in WAL mode, so readers never block the writer and the writer never
  blocks readers; concurrent writers wait for each other (``busy_timeout``) instead of failing;
* writes run in ``BEGIN IMMEDIATE`` transactions, so a read-modify-write never interleaves.

Corridors are user data: their writes use ``synchronous=FULL`` (durable once the call
returns). Plan results are recomputable caches: ``synchronous=NORMAL`` (safe against a crash
of the application, may lose the last results on power loss) and only the newest
``max_plans`` are kept (env ``RANGEPLAN_MAX_PLANS``, default 1000).

Records: ``{"id", "name", "created", "updated", "request"}``; ids are uuid4 hex strings,
timestamps ISO-8601 UTC with a ``Z`` suffix.
"""

from __future__ import annotations

import json
import os
import sqlite3
import threading
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

DB_NAME = "rangeplan.sqlite3"
DEFAULT_MAX_PLANS = 1000
BUSY_TIMEOUT_S = 30.0
PAGE_SIZE = 16384

_SCHEMA = """
CREATE TABLE IF NOT EXISTS corridors (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    id TEXT NOT NULL UNIQUE,
    name TEXT,
    created TEXT NOT NULL,
    updated TEXT NOT NULL,
    request TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS plans (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    id TEXT NOT NULL UNIQUE,
    created TEXT NOT NULL,
    corridor_id TEXT,
    request TEXT,
    result TEXT NOT NULL
);
-- pruning counts back max_plans rows from the newest: on this small index that reads a few
-- pages, on the table itself it read every kept plan's page (~1 ms per saved plan at 1000)
CREATE INDEX IF NOT EXISTS plans_by_seq ON plans (seq);
"""


def default_data_dir() -> Path:
    """Where the database lives: ``$RANGEPLAN_DATA_DIR``, else ``$XDG_DATA_HOME/rangeplan``,
    else ``~/.local/share/rangeplan`` (created on first use by :class:`Store`)."""
    env = os.environ.get("RANGEPLAN_DATA_DIR")
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_DATA_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".local" / "share"
    return base / "rangeplan"


def now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="microseconds").replace("+00:00", "Z")


def new_id() -> str:
    return uuid.uuid4().hex


class Connections:
    """Per-thread connections to one SQLite file, opened on first use and kept (closing the
    last connection to a WAL database checkpoints it, which made every call ~15x slower),
    and write transactions on them. Shared by :class:`Store` and the batch tables."""

    def __init__(self, path: Path):
        self.path = path
        self._local = threading.local()
        self._all: list[sqlite3.Connection] = []
        self._all_lock = threading.Lock()

    def get(self, synchronous: str = "FULL") -> sqlite3.Connection:
        """This thread's connection, with ``PRAGMA synchronous`` set to ``synchronous``."""
        con = getattr(self._local, "con", None)
        if con is None:
            # used only by this thread; check_same_thread=False only so close() may run anywhere
            con = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S, isolation_level=None,
                                  check_same_thread=False)
            con.execute(f"PRAGMA busy_timeout = {int(BUSY_TIMEOUT_S * 1000)}")
            self._local.con = con
            with self._all_lock:
                self._all.append(con)
        if getattr(self._local, "sync", None) != synchronous:
            con.execute(f"PRAGMA synchronous = {synchronous}")
            self._local.sync = synchronous
        return con

    @contextmanager
    def write(self, synchronous: str = "FULL") -> Iterator[sqlite3.Connection]:
        """A write transaction (``BEGIN IMMEDIATE``) on this thread's connection."""
        con = self.get(synchronous)
        con.execute("BEGIN IMMEDIATE")
        try:
            yield con
        except BaseException:
            con.execute("ROLLBACK")
            raise
        con.execute("COMMIT")

    def close(self) -> None:
        """Close every connection (any thread's)."""
        with self._all_lock:
            cons, self._all = self._all, []
        for con in cons:
            con.close()
        self._local = threading.local()


class Store:
    """Corridors and plans in a SQLite file. ``path`` is the database file, or a directory
    (then ``<dir>/rangeplan.sqlite3``); parent directories are created."""

    def __init__(self, path: Path | str | None = None, *, max_plans: int | None = None):
        path = Path(path).expanduser() if path is not None else default_data_dir()
        if path.is_dir() or path.suffix == "":
            path = path / DB_NAME
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        if max_plans is None:
            max_plans = int(os.environ.get("RANGEPLAN_MAX_PLANS", DEFAULT_MAX_PLANS))
        self.max_plans = max(1, int(max_plans))
        self._db = Connections(path)
        with self._connect() as con:
            # a new file gets 16 KiB pages: a ~150 kB plan result is 10 overflow pages, not
            # 38, ~0.3 ms less CPU per stored plan (no effect on an existing file)
            con.execute(f"PRAGMA page_size = {PAGE_SIZE}")
            mode = con.execute("PRAGMA journal_mode=WAL").fetchone()[0]
            if str(mode).lower() != "wal":
                raise RuntimeError(f"{path}: could not switch SQLite to WAL mode (got {mode!r})")
            con.executescript(_SCHEMA)

    # -- plumbing -----------------------------------------------------------------------
    @contextmanager
    def _connect(self, synchronous: str = "FULL"):
        yield self._db.get(synchronous)

    def close(self) -> None:
        """Close the connections this store opened (any thread's)."""
        self._db.close()

    def _write(self, synchronous: str = "FULL"):
        return self._db.write(synchronous)

    @staticmethod
    def _record(row) -> dict:
        id_, name, created, updated, request = row
        return {"id": id_, "name": name, "created": created, "updated": updated, "request": json.loads(request)}

    # -- corridors ----------------------------------------------------------------------
    def create_corridor(self, request: dict, name: str | None = None) -> dict:
        """Save a plan request as a new corridor; returns its record."""
        if name is None and isinstance(request, dict):
            name = request.get("name")
        text = json.dumps(request, allow_nan=False)
        id_, ts = new_id(), now_iso()
        with self._write() as con:
            con.execute("INSERT INTO corridors (id, name, created, updated, request) VALUES (?, ?, ?, ?, ?)",
                        (id_, name, ts, ts, text))
        return {"id": id_, "name": name, "created": ts, "updated": ts, "request": json.loads(text)}

    def get_corridor(self, id: str) -> dict | None:
        with self._connect() as con:
            row = con.execute("SELECT id, name, created, updated, request FROM corridors WHERE id = ?",
                              (id,)).fetchone()
        return self._record(row) if row else None

    def update_corridor(self, id: str, request: dict, name: str | None = None) -> dict | None:
        """Replace a corridor's request (and name, if given or present in the request);
        ``None`` if there is no such corridor."""
        if name is None and isinstance(request, dict):
            name = request.get("name")
        text = json.dumps(request, allow_nan=False)
        ts = now_iso()
        with self._write() as con:
            cur = con.execute("UPDATE corridors SET request = ?, name = coalesce(?, name), updated = ? WHERE id = ?",
                              (text, name, ts, id))
            if cur.rowcount == 0:
                return None
            row = con.execute("SELECT id, name, created, updated, request FROM corridors WHERE id = ?",
                              (id,)).fetchone()
        return self._record(row)

    def delete_corridor(self, id: str) -> bool:
        with self._write() as con:
            return con.execute("DELETE FROM corridors WHERE id = ?", (id,)).rowcount > 0

    def list_corridors(self) -> list[dict]:
        """All corridors, oldest first."""
        with self._connect() as con:
            rows = con.execute("SELECT id, name, created, updated, request FROM corridors ORDER BY seq").fetchall()
        return [self._record(r) for r in rows]

    # -- plans --------------------------------------------------------------------------
    def save_plan(self, result: dict, request: dict | None = None, corridor_id: str | None = None) -> str:
        """Store a plan result; returns its id. Only the newest ``max_plans`` are kept."""
        return self.save_plan_json(json.dumps(result, allow_nan=False), request, corridor_id)

    def save_plan_json(self, result_json: str, request: dict | None = None, corridor_id: str | None = None,
                       id: str | None = None) -> str:
        """:meth:`save_plan` for a result already serialised to JSON (the HTTP workers
        serialise once and store and send the same text)."""
        id_ = id or new_id()
        req = None if request is None else json.dumps(request, allow_nan=False)
        with self._write("NORMAL") as con:
            con.execute("INSERT INTO plans (id, created, corridor_id, request, result) VALUES (?, ?, ?, ?, ?)",
                        (id_, now_iso(), corridor_id, req, result_json))
            con.execute("DELETE FROM plans WHERE seq <= (SELECT seq FROM plans INDEXED BY plans_by_seq "
                        "ORDER BY seq DESC LIMIT 1 OFFSET ?)", (self.max_plans,))
        return id_

    def get_plan_json(self, id: str) -> str | None:
        """The stored result JSON text of a plan, or ``None``."""
        with self._connect() as con:
            row = con.execute("SELECT result FROM plans WHERE id = ?", (id,)).fetchone()
        return row[0] if row else None

    def get_plan(self, id: str) -> dict | None:
        text = self.get_plan_json(id)
        return None if text is None else json.loads(text)

    def plan_info(self, id: str) -> dict | None:
        """Metadata of a stored plan: ``{"id", "created", "corridor_id", "request"}``."""
        with self._connect() as con:
            row = con.execute("SELECT id, created, corridor_id, request FROM plans WHERE id = ?", (id,)).fetchone()
        if not row:
            return None
        return {"id": row[0], "created": row[1], "corridor_id": row[2],
                "request": None if row[3] is None else json.loads(row[3])}

    def count_plans(self) -> int:
        with self._connect() as con:
            return con.execute("SELECT count(*) FROM plans").fetchone()[0]
