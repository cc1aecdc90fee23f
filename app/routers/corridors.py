"""Saved corridors: ``POST/GET /v1/corridors``, ``GET/PUT/DELETE /v1/corridors/{id}`` and
``POST /v1/corridors/{id}/plan``. The store is read and written on executors of its own
(:mod:`app.storage_io`), never on the shared thread pool."""

from __future__ import annotations

import orjson
from fastapi import APIRouter, Query, Request
from fastapi.responses import Response
from pydantic import BaseModel, Field, ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException

from app import storage_io
from app.errors import error_response, errors_doc
from app.formats import PlanFormat
from app.routers.deps import Forces, Format, store
from app.routers.planning import PLAN_RESPONSES, plan_response
from app.storage import CURSOR_PATTERN, DEFAULT_PAGE_SIZE, MAX_PAGE_SIZE, BadCursor, Store, StoreBusy
from planner.schema import CorridorRecord, PlanRequest, error_details

__all__ = ["CorridorPageModel", "CorridorSummaryModel", "router"]

router = APIRouter(tags=["corridors"])


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


_CORRIDOR_LINKS = {name: {"operationId": op, "parameters": {"corridor_id": "$response.body#/id"}}
                   for name, op in (("GetCorridor", "get_corridor"), ("UpdateCorridor", "update_corridor"),
                                    ("DeleteCorridor", "delete_corridor"), ("PlanCorridor", "plan_corridor"))}


def _saved(body: PlanRequest) -> dict:
    """What storage keeps: the request as the client sent it (validated exactly as for planning)."""
    return body.to_json_dict()


async def _get_or_404(st: Store, corridor_id: str) -> dict:
    rec = await storage_io.read(st.get_corridor, corridor_id)
    if rec is None:
        raise StarletteHTTPException(404, f"no corridor with id {corridor_id!r}")
    return rec


@router.post("/v1/corridors", status_code=201, response_model=CorridorRecord, response_model_exclude_unset=True,
             operation_id="create_corridor",
             responses={201: {"description": "The saved corridor", "links": _CORRIDOR_LINKS,
                              "headers": {"Location": {"description": "The corridor's address",
                                                       "schema": {"type": "string"}}}},
                        **errors_doc(409, 413, 422, 507)})
async def create_corridor(body: PlanRequest, request: Request, response: Response):
    """Save a plan request as a corridor; its name is the request's ``name``, unique among
    corridors (409 if another has it: replace that one with PUT)."""
    rec = await storage_io.write(store(request).create_corridor, _saved(body), body.name)
    response.headers["Location"] = f"/v1/corridors/{rec['id']}"
    return rec


@router.get("/v1/corridors", response_model=CorridorPageModel, operation_id="list_corridors",
            responses={200: {"description": "A page of corridors", "links": {"NextPage": {
                "operationId": "list_corridors", "parameters": {"cursor": "$response.body#/next_cursor"}}}},
                       **errors_doc(422)})
async def list_corridors(request: Request,
                   limit: int = Query(DEFAULT_PAGE_SIZE, ge=1, le=MAX_PAGE_SIZE, description="Corridors per page"),
                   cursor: str | None = Query(None, pattern=CURSOR_PATTERN,
                                              description="next_cursor of the previous page")):
    """Saved corridors a page at a time, oldest first, as summaries."""
    # A page is read here, on the event loop, from its read-only connection: a bounded read of
    # the primary key's index (<= MAX_PAGE_SIZE summaries, no requests), far shorter than
    # handing it to a read thread and waiting for the GIL to come back (under 200 clients a
    # handoff cost the loop ~5 ms: benchmarks/README.md). Locked: on the read threads.
    st = store(request)
    try:
        try:
            items, nxt = st.corridor_page(limit, cursor, quick=True)
        except StoreBusy:
            items, nxt = await storage_io.read(st.corridor_page, limit, cursor)
    except BadCursor as exc:
        return error_response(422, "invalid_input", str(exc), "cursor")
    # the summaries are the model's fields as the store made them: sent as they are
    return Response(orjson.dumps({"items": items, "next_cursor": nxt}), media_type="application/json")


@router.get("/v1/corridors/{corridor_id}", response_model=CorridorRecord, response_model_exclude_unset=True,
            operation_id="get_corridor", responses=errors_doc(404))
async def get_corridor(corridor_id: str, request: Request):
    return await _get_or_404(store(request), corridor_id)


@router.put("/v1/corridors/{corridor_id}", response_model=CorridorRecord, response_model_exclude_unset=True,
            operation_id="update_corridor", responses=errors_doc(404, 409, 413, 422, 507))
async def update_corridor(corridor_id: str, body: PlanRequest, request: Request):
    """Replace a saved corridor's request (and name: 409 if another corridor has it)."""
    rec = await storage_io.write(store(request).update_corridor, corridor_id, _saved(body), body.name)
    if rec is None:
        raise StarletteHTTPException(404, f"no corridor with id {corridor_id!r}")
    return rec


@router.delete("/v1/corridors/{corridor_id}", status_code=204, response_class=Response,
               operation_id="delete_corridor", responses=errors_doc(404))
async def delete_corridor(corridor_id: str, request: Request):
    if not await storage_io.write(store(request).delete_corridor, corridor_id):
        raise StarletteHTTPException(404, f"no corridor with id {corridor_id!r}")
    return Response(status_code=204)


@router.post("/v1/corridors/{corridor_id}/plan", response_class=Response, operation_id="plan_corridor",
             responses={**PLAN_RESPONSES, **errors_doc(404)})
async def plan_corridor(corridor_id: str, request: Request, format: PlanFormat | None = Format,
                        forces: bool = Forces):
    """Plan a saved corridor; the result is stored with a link to the corridor."""
    rec = await storage_io.read(store(request).get_corridor, corridor_id)
    if rec is None:
        raise StarletteHTTPException(404, f"no corridor with id {corridor_id!r}")
    try:
        model = PlanRequest.model_validate(rec["request"])
    except ValidationError as exc:
        e = error_details(exc.errors())[0]
        return error_response(422, e["code"], "the saved corridor is not a valid plan request: "
                              + e["message"], e["field"])
    return await plan_response(request, model, format, corridor_id, forces)
