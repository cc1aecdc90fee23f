"""The CLI's resident planner (app/resident.py, issue 24): what the resident answers equals
what the CLI does in-process (files, messages, exit status), its client loads nothing heavy,
it is private to its key, it ends after its idle time, and its switches work.

Each test that starts a resident gives it a key of its own (``RANGEPLAN_RESIDENT_TAG``: every
``RANGEPLAN_*`` variable keys it) in the machine's kernel cache (its kernels are compiled: the
suite's ``make test`` compiles them first), and ends it (SIGTERM) or waits for it to end.
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import pytest

from app import resident

ROOT = Path(__file__).resolve().parent.parent
TABLE1 = ROOT / "app" / "static" / "examples" / "table1.json"
PROGRAM = ROOT / "app" / "static" / "examples" / "contour-part.ngc"
HEAVY = ("numpy", "numba", "pydantic", "planner", "scipy")
#: the planner modules the client may import: the package (its names load on use) and the
#: directory check (standard library only)
LIGHT = ("planner", "planner._lazy", "planner._private", "planner._version")


def env_with(idle: str, tag: str | None = None) -> dict[str, str]:
    env = {**os.environ, "RANGEPLAN_RESIDENT_S": idle, "RANGEPLAN_RESIDENT_TAG": tag or uuid.uuid4().hex}
    env.pop("PYTHONPATH", None)
    return env


def cli(args: list[str], env: dict[str, str], cwd: Path, stdin: str | None = None, *, umask: int | None = None,
        importtime: bool = False) -> subprocess.CompletedProcess:
    pre = [] if umask is None else ["-c", f"import os, sys; os.umask({umask}); from app.cli import main; "
                                          "sys.exit(main())"]
    cmd = [sys.executable, *(["-X", "importtime"] if importtime else []), *(pre or ["-m", "app.cli"]), *args]
    return subprocess.run(cmd, env=env, cwd=cwd, input=stdin, capture_output=True, text=True, timeout=300)


def paths(env: dict[str, str]) -> tuple[Path, Path]:
    d = resident.resident_dir(env, create=True)
    assert d is not None
    key = resident.resident_key(env)
    return d / f"{key}.sock", d / f"{key}.lock"


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"  # a zombie (no init reaping in a container) has ended


def start(env: dict[str, str]) -> int:
    """Start the resident of ``env`` as the CLI does, wait until it answers; its pid."""
    out = subprocess.run([sys.executable, "-c", "from app.resident import start_resident; print(start_resident())"],
                         env=env, cwd=ROOT, capture_output=True, text=True, check=True, timeout=120)
    pid = int(out.stdout.strip())
    sock = paths(env)[0]
    deadline = time.monotonic() + 180
    while resident.hand_off(["plan", "--help"], env, str(ROOT)) is None:
        assert alive(pid), "the resident ended before it listened"
        assert time.monotonic() < deadline, f"no resident at {sock}"
        time.sleep(0.2)
    return pid


def stop(pid: int) -> None:
    if alive(pid):
        os.kill(pid, signal.SIGTERM)
    deadline = time.monotonic() + 30
    while alive(pid):
        assert time.monotonic() < deadline
        time.sleep(0.05)


@pytest.fixture(scope="module")
def running():
    """One resident for the module's comparisons (its env, pid)."""
    env = env_with("120")
    pid = start(env)
    yield env, pid
    stop(pid)
    assert not any(p.exists() for p in paths(env))  # its socket and lock file removed when it ends


def without_times(text: str) -> str:
    return re.sub(r"compute \d+ ms", "compute N ms", text)


def trajectory(path: Path) -> dict:
    """The plan result without its measured times."""
    data = json.loads(path.read_text())
    for k in ("compute_ms", "qp_time_ms"):
        data["metrics"].pop(k, None)
    return data


@pytest.mark.slow
def test_the_resident_answers_as_the_cli_in_process(running, tmp_path):
    env, _ = running
    (tmp_path / "here").mkdir(), (tmp_path / "there").mkdir()
    # in-process (--no-resident) and through the resident, relative paths of the client's cwd
    a = cli(["plan", str(TABLE1), "-o", "a.json", "--no-resident"], env, tmp_path / "here")
    b = cli(["plan", str(TABLE1), "-o", "a.json"], env, tmp_path / "there", importtime=True)
    assert a.returncode == b.returncode == 0, (a.stderr, b.stderr[-2000:])
    modules = {ln.split("|")[-1].strip() for ln in b.stderr.splitlines() if ln.startswith("import time:")}
    # the planner's package and its standard-library-only modules (LIGHT) are light; any other
    # module of it, or a heavy library, means the client planned itself
    imported = {m.split(".")[0] for m in modules - set(LIGHT)}
    assert modules and not imported & set(HEAVY), f"the client planned itself: it imported {imported & set(HEAVY)}"
    said = [ln for ln in b.stderr.splitlines() if not ln.startswith("import time:")]
    assert without_times("\n".join(said) + "\n") == without_times(a.stderr) != ""
    assert a.stderr.startswith("wrote a.json: 240 steps")
    assert trajectory(tmp_path / "here" / "a.json") == trajectory(tmp_path / "there" / "a.json")
    # CSV (no measured times in it): the same bytes, the same file mode under the client's umask
    a = cli(["plan", str(TABLE1), "-o", "a.csv", "--no-resident"], env, tmp_path / "here", umask=0o077)
    b = cli(["plan", str(TABLE1), "-o", "a.csv"], env, tmp_path / "there", umask=0o077)
    assert a.returncode == b.returncode == 0 and without_times(a.stderr) == without_times(b.stderr)
    assert (tmp_path / "here" / "a.csv").read_bytes() == (tmp_path / "there" / "a.csv").read_bytes()
    assert (tmp_path / "there" / "a.csv").stat().st_mode & 0o777 == 0o600
    # standard input and standard output
    text = TABLE1.read_text()
    a = cli(["plan", "-", "--format", "csv", "--no-resident"], env, tmp_path, stdin=text)
    b = cli(["plan", "-", "--format", "csv"], env, tmp_path, stdin=text)
    assert a.returncode == b.returncode == 0 and a.stdout == b.stdout and a.stdout.count("\n") > 200
    assert a.stderr == b.stderr
    # the resident really answered those: it counts nothing, but a client with the resident
    # disabled gets no reply while this one does
    assert resident.hand_off(["plan", "--help"], {**env, "RANGEPLAN_RESIDENT_S": "0"}, str(tmp_path)) is None
    reply = resident.hand_off(["plan", "--help"], env, str(tmp_path))
    assert reply is not None and reply.code == 0 and "--no-resident" in reply.stdout


@pytest.mark.slow
def test_contour_through_the_resident(running, tmp_path):
    env, _ = running
    a = cli(["contour", str(PROGRAM), "--origin=-0.04,-0.015", "-o", "a.csv", "--no-resident"], env, tmp_path)
    reply = resident.hand_off(["contour", str(PROGRAM), "--origin=-0.04,-0.015", "-o", "b.csv"], env, str(tmp_path))
    assert reply is not None
    assert a.returncode == reply.code == 0
    assert without_times(a.stderr.replace("a.csv", "b.csv")) == without_times(reply.stderr)
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()


@pytest.mark.slow
@pytest.mark.parametrize("args, content", [
    (["plan", "bad.json"], '{"segments": [{"lower": [0.3, 0, 0], "upper": [0.31, 0.01, 0]}]}'),
    (["plan", "bad.json"], "{not json"),
    (["plan", "missing.json"], None),
    (["plan", "--format", "nope", "bad.json"], "{}"),
    (["contour", "bad.ngc", "--tolerance", "1"], "G1 X1 F100\n"),
])
def test_bad_input_exits_2_with_the_same_message(running, tmp_path, args, content):
    env, _ = running
    if content is not None:
        (tmp_path / args[-1 if args[-1].startswith("bad") else 1]).write_text(content)
    env = {**env, "COLUMNS": "120"}  # argparse's usage of an error: the client's width
    a = cli([*args, "--no-resident"], env, tmp_path)
    reply = resident.hand_off(args, env, str(tmp_path))
    assert reply is not None
    assert a.returncode == reply.code == 2
    assert reply.stderr == a.stderr.replace(" --no-resident", "") and reply.stdout == a.stdout == ""
    assert "Traceback" not in reply.stderr and reply.stderr.splitlines()[-1].startswith("rangeplan")


def test_the_client_imports_nothing_heavy_when_no_resident_runs():
    """Without a resident, the client's hand-off attempt costs a hash and a failed connect."""
    code = ("import sys, os; from app import resident; "
            "print(resident.hand_off(['plan', 'x.json'], dict(os.environ), os.getcwd())); "
            f"print(sorted(m for m in sys.modules if m.split('.')[0] in {HEAVY!r} and m not in {LIGHT!r}))")
    out = subprocess.run([sys.executable, "-c", code], env=env_with("600"), cwd=ROOT, capture_output=True,
                         text=True, check=True)
    assert out.stdout.split("\n")[:2] == ["None", "[]"]


@pytest.mark.slow
def test_another_key_never_connects(running, tmp_path):
    env, _ = running
    assert resident.hand_off(["plan", "--help"], env, str(tmp_path)) is not None
    for other in ({**env, "RANGEPLAN_RESIDENT_TAG": "another"}, {**env, "NUMBA_OPT": "1"},
                  {**env, "OPENBLAS_NUM_THREADS": "2"}):
        assert resident.resident_key(other) != resident.resident_key(env)
        assert resident.hand_off(["plan", "--help"], other, str(tmp_path)) is None
    # the idle time is no part of the key (a client with another one uses the same resident)
    assert resident.resident_key({**env, "RANGEPLAN_RESIDENT_S": "5"}) == resident.resident_key(env)
    # one resident per key: while this one runs (its lock held) no second one starts
    assert resident.start_resident(env) is None


def test_the_key_follows_every_source_file(tmp_path):
    (tmp_path / "pkg" / "sub").mkdir(parents=True)
    f = tmp_path / "pkg" / "sub" / "m.py"
    f.write_text("x = 1\n")
    env = {"HOME": "/nonexistent"}
    k1 = resident.resident_key(env, [tmp_path / "pkg"])
    f.write_text("x = 2\n")
    k2 = resident.resident_key(env, [tmp_path / "pkg"])
    (tmp_path / "pkg" / "sub" / "__pycache__").mkdir()
    (tmp_path / "pkg" / "sub" / "__pycache__" / "m.py").write_text("compiled")
    assert k1 != k2 == resident.resident_key(env, [tmp_path / "pkg"])


def test_the_directory_must_be_private(tmp_path):
    env = {"RANGEPLAN_KERNEL_CACHE": str(tmp_path)}
    d = resident.resident_dir(env, create=True)
    assert d == tmp_path / "resident" and d.stat().st_mode & 0o777 == 0o700
    d.chmod(0o755)
    assert resident.resident_dir(env) is None and resident.resident_dir(env, create=True) is None
    d.chmod(0o700)
    ro = tmp_path / "ro"
    ro.mkdir(mode=0o500)
    if os.getuid() != 0:  # root writes anywhere
        assert resident.resident_dir({"RANGEPLAN_KERNEL_CACHE": str(ro)}, create=True) is None
    assert resident.resident_dir({"RANGEPLAN_KERNEL_CACHE": str(tmp_path / "missing")}) is None


@pytest.mark.slow
def test_the_resident_ends_after_its_idle_time_and_replaces_a_stale_socket():
    env = env_with("1.5")
    sock, _ = paths(env)
    stale = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    stale.bind(str(sock))  # a socket left by a killed resident: nobody listens
    stale.close()
    assert resident.hand_off(["plan", "--help"], env, str(ROOT)) is None
    pid = start(env)  # answers (start() waits for a reply)
    t = time.monotonic()
    while alive(pid):
        assert time.monotonic() - t < 30, "the resident did not end after its idle time"
        time.sleep(0.1)
    assert not sock.exists() and not paths(env)[1].exists()


def test_no_resident_when_disabled_or_compiling(monkeypatch, tmp_path):
    import app.cli
    import planner.orchestrator.background as bg

    started = []
    monkeypatch.setattr(resident, "start_resident", lambda *a, **k: started.append(1))
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("RANGEPLAN_RESIDENT_S", "600")
    monkeypatch.setenv("RANGEPLAN_RESIDENT_TAG", uuid.uuid4().hex)
    assert app.cli.main(["plan", "missing.json", "--no-resident"]) == 2
    monkeypatch.setenv("RANGEPLAN_RESIDENT_S", "0")
    assert app.cli.main(["plan", "missing.json"]) == 2
    assert started == []
    monkeypatch.setenv("RANGEPLAN_RESIDENT_S", "600")
    assert app.cli.main(["plan", "missing.json"]) == 2
    assert started == [1]
    monkeypatch.undo()
    # a background compile running, or kernels not compiled: none starts (and no lock is taken)
    env = env_with("600")
    monkeypatch.setattr(bg, "running_compile", lambda: object())
    assert resident.start_resident(env) is None
    monkeypatch.setattr(bg, "running_compile", lambda: None)
    monkeypatch.setattr(bg, "kernels_ready", lambda mode=None: False)
    assert resident.start_resident(env) is None
    assert not paths(env)[1].exists()
    assert resident.start_resident(env_with("0")) is None


def test_a_bad_idle_time_is_named(tmp_path):
    """A value of RANGEPLAN_RESIDENT_S that does not parse: the command plans in-process as
    usual and says, in one line, that no resident starts and why."""
    out = cli(["plan", "missing.json"], env_with("soon"), tmp_path)
    assert out.returncode == 2
    assert out.stderr.splitlines() == ["rangeplan: error: missing.json: cannot read: No such file or directory",
                                       "rangeplan: warning: RANGEPLAN_RESIDENT_S: Input should be a valid number, "
                                       "unable to parse string as a number (got 'soon') (no resident planner started)"]


@pytest.mark.slow
def test_a_crashed_resident_makes_the_client_plan_itself(tmp_path):
    """A resident that closes the connection without answering (a crash): the CLI plans
    in-process, writes the same result and exits 0."""
    env = env_with("600")
    sock, lock = paths(env)
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o600)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # as a resident holds it: the CLI starts none
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(str(sock))
    listener.listen(4)
    calls = []

    def crash():
        conn, _ = listener.accept()
        calls.append(conn.recv(1 << 16))
        conn.close()

    t = threading.Thread(target=crash, daemon=True)
    t.start()
    try:
        out = cli(["plan", str(TABLE1), "-o", "x.csv"], env, tmp_path)
    finally:
        listener.close()
        sock.unlink()
        lock.unlink()
        os.close(fd)
    t.join(5)
    assert calls and b'"argv"' in calls[0]  # it asked the "resident" first
    assert out.returncode == 0 and out.stderr.startswith("wrote x.csv: 240 steps")
    assert (tmp_path / "x.csv").read_text().count("\n") > 200


@pytest.mark.slow
def test_concurrent_commands_are_served_one_after_another(running, tmp_path):
    env, _ = running
    replies: dict[int, resident.Reply | None] = {}

    def one(i: int) -> None:
        replies[i] = resident.hand_off(["plan", str(TABLE1), "-o", f"{i}.csv"], env, str(tmp_path))

    threads = [threading.Thread(target=one, args=(i,)) for i in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert all(r is not None and r.code == 0 and r.stderr.startswith(f"wrote {i}.csv") for i, r in replies.items())
    assert len(replies) == 3
    assert len({(tmp_path / f"{i}.csv").read_bytes() for i in range(3)}) == 1
