"""Liveness and readiness: ``GET /health``, ``GET /ready``."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field

from app.routers.deps import service
from planner import __version__ as VERSION

__all__ = ["VERSION", "router"]

router = APIRouter(tags=["service"])


class HealthModel(BaseModel):
    """Alive, and nothing else: no token is asked for, so nothing here tells anything."""

    status: str = Field(description="'ok': the server process answers (see /ready for planning and the version)")


class ReadyModel(BaseModel):
    status: str = Field(description="'ready', 'starting' (workers still loading the planner) or 'failed'")
    version: str = Field(description="rangeplan version (``rangeplan --version``, the image's label)")
    workers_ready: int = Field(description="Planning workers that have loaded the kernels (count)")
    workers: int = Field(description="Planning workers (count)")
    failures: list[str] = Field(description="Why workers cannot plan, if any")
    kernels: str = Field("compiled", description="'compiled', or 'compiling in the background, about N s left "
                         "...' after an install: plans then run on the numpy reference (same trajectories, ~100x "
                         "slower; their work estimate and limit at its costs)")
    pool: dict[str, Any] = Field(description="Planning pool: mode, workers, jobs in flight, time limit (s), memory "
                                 "limit per worker (MiB), workers replaced")
    jobs: dict[str, int] = Field(default_factory=dict, description="The jobs' share of the workers (contours and "
                                 "plans answered 202): workers (how many jobs may run at once, "
                                 "RANGEPLAN_JOB_WORKERS), running (jobs holding one), queued (jobs waiting for one); "
                                 "the other workers are kept for synchronous requests")
    editor_port: int | None = Field(description="TCP port of the browser editor, if it runs")


@router.get("/health", response_model=HealthModel)
async def health(request: Request):
    """Liveness: answers immediately, also while plans run (no data; for planning see /ready)."""
    return {"status": "ok"}


@router.get("/ready", response_model=ReadyModel,
            responses={503: {"model": ReadyModel, "description": "Not ready: the workers are loading the planner "
                             "or cannot plan"}})
async def ready(request: Request):
    """Readiness: 200 once at least one worker has loaded the planner's kernels and none
    has failed to; 503 before (or when they cannot plan). The container's health check."""
    svc = service(request)
    state = svc.readiness()
    body = {"status": "ready" if state["ready"] else "failed" if state["failures"] else "starting", "version": VERSION,
            "workers_ready": state["workers_ready"], "workers": state["workers"], "failures": state["failures"],
            "kernels": state.get("kernels", "compiled"), "pool": svc.stats(), "jobs": svc.jobs(),
            "editor_port": request.app.state.editor_port}
    return JSONResponse(body, status_code=200 if state["ready"] else 503)
