"""The HTTP planning service (FastAPI): POST a corridor, get a trajectory.

Endpoints (OpenAPI at ``/docs``; SI units in every field description)::

    GET  /health                      liveness + pool state (answers while plans run)
    GET  /v1/robots, /v1/robots/{n}   built-in robot descriptions
    POST /v1/plan                     plan request -> result JSON (CSV: Accept: text/csv or ?format=csv;
                                      machine output: ?format=gcode | joints | dxf)
    POST /v1/import                   DXF/SVG drawing -> {"layout", "report"}
    POST /v1/segment                  request with a layout -> cells and corridor, no planning
    POST/GET /v1/corridors            save / list corridors (SQLite)
    GET/PUT/DELETE /v1/corridors/{id} one saved corridor
    POST /v1/corridors/{id}/plan      plan a saved corridor
    GET  /v1/plans/{id}               a stored plan result again (any ?format=)
    GET  /                            landing page (static/)

Every 4xx/5xx has one body shape: ``{"error": {"code", "message", "field"}}``. Planning runs in
worker processes (:mod:`app.workers`) with a per-request compute limit; request bodies are
limited in size before parsing. Configuration by environment: ``RANGEPLAN_DATA_DIR``,
``RANGEPLAN_WORKERS`` (default: CPU count), ``RANGEPLAN_PLAN_TIMEOUT_S`` (30),
``RANGEPLAN_MAX_BODY_BYTES`` (2 MiB), ``RANGEPLAN_MAX_QUEUE`` (64), ``RANGEPLAN_EXECUTOR``
(``process`` | ``thread``).
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
from app.http_exchange import (
    FORMAT_HELP,
    PlanFormat,
    import_openapi,
    import_options,
    media_type,
    plan_content,
    read_drawing,
)
from app.storage import Store, default_data_dir
from app.workers import JobTimeout, PlanPool, PoolBusy, WorkerCrashed
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
STATIC_DIR = Path(__file__).resolve().parent.parent / "static"
DEFAULT_MAX_BODY = 2 * 1024 * 1024
DEFAULT_TIMEOUT_S = 30.0

_CODES_BY_STATUS = {400: "bad_request", 404: "not_found", 405: "method_not_allowed", 406: "not_acceptable",
                    413: "too_large", 415: "unsupported_media_type", 422: "invalid_input", 503: "busy"}


# ---------------------------------------------------------------------------------------
# response models (OpenAPI documentation; results are sent as pre-serialised JSON)

class ErrorDetail(BaseModel):
    code: str = Field(description="Stable machine-readable cause: invalid_input, unreachable, singular, "
                      "not_settled, diverged, no_path, infeasible, too_large, timeout, not_found, busy, "
                      "unavailable, internal_error, ...")
    message: str = Field(description="Plain-language explanation")
    field: str | None = Field(None, description="Path of the request field at fault, e.g. 'segments[3].lower'")
    details: list[dict[str, Any]] | None = Field(None, description="All validation failures "
                                                 "[{field, message}] when there are several")


class ErrorResponse(BaseModel):
    error: ErrorDetail


class HealthModel(BaseModel):
    status: str = Field(description="'ok'")
    version: str = Field(description="rangeplan version")
    pool: dict[str, Any] = Field(description="Planning pool: mode, workers, jobs in flight, time limit (s)")
    editor_port: int | None = Field(description="TCP port of the browser editor, if it runs")


def _errors(*statuses: int) -> dict:
    return {s: {"model": ErrorResponse, "description": {404: "Unknown id", 413: "Body too large",
                                                        415: "Not a drawing's content type",
                                                        422: "Invalid input or planner error",
                                                        503: "Too many plans queued",
                                                        500: "Internal error"}.get(s, "Error")} for s in statuses}


_PLAN_RESPONSES = {200: {"model": PlanResult, "description": "The planned trajectory (JSON, or CSV with a "
                         "header naming each column with its unit)",
                         "content": plan_content()},
                   **_errors(413, 422, 503)}


# ---------------------------------------------------------------------------------------
# errors

def error_response(status: int, code: str, message: str, field: str | None = None,
                   details: list | None = None, headers: dict | None = None) -> JSONResponse:
    err = {"code": code, "message": message, "field": field}
    if details:
        err["details"] = details
    return JSONResponse({"error": err}, status_code=status, headers=headers)


def _validation_response(exc: RequestValidationError) -> JSONResponse:
    """422 with the first failing field (planner.schema's paths: ``segments[3].lower``)."""
    details = error_details(exc.errors())
    first = details[0] if details else {"code": "invalid_input", "field": None, "message": "invalid input"}
    more = [{"field": d["field"], "message": d["message"]} for d in details] if len(details) > 1 else None
    return error_response(422, first["code"], first["message"], first["field"], more)


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
# body size limit (before parsing)

class _TooLarge(StarletteHTTPException):
    def __init__(self, limit: int):
        super().__init__(413, f"request body larger than the limit of {limit} bytes")


class BodySizeLimit:
    """Reject bodies over ``limit`` bytes with 413: by Content-Length up front, and by
    counting the streamed bytes (chunked bodies, lying headers)."""

    def __init__(self, app, limit: int):
        self.app, self.limit = app, limit

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        for k, v in scope.get("headers", ()):
            if k == b"content-length":
                try:
                    n = int(v)
                except ValueError:
                    n = -1
                if n < 0:
                    return await error_response(400, "bad_request", "invalid Content-Length header")(
                        scope, receive, send)
                if n > self.limit:
                    return await error_response(413, "too_large", f"request body of {n} bytes is larger "
                                                f"than the limit of {self.limit} bytes")(scope, receive, send)
        seen = 0
        limit = self.limit

        async def limited():
            nonlocal seen
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > limit:
                    raise _TooLarge(limit)
            return msg

        started = False

        async def tracking_send(msg):
            nonlocal started
            if msg["type"] == "http.response.start":
                started = True
            await send(msg)

        try:
            await self.app(scope, limited, tracking_send)
        except _TooLarge as exc:
            if not started:
                await error_response(413, "too_large", exc.detail)(scope, receive, send)


# ---------------------------------------------------------------------------------------
# the app

def _env_float(name: str, default: float) -> float:
    try:
        return float(os.environ.get(name, default))
    except ValueError:
        return default


def create_app(store: Store | None = None, *, workers: int | None = None, timeout_s: float | None = None,
               max_body_bytes: int | None = None, max_queue: int | None = None, executor: str | None = None,
               editor_port: int | None = None) -> FastAPI:
    """The FastAPI app. ``store`` defaults to the SQLite file in :func:`default_data_dir`;
    other arguments default to the ``RANGEPLAN_*`` environment variables."""
    store = store if store is not None else Store(default_data_dir())
    workers = workers or int(_env_float("RANGEPLAN_WORKERS", os.cpu_count() or 1))
    timeout_s = timeout_s or _env_float("RANGEPLAN_PLAN_TIMEOUT_S", DEFAULT_TIMEOUT_S)
    max_body = max_body_bytes or int(_env_float("RANGEPLAN_MAX_BODY_BYTES", DEFAULT_MAX_BODY))
    max_queue = max_queue if max_queue is not None else int(_env_float("RANGEPLAN_MAX_QUEUE", 64))
    executor = executor or os.environ.get("RANGEPLAN_EXECUTOR", "process")

    start_lock = threading.Lock()

    def ensure_pool(app: FastAPI) -> PlanPool:
        """The pool, started at lifespan startup (or on first use by a server that runs no
        lifespan, e.g. some ASGI test transports)."""
        with start_lock:
            if getattr(app.state, "pool", None) is None:
                pool = PlanPool(workers, timeout_s, max_queue, mode=executor)
                app.state.threads = ThreadPoolExecutor(max_workers=pool.capacity + 4,
                                                       thread_name_prefix="rangeplan-wait")
                app.state.pool = pool
            return app.state.pool

    def close_pool(app: FastAPI) -> None:
        with start_lock:
            pool, app.state.pool = getattr(app.state, "pool", None), None
            if pool is not None:
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
    )
    app.state.store = store
    app.state.editor_port = editor_port
    app.state.pool = None
    app.state.close_pool = lambda: close_pool(app)
    app.add_middleware(BodySizeLimit, limit=max_body)
    app.include_router(batch_router())  # /v1/batches (app/batch/): batches on their own workers

    @app.exception_handler(RequestValidationError)
    async def _on_validation(request: Request, exc: RequestValidationError):
        return _validation_response(exc)

    @app.exception_handler(StarletteHTTPException)
    async def _on_http(request: Request, exc: StarletteHTTPException):
        if exc.status_code == 400 and exc.detail == "There was an error parsing the body":
            # FastAPI's answer to a body that is not UTF-8: invalid JSON like any other
            return error_response(422, "invalid_input", "body is not valid JSON (it must be UTF-8 text)")
        code = _CODES_BY_STATUS.get(exc.status_code, "http_error")
        msg = exc.detail if isinstance(exc.detail, str) else json.dumps(exc.detail)
        if exc.status_code == 404 and msg == "Not Found":
            msg = f"no such resource: {request.url.path}"
        return error_response(exc.status_code, code, msg, headers=getattr(exc, "headers", None))

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
        except JobTimeout:
            if job["kind"] == "import":
                return error_response(422, "timeout", f"reading the drawing took longer than the compute limit of "
                                      f"{pool.timeout_s:g} s and was stopped; choose fewer layers or a larger "
                                      "flatten_tolerance", "drawing")
            return error_response(422, "timeout", f"planning took longer than the compute limit of "
                                  f"{pool.timeout_s:g} s and was stopped; use fewer segments or samples, "
                                  "a shorter settings.tail_max_s, or a larger settings.Ts")
        except PoolBusy as exc:
            return error_response(503, "busy", f"too many plans in progress ({exc}); retry shortly",
                                  headers={"Retry-After": "1"})
        except WorkerCrashed as exc:
            return error_response(500, "internal_error", f"the planning process died: {exc}")
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
        """Liveness: answers immediately, also while plans run."""
        pool = getattr(request.app.state, "pool", None)
        return {"status": "ok", "version": VERSION, "pool": pool.stats() if pool else {},
                "editor_port": request.app.state.editor_port}

    @app.get("/v1/robots", response_model=list[RobotSummary], tags=["robots"])
    def robots() -> list[RobotSummary]:
        """The built-in robots."""
        return [RobotSummary(name=name, description=builtin_description(name).description,
                             legs=builtin_description(name).n_legs) for name in builtin_robot_names()]

    @app.get("/v1/robots/{name}", response_model=RobotDescription, tags=["robots"], responses=_errors(404))
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
                         **_errors(413, 415, 422, 503)})
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
                         **_errors(413, 422, 503)})
    async def segment(body: PlanRequest, request: Request):
        """Segment a ``layout`` (workspace with obstacles) into cells and a corridor, without planning."""
        if body.layout is None:
            return error_response(422, "invalid_input", "a segmentation request needs a layout", "layout")
        return await run_job(request, {"kind": "segment", "request": body})

    @app.get("/v1/plans/{plan_id}", tags=["planning"], response_class=Response, responses={
        200: _PLAN_RESPONSES[200], **_errors(404)})
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
              tags=["corridors"],
              responses=_errors(413, 422))
    def create_corridor(body: PlanRequest, request: Request, response: Response):
        """Save a plan request as a corridor; its name is the request's ``name``."""
        rec = request.app.state.store.create_corridor(saved(body), body.name)
        response.headers["Location"] = f"/v1/corridors/{rec['id']}"
        return rec

    @app.get("/v1/corridors", response_model=list[CorridorRecord], response_model_exclude_unset=True,
             tags=["corridors"])
    def list_corridors(request: Request):
        """All saved corridors, oldest first."""
        return request.app.state.store.list_corridors()

    @app.get("/v1/corridors/{corridor_id}", response_model=CorridorRecord, response_model_exclude_unset=True,
             tags=["corridors"],
             responses=_errors(404))
    def get_corridor(corridor_id: str, request: Request):
        return get_or_404(request.app.state.store, corridor_id)

    @app.put("/v1/corridors/{corridor_id}", response_model=CorridorRecord, response_model_exclude_unset=True,
             tags=["corridors"],
             responses=_errors(404, 413, 422))
    def update_corridor(corridor_id: str, body: PlanRequest, request: Request):
        """Replace a saved corridor's request (and name)."""
        rec = request.app.state.store.update_corridor(corridor_id, saved(body), body.name)
        if rec is None:
            raise StarletteHTTPException(404, f"no corridor with id {corridor_id!r}")
        return rec

    @app.delete("/v1/corridors/{corridor_id}", status_code=204, response_class=Response, tags=["corridors"],
                responses=_errors(404))
    def delete_corridor(corridor_id: str, request: Request):
        if not request.app.state.store.delete_corridor(corridor_id):
            raise StarletteHTTPException(404, f"no corridor with id {corridor_id!r}")
        return Response(status_code=204)

    @app.post("/v1/corridors/{corridor_id}/plan", tags=["corridors"], response_class=Response,
              responses={**_PLAN_RESPONSES, **_errors(404)})
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

    # -- landing page ---------------------------------------------------------------------
    if STATIC_DIR.is_dir():
        from fastapi.staticfiles import StaticFiles
        app.mount("/", StaticFiles(directory=STATIC_DIR, html=True), name="static")
    else:
        @app.get("/", include_in_schema=False)
        def root():
            return RedirectResponse("/docs")

    return app
