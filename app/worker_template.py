"""The template of the planning workers (issue 24): imported once, by multiprocessing's fork
server only (``set_forkserver_preload``, :class:`app.workers.PlanPool` with
``start="forkserver"``), never by the server itself.

Importing it lowers the CPU priority (the workers' ``nice``), imports the planner and loads
(or, after an install, compiles) its kernels, as a worker started by ``python -m app.workers``
does (:mod:`app.worker_process`: this module never imports the pool's). Every worker is then
a ``fork()`` of this process: it has the planner and its kernels in memory from the start
(copy-on-write pages, shared until written) and is ready to plan in milliseconds instead of the
1-3 s of a new interpreter loading numba and the kernels.
"""

from __future__ import annotations

import os
from multiprocessing import spawn
from typing import Any

from app.worker_process import WORKER_NICE, load_planner

__all__ = ["PID", "STATUS"]

_prepare = spawn.prepare


def _prepare_without_main(data: dict[str, Any]) -> None:
    """multiprocessing's preparation of a new child, without running the server's ``__main__``
    again in it (the console script, ``python -m app.cli``, pytest: a worker needs none of it,
    and a script without a ``__name__`` guard would start another server or pool in it)."""
    _prepare({k: v for k, v in data.items() if k not in ("init_main_from_name", "init_main_from_path")})


spawn.prepare = _prepare_without_main  # in the fork server only: its children are our workers

#: the process that imported this module (the fork server): the parent of the workers
PID = os.getpid()
try:
    os.nice(WORKER_NICE)  # inherited by every worker forked from here
except OSError:
    pass
#: ``("ready", None)`` or ``("failed", reason)``: what each forked worker reports to the pool
STATUS: tuple[str, str | None] = load_planner()
