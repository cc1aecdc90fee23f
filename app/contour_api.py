"""``POST /v1/contour``: contour a G-code program (issue 22; :mod:`planner.contour`).

An ``APIRouter`` included by :func:`app.api.create_app` (one line). The request body is the
schema's :class:`~planner.schema.ContourRequest`; the response the usual plan result (with its
``contour`` section) or ``?format=csv|gcode|joints|dxf``, stored like a plan (``GET
/v1/plans/{id}``). The program is read and its work estimated in the server process before a
worker is taken: a bad program or one over the compute limit is a 422 at once, naming the
line (field ``program``) and the cause; the body size limit bounds the program's text.
"""

from __future__ import annotations

import asyncio
from typing import Any

from fastapi import APIRouter, Query, Request
from fastapi.responses import Response

from app.errors import error_response, errors_doc
from app.http_exchange import FORMAT_HELP, PlanFormat, media_type, plan_content
from app.workers import describe_failure
from planner.errors import PlannerError
from planner.exchange import EXPORT_FORMATS
from planner.schema import ContourRequest, PlanResult

__all__ = ["router"]

router = APIRouter()
_FORMAT = Query(None, description=FORMAT_HELP)
_FORCES = Query(False, description="With format=joints: add the drive forces (N)")

_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {"model": PlanResult, "description": "The planned trajectory of the whole program with its `contour` "
          "section (JSON), or CSV, G-code, leg lengths or DXF with ?format=", "content": plan_content()},
    **errors_doc(413, 422, 503)}


@router.post("/v1/contour", tags=["planning"], response_class=Response, responses=_RESPONSES)
async def contour(body: ContourRequest, request: Request, format: PlanFormat | None = _FORMAT,
                  forces: bool = _FORCES):
    """Contour a G-code program (RS274NGC: G0 G1 G2 G3 G4 G17 G20 G21 G90 G91 G61 G64 P, F, S, T,
    M3/M5/M6): every cut pass within `tolerance_m` of the programmed path (each sample and the
    straight move to the next), `feed` `program` (never faster than F) or `fastest` (as the
    drives allow); `origin` places program zero in the robot frame (m)."""
    from planner.contour import estimate_contour
    from planner.exchange import read_gcode

    try:
        program = read_gcode(body.program, cut_below=body.cut_below_m, z_rapid_m_s=body.z_rapid_m_s)
        body.plan_settings()
        seconds, detail = estimate_contour(body, program)
    except PlannerError as exc:
        return error_response(422, exc.code, exc.message, exc.field)
    pool = request.app.state.pool
    if seconds > pool.timeout_s:
        return error_response(422, "too_much_work", f"this program needs an estimated {seconds:.3g} s of planning "
                              f"({detail}), more than this server's limit of {pool.timeout_s:g} s; split the "
                              "program, give a larger tolerance_m or settings.Ts, or feed 'program'", "program")
    fmt = format or ("csv" if "text/csv" in request.headers.get("accept", "") else "json")
    job = {"kind": "contour", "request": body, "format": fmt, "forces": forces, "source": "POST /v1/contour",
           "store": str(request.app.state.store.path)}
    loop = asyncio.get_running_loop()
    try:
        out: Any = await loop.run_in_executor(request.app.state.threads, pool.run, job)
    except Exception as exc:  # the pool's own failures: timeout, busy, memory, crashed worker
        status, e = describe_failure(exc, pool, "plan")
        return error_response(status, e["code"], e["message"], e["field"],
                              headers={"Retry-After": "1"} if status == 503 else None)
    if out[0] == "error":
        e = out[1]
        return error_response(422, e["code"], e["message"], e.get("field"))
    if out[0] == "crash":
        return error_response(500, "internal_error", "the planner failed unexpectedly: " + out[1].splitlines()[0])
    _, payload, meta = out
    headers = {}
    if meta.get("plan_id"):
        headers["Location"] = f"/v1/plans/{meta['plan_id']}"
        headers["X-Plan-Id"] = meta["plan_id"]
    if fmt not in ("json", "csv"):
        ext = EXPORT_FORMATS[fmt].extension
        headers["Content-Disposition"] = f'attachment; filename="contour-{meta.get("plan_id") or "result"}{ext}"'
    return Response(payload, media_type=media_type(fmt), headers=headers)
