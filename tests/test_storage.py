"""The SQLite store: CRUD semantics, WAL mode, persistence, concurrent writers lose nothing."""

from __future__ import annotations

import json
import os
import sqlite3
import threading
from datetime import datetime
from pathlib import Path

import pytest

from app.storage import Store, default_data_dir

TABLE1 = json.loads((Path(__file__).resolve().parents[1] / "app/static/examples/table1.json").read_text())


def test_default_data_dir_env(monkeypatch, tmp_path):
    monkeypatch.setenv("RANGEPLAN_DATA_DIR", str(tmp_path / "d"))
    assert default_data_dir() == tmp_path / "d"
    monkeypatch.delenv("RANGEPLAN_DATA_DIR")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert default_data_dir() == tmp_path / "xdg" / "rangeplan"


def test_wal_mode_and_file_location(tmp_path):
    st = Store(tmp_path / "data")
    assert st.path == tmp_path / "data" / "rangeplan.sqlite3" and st.path.exists()
    con = sqlite3.connect(st.path)
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    con.close()


def test_corridor_crud_roundtrip(tmp_path):
    st = Store(tmp_path)
    rec = st.create_corridor(TABLE1)
    assert len(rec["id"]) == 32 and int(rec["id"], 16) >= 0  # uuid4 hex
    assert rec["name"] == TABLE1["name"]
    assert rec["request"] == TABLE1
    assert rec["created"].endswith("Z") and datetime.fromisoformat(rec["created"].replace("Z", "+00:00"))
    assert st.get_corridor(rec["id"]) == rec

    changed = json.loads(json.dumps(TABLE1))
    changed["segments"][3]["upper"][0] = -0.021
    upd = st.update_corridor(rec["id"], changed, name="moved")
    assert upd["name"] == "moved" and upd["request"]["segments"][3]["upper"][0] == -0.021
    assert upd["created"] == rec["created"] and upd["updated"] >= rec["updated"]
    assert st.get_corridor(rec["id"])["request"] == changed

    assert st.update_corridor("0" * 32, changed) is None
    assert [r["id"] for r in st.list_corridors()] == [rec["id"]]
    assert st.delete_corridor(rec["id"]) is True
    assert st.delete_corridor(rec["id"]) is False
    assert st.get_corridor(rec["id"]) is None and st.list_corridors() == []


def test_corridors_survive_reopen(tmp_path):
    ids = [Store(tmp_path).create_corridor(TABLE1, name=f"c{i}")["id"] for i in range(3)]
    st = Store(tmp_path)
    assert [r["id"] for r in st.list_corridors()] == ids
    assert [r["name"] for r in st.list_corridors()] == ["c0", "c1", "c2"]


def test_nan_is_refused_not_stored(tmp_path):
    st = Store(tmp_path)
    with pytest.raises(ValueError):
        st.create_corridor({"segments": [{"lower": [float("nan"), 0, 0]}]})
    assert st.list_corridors() == []


def test_plans_saved_fetched_and_pruned(tmp_path):
    st = Store(tmp_path, max_plans=5)
    ids = [st.save_plan({"k": i, "pose": [[0.1 * i, 0.0, 0.0]]}, request={"i": i}) for i in range(8)]
    assert st.count_plans() == 5
    for i in range(3):
        assert st.get_plan(ids[i]) is None  # the oldest went first
    for i in range(3, 8):
        assert st.get_plan(ids[i])["k"] == i
        assert st.plan_info(ids[i])["request"] == {"i": i}


def test_concurrent_writers_lose_nothing(tmp_path):
    """8 threads, each its own Store object (as the API's worker processes have), create,
    update and delete corridors and save plans at once: every write that returned is there."""
    path = tmp_path / "db"
    Store(path)
    n_threads, per_thread = 8, 25
    created: list[list[str]] = [[] for _ in range(n_threads)]
    plans: list[list[str]] = [[] for _ in range(n_threads)]
    errors = []
    barrier = threading.Barrier(n_threads)

    def work(t):
        try:
            st = Store(path)
            barrier.wait()
            for i in range(per_thread):
                rec = st.create_corridor({"t": t, "i": i, "v": 0}, name=f"t{t}-{i}")
                created[t].append(rec["id"])
                assert st.update_corridor(rec["id"], {"t": t, "i": i, "v": 1}) is not None
                plans[t].append(st.save_plan({"t": t, "i": i}, corridor_id=rec["id"]))
                if i % 5 == 4:  # delete every fifth
                    assert st.delete_corridor(rec["id"])
        except Exception as exc:  # surfaced below
            errors.append(repr(exc))

    threads = [threading.Thread(target=work, args=(t,)) for t in range(n_threads)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert not errors, errors
    st = Store(path)
    records = {r["id"]: r for r in st.list_corridors()}
    expected = {cid for t in range(n_threads) for i, cid in enumerate(created[t]) if i % 5 != 4}
    assert set(records) == expected
    for t in range(n_threads):
        for i, cid in enumerate(created[t]):
            if i % 5 != 4:
                assert records[cid]["request"] == {"t": t, "i": i, "v": 1}
                assert records[cid]["name"] == f"t{t}-{i}"
            assert st.get_plan(plans[t][i]) == {"t": t, "i": i}
    assert st.count_plans() == n_threads * per_thread


def test_pruning_reads_the_seq_index_and_old_files_get_it(tmp_path):
    """Pruning finds the oldest plan to keep on the small seq index, not by reading every
    kept plan's row; a database made before the index existed gets it when opened."""
    path = tmp_path / "old.sqlite3"
    con = sqlite3.connect(path)
    con.executescript("PRAGMA journal_mode=WAL;" + _SCHEMA_WITHOUT_INDEX)
    for i in range(4):
        con.execute("INSERT INTO plans (id, created, result) VALUES (?, 'x', ?)", (f"old{i}", json.dumps({"k": i})))
    con.commit()
    con.close()
    st = Store(path, max_plans=3)
    new = st.save_plan({"k": 4})
    assert st.count_plans() == 3
    assert [st.get_plan(i) for i in ("old0", "old1")] == [None, None]
    assert st.get_plan("old2") == {"k": 2} and st.get_plan(new) == {"k": 4}
    with st._connect() as con:
        assert con.execute("SELECT sql FROM sqlite_master WHERE name = 'plans_by_seq'").fetchone()[0].endswith(
            "ON plans (seq)")


_SCHEMA_WITHOUT_INDEX = """
CREATE TABLE plans (seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT NOT NULL UNIQUE, created TEXT NOT NULL,
                    corridor_id TEXT, request TEXT, result TEXT NOT NULL);
"""


def test_new_file_has_large_pages_existing_file_keeps_its_own(tmp_path):
    st = Store(tmp_path / "new")
    with st._connect() as con:
        assert con.execute("PRAGMA page_size").fetchone()[0] == 16384
    old = tmp_path / "old.sqlite3"
    con = sqlite3.connect(old)
    con.execute("CREATE TABLE t (x)")
    con.commit()
    default_page = con.execute("PRAGMA page_size").fetchone()[0]
    con.close()
    assert default_page != 16384
    st = Store(old)
    rec = st.create_corridor(TABLE1)
    assert st.get_corridor(rec["id"])["request"] == TABLE1
    with st._connect() as con:
        assert con.execute("PRAGMA page_size").fetchone()[0] == default_page
        assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


# ---------------------------------------------------------------------------------------
# bounds (issue 15): pages, quotas, unique names

def test_pages_visit_every_corridor_once_in_order_while_others_are_added(tmp_path):
    st = Store(tmp_path)
    ids = [st.create_corridor({"i": i}, name=f"c{i}")["id"] for i in range(23)]
    seen, cursor, pages = [], None, 0
    while True:
        items, cursor = st.corridor_page(limit=5, cursor=cursor)
        seen += [r["id"] for r in items]
        pages += 1
        if pages == 2:  # added meanwhile: appears at the end, nothing is skipped or repeated
            ids.append(st.create_corridor({"late": 1}, name="late")["id"])
        if cursor is None:
            break
    assert seen == ids and pages == 5
    first = st.corridor_page(limit=3)[0][0]
    assert set(first) == {"id", "name", "created", "updated", "bytes"}
    assert first["bytes"] == len(json.dumps({"i": 0}).encode())
    from app.storage import BadCursor
    for bad in ("nonsense", "eDk5", "!!"):
        with pytest.raises(BadCursor):
            st.corridor_page(cursor=bad)


@pytest.mark.serial  # a bound of 0.6 s
def test_a_quick_page_is_the_same_page_read_only_and_never_waits_for_a_lock(tmp_path):
    """The event loop's page read (read-only connection) gives what the read threads give,
    cannot write, and raises StoreBusy at once while another connection holds the database
    exclusively (the route then reads on a thread)."""
    import time

    from app.storage import QUICK_BUSY_TIMEOUT_S, StoreBusy
    st = Store(tmp_path)
    for i in range(7):
        st.create_corridor({"i": i}, name=f"c{i}")
    cursor = None
    while True:
        quick = st.corridor_page(limit=3, cursor=cursor, quick=True)
        assert quick == st.corridor_page(limit=3, cursor=cursor)
        cursor = quick[1]
        if cursor is None:
            break
    with pytest.raises(sqlite3.OperationalError, match="readonly"):
        st._db.reader().execute("DELETE FROM corridors")
    st.close()  # the store's connections closed: the other connection can take the database
    other = sqlite3.connect(st.path, isolation_level=None)
    other.execute("PRAGMA locking_mode = EXCLUSIVE")
    other.execute("BEGIN EXCLUSIVE")
    other.execute("UPDATE corridors SET name = name")
    try:
        t0 = time.monotonic()
        with pytest.raises(StoreBusy):
            st.corridor_page(quick=True)
        assert time.monotonic() - t0 < 0.5 + 20 * QUICK_BUSY_TIMEOUT_S
    finally:
        other.execute("COMMIT")
        other.close()
    assert len(st.corridor_page(quick=True)[0]) == 7


def test_names_are_unique_among_corridors(tmp_path):
    from app.storage import NameTaken
    st = Store(tmp_path)
    a = st.create_corridor(TABLE1, name="cell 7")
    with pytest.raises(NameTaken) as exc:
        st.create_corridor(TABLE1, name="cell 7")
    assert exc.value.holder == a["id"] and a["id"] in str(exc.value)
    b = st.create_corridor(TABLE1, name="cell 8")
    with pytest.raises(NameTaken):
        st.update_corridor(b["id"], TABLE1, name="cell 7")
    assert st.update_corridor(a["id"], TABLE1, name="cell 7")["name"] == "cell 7"  # its own name
    st.create_corridor({"x": 1}, name=None)
    st.create_corridor({"x": 2}, name=None)  # unnamed corridors do not clash
    st.delete_corridor(a["id"])
    assert st.create_corridor(TABLE1, name="cell 7")["name"] == "cell 7"


def test_quota_per_corridor_and_in_total_plans_make_room_first(tmp_path):
    from app.storage import StoreFull, TooLarge
    one = len(json.dumps(TABLE1).encode())
    st = Store(tmp_path, max_corridor_bytes=2 * one, max_total_bytes=5 * one, max_plan_bytes=one)
    with pytest.raises(TooLarge, match="RANGEPLAN_MAX_CORRIDOR_BYTES"):
        st.create_corridor({"pad": "x" * (2 * one)})
    small_result = json.dumps({"r": "y" * (one // 2 - 40)})
    plan_ids = [st.save_plan_json(small_result) for _ in range(4)]  # ~2 corridors' worth
    assert all(plan_ids) and st.count_plans() == 4
    assert st.save_plan_json(json.dumps({"r": "z" * (2 * one)})) is None  # over max_plan_bytes: not stored
    for i in range(4):
        st.create_corridor(TABLE1, name=f"c{i}")
    u = st.usage()
    assert u["corridors"] == 4 * one and u["corridors"] + u["plans"] <= 5 * one
    assert st.count_plans() < 4 and st.get_plan_json(plan_ids[-1]) is not None  # the oldest went first
    st.create_corridor(TABLE1, name="c4")
    assert st.count_plans() == 0
    with pytest.raises(StoreFull, match="RANGEPLAN_MAX_STORE_BYTES"):
        st.create_corridor(TABLE1, name="c5")
    assert st.save_plan_json(small_result) is None  # no room left for caches either
    # replacing a corridor by one of the same size fits (its old bytes are freed)
    rec = st.list_corridors()[0]
    assert st.update_corridor(rec["id"], TABLE1) is not None


def test_file_from_before_the_quotas_gets_sizes(tmp_path):
    path = tmp_path / "old.sqlite3"
    con = sqlite3.connect(path)
    con.executescript("""
        CREATE TABLE corridors (seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT NOT NULL UNIQUE, name TEXT,
                                created TEXT NOT NULL, updated TEXT NOT NULL, request TEXT NOT NULL);
        CREATE TABLE plans (seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT NOT NULL UNIQUE, created TEXT NOT NULL,
                            corridor_id TEXT, request TEXT, result TEXT NOT NULL);""")
    text = json.dumps(TABLE1)
    for i in range(2):  # saved twice under one name before names were unique
        con.execute("INSERT INTO corridors (id, name, created, updated, request) VALUES (?, 'dup', 't', 't', ?)",
                    (f"{i:032x}", text))
    con.commit()
    con.close()
    st = Store(path)
    assert st.usage()["corridors"] == 2 * len(text.encode())
    assert [r["bytes"] for r in st.corridor_page()[0]] == [len(text.encode())] * 2
    assert st.update_corridor(f"{0:032x}", TABLE1, name="dup")["name"] == "dup"  # keeps its old name


def test_database_in_a_group_writable_directory_is_group_writable(tmp_path):
    """A container's /data is writable by group 0 for any uid (Kubernetes runAsUser,
    OpenShift): the database (and SQLite's -wal and -shm beside it) made by one uid must be
    writable by another of the group, whatever the umask; elsewhere the umask rules."""
    import stat

    shared, private = tmp_path / "shared", tmp_path / "private"
    shared.mkdir(mode=0o2775)
    shared.chmod(0o2775)
    private.mkdir(mode=0o755)
    private.chmod(0o755)
    old = os.umask(0o022)
    try:
        s = Store(shared)
        s.create_corridor({"segments": []}, name="a")
        modes = {p.name: stat.S_IMODE(p.stat().st_mode) for p in shared.iterdir()}
        assert "rangeplan.sqlite3-wal" in modes, modes
        assert all(m & 0o060 == 0o060 for m in modes.values()), {k: oct(m) for k, m in modes.items()}
        assert all(m & 0o007 == 0 for m in modes.values()), "not readable by others"
        s.close()
        p = Store(private)
        p.create_corridor({"segments": []}, name="a")
        assert stat.S_IMODE((private / "rangeplan.sqlite3").stat().st_mode) == 0o644  # the umask's
        p.close()
        # a file made before (without the group's write bit) gets it when its owner opens it
        (private / "rangeplan.sqlite3").rename(shared / "old.sqlite3")
        Store(shared / "old.sqlite3").close()
        assert stat.S_IMODE((shared / "old.sqlite3").stat().st_mode) & 0o060 == 0o060
    finally:
        os.umask(old)


class _Chunks:
    """A file-like sink that records the size of each write."""

    def __init__(self):
        self.parts: list[bytes] = []

    def write(self, data: bytes) -> int:
        self.parts.append(bytes(data))
        return len(data)


def test_plan_json_is_copied_as_stored_in_chunks(tmp_path):
    """A stored plan's JSON is copied out byte for byte, a bounded chunk at a time (issue 33)."""
    st = Store(tmp_path)
    text = json.dumps({"plan_id": None, "note": "é" * 1000, "x": list(range(5000))})
    plan_id = st.save_plan_json(text)
    out = _Chunks()
    assert st.copy_plan_json(plan_id, out, chunk=4096)
    assert b"".join(out.parts) == text.encode() and max(map(len, out.parts)) <= 4096 and len(out.parts) > 5
    assert not st.copy_plan_json("f" * 32, _Chunks())
