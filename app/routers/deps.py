"""What the routers share: the app's store and job service, the output format of a request,
and the one translation of a job's outcome into an HTTP response."""

from __future__ import annotations

import os
import time

from fastapi import Query, Request
from fastapi.responses import FileResponse, Response
from starlette.background import BackgroundTask

from app.errors import error_response
from app.formats import OUTPUT_FORMATS, format_help
from app.jobs import Failed, Job, Outcome
from app.observability import observe_job
from app.service import JobService
from app.storage import Store

__all__ = ["Forces", "Format", "attachment", "media_type", "outcome_response", "plan_format", "service", "store",
           "submit"]

Format = Query(None, description=format_help())
Forces = Query(False, description="With format=joints: add one drive-force column per leg (N)")


def store(request: Request) -> Store:
    return request.app.state.store


def service(request: Request) -> JobService:
    """The app's job service (started at lifespan startup, or on first use by a server that
    runs no lifespan, e.g. some ASGI test transports)."""
    return request.app.state.ensure_service()


def media_type(fmt: str) -> str:
    """The response media type of an output format."""
    spec = OUTPUT_FORMATS.get(fmt)
    return spec.media_type if spec is not None else "application/json"


def attachment(plan_id: str | None, fmt: str) -> str:
    return f'attachment; filename="plan-{plan_id or "result"}{OUTPUT_FORMATS[fmt].extension}"'


def plan_format(request: Request, fmt: str | None) -> str:
    """``?format=``, else CSV when the Accept header asks for it (and not JSON), else JSON."""
    if fmt is not None:
        return fmt
    accept = request.headers.get("accept", "")
    return "csv" if "text/csv" in accept and "application/json" not in accept else "json"


def outcome_response(outcome: Outcome, fmt: str = "json", name: str | None = None) -> Response:
    """The HTTP answer of a job's outcome: its error (with ``Retry-After`` when busy), or its
    bytes (or spool file, streamed and then deleted) with the new plan's address headers
    and, for a machine format, the attachment's name (``name``: a stored plan's id)."""
    if isinstance(outcome, Failed):
        e = outcome.error
        return error_response(outcome.status, e.code, e.message, e.field,
                              headers={"Retry-After": "1"} if outcome.status == 503 else None)
    headers = {}
    if outcome.plan_id:
        headers["Location"] = f"/v1/plans/{outcome.plan_id}"
        headers["X-Plan-Id"] = outcome.plan_id
    spec = OUTPUT_FORMATS.get(fmt)
    if spec is not None and spec.machine:
        headers["Content-Disposition"] = attachment(name or outcome.plan_id, fmt)
    if outcome.path is not None:
        return FileResponse(outcome.path, media_type=media_type(fmt), headers=headers,
                            background=BackgroundTask(_unlink, outcome.path))
    return Response(outcome.payload or b"", media_type=media_type(fmt), headers=headers)


def _unlink(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


async def submit(request: Request, job: Job, fmt: str = "json", name: str | None = None) -> Response:
    """Run ``job`` on the app's job service and answer its outcome (counted in the metrics)."""
    t0 = time.perf_counter()
    outcome = await service(request).arun(job)
    observe_job(request.app, job, time.perf_counter() - t0, outcome)
    return outcome_response(outcome, fmt, name)
