"""The one wording of a plan that did not run to the end, as ``{"code", "message", "field"}``:
the HTTP API's planning workers (:mod:`app.jobs`, :mod:`app.workers`), the editor's re-plans
and the batch engine (:mod:`app.batch.engine`) answer alike; and the memory cap of a planning
process (:func:`limit_memory`) whose excess :func:`out_of_memory` reports. Plain functions on
plain values: no web framework, storage or planner import (the batch engine's workers import it).
"""

from __future__ import annotations

from typing import Any

__all__ = ["contour_timeout", "degenerate", "import_timeout", "limit_memory", "out_of_memory", "timeout",
           "too_much_work"]


def limit_memory(memory_mb: int | None) -> None:
    """Cap this process's address space at ``memory_mb`` MiB (``RLIMIT_AS``; None or 0: no
    cap): an allocation beyond it fails (``MemoryError``) instead of taking the machine's
    memory. Called by a planning process after loading the planner."""
    if memory_mb:
        import resource

        limit = int(memory_mb) * 1024 * 1024
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))


def too_much_work(estimate: Any, limit_s: float, time_limit_s: float | None = None) -> dict[str, Any]:
    """A request whose work estimate (:class:`planner.WorkEstimate`) exceeds the work ``limit_s``
    [s] admitted under the compute limit ``time_limit_s`` [s]: refused before planning."""
    return {"code": "too_much_work", "message": estimate.message(limit_s, time_limit_s), "field": estimate.field}


def timeout(limit_s: float) -> dict[str, Any]:
    """A plan stopped at the compute limit ``limit_s`` [s]."""
    return {"code": "timeout", "field": None,
            "message": f"planning took longer than the compute limit of {limit_s:g} s and was stopped; use fewer "
                       "segments or samples, a shorter settings.tail_max_s, or a larger settings.Ts"}


def contour_timeout(limit_s: float) -> dict[str, Any]:
    """A contour stopped at the compute limit ``limit_s`` [s] (admitted by its estimate, which
    it outran): what lowers a contour's work, not a corridor's."""
    return {"code": "timeout", "field": "program",
            "message": f"contouring took longer than the compute limit of {limit_s:g} s and was stopped; split the "
                       "program into shorter ones, use feed 'program' instead of 'fastest', or a settings.Ts nearer "
                       "the default 0.01 s"}


def import_timeout(limit_s: float) -> dict[str, Any]:
    """A drawing whose reading was stopped at the compute limit ``limit_s`` [s]."""
    return {"code": "timeout", "field": "drawing",
            "message": f"reading the drawing took longer than the compute limit of {limit_s:g} s and was stopped; "
                       "choose fewer layers or a larger flatten_tolerance"}


def out_of_memory(memory_mb: int | None, kind: str = "plan") -> dict[str, Any]:
    """A job that needed more memory than its process's limit ``memory_mb`` [MiB] (None: no
    limit, the machine's memory ran out), worded for its ``kind`` (a job's ``kind``: a drawing
    import or a G-code program is not "planning this request", issue 33)."""
    limit = f"the worker process's memory limit of {memory_mb} MiB" if memory_mb else "the memory available"
    what, change = {
        "import": ("reading this drawing", "use a coarser flatten_tolerance, fewer layers, or splines given by "
                   "control points rather than fit points"),
        "contour": ("contouring this program", "split the program, or give a larger tolerance_m or settings.Ts"),
    }.get(kind, ("planning this request", "use fewer segments or samples per segment, or a larger settings.Ts"))
    return {"code": "too_much_memory", "field": "drawing" if kind == "import" else None,
            "message": f"{what} needed more than {limit} (RANGEPLAN_WORKER_MEMORY_MB) and was stopped; {change}"}


def degenerate(exc: BaseException, custom_robot: bool) -> dict[str, Any]:
    """A singular or non-finite model matrix the planner's own checks let through: the
    input's fault (``custom_robot``: the request describes its own robot), not the server's."""
    return {"code": "singular", "field": "robot" if custom_robot else None,
            "message": f"the robot model is degenerate here ({type(exc).__name__}: {exc}); check that the "
                       "robot's pivots are distinct, its legs have positive length, masses and inertias "
                       "are positive, and the corridor avoids singular poses"}
