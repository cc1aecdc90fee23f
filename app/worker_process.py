"""What a planning process is, before it is a worker of a pool: its CPU priority and its
warm-up (:func:`load_planner`). Shared by the pool (:mod:`app.workers`, a worker started as a
fresh interpreter) and the fork server's template (:mod:`app.worker_template`), which imports
this module, never the pool's (no import cycle between the two)."""

from __future__ import annotations

__all__ = ["PRELOAD", "WORKER_NICE", "load_planner"]

#: CPU priority of the workers relative to the server process
WORKER_NICE = 5

#: modules a worker imports at its start that the warm-up's tiny plans do not load, so that
#: no job pays for them: ``scipy.optimize`` (the contour's Z ramps, ``linprog`` in
#: ``planner.contour.zaxis``: ~0.2-0.5 CPU s of imports the first ramp in a fresh worker paid)
PRELOAD = ("scipy.optimize",)


def load_planner() -> tuple[str, str | None]:
    """Import the planner and load its compiled kernels (before the first job, not during it;
    and the storage, the export writers and :data:`PRELOAD`): ``("ready", None)`` or
    ``("failed", reason)``."""
    import importlib

    import app.formats
    import app.storage  # noqa: F401
    import planner
    from planner.orchestrator.background import kernels_ready, running_compile
    try:
        if not kernels_ready() and running_compile() is not None:
            # they compile in the background (app.service.JobService): jobs plan on the reference meanwhile
            planner.warm_up(backend="reference")
        else:
            planner.warm_up()  # ~0.3 s from numba's on-disk cache; compiles after an install
        for name in PRELOAD:
            importlib.import_module(name)
    except Exception as exc:  # the worker cannot plan: say why (the pool reports it, /ready stays 503)
        return ("failed", f"{type(exc).__name__}: {exc}")
    return ("ready", None)
