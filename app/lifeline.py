"""Child processes end with the server (issue 21): a worker whose parent died exits.

A ``kill -9`` of the server runs none of its shutdown code, so its children must notice on
their own. Each child process of the service (the planning workers of :mod:`app.workers`,
the batch workers of :mod:`app.batch.executors`) calls :func:`exit_with_parent` first
thing:

* on Linux, ``prctl(PR_SET_PDEATHSIG, SIGKILL)``: the kernel kills the child the moment the
  parent goes. The signal is tied to the *thread* that started the child, so it is only
  armed where that thread lives as long as the process (``thread_bound=False`` otherwise:
  a planning worker replaced from a request thread, a process pool's worker started by
  whichever thread submitted first);
* everywhere, a daemon thread that checks twice a second whether the parent is still the
  one that started it (``os.getppid()`` changes when the child is re-parented to init or a
  sub-reaper) and ends the process (``os._exit``) when it is not: a child stuck in a long
  job is gone within 0.5 s, without the thread caveat.

multiprocessing's resource tracker (started for the batch pool's semaphores) holds no job:
it exits by itself when the last process holding its pipe (the server and the batch
workers) is gone.
"""

from __future__ import annotations

import os
import sys
import threading

__all__ = ["exit_with_parent", "watch_parent"]

POLL_S = 0.5
_PR_SET_PDEATHSIG = 1


def _pdeathsig() -> bool:
    """Arm the kernel's parent-death signal (SIGKILL); False where there is none."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes
        import signal

        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def watch_parent(parent: int, poll_s: float = POLL_S) -> threading.Thread:
    """Start the daemon thread that ends this process once its parent is no longer ``parent``."""

    def watch() -> None:
        ev = threading.Event()
        while os.getppid() == parent:
            ev.wait(poll_s)
        os._exit(70)  # EX_SOFTWARE: no cleanup, the parent that would collect results is gone

    t = threading.Thread(target=watch, name="rangeplan-parent-watch", daemon=True)
    t.start()
    return t


def exit_with_parent(parent: int, *, thread_bound: bool = False) -> None:
    """Make this (child) process end when its parent does. ``parent``: the pid of the process
    that started this one (passed by it: if it is already gone, this one exits now).
    ``thread_bound``: the thread that started this process lives as long as the parent
    process (then the kernel's parent-death signal is armed too)."""
    if thread_bound:
        _pdeathsig()
    if os.getppid() != parent:
        os._exit(70)
    watch_parent(parent)
