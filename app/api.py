"""The HTTP planning service (FastAPI): POST a corridor, get a trajectory.

Endpoints (OpenAPI at ``/docs``, ReDoc at ``/redoc``, both served offline; SI units in every
field description)::

    GET  /health                      liveness (answers while plans run; no data)
    GET  /ready                       200 once the workers have loaded the kernels and can plan, else 503
    GET  /v1/robots, /v1/robots/{n}   built-in robot descriptions
    POST /v1/plan                     plan request -> result JSON (CSV: Accept: text/csv or ?format=csv;
                                      machine output: ?format=gcode | joints | dxf)
    POST /v1/import                   DXF/SVG drawing -> {"layout", "report"}
    POST /v1/segment                  request with a layout -> cells and corridor, no planning
    POST/GET /v1/corridors            save / list corridors (SQLite; lists by page, ?limit=&cursor=)
    GET/PUT/DELETE /v1/corridors/{id} one saved corridor
    POST /v1/corridors/{id}/plan      plan a saved corridor
    GET  /v1/plans/{id}               a stored plan result again (any ?format=)
    GET  /                            landing page (static/)

Every 4xx/5xx has one body shape: ``{"error": {"code", "message", "field"}}`` (:mod:`app.errors`).
Planning runs in worker processes (:mod:`app.workers`) with a per-request compute limit, a
work estimate checked before a job is queued and a memory limit per worker; request bodies
are limited in size before parsing (:mod:`app.middleware`); the token, Host, origin and CORS
rules are :mod:`app.security`; storage quotas and the duplicate-name rule :mod:`app.storage`.
Configuration by environment: ``RANGEPLAN_DATA_DIR``, ``RANGEPLAN_WORKERS`` (default: CPU
count), ``RANGEPLAN_PLAN_TIMEOUT_S`` (30), ``RANGEPLAN_MAX_BODY_BYTES`` (2 MiB),
``RANGEPLAN_MAX_QUEUE`` (64), ``RANGEPLAN_EXECUTOR`` (``process`` | ``thread``),
``RANGEPLAN_WORKER_MEMORY_MB`` (2048), and those of :mod:`app.security` and :mod:`app.storage`.
"""

from __future__ import annotations

import asyncio
import json
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, RedirectResponse, Response
from pydantic import BaseModel, Field
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.batch.api import batch_router
from app.contour_api import router as contour_router
from app.docs import install_docs
from app.errors import CODES_BY_STATUS, error_response, errors_doc, validation_response
from app.http_exchange import (
    FORMAT_HELP,
    PlanFormat,
    import_openapi,
    import_options,
    media_type,
    plan_content,
    read_drawing,
)
from app.middleware import BodySizeLimit
from app.security import AccessPolicy, install_access_control
from app.storage import (
    CURSOR_PATTERN,
    DEFAULT_PAGE_SIZE,
    MAX_PAGE_SIZE,
    BadCursor,
    NameTaken,
    QuotaError,
    Store,
    StoreFull,
    TooLarge,
    default_data_dir,
)
from app.workers import (
    DEFAULT_MEMORY_MB,
    JobTimeout,
    PlanPool,
    PoolBusy,
    TooMuchWork,
    WorkerCrashed,
    describe_failure,
)
from planner.errors import PlannerError
from planner.exchange import EXPORT_FORMATS, export
from planner.orchestrator import to_csv
from planner.schema import (
    CorridorRecord,
    ImportOptions,
    ImportResult,
    PlanRequest,
    PlanResult,
    RobotDescription,
    RobotSummary,
    SegmentationResult,
    builtin_description,
    builtin_robot_names,
    error_details,
    planner_error,
)

VERSION = "0.1.0"
#: the landing page (``RANGEPLAN_STATIC_DIR`` overrides: an installed package has no ``static/``)
STATIC_DIR = Path(__file__).resolve().parent.parent / "static"
DEFAULT_MAX_BODY = 2 * 1024 * 1024
DEFAULT_TIMEOUT_S = 30.0

# ---------------------------------------------------------------------------------------
# response models (OpenAPI documentation; results are sent as pre-serialised JSON)

class CorridorSummaryModel(BaseModel):
    id: str = Field(description="Corridor id (uuid4 hex)")
    name: str | None = Field(description="Corridor name (unique among corridors)")
    created: str = Field(description="Creation time, ISO-8601 UTC")
    updated: str = Field(description="Last update time, ISO-8601 UTC")
    bytes: int = Field(description="Size of the stored request JSON in bytes")


class CorridorPageModel(BaseModel):
    items: list[CorridorSummaryModel] = Field(description="Corridors of this page, oldest first (no requests: "
                                              "GET /v1/corridors/{id} for one)")
    next_cursor: str | None = Field(description="Pass as ?cursor= for the next page; null on the last page")


class HealthModel(BaseModel):
    status: str = Field(description="'ok': the server process answers (see /ready for planning)")
    version: str = Field(description="rangeplan version")
    pool: dict[str, Any] = Field(description="Planning pool: mode, workers, jobs in flight, time limit (s), memory "
                                 "limit per worker (MiB)")
    editor_port: int | None = Field(description="TCP port of the browser editor, if it runs")


class ReadyModel(BaseModel):
    status: str = Field(description="'ready', 'starting' (workers still loading the planner) or 'failed'")
    workers_ready: int = Field(description="Planning workers that have loaded the kernels (count)")
    workers: int = Field(description="Planning workers (count)")
    failures: list[str] = Field(description="Why workers cannot plan, if any")


_PLAN_HEADERS = {"Location": {"description": "GET this to fetch the result again (absent if not stored)",
                              "schema": {"type": "string"}},
                 "X-Plan-Id": {"description": "The plan's id (absent if not stored)", "schema": {"type": "string"}}}
_PLAN_RESPONSES = {200: {"model": PlanResult, "description": "The planned trajectory (JSON, or CSV with a "
                         "header naming each column with its unit)",
                         "content": plan_content(), "headers": _PLAN_HEADERS,
                         "links": {"GetPlan": {"operationId": "get_plan",
                                               "parameters": {"plan_id": "$response.header.X-Plan-Id"}}}},
                   **errors_doc(413, 422, 503)}
_CORRIDOR_LINKS = {name: {"operationId": op, "parameters": {"corridor_id": "$response.body#/id"}}
                   for name, op in (("GetCorridor", "get_corridor"), ("UpdateCorridor", "update_corridor"),
                                    ("DeleteCorridor", "delete_corridor"), ("PlanCorridor", "plan_corridor"))}


def _attachment(plan_id: str | None, fmt: str) -> str:
    return f'attachment; filename="plan-{plan_id or "result"}{EXPORT_FORMATS[fmt].extension}"'


def _stored_layout(store: Store, plan_id: str):
    """The layout of a stored plan's request (for a DXF's obstacles), or None."""
    info = store.plan_info(plan_id)
    try:
        return PlanRequest.model_validate(info["request"]).layout if info and info.get("request") else None
    except ValueError:  # a request stored by an older version: the DXF has no obstacles then
        return None


# ---------------------------------------------------------------------------------------
# the app

def _env_float(name: str, default: float) -> float:
    try:
        return float(os.environ.get(name, default))
    except ValueError:
        return default


def create_app(store: Store | None = None, *, workers: int | None = None, timeout_s: float | None = None,
               max_body_bytes: int | None = None, max_queue: int | None = None, executor: str | None = None,
               editor_port: int | None = None, access: AccessPolicy | None = None, pool: PlanPool | None = None,
               memory_mb: int | None = None) -> FastAPI:
    """The FastAPI app. ``store`` defaults to the SQLite file in :func:`default_data_dir`;
    ``access`` to :meth:`AccessPolicy.from_env`; other arguments to the ``RANGEPLAN_*``
    environment variables. ``pool``: a planning pool shared with the editor (the caller
    closes it); by default the app starts and closes its own."""
    store = store if store is not None else Store(default_data_dir())
    workers = workers or int(_env_float("RANGEPLAN_WORKERS", os.cpu_count() or 1))
    timeout_s = timeout_s or _env_float("RANGEPLAN_PLAN_TIMEOUT_S", DEFAULT_TIMEOUT_S)
    max_body = max_body_bytes or int(_env_float("RANGEPLAN_MAX_BODY_BYTES", DEFAULT_MAX_BODY))
    max_queue = max_queue if max_queue is not None else int(_env_float("RANGEPLAN_MAX_QUEUE", 64))
    executor = executor or os.environ.get("RANGEPLAN_EXECUTOR", "process")
    memory_mb = memory_mb if memory_mb is not None else int(_env_float("RANGEPLAN_WORKER_MEMORY_MB",
                                                                       DEFAULT_MEMORY_MB))
    access = access if access is not None else AccessPolicy.from_env()
    shared_pool = pool

    start_lock = threading.Lock()

    def ensure_pool(app: FastAPI) -> PlanPool:
        """The pool, started at lifespan startup (or on first use by a server that runs no
        lifespan, e.g. some ASGI test transports)."""
        with start_lock:
            if getattr(app.state, "pool", None) is None:
                pool = shared_pool or PlanPool(workers, timeout_s, max_queue, mode=executor, memory_mb=memory_mb)
                app.state.threads = ThreadPoolExecutor(max_workers=pool.capacity + 4,
                                                       thread_name_prefix="rangeplan-wait")
                app.state.pool = pool
            return app.state.pool

    def close_pool(app: FastAPI) -> None:
        with start_lock:
            pool, app.state.pool = getattr(app.state, "pool", None), None
            if pool is not None:
                if pool is not shared_pool:
                    pool.close()
                app.state.threads.shutdown(wait=False, cancel_futures=True)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        ensure_pool(app)
        try:
            yield
        finally:
            close_pool(app)

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
    app.state.store = store
    app.state.editor_port = editor_port
    app.state.pool = None
    app.state.close_pool = lambda: close_pool(app)
    # the bounds of one plan, also those of each batch item (app.batch: its own workers)
    app.state.plan_limits = {"timeout_s": shared_pool.timeout_s if shared_pool else timeout_s,
                             "memory_mb": shared_pool.memory_mb if shared_pool else memory_mb}
    app.add_middleware(BodySizeLimit, limit=max_body)
    app.include_router(batch_router())  # /v1/batches (app/batch/): batches on their own workers
    app.include_router(contour_router)  # /v1/contour (app/contour_api.py): G-code programs
    install_access_control(app, access)  # outside the body limit: refused before the body is read
    app.state.access = access

    @app.exception_handler(RequestValidationError)
    async def _on_validation(request: Request, exc: RequestValidationError):
        return validation_response(exc)

    @app.exception_handler(StarletteHTTPException)
    async def _on_http(request: Request, exc: StarletteHTTPException):
        if exc.status_code == 400 and exc.detail == "There was an error parsing the body":
            # FastAPI's answer to a body that is not UTF-8: invalid JSON like any other
            return error_response(422, "invalid_input", "body is not valid JSON (it must be UTF-8 text)")
        code = CODES_BY_STATUS.get(exc.status_code, "http_error")
        msg = exc.detail if isinstance(exc.detail, str) else json.dumps(exc.detail)
        headers = getattr(exc, "headers", None)
        if exc.status_code == 405:  # every method of the path, not only those of the first route that matched it
            allowed = sorted({m for r in request.app.routes if getattr(r, "methods", None)
                              and r.path_regex.match(request.url.path) for m in r.methods})
            headers = {**(headers or {}), "Allow": ", ".join(allowed)}
            msg = f"{request.method} is not allowed on {request.url.path}; allowed: {', '.join(allowed)}"
        if exc.status_code == 404 and msg == "Not Found":
            msg = f"no such resource: {request.url.path}"
        return error_response(exc.status_code, code, msg, headers=headers)

    @app.exception_handler(QuotaError)
    async def _on_quota(request: Request, exc: QuotaError):
        if isinstance(exc, NameTaken):
            return error_response(409, "name_taken", str(exc), "name")
        if isinstance(exc, TooLarge):
            return error_response(413, "too_large", str(exc))
        assert isinstance(exc, StoreFull)
        return error_response(507, "storage_full", str(exc))

    @app.exception_handler(PlannerError)
    async def _on_planner(request: Request, exc: PlannerError):
        return error_response(422, exc.code, exc.message, exc.field)

    @app.exception_handler(Exception)
    async def _on_internal(request: Request, exc: Exception):
        return error_response(500, "internal_error", f"internal error: {type(exc).__name__}")

    async def run_job(request: Request, job: dict, media_type: str = "application/json") -> Response:
        pool = ensure_pool(request.app)
        loop = asyncio.get_running_loop()
        try:
            out: Any = await loop.run_in_executor(request.app.state.threads, pool.run, job)
        except (JobTimeout, TooMuchWork, PoolBusy, WorkerCrashed) as exc:
            status, e = describe_failure(exc, pool, job["kind"])
            return error_response(status, e["code"], e["message"], e["field"],
                                  headers={"Retry-After": "1"} if status == 503 else None)
        if out[0] == "error":
            e = out[1]
            return error_response(422, e["code"], e["message"], e.get("field"))
        if out[0] == "crash":
            return error_response(500, "internal_error", "the planner failed unexpectedly: "
                                  + out[1].splitlines()[0])
        _, payload, meta = out
        headers = {}
        if meta.get("plan_id"):
            headers["Location"] = f"/v1/plans/{meta['plan_id']}"
            headers["X-Plan-Id"] = meta["plan_id"]
        fmt = job.get("format")
        if fmt in EXPORT_FORMATS:
            headers["Content-Disposition"] = _attachment(meta.get("plan_id"), fmt)
        return Response(payload, media_type=media_type, headers=headers)

    def plan_format(request: Request, fmt: str | None) -> str:
        if fmt is not None:
            return fmt
        accept = request.headers.get("accept", "")
        return "csv" if "text/csv" in accept and "application/json" not in accept else "json"

    async def plan_response(request: Request, req: PlanRequest, fmt: str | None, corridor_id: str | None = None,
                            forces: bool = False):
        fmt = plan_format(request, fmt)
        job = {"kind": "plan", "request": req, "format": fmt, "forces": forces,
               "source": f"corridor {corridor_id}" if corridor_id else "POST /v1/plan",
               "store": str(request.app.state.store.path), "corridor_id": corridor_id}
        return await run_job(request, job, media_type(fmt))

    Format = Query(None, description=FORMAT_HELP)
    Forces = Query(False, description="With format=joints: add one drive-force column per leg (N)")

    # -- service --------------------------------------------------------------------------
    @app.get("/health", response_model=HealthModel, tags=["service"])
    async def health(request: Request):
        """Liveness: answers immediately, also while plans run (no data; for planning see /ready)."""
        pool = getattr(request.app.state, "pool", None)
        return {"status": "ok", "version": VERSION, "pool": pool.stats() if pool else {},
                "editor_port": request.app.state.editor_port}

    @app.get("/ready", response_model=ReadyModel, tags=["service"],
             responses={503: {"model": ReadyModel, "description": "Not ready: the workers are loading the planner "
                              "or cannot plan"}})
    async def ready(request: Request):
        """Readiness: 200 once at least one worker has loaded the planner's kernels and none
        has failed to; 503 before (or when they cannot plan). The container's health check."""
        state = ensure_pool(request.app).readiness()
        body = {"status": "ready" if state["ready"] else "failed" if state["failures"] else "starting",
                "workers_ready": state["workers_ready"], "workers": state["workers"], "failures": state["failures"]}
        return JSONResponse(body, status_code=200 if state["ready"] else 503)

    @app.get("/v1/robots", response_model=list[RobotSummary], tags=["robots"])
    def robots() -> list[RobotSummary]:
        """The built-in robots."""
        return [RobotSummary(name=name, description=builtin_description(name).description,
                             legs=builtin_description(name).n_legs) for name in builtin_robot_names()]

    @app.get("/v1/robots/{name}", response_model=RobotDescription, tags=["robots"], responses=errors_doc(404))
    def robot(name: str) -> RobotDescription:
        """A built-in robot's full description (pivots in m, masses in kg, inertias in kg m^2,
        limits in m, N, m/s); the same object a request may give as ``robot``."""
        if name not in builtin_robot_names():
            raise StarletteHTTPException(404, f"unknown robot {name!r}; built-in robots: "
                                         f"{', '.join(builtin_robot_names())}")
        return builtin_description(name)

    # -- planning -------------------------------------------------------------------------
    @app.post("/v1/plan", tags=["planning"], response_class=Response, responses=_PLAN_RESPONSES)
    async def plan(body: PlanRequest, request: Request, format: PlanFormat | None = Format, forces: bool = Forces):
        """Plan a trajectory for a corridor (``segments``), a reference or a ``layout``.
        The result is stored: fetch it again at ``GET /v1/plans/{plan_id}``."""
        return await plan_response(request, body, format, forces=forces)

    @app.post("/v1/import", tags=["planning"], response_class=Response, openapi_extra=import_openapi(),
              responses={200: {"model": ImportResult, "description": "The drawing as a layout (m, rad) and a "
                               "report of the shapes used, holes, pieces left open and the units applied"},
                         **errors_doc(413, 415, 422, 503)})
    async def import_drawing(request: Request):
        """Read a DXF or SVG drawing (the body, or a multipart file upload): its closed shapes
        become a layout's obstacles, placed by the query parameters (units, layers, offset [m],
        rotation [rad], scale, tolerances [m], margin [m], bounds_layer, start, end)."""
        from pydantic import ValidationError
        try:
            options = ImportOptions.model_validate(import_options(request))
        except ValidationError as exc:
            raise planner_error(exc) from None
        data, filename, content_type = await read_drawing(request)
        return await run_job(request, {"kind": "import", "data": data, "options": options, "filename": filename,
                                       "content_type": content_type})

    @app.post("/v1/segment", tags=["planning"], response_class=Response,
              responses={200: {"model": SegmentationResult, "description": "Cells and corridor"},
                         **errors_doc(413, 422, 503)})
    async def segment(body: PlanRequest, request: Request):
        """Segment a ``layout`` (workspace with obstacles) into cells and a corridor, without planning."""
        if body.layout is None:
            return error_response(422, "invalid_input", "a segmentation request needs a layout", "layout")
        return await run_job(request, {"kind": "segment", "request": body})

    @app.get("/v1/plans/{plan_id}", tags=["planning"], response_class=Response, operation_id="get_plan", responses={
        200: {k: v for k, v in _PLAN_RESPONSES[200].items() if k not in ("links", "headers")}, **errors_doc(404)})
    def get_plan(plan_id: str, request: Request, format: PlanFormat | None = Format, forces: bool = Forces):
        """A stored plan result (the newest plans are kept; see RANGEPLAN_MAX_PLANS)."""
        store: Store = request.app.state.store
        text = store.get_plan_json(plan_id)
        if text is None:
            raise StarletteHTTPException(404, f"no plan with id {plan_id!r}")
        fmt = plan_format(request, format)
        if fmt == "csv":
            return Response(to_csv(PlanResult.model_validate_json(text)), media_type=media_type(fmt))
        if fmt in EXPORT_FORMATS:
            layout = _stored_layout(store, plan_id) if fmt == "dxf" else None
            body = export(PlanResult.model_validate_json(text), fmt, layout=layout,  # type: ignore[arg-type]
                          forces=forces, source=f"plan {plan_id}")
            return Response(body, media_type=media_type(fmt),
                            headers={"Content-Disposition": _attachment(plan_id, fmt)})
        return Response(text, media_type="application/json")

    # -- corridors ------------------------------------------------------------------------
    def saved(body: PlanRequest) -> dict:
        """What storage keeps: the request as the client sent it (validated exactly as for planning)."""
        return body.to_json_dict()

    def get_or_404(store: Store, corridor_id: str) -> dict:
        rec = store.get_corridor(corridor_id)
        if rec is None:
            raise StarletteHTTPException(404, f"no corridor with id {corridor_id!r}")
        return rec

    @app.post("/v1/corridors", status_code=201, response_model=CorridorRecord, response_model_exclude_unset=True,
              tags=["corridors"], operation_id="create_corridor",
              responses={201: {"description": "The saved corridor", "links": _CORRIDOR_LINKS,
                               "headers": {"Location": {"description": "The corridor's address",
                                                        "schema": {"type": "string"}}}},
                         **errors_doc(409, 413, 422, 507)})
    def create_corridor(body: PlanRequest, request: Request, response: Response):
        """Save a plan request as a corridor; its name is the request's ``name``, unique among
        corridors (409 if another has it: replace that one with PUT)."""
        rec = request.app.state.store.create_corridor(saved(body), body.name)
        response.headers["Location"] = f"/v1/corridors/{rec['id']}"
        return rec

    @app.get("/v1/corridors", response_model=CorridorPageModel, tags=["corridors"], operation_id="list_corridors",
             responses={200: {"description": "A page of corridors", "links": {"NextPage": {
                 "operationId": "list_corridors", "parameters": {"cursor": "$response.body#/next_cursor"}}}},
                        **errors_doc(422)})
    def list_corridors(request: Request,
                       limit: int = Query(DEFAULT_PAGE_SIZE, ge=1, le=MAX_PAGE_SIZE, description="Corridors per page"),
                       cursor: str | None = Query(None, pattern=CURSOR_PATTERN,
                                                  description="next_cursor of the previous page")):
        """Saved corridors a page at a time, oldest first, as summaries."""
        try:
            items, nxt = request.app.state.store.corridor_page(limit, cursor)
        except BadCursor as exc:
            return error_response(422, "invalid_input", str(exc), "cursor")
        return {"items": items, "next_cursor": nxt}

    @app.get("/v1/corridors/{corridor_id}", response_model=CorridorRecord, response_model_exclude_unset=True,
             tags=["corridors"], operation_id="get_corridor", responses=errors_doc(404))
    def get_corridor(corridor_id: str, request: Request):
        return get_or_404(request.app.state.store, corridor_id)

    @app.put("/v1/corridors/{corridor_id}", response_model=CorridorRecord, response_model_exclude_unset=True,
             tags=["corridors"], operation_id="update_corridor", responses=errors_doc(404, 409, 413, 422, 507))
    def update_corridor(corridor_id: str, body: PlanRequest, request: Request):
        """Replace a saved corridor's request (and name: 409 if another corridor has it)."""
        rec = request.app.state.store.update_corridor(corridor_id, saved(body), body.name)
        if rec is None:
            raise StarletteHTTPException(404, f"no corridor with id {corridor_id!r}")
        return rec

    @app.delete("/v1/corridors/{corridor_id}", status_code=204, response_class=Response, tags=["corridors"],
                operation_id="delete_corridor", responses=errors_doc(404))
    def delete_corridor(corridor_id: str, request: Request):
        if not request.app.state.store.delete_corridor(corridor_id):
            raise StarletteHTTPException(404, f"no corridor with id {corridor_id!r}")
        return Response(status_code=204)

    @app.post("/v1/corridors/{corridor_id}/plan", tags=["corridors"], response_class=Response,
              operation_id="plan_corridor", responses={**_PLAN_RESPONSES, **errors_doc(404)})
    async def plan_corridor(corridor_id: str, request: Request, format: PlanFormat | None = Format,
                            forces: bool = Forces):
        """Plan a saved corridor; the result is stored with a link to the corridor."""
        store: Store = request.app.state.store
        rec = await asyncio.get_running_loop().run_in_executor(None, store.get_corridor, corridor_id)
        if rec is None:
            raise StarletteHTTPException(404, f"no corridor with id {corridor_id!r}")
        from pydantic import ValidationError
        try:
            model = PlanRequest.model_validate(rec["request"])
        except ValidationError as exc:
            e = error_details(exc.errors())[0]
            return error_response(422, e["code"], "the saved corridor is not a valid plan request: "
                                  + e["message"], e["field"])
        return await plan_response(request, model, format, corridor_id, forces)

    # -- documentation (offline) and landing page -------------------------------------------
    install_docs(app)
    # the landing page's files as routes of their own and the examples under /examples (no
    # catch-all mount at "/": it answered every unknown method and path, preflights included, with 405)
    static_dir = Path(os.environ.get("RANGEPLAN_STATIC_DIR") or STATIC_DIR)
    if (static_dir / "index.html").is_file():
        from fastapi.responses import FileResponse
        from fastapi.staticfiles import StaticFiles

        def serve_file(path: Path):
            return lambda: FileResponse(path)

        for f in sorted(static_dir.iterdir()):
            if f.is_file():
                app.add_api_route("/" if f.name == "index.html" else f"/{f.name}", serve_file(f), methods=["GET"],
                                  include_in_schema=False)
        if (static_dir / "examples").is_dir():
            app.mount("/examples", StaticFiles(directory=static_dir / "examples"), name="examples")
    else:
        @app.get("/", include_in_schema=False)
        def root():
            return RedirectResponse("/docs")

    return app
