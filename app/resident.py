"""The resident planner of the CLI (issue 24): ``rangeplan plan`` and ``rangeplan contour`` in
~0.1 s instead of ~1.5 s, the way dmypy, the Gradle daemon or Nailgun do it.

A warm ``rangeplan plan`` spends ~1.5 s starting (numba, the pydantic models, scipy, loading
the cached kernels) for a ~30 ms plan. So the first plan (in-process, as always) starts, after
writing its output, one detached *resident* process of the same installed code that loads all
of it once (:func:`serve`) and listens on a Unix domain socket; later ``plan`` / ``contour``
commands hand their argv, working directory, umask and standard input (for ``-``) to it
(:func:`hand_off`) and print what it answers: the same files written, the same messages on
stdout and stderr, the same exit status (2 for bad input) as the in-process CLI.

* **Light client**: this module imports nothing heavy (no numpy, numba, pydantic or planner):
  the client knows it can hand off before anything of the planner loads.
* **Key**: the socket is ``<dir>/<key>.sock``, ``key`` the hash of the interpreter, every
  file of the installed ``planner`` and ``app`` packages (their content), the installed
  versions (file stamps) of the planner's dependencies, and the environment variables that
  change what a plan does or where its kernels live (every ``RANGEPLAN_*`` but
  ``RANGEPLAN_RESIDENT_S``, ``NUMBA_*``, the BLAS thread counts, ``PYTHON*``, the locale,
  ``XDG_CACHE_HOME``, ``HOME``): an upgrade, an edited source file or another environment
  never talks to an old resident (it finds no socket, plans in-process and starts its own).
* **Private**: ``<dir>`` is ``rangeplan-resident`` beside the kernel cache
  (``$NUMBA_CACHE_DIR/rangeplan-resident``, else ``$RANGEPLAN_KERNEL_CACHE/resident``, else
  ``~/.cache/rangeplan/resident``), created mode 0700 and used only when it is a directory
  of this user with no access for others (no resident otherwise: a read-only or foreign cache
  directory just plans in-process). The socket is 0600, and the resident answers only a peer
  of its own uid (``SO_PEERCRED``); the client checks the resident's uid the same way.
* **One per key**: the resident holds an ``flock`` on ``<key>.lock`` for its whole life (its
  pid in the file; removed when it ends, while still locked); a second one exits at once; a
  socket left by a killed resident is removed by the next one (which holds the lock) before
  it binds.
* **Lifetime**: it binds only after loading everything (a client never waits for its warm-up:
  it plans in-process meanwhile) and exits after ``RANGEPLAN_RESIDENT_S`` seconds (default
  600) without a request; 0 disables it (``--no-resident`` for one command). It is not
  started while the kernels compile in the background (:mod:`planner.orchestrator.background`).
* **Failures**: a resident that crashes, closes the connection or answers garbage makes the
  client plan in-process (:func:`hand_off` returns None); an unexpected exception in the
  resident is answered "plan it yourself", so the in-process CLI shows its own traceback.
* Requests are served one at a time (planning is CPU bound; the CLI's working directory,
  umask and standard streams are process state); a waiting client blocks until its turn.
"""

from __future__ import annotations

import hashlib
import json
import os
import socket
import struct
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

__all__ = ["COMMANDS", "DEFAULT_IDLE_S", "Reply", "hand_off", "idle_seconds", "resident_dir", "resident_key",
           "serve", "snapshot_environment", "socket_path", "start_resident"]

#: the commands a resident runs
COMMANDS = ("plan", "contour")
#: seconds a resident waits for a request before it exits (``RANGEPLAN_RESIDENT_S``)
DEFAULT_IDLE_S = 600.0
_PROTOCOL = 1
_HEADER = struct.Struct("!Q")
#: the environment that keys a resident (a prefix ends with ``_``; else the exact name)
_KEYED = ("RANGEPLAN_", "NUMBA_", "OPENBLAS_", "OMP_", "MKL_", "PYTHON", "LANG", "LC_", "XDG_CACHE_HOME", "HOME")
_NOT_KEYED = ("RANGEPLAN_RESIDENT_S",)
#: the BLAS thread counts :mod:`app.cli` sets to 1 where they are unset
_BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
#: the installed packages whose file stamps key a resident (an upgrade changes them)
_DEPENDENCIES = ("numpy", "numba", "llvmlite", "scipy", "pydantic", "pydantic_core", "shapely", "daqp", "ezdxf",
                 "orjson")
#: options of ``plan`` / ``contour`` that take a value (to find the input argument)
_VALUE_OPTIONS = {"-o", "--output", "--format", "--origin", "--tolerance", "--feed", "--cut-below", "--settings"}


def snapshot_environment() -> dict[str, str]:
    """The process environment (the client keys its socket by it and sends it on; the
    resident compares it with its own)."""
    return dict(os.environ)


def _keyed_env(env: Mapping[str, str]) -> dict[str, str]:
    return {k: v for k, v in sorted(env.items())
            if k.startswith(_KEYED) and k not in _NOT_KEYED}


def idle_seconds(env: Mapping[str, str]) -> float | None:
    """``RANGEPLAN_RESIDENT_S`` of ``env``: seconds > 0, or None (0 or below: disabled; a
    value that does not parse: None here, named by :func:`start_resident`)."""
    text = env.get("RANGEPLAN_RESIDENT_S", "")
    if text == "":
        return DEFAULT_IDLE_S
    try:
        value = float(text)
    except ValueError:
        return None
    return value if value > 0 else None


def _package_dirs() -> list[Path]:
    here = Path(__file__).resolve().parent  # app/; planner/ is installed beside it (one distribution)
    return [here, here.parent / "planner"]


def _code_hash(roots: Sequence[Path]) -> str:
    """sha256 of every file under ``roots`` (relative path and content; ``__pycache__`` left out)."""
    h = hashlib.sha256()
    for root in roots:
        stack = [root]
        while stack:
            d = stack.pop()
            try:
                entries = sorted(os.scandir(d), key=lambda e: e.name)
            except OSError:
                continue
            for e in entries:
                if e.is_dir(follow_symlinks=False):
                    if e.name != "__pycache__":
                        stack.append(Path(e.path))
                elif e.name.endswith((".py", ".json")):
                    h.update(os.fsencode(e.path) + b"\0")
                    try:
                        with open(e.path, "rb") as f:
                            h.update(f.read())
                    except OSError:
                        pass
                    h.update(b"\0")
    return h.hexdigest()


def _dependency_stamps() -> str:
    """Where each dependency is installed and its ``__init__``'s size and mtime (without
    importing it)."""
    from importlib.machinery import PathFinder

    out = []
    for name in _DEPENDENCIES:
        spec = PathFinder.find_spec(name)
        origin = spec.origin if spec is not None else None
        try:
            st = os.stat(origin) if origin else None
        except OSError:
            st = None
        out.append(f"{name} {origin} {st.st_size if st else '-'} {st.st_mtime_ns if st else '-'}")
    return "\n".join(out)


def resident_key(env: Mapping[str, str], roots: Sequence[Path] | None = None) -> str:
    """The key of the resident this code and environment may talk to (hex, 32 digits)."""
    h = hashlib.sha256(f"rangeplan resident {_PROTOCOL}\n{sys.executable}\n{sys.version}\n".encode())
    h.update(_code_hash(_package_dirs() if roots is None else roots).encode())
    h.update(_dependency_stamps().encode())
    h.update(json.dumps(_keyed_env(env)).encode())
    return h.hexdigest()[:32]


def resident_dir(env: Mapping[str, str], create: bool = False) -> Path | None:
    """The private directory of the residents' sockets beside the kernel cache (see the module
    docstring), or None when it is missing (and not ``create``), cannot be created, is no
    directory of this user, or others have access to it."""
    if env.get("NUMBA_CACHE_DIR"):
        d = Path(env["NUMBA_CACHE_DIR"]) / "rangeplan-resident"
    elif env.get("RANGEPLAN_KERNEL_CACHE"):
        d = Path(env["RANGEPLAN_KERNEL_CACHE"]) / "resident"
    else:
        base = env.get("XDG_CACHE_HOME") or os.path.join(env.get("HOME") or os.path.expanduser("~"), ".cache")
        d = Path(base) / "rangeplan" / "resident"
    try:
        if create:
            d.parent.mkdir(parents=True, exist_ok=True)
            try:
                d.mkdir(mode=0o700)
            except FileExistsError:
                pass
    except OSError:
        return None
    from planner._private import distrust

    return None if distrust(d, owners=(os.geteuid(),), mask=0o077) else d


def socket_path(directory: Path, key: str) -> Path | None:
    """``<directory>/<key>.sock``, or None when too long for a Unix socket address."""
    p = directory / f"{key}.sock"
    return p if len(os.fsencode(str(p))) < 104 else None


def _peer_uid(sock: socket.socket) -> int:
    pid_uid_gid = sock.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
    return struct.unpack("3i", pid_uid_gid)[1]


def _send(sock: socket.socket, obj: object) -> None:
    data = json.dumps(obj).encode()
    sock.sendall(_HEADER.pack(len(data)) + data)


def _recv(sock: socket.socket) -> object:
    """One message; raises ConnectionError when the peer closed the connection before its end."""
    def exactly(n: int) -> bytes:
        chunks, got = [], 0
        while got < n:
            b = sock.recv(min(n - got, 1 << 20))
            if not b:
                raise ConnectionError("closed")
            chunks.append(b)
            got += len(b)
        return b"".join(chunks)

    (n,) = _HEADER.unpack(exactly(_HEADER.size))
    return json.loads(exactly(n))


def _input_argument(argv: Sequence[str]) -> str | None:
    """The input (request file or G-code program) of a ``plan`` / ``contour`` argv, or None."""
    it = iter(argv)
    for a in it:
        if a in COMMANDS:
            break
    for a in it:
        if a in _VALUE_OPTIONS:
            next(it, None)
        elif a == "-" or not a.startswith("-"):
            return a
    return None


class Reply:
    """What the resident answered: standard output and error text and the exit status (a
    plain class: :mod:`dataclasses` would import :mod:`inspect`, ~10 ms of the client's start)."""

    __slots__ = ("code", "stderr", "stdout")

    def __init__(self, code: int, stdout: str, stderr: str) -> None:
        self.code, self.stdout, self.stderr = code, stdout, stderr

    def __repr__(self) -> str:
        return f"Reply(code={self.code}, stdout={len(self.stdout)} chars, stderr={self.stderr!r})"


def hand_off(argv: Sequence[str], env: Mapping[str, str], cwd: str, stdin: str | None = None,
             timeout_s: float | None = None) -> Reply | None:
    """Run ``rangeplan <argv>`` in the resident of ``env``'s key: its reply, or None when
    there is none (disabled, not running, another uid, a crash, an unreadable reply) and the
    command is to run in-process. ``stdin``: the standard input's text (the input ``-``)."""
    if idle_seconds(env) is None or "--no-resident" in argv or "--" in argv:
        return None
    d = resident_dir(env)
    path = socket_path(d, resident_key(env)) if d is not None else None
    if path is None:
        return None
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.settimeout(timeout_s)
        try:
            sock.connect(str(path))
        except OSError:
            return None  # none listens (no socket, or one left by an ended resident)
        if _peer_uid(sock) != os.getuid():
            return None
        _send(sock, {"protocol": _PROTOCOL, "argv": list(argv), "cwd": cwd, "env": _keyed_env(env),
                     "umask": _umask(), "stdin": stdin, "columns": _columns(env)})
        r = _recv(sock)
        if not isinstance(r, dict) or r.get("fallback") or not isinstance(r.get("code"), int):
            return None
        return Reply(r["code"], str(r.get("stdout", "")), str(r.get("stderr", "")))
    except (OSError, ValueError, struct.error):
        return None
    finally:
        sock.close()


def _columns(env: Mapping[str, str]) -> int:
    """The width argparse wraps its usage and help to here (as :func:`shutil.get_terminal_size`
    finds it: ``COLUMNS``, else the terminal of standard output, else 80)."""
    try:
        return int(env["COLUMNS"])
    except (KeyError, ValueError):
        pass
    try:
        return os.get_terminal_size(sys.__stdout__.fileno()).columns if sys.__stdout__ else 80
    except (OSError, ValueError, AttributeError):
        return 80


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def client_main(argv: Sequence[str], command: str) -> tuple[int | None, bool]:
    """The CLI's side (:func:`app.cli.main`): (the exit status the resident answered, after
    printing its output; or None: run in-process), and whether to start a resident after
    running in-process. Reads the standard input first when the input is ``-`` (then puts
    the text back as ``sys.stdin`` for the in-process run)."""
    env = snapshot_environment()
    if command not in COMMANDS or "--no-resident" in argv:
        return None, False
    if idle_seconds(env) is None:  # off (0), or a value that does not parse: start_resident names it
        try:
            float(env.get("RANGEPLAN_RESIDENT_S", ""))
            return None, False
        except ValueError:
            return None, True
    stdin = None
    if _input_argument(argv) == "-":
        import io

        stdin = sys.stdin.read()
        sys.stdin = io.StringIO(stdin)
    try:
        cwd = os.getcwd()
    except OSError:  # removed: the in-process command says what it cannot read
        return None, False
    reply = hand_off(argv, env, cwd, stdin)
    if reply is None:
        return None, True
    sys.stderr.write(reply.stderr)
    sys.stderr.flush()
    sys.stdout.write(reply.stdout)
    sys.stdout.flush()
    return reply.code, False


def start_resident(env: Mapping[str, str] | None = None) -> int | None:
    """Start the resident of this code and environment, detached (its own session, standard
    streams on /dev/null), unless it is disabled, one runs (its lock held), the kernels are
    not all compiled or compile in the background, or its directory is not private and
    writable; returns its pid. The idle time is checked by :func:`app.settings.settings`
    (a value that does not parse: a warning on stderr naming it, no resident)."""
    import fcntl
    import subprocess

    from app.settings import SettingsError, settings

    # the resident runs app.cli, which sets the BLAS thread counts where they are unset (keyed)
    env = {**dict.fromkeys(_BLAS_THREADS, "1"), **(snapshot_environment() if env is None else env)}
    try:
        idle = settings({"RANGEPLAN_RESIDENT_S": env.get("RANGEPLAN_RESIDENT_S", "")}).resident_s
    except SettingsError as exc:
        print(f"rangeplan: warning: {exc} (no resident planner started)", file=sys.stderr)
        return None
    if idle <= 0:
        return None
    from planner.orchestrator.background import kernels_ready, running_compile

    if running_compile() is not None or not kernels_ready(None):
        return None
    d = resident_dir(env, create=True)
    key = resident_key(env)
    if d is None or socket_path(d, key) is None:
        return None
    try:
        fd = os.open(d / f"{key}.lock", os.O_RDWR)
    except FileNotFoundError:
        fd = None  # no resident of this key runs (the lock file is the resident's)
    except OSError:
        return None
    if fd is not None:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # free: no resident of this key runs
        except BlockingIOError:
            os.close(fd)
            return None
    try:
        # -P: no working directory on sys.path (a command's directory never shadows a module)
        proc = subprocess.Popen([sys.executable, "-P", "-c", "from app.cli import resident_main; resident_main()", key],
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True, close_fds=True, env=dict(env))
    except OSError:
        return None
    finally:
        if fd is not None:
            os.close(fd)  # the resident takes the lock itself
    return proc.pid


class _Stop(BaseException):
    """SIGTERM: the resident ends (a request it was running is answered by the client itself)."""


def serve(key: str, run: Callable[[list[str]], int], warm_up: Callable[[], object]) -> int:
    """The resident (``key``: the one its starter computed; it exits when its own differs):
    take the lock, ``warm_up`` (load the planner and its kernels), bind the socket and run
    each request with ``run`` (:func:`app.cli.run`: the CLI without hand-off) until
    ``RANGEPLAN_RESIDENT_S`` seconds pass without one. Returns the exit status."""
    import fcntl
    import signal

    from app.settings import settings

    def stop(signum: int, frame: object) -> None:
        raise _Stop

    signal.signal(signal.SIGTERM, stop)  # ends like the idle timeout: the socket removed
    env = snapshot_environment()
    idle = settings({"RANGEPLAN_RESIDENT_S": env.get("RANGEPLAN_RESIDENT_S", "")}).resident_s
    d = resident_dir(env)
    if idle <= 0 or d is None or resident_key(env) != key:
        return 1
    lock_path = d / f"{key}.lock"
    lock = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o600)
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        if os.fstat(lock).st_ino != os.stat(lock_path).st_ino:
            raise BlockingIOError  # an ending resident removed this lock file: the next start takes a new one
    except (BlockingIOError, FileNotFoundError):
        return 0  # another resident of this key runs
    os.ftruncate(lock, 0)
    os.write(lock, f"{os.getpid()}\n".encode())
    warm_up()
    path = socket_path(d, key)
    assert path is not None
    try:
        path.unlink()  # left by a resident that was killed (the lock is ours: none listens)
    except FileNotFoundError:
        pass
    old_mask = os.umask(0o177)  # the socket 0600 from its creation
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        listener.bind(str(path))
    finally:
        os.umask(old_mask)
    inode = os.stat(path).st_ino
    listener.listen(16)
    listener.settimeout(idle)
    os.chdir("/")
    try:
        while True:
            try:
                conn, _ = listener.accept()
            except TimeoutError:
                return 0
            with conn:
                _serve_one(conn, env, run)
    except _Stop:
        return 0
    finally:
        listener.close()
        try:
            if os.stat(path).st_ino == inode:
                path.unlink()
        except OSError:
            pass
        lock_path.unlink(missing_ok=True)  # before the lock is released (when this process ends)


def _serve_one(conn: socket.socket, env: Mapping[str, str], run: Callable[[list[str]], int]) -> None:
    import contextlib
    import io

    conn.settimeout(30.0)  # a client sends its request at once
    try:
        if _peer_uid(conn) != os.getuid():
            return
        req = _recv(conn)
    except (OSError, ValueError, struct.error):
        return
    conn.settimeout(None)
    if (not isinstance(req, dict) or req.get("protocol") != _PROTOCOL or req.get("env") != _keyed_env(env)
            or not isinstance(req.get("argv"), list) or not isinstance(req.get("cwd"), str)):
        _reply(conn, {"fallback": "request"})
        return
    out, err = io.StringIO(), io.StringIO()
    old_stdin, old_mask = sys.stdin, os.umask(int(req.get("umask", 0o022)))
    try:
        os.chdir(req["cwd"])
        os.environ["COLUMNS"] = str(int(req.get("columns", 80)))  # argparse's width of the client's terminal
        sys.stdin = io.StringIO(req.get("stdin") or "")
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = run([str(a) for a in req["argv"]])
            except SystemExit as exc:  # argparse: usage errors (2), --help (0)
                code = exc.code if isinstance(exc.code, int) else 0 if exc.code is None else 1
                if isinstance(exc.code, str):
                    print(exc.code, file=sys.stderr)
        answer: dict = {"code": int(code), "stdout": out.getvalue(), "stderr": err.getvalue()}
    except _Stop:
        raise
    except BaseException:  # any other failure: the client runs the command itself (its own traceback)
        answer = {"fallback": "error"}
    finally:
        sys.stdin = old_stdin
        os.environ.pop("COLUMNS", None)
        os.umask(old_mask)
        os.chdir("/")
    _reply(conn, answer)


def _reply(conn: socket.socket, obj: object) -> None:
    try:
        _send(conn, obj)
    except OSError:
        pass  # the client went away
