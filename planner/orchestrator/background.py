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
  ``backend = "reference"`` (its result's ``settings.backend`` records it).
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

from .._jit import kernel_cache, kernel_cache_dir, save_error

__all__ = ["BackgroundCompile", "LOCK", "LOG", "MARKER", "compile_in_background", "kernels_ready", "mark_compiled",
           "running_compile", "while_compiling"]

#: the done-marker: written in the kernel cache directory by a warm-up that compiled (or
#: loaded) every kernel of every path
MARKER = "compiled"
#: the lock file of the background compile (its pid, start time and estimate, as JSON)
LOCK = "compile.lock"
#: the background compile's output (progress lines, any error)
LOG = "compile.log"
#: CPU priority of the background compile relative to its caller
COMPILE_NICE = 5

_children: list[subprocess.Popen] = []  # background compiles this process started (reaped when seen done)


#: flags of every file this module opens in the cache directory: never through a symlink
_NOFOLLOW = os.O_NOFOLLOW | os.O_CLOEXEC


def mark_compiled() -> None:
    """Write the done-marker (after a full warm-up whose kernels were all saved; nothing when
    the cache is not writable)."""
    if not kernel_cache().lasting or save_error() is not None:
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

    def note(self, plan_s: float | None = None) -> str:
        """The one line the CLI prints on stderr for a plan that runs on the reference
        (``plan_s``: its work estimate at the reference's costs [s], said where given)."""
        took = f", about {plan_s:.2g} s for this plan" if plan_s is not None else ""
        return (f"kernels not compiled yet: this plan runs on the numpy reference (same trajectory, ~100x slower"
                f"{took}); "
                f"{'compiling them in the background' if self.started else 'they are compiling in the background'}"
                f", about {self.eta_s:.0f} s left (pid {self.pid}, log {self.log})")

    def ready_in(self) -> str:
        """``about N s`` (for an error that says when the kernels will be ready)."""
        return f"about {self.eta_s:.0f} s"


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
    they cannot compile in the background); else the background compile of the kernels (started if none runs),
    and the caller plans with ``settings.backend = "reference"`` meanwhile."""
    if backend != "compiled" or kernels_ready(mode):
        return None
    return compile_in_background()


def _background_main(fd: int, warm_up: Callable[[], float]) -> None:
    """``python -m planner --background FD``: compile every kernel (``warm_up``, given by the
    caller: :mod:`.plan` imports this module) holding the lock ``FD``."""
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
    with compile_progress(sys.stdout, interval=10.0):
        seconds = warm_up()
    print(f"planner kernels ready in {seconds:.1f} s", flush=True)
