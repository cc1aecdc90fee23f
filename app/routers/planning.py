"""Planning: ``POST /v1/plan``, ``POST /v1/import``, ``POST /v1/segment`` and
``GET /v1/plans/{id}`` (a stored plan again, in any output format: a spool file the server
streams and then deletes; an export job on a worker writes it, JSON is the stored text
copied as it is on the store's read threads)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import Response
from pydantic import ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException

from app import storage_io
from app.errors import error_response, errors_doc
from app.formats import PlanFormat
from app.http_exchange import import_openapi, import_options, plan_content, read_drawing
from app.jobs import ExportJob, ImportJob, PlanJob, SegmentJob, spool_dir, spool_plan_json
from app.routers.deps import Forces, Format, outcome_response, plan_format, store, submit
from app.routers.jobs import ACCEPTED_DOC, PREFER, run_as_job
from planner.schema import ImportOptions, ImportResult, PlanRequest, PlanResult, SegmentationResult, planner_error

__all__ = ["PLAN_RESPONSES", "plan_response", "router"]

router = APIRouter(tags=["planning"])

_PLAN_HEADERS = {"Location": {"description": "GET this to fetch the result again (absent if not stored)",
                              "schema": {"type": "string"}},
                 "X-Plan-Id": {"description": "The plan's id (absent if not stored)", "schema": {"type": "string"}}}
PLAN_RESPONSES = {200: {"model": PlanResult, "description": "The planned trajectory (JSON, or CSV with a "
                        "header naming each column with its unit)",
                        "content": plan_content(), "headers": _PLAN_HEADERS,
                        "links": {"GetPlan": {"operationId": "get_plan",
                                              "parameters": {"plan_id": "$response.header.X-Plan-Id"}}}},
                  **errors_doc(413, 422, 503)}


async def plan_response(request: Request, req: PlanRequest, fmt: str | None, corridor_id: str | None = None,
                        forces: bool = False, as_job: bool = False) -> Response:
    """Plan ``req`` on a worker (stored, linked to ``corridor_id``) and answer in ``fmt``
    (``as_job``: or as a job, 202, when long or asked: :func:`app.routers.jobs.run_as_job`)."""
    fmt = plan_format(request, fmt)
    job = PlanJob(req, fmt, forces, source=f"corridor {corridor_id}" if corridor_id else "POST /v1/plan",
                  store=str(store(request).path), corridor_id=corridor_id)
    if as_job:
        return await run_as_job(request, job, fmt)
    return await submit(request, job, fmt)


@router.post("/v1/plan", response_class=Response, responses={**PLAN_RESPONSES, **ACCEPTED_DOC})
async def plan(body: PlanRequest, request: Request, format: PlanFormat | None = Format, forces: bool = Forces,
               prefer: str | None = PREFER):
    """Plan a trajectory for a corridor (``segments``), a reference or a ``layout``.
    The result is stored: fetch it again at ``GET /v1/plans/{plan_id}``. A long plan (work
    estimate over RANGEPLAN_ASYNC_AFTER_S, or `Prefer: respond-async`) is answered 202
    Accepted with a job (`Location: /v1/jobs/{id}`)."""
    return await plan_response(request, body, format, forces=forces, as_job=True)


@router.post("/v1/import", response_class=Response, openapi_extra=import_openapi(),
             responses={200: {"model": ImportResult, "description": "The drawing as a layout (m, rad) and a "
                              "report of the shapes used, holes, pieces left open and the units applied"},
                        **errors_doc(413, 415, 422, 503)})
async def import_drawing(request: Request):
    """Read a DXF or SVG drawing (the body, or a multipart file upload): its closed shapes
    become a layout's obstacles, placed by the query parameters (units, layers, offset [m],
    rotation [rad], scale, tolerances [m], margin [m], bounds_layer, start, end)."""
    try:
        options = ImportOptions.model_validate(import_options(request))
    except ValidationError as exc:
        raise planner_error(exc) from None
    data, filename, content_type = await read_drawing(request)
    return await submit(request, ImportJob(data, options, filename, content_type))


@router.post("/v1/segment", response_class=Response,
             responses={200: {"model": SegmentationResult, "description": "Cells and corridor"},
                        **errors_doc(413, 422, 503)})
async def segment(body: PlanRequest, request: Request):
    """Segment a ``layout`` (workspace with obstacles) into cells and a corridor, without planning."""
    if body.layout is None:
        return error_response(422, "invalid_input", "a segmentation request needs a layout", "layout")
    return await submit(request, SegmentJob(body))


@router.get("/v1/plans/{plan_id}", response_class=Response, operation_id="get_plan", responses={
    200: {k: v for k, v in PLAN_RESPONSES[200].items() if k not in ("links", "headers")}, **errors_doc(404)})
async def get_plan(plan_id: str, request: Request, format: PlanFormat | None = Format, forces: bool = Forces):
    """A stored plan result (the newest plans are kept; see RANGEPLAN_MAX_PLANS)."""
    st = store(request)
    fmt = plan_format(request, format)
    if fmt == "json":  # the stored form: copied as it is, never parsed nor held whole
        return outcome_response(await storage_io.read(spool_plan_json, st, plan_id, spool_dir(st.path)), fmt)
    if not await storage_io.read(st.has_plan, plan_id):
        raise StarletteHTTPException(404, f"no plan with id {plan_id!r}")
    job = ExportJob(plan_id, str(st.path), fmt, forces, spool_dir(st.path))
    return await submit(request, job, fmt, name=plan_id)
