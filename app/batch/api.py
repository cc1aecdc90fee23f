"""``/v1/batches``: plan many requests in the background, with progress and stored results
(plan requests and contour requests, G-code programs, side by side).

    POST   /v1/batches                 {"requests": [...], "name": ...} or JSON Lines -> 202 {id, state, ...}
    GET    /v1/batches                 the newest batches' progress
    GET    /v1/batches/{id}            state and progress (total, done, ok, failed, running, rate, ETA)
    GET    /v1/batches/{id}/results    JSON Lines in item order (?wait=true: until the batch ends);
                                       ?format=csv: the summary (the CLI's summary.csv columns)
    POST   /v1/batches/{id}/cancel     cancel: no further items start (finished results are kept)
    DELETE /v1/batches/{id}            delete the batch and its results (cancelling what still runs)

:func:`batch_router` is included by :func:`app.api.create_app`; its lifespan starts the
:class:`~app.batch.service.BatchService` (resuming unfinished batches) beside the app's
planning pool and stops it at shutdown. Errors have the service's one shape and helpers
(:mod:`app.errors`); the token, Host and CORS rules of :mod:`app.security` cover ``/v1/batches``
like every ``/v1`` path, and each item has the bounds of a single plan (its work estimate,
compute limit and memory cap: :mod:`app.batch.service`).
"""

from __future__ import annotations

import asyncio
import threading
from contextlib import asynccontextmanager
from typing import Any, Literal

import orjson
from fastapi import APIRouter, FastAPI, Query, Request
from fastapi.responses import JSONResponse, Response, StreamingResponse
from pydantic import BaseModel, Field
from starlette.exceptions import HTTPException

from app.errors import error_response, errors_doc
from app.json_limits import json_error_text

from .service import BatchService, QueueFull

__all__ = ["batch_router", "BatchProgress"]

_LOCK = threading.Lock()
JSONL_TYPES = ("application/x-ndjson", "application/jsonl", "application/x-jsonlines", "application/json-lines")


class BatchProgress(BaseModel):
    id: str = Field(description="Batch id (uuid4 hex)")
    name: str | None = Field(description="Batch name")
    state: Literal["queued", "running", "done", "cancelled"] = Field(description="Batch state")
    created: str = Field(description="Creation time, ISO-8601 UTC")
    format: str = Field(description="Result format ('json')")
    total: int = Field(description="Items in the batch (count)")
    done: int = Field(description="Items finished, whatever the outcome (count)")
    ok: int = Field(description="Items planned (count)")
    failed: int = Field(description="Items that failed: a planner error (code in the results) or a lost worker "
                        "(count)")
    cancelled: int = Field(description="Items cancelled before they finished (count)")
    running: int = Field(description="Items being planned on the workers now, at most the workers' slots (count)")
    pending: int = Field(description="Items waiting, also those sent ahead to a busy worker (count)")
    rate_per_s: float | None = Field(description="Items planned (ok or failed, not cancelled) per second since the "
                                     "batch started or resumed, 1/s")
    eta_s: float | None = Field(description="Estimated time to finish at that rate, s")
    elapsed_s: float | None = Field(description="Time since the batch started or resumed, s")


class BatchCreate(BaseModel):
    requests: list[dict[str, Any]] = Field(description="Plan requests, each the body of POST /v1/plan "
                                           "(m, m, rad, s), or contour requests, each the body of POST "
                                           "/v1/contour (an object with 'program': a G-code program); each is "
                                           "validated on its own, an invalid one is that item's error")
    name: str | None = Field(None, description="Batch name")


def _service(app: FastAPI) -> BatchService:
    """The app's batch service (started by the lifespan, or on first use by a server that
    runs none), with the app's bounds of one plan (compute limit, memory cap per worker)."""
    with _LOCK:
        svc = getattr(app.state, "batches", None)
        if svc is None:
            limits = getattr(app.state, "plan_limits", None) or {}
            svc = app.state.batches = BatchService(app.state.store.path, timeout_s=limits.get("timeout_s"),
                                                   memory_mb=limits.get("memory_mb"))
            svc.start()
        return svc


@asynccontextmanager
async def _lifespan(app: FastAPI):
    await asyncio.get_running_loop().run_in_executor(None, _service, app)
    try:
        yield
    finally:
        svc = getattr(app.state, "batches", None)
        app.state.batches = None
        if svc is not None:
            await asyncio.get_running_loop().run_in_executor(None, svc.close)


def _not_an_object(line: bytes) -> str | None:
    """Why a JSON Lines line is not a JSON object (None if it is one)."""
    try:
        doc = orjson.loads(line)
    except orjson.JSONDecodeError as exc:
        return f"is not valid JSON ({json_error_text(exc)})"
    if not isinstance(doc, dict):
        return f"is a JSON {_JSON_TYPES.get(type(doc), type(doc).__name__)}, not an object"
    return None


_JSON_TYPES = {list: "array", str: "string", int: "number", float: "number", bool: "boolean", type(None): "null"}


def _parse_body(body: bytes, content_type: str) -> tuple[list[str], str | None] | JSONResponse:
    """The requests as JSON texts (each validated later, by the worker that plans it)."""
    if content_type in JSONL_TYPES:
        reqs = []
        for number, ln in enumerate(body.splitlines(), 1):
            if not ln.strip():
                continue
            problem = _not_an_object(ln)
            if problem:  # each line is one request, a JSON object: anything else is the body's error
                return error_response(422, "invalid_input", f"line {number} of the JSON Lines body {problem}: each "
                                      "line must be one request, a JSON object (the body of POST /v1/plan or "
                                      "POST /v1/contour)",
                                      f"requests[{len(reqs)}]")
            reqs.append(ln.decode("utf-8"))
        if not reqs:
            return error_response(422, "invalid_input", "the JSON Lines body holds no request", "requests")
        return reqs, None
    try:
        doc = orjson.loads(body)
    except orjson.JSONDecodeError as exc:
        return error_response(422, "invalid_input", f"body is not valid JSON: {json_error_text(exc)}")
    if not isinstance(doc, dict):
        return error_response(422, "invalid_input", "a batch is a JSON object {\"requests\": [...], \"name\": ...}")
    unknown = sorted(set(doc) - {"requests", "name"})
    if unknown:
        return error_response(422, "invalid_input", "unknown field: not a field of this object", unknown[0])
    reqs, name = doc.get("requests"), doc.get("name")
    if not isinstance(reqs, list) or not reqs:
        return error_response(422, "invalid_input", "must be a non-empty list of plan or contour requests",
                                  "requests")
    for i, r in enumerate(reqs):  # each is validated as a plan or contour request later; no object is none
        if not isinstance(r, dict):
            return error_response(422, "invalid_input", "must be a JSON object: a plan request (the body of "
                                  "POST /v1/plan) or a contour request (of POST /v1/contour)", f"requests[{i}]")
    if name is not None and not isinstance(name, str):
        return error_response(422, "invalid_input", "must be a string", "name")
    return [orjson.dumps(r).decode() for r in reqs], name


def batch_router() -> APIRouter:
    router = APIRouter(lifespan=_lifespan, tags=["batches"])
    errs: dict[int | str, dict[str, Any]] = errors_doc(404, 413, 422, 503, descriptions={
        404: "Unknown batch id", 422: "Invalid batch or query parameter", 503: "Too many batch items queued"})

    @router.post("/v1/batches", status_code=202, response_model=BatchProgress,
                 responses={k: errs[k] for k in (413, 422, 503)},
                 openapi_extra={"requestBody": {"required": True, "content": {
                     "application/json": {"schema": BatchCreate.model_json_schema()},
                     "application/x-ndjson": {"schema": {"type": "string", "description": "One plan or contour "
                                                         "request per line (JSON Lines)"}}}}})
    async def create_batch(request: Request, name: str | None = Query(None, description="Batch name (JSON Lines "
                                                                             "bodies; a JSON body has its own)")):
        """Queue a batch of plan requests (bodies of ``POST /v1/plan``) and contour requests (bodies
        of ``POST /v1/contour``: a G-code program), mixed as you like; answers 202 at once with its
        id (``Location``).
        Each item is validated and planned on its own: a bad item is reported in the results
        with its code, the others are planned."""
        svc = _service(request.app)
        ctype = request.headers.get("content-type", "application/json").split(";")[0].strip().lower()
        parsed = _parse_body(await request.body(), ctype)
        if isinstance(parsed, JSONResponse):
            return parsed
        reqs, body_name = parsed
        if len(reqs) > svc.max_items:
            return error_response(422, "too_large", f"{len(reqs)} requests; a batch holds at most {svc.max_items} "
                          "(RANGEPLAN_MAX_BATCH_ITEMS)", "requests")
        try:
            out = await asyncio.get_running_loop().run_in_executor(None, svc.create, reqs, body_name or name)
        except QueueFull as exc:
            return error_response(503, "busy", f"too many batch items queued ({exc}); retry later",
                          headers={"Retry-After": "30"})
        return JSONResponse(out, status_code=202, headers={"Location": f"/v1/batches/{out['id']}"})

    @router.get("/v1/batches", response_model=list[BatchProgress], responses={422: errs[422]})
    def list_batches(request: Request, limit: int = Query(100, ge=1, le=1000, description="At most this many "
                                                                                  "(count), newest first")):
        """The newest batches and their progress."""
        service = _service(request.app)
        return [service.at_workers(p) for p in service.store.list(limit)]

    @router.get("/v1/batches/{batch_id}", response_model=BatchProgress, responses={404: errs[404], 422: errs[422]})
    def get_batch(batch_id: str, request: Request):
        """State and progress of a batch."""
        out = _service(request.app).progress(batch_id)
        if out is None:
            raise HTTPException(404, f"no batch with id {batch_id!r}")
        return out

    @router.get("/v1/batches/{batch_id}/results", response_class=Response, responses={
        200: {"description": "JSON Lines, one object per item in item order: {item, status, kind, name, engine, "
              "worker, attempts, summary | error, result} (kind: plan | contour; result: the plan result, as "
              "POST /v1/plan or POST /v1/contour); or the "
              "summary CSV (one row per item; units in the column names)",
              "content": {"application/x-ndjson": {"schema": {"type": "string"}},
                          "text/csv": {"schema": {"type": "string"}}}}, 404: errs[404], 422: errs[422]})
    def batch_results(batch_id: str, request: Request,
                      format: Literal["jsonl", "csv"] = Query("jsonl", description="'jsonl' (default) or 'csv' "
                                                              "(the summary)"),
                      wait: bool = Query(False, description="Stream every item as it finishes, until the batch "
                                         "ends (default: the items finished so far)")):
        """The batch's results, streamed in item order."""
        svc = _service(request.app)
        if format == "csv":
            rows = svc.summary_rows(batch_id)
            if rows is None:
                raise HTTPException(404, f"no batch with id {batch_id!r}")
            from .summary import header_line, row_line

            def csv_lines():
                yield header_line()
                for r in rows:
                    yield row_line(r)
            return StreamingResponse(csv_lines(), media_type="text/csv; charset=utf-8")
        lines = svc.results(batch_id, wait=wait)
        if lines is None:
            raise HTTPException(404, f"no batch with id {batch_id!r}")
        return StreamingResponse(lines, media_type="application/x-ndjson")

    @router.post("/v1/batches/{batch_id}/cancel", response_model=BatchProgress,
                 responses={404: errs[404], 422: errs[422]})
    def cancel_batch(batch_id: str, request: Request):
        """Cancel a batch: no further items start; the items that finished keep their results
        (``GET .../results``); the batch stays listed, ``state`` ``cancelled``."""
        out = _service(request.app).cancel(batch_id)
        if out is None:
            raise HTTPException(404, f"no batch with id {batch_id!r}")
        return out

    @router.delete("/v1/batches/{batch_id}", status_code=204, response_class=Response,
                   responses={204: {"description": "Deleted"}, 404: errs[404], 422: errs[422]})
    def delete_batch(batch_id: str, request: Request):
        """Delete a batch and its stored results; items still waiting or running are cancelled
        first. Keep the results with ``POST /v1/batches/{id}/cancel`` instead."""
        if not _service(request.app).delete(batch_id):
            raise HTTPException(404, f"no batch with id {batch_id!r}")
        return Response(status_code=204)

    return router
