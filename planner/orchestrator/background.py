"""Plan on the numpy reference while the kernels compile in the background (issue 24).

After installing, the compiled kernels (numba, ``cache=True``) take minutes to compile; the
numpy reference (``settings.backend = "reference"``) plans the same trajectories (Table I:
4e-16 m) in seconds without compiling anything. The user-facing edges (the CLI's ``plan``
and ``contour``, ``rangeplan serve``) choose this fallback explicitly with
:func:`while_compiling`; :func:`planner.plan` itself never switches backends, and library
users, ``make test`` and batches keep compiling in the foreground (:func:`warm_up`).

* :func:`kernels_ready`: whether a mode's kernels are in the on-disk cache (one ``stat`` of
  the done-marker :data:`MARKER` a finished warm-up writes, else numba's cache index of each
  kernel: a few ms);
* :func:`compile_in_background`: one detached process (``python -m planner --background``,
  its own session, so it outlives the caller) compiles every kernel; at most one per cache
  directory: it holds an ``flock`` on :data:`LOCK` there for its whole life (the kernel
  releases it when the process ends, however it ends: a killed compile never blocks the
  next), and the lock file records its pid, start time and estimate for the callers that
  find it running; its output goes to :data:`LOG` in the cache directory;
* :func:`while_compiling`: the policy of the edges: None when a plan can run as asked, else
  the running background compile (started if none runs), and the caller plans with
  ``backend = "reference"`` (its result's ``settings.backend`` records it);
* a background compile that fails (a full disk, any error) records why in :data:`FAILED` in
  the cache directory (or finds too little free space before starting: :data:`MIN_FREE_BYTES`);
  until the cause can have changed (:func:`earlier_failure`: another kernel key, the
  directory became writable, :data:`FREE_MARGIN_BYTES` more free space, or
  :data:`RETRY_S` passed) no other starts, and the edges plan on the reference saying so.
"""

from __future__ import annotations

import fcntl
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from .._jit import kernel_cache, kernel_cache_dir, kernel_key

__all__ = ["BackgroundCompile", "FAILED", "LOCK", "LOG", "MARKER", "compile_in_background", "earlier_failure",
           "kernels_ready", "mark_compiled", "running_compile", "while_compiling"]

#: the done-marker: written in the kernel cache directory by a warm-up that compiled (or
#: loaded) every kernel of every path
MARKER = "compiled"
#: the lock file of the background compile (its pid, start time and estimate, as JSON)
LOCK = "compile.lock"
#: the background compile's output (progress lines, any error)
LOG = "compile.log"
#: the record of a failed background compile (its cause, the kernel key, the time, the cache
#: directory's writability and free space then, as JSON)
FAILED = "compile.failed"
#: CPU priority of the background compile relative to its caller
COMPILE_NICE = 5
#: free space the background compile needs in the cache directory [B] (the kernels take ~15 MB)
MIN_FREE_BYTES = 64 * 1024 * 1024
#: more free space than at a failure that makes it worth trying again [B]
FREE_MARGIN_BYTES = 64 * 1024 * 1024
#: time after which a failed background compile is tried again whatever changed [s]
RETRY_S = 3600.0

_children: list[subprocess.Popen] = []  # background compiles this process started (reaped when seen done)


#: flags of every file this module opens in the cache directory: never through a symlink
_NOFOLLOW = os.O_NOFOLLOW | os.O_CLOEXEC


def mark_compiled() -> None:
    """Write the done-marker (after a full warm-up, whose kernels numba saved or raised; nothing
    when the cache is temporary)."""
    if not kernel_cache().lasting:
        return
    try:
        fd = os.open(kernel_cache_dir() / MARKER, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | _NOFOLLOW, 0o644)
        try:
            os.write(fd, f"{time.time():.0f}\n".encode())
        finally:
            os.close(fd)
    except OSError:
        pass


def _mode_kernel(dispatcher: object, mode: str | None) -> bool:
    """Whether a kernel runs in ``mode`` (None: every kernel): the paper mode needs none of the
    constrained mode's (:mod:`planner.constraints`, the constrained loop)."""
    func = getattr(dispatcher, "py_func", None)
    if mode != "paper" or func is None:
        return True
    return not (func.__module__.startswith("planner.constraints") or func.__name__ == "simulate_constrained")


def kernels_ready(mode: str | None = None) -> bool:
    """Whether every kernel a plan in ``mode`` (``"paper"``, ``"constrained"``; None: all)
    runs loads from the on-disk cache instead of compiling."""
    if (kernel_cache_dir() / MARKER).exists():
        return True
    from .compiling import _cached, _inlined, kernel_dispatchers

    return all(_cached(d) is not False for d in kernel_dispatchers().values()
               if _mode_kernel(d, mode) and not _inlined(d))


@dataclass(frozen=True)
class BackgroundCompile:
    """A background compile of the kernels: its process id, log file, estimated seconds left
    [s] (at the reference machine's compile speed) and whether this call started it."""

    pid: int | None
    log: Path
    eta_s: float
    started: bool
    #: why the background compile failed earlier (none runs, none starts: :func:`earlier_failure`)
    failed: str | None = None

    def note(self, plan_s: float | None = None) -> str:
        """The one line the CLI prints on stderr for a plan that runs on the reference
        (``plan_s``: its work estimate at the reference's costs [s], said where given)."""
        took = f", about {plan_s:.2g} s for this plan" if plan_s is not None else ""
        if self.failed is not None:
            return (f"kernels not compiled: the background compile failed earlier ({self.failed}; log {self.log}); "
                    f"this plan runs on the numpy reference (same trajectory, ~100x slower{took}); it is tried again "
                    f"when that can have changed (more free space, a writable cache, another version, or in an hour)")
        return (f"kernels not compiled yet: this plan runs on the numpy reference (same trajectory, ~100x slower"
                f"{took}); "
                f"{'compiling them in the background' if self.started else 'they are compiling in the background'}"
                f", about {self.eta_s:.0f} s left (pid {self.pid}, log {self.log})")

    def ready_in(self) -> str:
        """``about N s`` (for an error that says when the kernels will be ready)."""
        return f"about {self.eta_s:.0f} s" if self.failed is None else "no time soon (it failed earlier)"


def _eta(info: dict) -> float:
    return max(float(info.get("eta_s", 0.0)) - (time.time() - float(info.get("started", time.time()))), 1.0)


def _read_info(fd: int) -> dict:
    """The running compile's record (its starter writes it just after starting it: waited for,
    up to 2 s)."""
    deadline = time.monotonic() + 2.0
    while True:
        try:
            os.lseek(fd, 0, os.SEEK_SET)
            info = json.loads(os.read(fd, 4096).decode() or "{}")
        except (OSError, ValueError):
            info = {}
        if info.get("pid") or time.monotonic() > deadline:
            return info
        time.sleep(0.02)


def _reap() -> None:
    for p in list(_children):
        if p.poll() is not None:
            _children.remove(p)


def running_compile() -> BackgroundCompile | None:
    """The background compile running for this cache directory, or None (none runs)."""
    _reap()
    d = kernel_cache_dir()
    try:
        fd = os.open(d / LOCK, os.O_RDONLY | _NOFOLLOW)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            info = _read_info(fd)
            return BackgroundCompile(info.get("pid"), d / LOG, _eta(info), False)
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


def _state(d: Path) -> dict:
    """What a failure of the background compile in ``d`` depends on: the kernel key, whether
    ``d`` can be written and its free space [B]."""
    try:
        vfs = os.statvfs(d)
        free = vfs.f_bavail * vfs.f_frsize
    except OSError:
        free = 0
    return {"key": kernel_key(), "writable": os.access(d, os.W_OK), "free_bytes": free}


def _applies(record: dict, now: dict, t: float) -> bool:
    """Whether a failure ``record`` still holds for the state ``now`` at time ``t`` [s]: the
    same key, no newly writable directory, not :data:`FREE_MARGIN_BYTES` more free space, and
    less than :data:`RETRY_S` ago."""
    return (record.get("key") == now["key"] and not (now["writable"] and not record.get("writable", True))
            and now["free_bytes"] < int(record.get("free_bytes", 0)) + FREE_MARGIN_BYTES
            and 0.0 <= t - float(record.get("time", 0.0)) < RETRY_S)


def _record_failure(d: Path, cause: str) -> None:
    """Write :data:`FAILED` (nothing when it cannot be written: a full disk is found again by
    :data:`MIN_FREE_BYTES` before the next start)."""
    record = {"cause": cause, "time": round(time.time(), 1), **_state(d)}
    try:
        fd = os.open(d / FAILED, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | _NOFOLLOW, 0o644)
        try:
            os.write(fd, json.dumps(record).encode())
        finally:
            os.close(fd)
    except OSError:
        pass


def earlier_failure() -> str | None:
    """Why the background compile failed earlier, while that still holds (:func:`_applies`;
    a record that no longer does is removed), or the lack of free space that would make it
    fail; None when a background compile may start."""
    d = kernel_cache_dir()
    now = _state(d)
    if now["free_bytes"] < MIN_FREE_BYTES:
        return f"only {now['free_bytes'] / 2**20:.0f} MiB free in {d}, the kernels need ~{MIN_FREE_BYTES // 2**20} MiB"
    try:
        fd = os.open(d / FAILED, os.O_RDONLY | _NOFOLLOW)
    except OSError:
        return None
    try:
        record = json.loads(os.read(fd, 65536).decode() or "{}")
    except (OSError, ValueError):
        record = {}
    finally:
        os.close(fd)
    if _applies(record, now, time.time()):
        return f"{record.get('cause')}, {time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(record['time']))}"
    try:
        os.unlink(d / FAILED)
    except OSError:
        pass
    return None


def compile_in_background() -> BackgroundCompile | None:
    """Start the background compile of every kernel, or find the one running (its lock held);
    None when the kernel cache does not last beyond this process (read-only, temporary: the
    caller compiles in the foreground) or every kernel is compiled by now."""
    _reap()
    d = kernel_cache_dir()
    if not kernel_cache().lasting:
        return None
    try:
        fd = os.open(d / LOCK, os.O_RDWR | os.O_CREAT | _NOFOLLOW, 0o644)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:  # one is running
            info = _read_info(fd)
            return BackgroundCompile(info.get("pid"), d / LOG, _eta(info), False)
        if kernels_ready():
            return None
        failed = earlier_failure()
        if failed is not None:
            return BackgroundCompile(None, d / LOG, 0.0, False, failed)
        from .compiling import _cost, pending_kernels

        eta = sum(_cost(name.rsplit(".", 1)[-1]) for name in pending_kernels())
        log = os.open(d / LOG, os.O_WRONLY | os.O_APPEND | os.O_CREAT | _NOFOLLOW, 0o644)
        try:
            proc = subprocess.Popen([sys.executable, "-m", "planner", "--background", str(fd)], pass_fds=(fd,),
                                    stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                    start_new_session=True, close_fds=True)
        finally:
            os.close(log)
        _children.append(proc)
        info = {"pid": proc.pid, "started": time.time(), "eta_s": round(eta, 1)}
        os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_SET)
        os.write(fd, json.dumps(info).encode())
        return BackgroundCompile(proc.pid, d / LOG, eta, True)
    finally:
        os.close(fd)  # the child holds the lock (the same open file) until it ends


def while_compiling(backend: str, mode: str | None) -> BackgroundCompile | None:
    """The fallback policy of the edges: None when a plan on ``backend`` in ``mode`` (None:
    every mode) runs as asked (the reference backend; or the mode's kernels are compiled; or
    they cannot compile in the background); else the background compile of the kernels (started if none runs,
    or the one that failed earlier), and the caller plans with ``settings.backend = "reference"`` meanwhile."""
    if backend != "compiled" or kernels_ready(mode):
        return None
    return compile_in_background()


def _background_main(fd: int, warm_up: Callable[[], float]) -> None:
    """``python -m planner --background FD``: compile every kernel (``warm_up``, given by the
    caller: :mod:`.plan` imports this module) holding the lock ``FD``; a failure (or a kernel
    that could not be saved) is recorded (:data:`FAILED`) and ends the process with status 1."""
    from .compiling import compile_progress

    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # inherited from the caller: held already
    except BlockingIOError:
        print("another background compile holds the lock", flush=True)
        return
    try:
        os.nice(COMPILE_NICE)
    except OSError:
        pass
    print(f"background compile (pid {os.getpid()}) started {time.strftime('%Y-%m-%d %H:%M:%S')}", flush=True)
    try:
        with compile_progress(sys.stdout, interval=10.0):
            seconds = warm_up()  # a kernel numba cannot save (a full disk) raises its OSError
    except Exception as exc:
        cause = f"{type(exc).__name__}: {exc}"
        _record_failure(kernel_cache_dir(), cause)
        try:
            print(f"background compile failed: {cause}", flush=True)
        except OSError:
            pass
        raise SystemExit(1) from None
    print(f"planner kernels ready in {seconds:.1f} s", flush=True)
