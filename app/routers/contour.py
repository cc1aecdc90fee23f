"""``POST /v1/contour``: contour a G-code program (issue 22; :mod:`planner.contour`).

An ``APIRouter`` included by :func:`app.api.create_app`. The request body is the schema's
:class:`~planner.schema.ContourRequest`; the response the usual plan result (with its
``contour`` section) or ``?format=csv|gcode|joints|dxf``, stored like a plan (``GET
/v1/plans/{id}``). The handler only validates the body: a worker of the synchronous lane
reads the program, never the server process (a program of tens of thousands of lines takes
seconds and ~90 MB to read), under the synchronous time limit and the memory cap, and
estimates it before anything is queued: a bad program is a 422 naming the line (field
``program``) and the cause, one whose work estimate exceeds the jobs' compute limit is refused
(``too_much_work``) before it is planned, a short one is planned on that worker (read once);
the body size limit bounds the program's text (413), and so the read and the estimate (6 CPU
s at the cap: benchmarks/bench_contour_lanes.py). A long program is a job
(:mod:`app.routers.jobs`): 202 Accepted with its estimate, its progress, then its result.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import Response

from app.errors import errors_doc
from app.formats import PlanFormat
from app.http_exchange import plan_content
from app.jobs import ContourJob
from app.routers.deps import Forces, Format, plan_format, store
from app.routers.jobs import ACCEPTED_DOC, PREFER, run_as_job
from planner.schema import ContourRequest, PlanResult

__all__ = ["router"]

router = APIRouter(tags=["planning"])

_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {"model": PlanResult, "description": "The planned trajectory of the whole program with its `contour` "
          "section (JSON), or CSV, G-code, leg lengths or DXF with ?format=", "content": plan_content()},
    **ACCEPTED_DOC, **errors_doc(413, 422, 503)}


@router.post("/v1/contour", response_class=Response, responses=_RESPONSES)
async def contour(body: ContourRequest, request: Request, format: PlanFormat | None = Format,
                  forces: bool = Forces, prefer: str | None = PREFER):
    """Contour a G-code program (RS274NGC: G0 G1 G2 G3 G4 G17 G20 G21 G90 G91 G61 G64 P, F, S, T,
    M3/M5/M6): every cut pass within `tolerance_m` of the programmed path (each sample and the
    straight move to the next), `feed` `program` (never faster than F) or `fastest` (as the
    drives allow); `origin` places program zero in the robot frame (m). Stored like a plan.
    A long program (work estimate over RANGEPLAN_ASYNC_AFTER_S, or `Prefer: respond-async`) is
    answered 202 Accepted with a job (`Location: /v1/jobs/{id}`: progress in cut passes, time
    left, then the stored plan's URL)."""
    fmt = plan_format(request, format)
    job = ContourJob(body, fmt, forces, source="POST /v1/contour", store=str(store(request).path))
    return await run_as_job(request, job, fmt)
