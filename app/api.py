"""The HTTP planning service (FastAPI): POST a corridor, get a trajectory.

Endpoints (OpenAPI at ``/docs``, ReDoc at ``/redoc``, both served offline; SI units in every
field description)::

    GET  /health                      liveness (answers while plans run; no data)
    GET  /ready                       200 once the workers have loaded the kernels and can plan, else 503;
                                      the pool's state and the editor's port
    GET  /v1/robots, /v1/robots/{n}   built-in robot descriptions
    POST /v1/plan                     plan request -> result JSON (CSV: Accept: text/csv or ?format=csv;
                                      machine output: ?format=gcode | joints | dxf)
    POST /v1/import                   DXF/SVG drawing -> {"layout", "report"}
    POST /v1/segment                  request with a layout -> cells and corridor, no planning
    POST/GET /v1/corridors            save / list corridors (SQLite; lists by page, ?limit=&cursor=)
    GET/PUT/DELETE /v1/corridors/{id} one saved corridor
    POST /v1/corridors/{id}/plan      plan a saved corridor
    GET  /v1/plans/{id}               a stored plan result again (any ?format=)
    /v1/batches...                    batches (:mod:`app.batch.api`)
    GET  /                            landing page (static/)

The routes are ``APIRouter`` modules (:mod:`app.routers`); :func:`create_app` composes them
with the middleware, the access rules and the exception handlers (:mod:`app.handlers`), and
owns the job service (:class:`app.service.JobService`) every route submits its work to.

Every 4xx/5xx has one body shape: ``{"error": {"code", "message", "field"}}`` (:mod:`app.errors`).
Planning runs in worker processes (:mod:`app.workers`) with a per-request compute limit, a
work estimate checked before a job is queued and a memory limit per worker; request bodies
are limited in size before parsing (:mod:`app.middleware`); the token, Host, origin and CORS
rules are :mod:`app.security`; storage quotas and the duplicate-name rule :mod:`app.storage`.
Configuration: :class:`app.settings.Settings` (the ``RANGEPLAN_*`` environment).
"""

from __future__ import annotations

import threading
from contextlib import asynccontextmanager

from fastapi import FastAPI

from app.admission import Admission, AdmissionGate
from app.batch.api import batch_router
from app.docs import install_docs
from app.handlers import install_error_handlers
from app.jobs import clean_spool, spool_dir
from app.middleware import BodySizeLimit
from app.observability import install_observability
from app.routers import corridors, jobs, planning, robots
from app.routers import service as service_routes
from app.routers.contour import router as contour_router
from app.routers.pages import STATIC_DIR, install_pages
from app.routers.service import VERSION
from app.security import AccessPolicy, install_access_control
from app.service import JobService
from app.settings import settings as read_settings
from app.storage import Store, default_data_dir
from app.workers import PlanPool

__all__ = ["STATIC_DIR", "VERSION", "create_app"]


class _ServiceHolder:
    """The app's job service: started at lifespan startup (or on first use by a server that
    runs no lifespan), closed at shutdown; a service or pool given by the caller (shared
    with the editor) is used and left open."""

    def __init__(self, app: FastAPI, make, shared: JobService | None):
        self._app, self._make, self._shared = app, make, shared
        self._lock = threading.Lock()

    def ensure(self) -> JobService:
        with self._lock:
            svc = self._app.state.service
            if svc is None:
                svc = self._app.state.service = self._shared or self._make()
                self._app.state.pool = svc.pool
            return svc

    def close(self) -> None:
        with self._lock:
            svc, self._app.state.service = self._app.state.service, None
            self._app.state.pool = None
        if svc is not None:
            svc.close(pool=svc is not self._shared)


def create_app(store: Store | None = None, *, workers: int | None = None, timeout_s: float | None = None,
               max_body_bytes: int | None = None, max_queue: int | None = None, executor: str | None = None,
               editor_port: int | None = None, access: AccessPolicy | None = None, pool: PlanPool | None = None,
               memory_mb: int | None = None, service: JobService | None = None,
               job_workers: int | None = None) -> FastAPI:
    """The FastAPI app. ``store`` defaults to the SQLite file in :func:`default_data_dir`;
    ``access`` to :meth:`AccessPolicy.from_env`; other arguments to :class:`app.settings.Settings`
    (the ``RANGEPLAN_*`` environment). ``service`` (or ``pool``): a job service shared with
    the editor (the caller closes it); by default the app starts and closes its own;
    ``job_workers``: the jobs' share of its workers (``RANGEPLAN_JOB_WORKERS``)."""
    cfg = read_settings()
    store = store if store is not None else Store(default_data_dir())
    clean_spool(spool_dir(store.path))  # export files of responses that never finished
    job_workers = job_workers or cfg.job_workers
    shared = service or (JobService(pool, export_timeout_s=cfg.export_timeout_s, job_workers=job_workers)
                         if pool is not None else None)
    timeout_s = timeout_s or cfg.plan_timeout_s
    memory_mb = memory_mb if memory_mb is not None else cfg.worker_memory_mb

    def make() -> JobService:
        queue = max_queue if max_queue is not None else cfg.max_queue
        return JobService.start(workers or cfg.workers, timeout_s, queue, mode=executor or cfg.executor,
                                memory_mb=memory_mb, export_timeout_s=cfg.export_timeout_s, start=cfg.worker_start,
                                job_workers=job_workers)

    holder: _ServiceHolder

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        holder.ensure().start_threads()
        try:
            yield
        finally:
            holder.close()

    app = FastAPI(
        title="rangeplan",
        version=VERSION,
        summary="Offline trajectory planning for planar parallel robots by range-space predictive control",
        description="POST a corridor (ranges of poses the tool may pass through), get a time-optimal-ish, "
                    "drive-force-aware trajectory for the full robot dynamics. SI units throughout: m, rad, "
                    "s, N. Errors: `{\"error\": {\"code\", \"message\", \"field\"}}`.",
        lifespan=lifespan,
        docs_url=None,
        redoc_url=None,  # served offline by app.docs
    )
    holder = _ServiceHolder(app, make, shared)
    app.state.store = store
    app.state.editor_port = editor_port
    app.state.service = app.state.pool = None
    app.state.ensure_service = holder.ensure
    app.state.close_pool = holder.close
    # the bounds of one plan, also those of each batch item (app.batch: its own workers)
    app.state.plan_limits = {"timeout_s": shared.timeout_s if shared else timeout_s,
                             "memory_mb": shared.memory_mb if shared else memory_mb}
    app.add_middleware(BodySizeLimit, limit=max_body_bytes or cfg.max_body_bytes)
    app.include_router(batch_router())  # /v1/batches (app/batch/): batches on their own workers
    app.include_router(contour_router)  # /v1/contour (app/routers/contour.py): G-code programs
    access = access if access is not None else AccessPolicy.from_env()
    install_access_control(app, access)  # outside the body limit: refused before the body is read
    # outside the access rules: a burst waits here unread (app/admission.py), the probes pass
    app.state.admission = Admission(cfg.admission_queue)
    app.add_middleware(AdmissionGate, admission=app.state.admission)
    install_observability(app, access_log=cfg.access_log)  # request ids, JSON access lines, GET /metrics
    app.state.access = access
    install_error_handlers(app)
    for routes in (service_routes, robots, planning, corridors, jobs):
        app.include_router(routes.router)
    install_docs(app)
    install_pages(app, cfg.static_dir)
    return app
