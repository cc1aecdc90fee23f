"""What the routers share: the app's store and job service, the output format of a request,
and the one translation of a job's outcome into an HTTP response."""

from __future__ import annotations

import os
import time

from fastapi import Query, Request
from fastapi.responses import FileResponse, Response
from starlette.background import BackgroundTask

from app import storage_io
from app.errors import error_response
from app.formats import OUTPUT_FORMATS, format_help
from app.job_progress import first_free, retry_after
from app.jobs import Failed, Job, Outcome
from app.observability import observe_job
from app.service import JobService
from app.storage import Store

__all__ = ["Forces", "Format", "attachment", "busy_retry_after", "media_type", "outcome_response", "plan_format",
           "respond", "service", "store", "submit"]

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


def outcome_response(outcome: Outcome, fmt: str = "json", name: str | None = None, retry_s: int = 1) -> Response:
    """The HTTP answer of a job's outcome: its error (with ``Retry-After: retry_s`` when busy),
    or its bytes (or spool file, streamed and then deleted) with the new plan's address headers
    and, for a machine format, the attachment's name (``name``: a stored plan's id)."""
    if isinstance(outcome, Failed):
        e = outcome.error
        return error_response(outcome.status, e.code, e.message, e.field,
                              headers={"Retry-After": str(retry_s)} if outcome.status == 503 else None)
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


async def busy_retry_after(request: Request) -> int:
    """The ``Retry-After`` [s] of a busy answer (503): when the first slot is expected to free,
    the least time left of the running jobs (their rows, read off the event loop) and of the
    synchronous requests on the workers (:func:`app.job_progress.first_free`), within 1-60 s."""
    rows = await storage_io.read(store(request).unfinished_jobs)
    return retry_after(first_free(rows, time.time(), service(request).sync_left()))


async def submit(request: Request, job: Job, fmt: str = "json", name: str | None = None) -> Response:
    """Run ``job`` on the app's job service and answer its outcome (counted in the metrics; a
    busy answer says when to come back: :func:`busy_retry_after`)."""
    t0 = time.perf_counter()
    outcome = await service(request).arun(job)
    observe_job(request.app, job, time.perf_counter() - t0, outcome)
    return await respond(request, outcome, fmt, name)


async def respond(request: Request, outcome: Outcome, fmt: str = "json", name: str | None = None) -> Response:
    """:func:`outcome_response`, with a busy answer's ``Retry-After`` from the work under way."""
    busy = isinstance(outcome, Failed) and outcome.status == 503
    return outcome_response(outcome, fmt, name, await busy_retry_after(request) if busy else 1)
