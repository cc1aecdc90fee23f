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

Bounds (issue 15), all configurable:

* **per object**: a corridor's request JSON may be at most ``max_corridor_bytes``
  (``RANGEPLAN_MAX_CORRIDOR_BYTES``, 1 MiB): :class:`TooLarge`; a plan result larger than
  ``max_plan_bytes`` (``RANGEPLAN_MAX_PLAN_BYTES``, 64 MiB) is returned but not stored;
* **in total**: corridors and stored plans together at most ``max_total_bytes``
  (``RANGEPLAN_MAX_STORE_BYTES``, 1 GiB) of JSON text. Plans are caches: the oldest are
  dropped to make room. Corridors are user data: a corridor that does not fit is refused
  (:class:`StoreFull`), nothing is dropped;
* **names**: a corridor's name is unique among corridors (a corridor without a name has
  none). Saving a second corridor under a taken name, or renaming one to it, raises
  :class:`NameTaken` naming the holder (the API answers 409); replace that corridor instead
  (``update_corridor``). Corridors saved twice under one name before this rule keep their
  names until one is renamed.
* **lists** are read a page at a time (:meth:`Store.corridor_page`, a cursor after the
  last row), as summaries without the request.
"""

from __future__ import annotations

import json
import os
import sqlite3
import stat
import threading
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path
from typing import BinaryIO

from app.storage_jobs import JobRows

DB_NAME = "rangeplan.sqlite3"
#: (the quotas' defaults are those of :class:`app.settings.Settings`)
#: corridors per page of a list: default and largest
DEFAULT_PAGE_SIZE = 50
MAX_PAGE_SIZE = 200
BUSY_TIMEOUT_S = 30.0
#: how long a read on the event loop's read-only connection may wait for SQLite's lock [s]
#: before it is handed to the read threads instead (:meth:`Store.corridor_page`, ``quick``)
QUICK_BUSY_TIMEOUT_S = 0.005
PAGE_SIZE = 16384
#: bytes of a stored plan read at a time when it is copied out as it is (:meth:`Store.copy_plan_json`)
COPY_CHUNK = 1 << 20

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
-- jobs of the HTTP API (a long contour or plan answered 202: app/routers/jobs.py): the server
-- creates and ends a row, the worker running the job writes its estimate and progress
CREATE TABLE IF NOT EXISTS jobs (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    id TEXT NOT NULL UNIQUE,
    kind TEXT NOT NULL,
    state TEXT NOT NULL,
    created REAL NOT NULL,
    started REAL,
    updated REAL,
    finished REAL,
    done INTEGER NOT NULL DEFAULT 0,
    total INTEGER,
    unit TEXT NOT NULL,
    estimate_s REAL,
    plan_id TEXT,
    error TEXT
);
"""

# sizes (bytes of JSON text) for the quotas; added to files made before the quotas. The
# indexes cover sum(size) and the name lookup without reading the (large) rows.
_MIGRATIONS = """
CREATE INDEX IF NOT EXISTS corridors_by_size ON corridors (size);
CREATE INDEX IF NOT EXISTS corridors_by_name ON corridors (name);
CREATE INDEX IF NOT EXISTS plans_by_size ON plans (seq, size);
"""


class QuotaError(Exception):
    """A write refused by one of the store's bounds."""


class TooLarge(QuotaError):
    """One object larger than its limit (HTTP 413)."""


class StoreFull(QuotaError):
    """The store's total size would exceed its limit (HTTP 507)."""


class NameTaken(QuotaError):
    """Another corridor already has this name (HTTP 409)."""

    def __init__(self, name: str, holder: str):
        super().__init__(f"a corridor named {name!r} already exists (id {holder}); replace it with "
                         f"PUT /v1/corridors/{holder}, or choose another name")
        self.name, self.holder = name, holder


class BadCursor(ValueError):
    """A list cursor this store did not make."""


class StoreBusy(Exception):
    """A quick read found the database locked (it does not wait: read it on a thread)."""


#: what a cursor looks like (a row position; any such string is a valid cursor)
CURSOR_PATTERN = r"^[0-9]{1,18}$"


def encode_cursor(seq: int) -> str:
    return str(int(seq))


def decode_cursor(cursor: str) -> int:
    if not (cursor.isascii() and cursor.isdigit() and len(cursor) <= 18):
        raise BadCursor("not a cursor of this list (use next_cursor from the previous page)")
    return int(cursor)


def default_data_dir() -> Path:
    """Where the database lives: ``$RANGEPLAN_DATA_DIR``, else ``$XDG_DATA_HOME/rangeplan``,
    else ``~/.local/share/rangeplan`` (created on first use by :class:`Store`)."""
    from app.settings import settings

    cfg = settings()
    if cfg.data_dir is not None:
        return cfg.data_dir.expanduser()
    base = cfg.xdg_data_home.expanduser() if cfg.xdg_data_home is not None else Path.home() / ".local" / "share"
    return base / "rangeplan"


def now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="microseconds").replace("+00:00", "Z")


def new_id() -> str:
    return uuid.uuid4().hex


def _share_with_group(path: Path) -> None:
    """In a directory its group may write (a container's ``/data``: group 0, any uid), make
    the database file writable by that group too, whoever creates it: a service run under
    another uid of the group (Kubernetes ``runAsUser``, OpenShift) must write what an earlier
    one made (SQLite gives the ``-wal`` and ``-shm`` files the database's permissions). A
    file made before, by this uid, gets the group's write bit; elsewhere the umask rules."""
    try:
        if not os.stat(path.parent).st_mode & stat.S_IWGRP:
            return
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o660)
        except FileExistsError:
            st = os.stat(path)
            if st.st_uid == os.getuid() and not st.st_mode & stat.S_IWGRP:
                os.chmod(path, stat.S_IMODE(st.st_mode) | stat.S_IRGRP | stat.S_IWGRP)
            return
        try:
            os.fchmod(fd, 0o660)  # not narrowed by the umask
        finally:
            os.close(fd)
    except OSError:  # not ours to change: SQLite says what it cannot do
        pass


class Connections:
    """Per-thread connections to one SQLite file, opened on first use and kept (closing the
    last connection to a WAL database checkpoints it, which made every call ~15x slower),
    and write transactions on them. Shared by :class:`Store` and the batch tables."""

    def __init__(self, path: Path):
        self.path = path
        _share_with_group(path)
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

    def reader(self) -> sqlite3.Connection:
        """This thread's read-only connection (``mode=ro``, ``query_only``), which waits at
        most :data:`QUICK_BUSY_TIMEOUT_S` for a lock: for short bounded reads on a thread
        that must not wait (the event loop's)."""
        con = getattr(self._local, "ro", None)
        if con is None:
            con = sqlite3.connect(f"{self.path.resolve().as_uri()}?mode=ro", uri=True, timeout=QUICK_BUSY_TIMEOUT_S,
                                  isolation_level=None, check_same_thread=False)
            con.execute("PRAGMA query_only = 1")
            self._local.ro = con
            with self._all_lock:
                self._all.append(con)
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


class Store(JobRows):
    """Corridors and plans in a SQLite file. ``path`` is the database file, or a directory
    (then ``<dir>/rangeplan.sqlite3``); parent directories are created."""

    def __init__(self, path: Path | str | None = None, *, max_plans: int | None = None,
                 max_corridor_bytes: int | None = None, max_plan_bytes: int | None = None,
                 max_total_bytes: int | None = None):
        path = Path(path).expanduser() if path is not None else default_data_dir()
        if path.is_dir() or path.suffix == "":
            path = path / DB_NAME
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        from app.settings import settings

        cfg = settings()  # RANGEPLAN_MAX_PLANS, _MAX_CORRIDOR_BYTES, _MAX_PLAN_BYTES, _MAX_STORE_BYTES
        self.max_plans = max(1, int(max_plans if max_plans is not None else cfg.max_plans))
        self.max_corridor_bytes = int(max_corridor_bytes or cfg.max_corridor_bytes)
        self.max_plan_bytes = int(max_plan_bytes or cfg.max_plan_bytes)
        self.max_total_bytes = int(max_total_bytes or cfg.max_store_bytes)
        self._db = Connections(path)
        with self._connect() as con:
            # a new file gets 16 KiB pages: a ~150 kB plan result is 10 overflow pages, not
            # 38, ~0.3 ms less CPU per stored plan (no effect on an existing file)
            con.execute(f"PRAGMA page_size = {PAGE_SIZE}")
            mode = con.execute("PRAGMA journal_mode=WAL").fetchone()[0]
            if str(mode).lower() != "wal":
                raise RuntimeError(f"{path}: could not switch SQLite to WAL mode (got {mode!r})")
            con.executescript(_SCHEMA)
            self._migrate(con)

    @staticmethod
    def _migrate(con: sqlite3.Connection) -> None:
        """Add the ``size`` columns (files made before the quotas) and their indexes."""
        for table, column in (("corridors", "request"), ("plans", "result")):
            cols = {r[1] for r in con.execute(f"PRAGMA table_info({table})")}
            if "size" not in cols:
                con.execute("BEGIN IMMEDIATE")
                try:
                    if "size" not in {r[1] for r in con.execute(f"PRAGMA table_info({table})")}:
                        con.execute(f"ALTER TABLE {table} ADD COLUMN size INTEGER NOT NULL DEFAULT 0")
                        con.execute(f"UPDATE {table} SET size = length(CAST({column} AS BLOB))")
                    con.execute("COMMIT")
                except BaseException:
                    con.execute("ROLLBACK")
                    raise
        con.executescript(_MIGRATIONS)

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

    # -- quotas -------------------------------------------------------------------------
    def _corridor_text(self, request: dict) -> str:
        text = json.dumps(request, allow_nan=False)
        n = len(text.encode())
        if n > self.max_corridor_bytes:
            raise TooLarge(f"the corridor is {n} bytes of JSON, more than the limit of {self.max_corridor_bytes} "
                           "bytes per corridor (RANGEPLAN_MAX_CORRIDOR_BYTES)")
        return text

    @staticmethod
    def _sizes(con: sqlite3.Connection) -> tuple[int, int]:
        """(bytes of corridors, bytes of plans) stored."""
        return (con.execute("SELECT coalesce(sum(size), 0) FROM corridors").fetchone()[0],
                con.execute("SELECT coalesce(sum(size), 0) FROM plans").fetchone()[0])

    def _make_room(self, con: sqlite3.Connection, need: int, freed: int = 0) -> bool:
        """Drop the oldest plans until ``need`` more bytes fit in the total (``freed``: bytes
        the write replaces); False if even without any plan they do not."""
        corridors, plans = self._sizes(con)
        excess = corridors + plans - freed + need - self.max_total_bytes
        if excess <= 0:
            return True
        if corridors - freed + need > self.max_total_bytes:
            return False
        cutoff, dropped = None, 0
        for seq, size in con.execute("SELECT seq, size FROM plans INDEXED BY plans_by_size ORDER BY seq"):
            cutoff, dropped = seq, dropped + size
            if dropped >= excess:
                break
        if cutoff is not None:
            con.execute("DELETE FROM plans WHERE seq <= ?", (cutoff,))
        return True

    def _check_room(self, con: sqlite3.Connection, need: int, freed: int = 0) -> None:
        if not self._make_room(con, need, freed):
            corridors, _ = self._sizes(con)
            raise StoreFull(f"the store is full: corridors take {corridors} of its {self.max_total_bytes} bytes "
                            f"(RANGEPLAN_MAX_STORE_BYTES) and this one needs {need}; delete corridors first")

    def _check_name(self, con: sqlite3.Connection, name: str | None, own_id: str | None = None) -> None:
        if name is None:
            return
        row = con.execute("SELECT id FROM corridors WHERE name = ? AND id IS NOT ? LIMIT 1",
                          (name, own_id)).fetchone()
        if row:
            raise NameTaken(name, row[0])

    def usage(self) -> dict:
        """Bytes used and the limits: ``{"corridors", "plans", "total_limit", "corridor_limit"}``."""
        with self._connect() as con:
            corridors, plans = self._sizes(con)
        return {"corridors": corridors, "plans": plans, "total_limit": self.max_total_bytes,
                "corridor_limit": self.max_corridor_bytes}

    # -- corridors ----------------------------------------------------------------------
    def create_corridor(self, request: dict, name: str | None = None) -> dict:
        """Save a plan request as a new corridor; returns its record. Raises
        :class:`TooLarge`, :class:`StoreFull` or :class:`NameTaken` (the module docstring)."""
        if name is None and isinstance(request, dict):
            name = request.get("name")
        text = self._corridor_text(request)
        size = len(text.encode())
        id_, ts = new_id(), now_iso()
        with self._write() as con:
            self._check_name(con, name)
            self._check_room(con, size)
            con.execute("INSERT INTO corridors (id, name, created, updated, request, size) VALUES (?, ?, ?, ?, ?, ?)",
                        (id_, name, ts, ts, text, size))
        return {"id": id_, "name": name, "created": ts, "updated": ts, "request": json.loads(text)}

    def get_corridor(self, id: str) -> dict | None:
        with self._connect() as con:
            row = con.execute("SELECT id, name, created, updated, request FROM corridors WHERE id = ?",
                              (id,)).fetchone()
        return self._record(row) if row else None

    def update_corridor(self, id: str, request: dict, name: str | None = None) -> dict | None:
        """Replace a corridor's request (and name, if given or present in the request);
        ``None`` if there is no such corridor. Raises as :meth:`create_corridor`."""
        if name is None and isinstance(request, dict):
            name = request.get("name")
        text = self._corridor_text(request)
        size = len(text.encode())
        ts = now_iso()
        with self._write() as con:
            old = con.execute("SELECT size, name FROM corridors WHERE id = ?", (id,)).fetchone()
            if old is None:
                return None
            if name != old[1]:  # a name held twice from before the rule may stay as it is
                self._check_name(con, name, id)
            self._check_room(con, size, freed=old[0])
            con.execute("UPDATE corridors SET request = ?, name = coalesce(?, name), updated = ?, size = ? "
                        "WHERE id = ?", (text, name, ts, size, id))
            row = con.execute("SELECT id, name, created, updated, request FROM corridors WHERE id = ?",
                              (id,)).fetchone()
        return self._record(row)

    def delete_corridor(self, id: str) -> bool:
        with self._write() as con:
            return con.execute("DELETE FROM corridors WHERE id = ?", (id,)).rowcount > 0

    def list_corridors(self) -> list[dict]:
        """All corridors, oldest first, with their requests (for a few; lists of many read
        :meth:`corridor_page`)."""
        with self._connect() as con:
            rows = con.execute("SELECT id, name, created, updated, request FROM corridors ORDER BY seq").fetchall()
        return [self._record(r) for r in rows]

    def corridor_page(self, limit: int = DEFAULT_PAGE_SIZE, cursor: str | None = None, *,
                      quick: bool = False) -> tuple[list[dict], str | None]:
        """Up to ``limit`` corridors after ``cursor`` (None: from the first), oldest first, as
        summaries ``{"id", "name", "created", "updated", "bytes"}``; and the cursor of the
        next page (None after the last). Raises :class:`BadCursor`. With ``quick``: on this
        thread's read-only connection (:meth:`Connections.reader`), raising
        :class:`StoreBusy` instead of waiting for a lock (a read of at most
        :data:`MAX_PAGE_SIZE` rows of the primary key's index, without the requests: short
        enough for the event loop)."""
        after = decode_cursor(cursor) if cursor else 0
        limit = max(1, min(int(limit), MAX_PAGE_SIZE))
        if quick:
            try:
                rows = self._db.reader().execute("SELECT seq, id, name, created, updated, size FROM corridors "
                                                 "WHERE seq > ? ORDER BY seq LIMIT ?", (after, limit + 1)).fetchall()
            except sqlite3.OperationalError as exc:  # locked (a checkpoint, recovery) or not created yet
                raise StoreBusy(str(exc)) from None
            return self._page(rows, limit)
        with self._connect() as con:
            rows = con.execute("SELECT seq, id, name, created, updated, size FROM corridors WHERE seq > ? "
                               "ORDER BY seq LIMIT ?", (after, limit + 1)).fetchall()
        return self._page(rows, limit)

    @staticmethod
    def _page(rows: list, limit: int) -> tuple[list[dict], str | None]:
        more = len(rows) > limit
        rows = rows[:limit]
        items = [{"id": r[1], "name": r[2], "created": r[3], "updated": r[4], "bytes": r[5]} for r in rows]
        return items, (encode_cursor(rows[-1][0]) if more else None)

    # -- plans --------------------------------------------------------------------------
    def save_plan(self, result: dict, request: dict | None = None, corridor_id: str | None = None) -> str | None:
        """Store a plan result; returns its id (None: not stored, see :meth:`save_plan_json`).
        Only the newest ``max_plans`` are kept."""
        return self.save_plan_json(json.dumps(result, allow_nan=False), request, corridor_id)

    def save_plan_json(self, result_json: str, request: dict | None = None, corridor_id: str | None = None,
                       id: str | None = None) -> str | None:
        """:meth:`save_plan` for a result already serialised to JSON (the HTTP workers
        serialise once and store and send the same text). Returns None (nothing stored) for
        a result over ``max_plan_bytes`` or one that does not fit beside the corridors."""
        id_ = id or new_id()
        req = None if request is None else json.dumps(request, allow_nan=False)
        size = len(result_json.encode()) + (len(req.encode()) if req else 0)
        if size > self.max_plan_bytes:
            return None
        with self._write("NORMAL") as con:
            if not self._make_room(con, size):
                return None
            con.execute("INSERT INTO plans (id, created, corridor_id, request, result, size) VALUES (?, ?, ?, ?, ?, ?)",
                        (id_, now_iso(), corridor_id, req, result_json, size))
            con.execute("DELETE FROM plans WHERE seq <= (SELECT seq FROM plans INDEXED BY plans_by_seq "
                        "ORDER BY seq DESC LIMIT 1 OFFSET ?)", (self.max_plans,))
        return id_

    def get_plan_json(self, id: str) -> str | None:
        """The stored result JSON text of a plan, or ``None``."""
        with self._connect() as con:
            row = con.execute("SELECT result FROM plans WHERE id = ?", (id,)).fetchone()
        return row[0] if row else None

    def copy_plan_json(self, id: str, out: BinaryIO, chunk: int = COPY_CHUNK) -> bool:
        """Write the stored result JSON of a plan to ``out`` as it is stored (its UTF-8 bytes,
        never parsed), ``chunk`` bytes at a time (SQLite's incremental blob reads: the whole
        text is never in memory); False if there is no such plan."""
        con = self._db.get()
        con.execute("BEGIN")  # one read snapshot: the row found is the row copied
        try:
            row = con.execute("SELECT seq FROM plans WHERE id = ?", (id,)).fetchone()
            if row is None:
                return False
            with con.blobopen("plans", "result", row[0], readonly=True) as blob:
                while data := blob.read(chunk):
                    out.write(data)
            return True
        finally:
            con.execute("COMMIT")

    def has_plan(self, id: str) -> bool:
        """Whether a plan of this id is stored (without reading it)."""
        with self._connect() as con:
            return con.execute("SELECT 1 FROM plans WHERE id = ?", (id,)).fetchone() is not None

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
