"""The one error shape of the HTTP API, ``{"error": {"code", "message", "field"}}``: its
models (for the OpenAPI document; :class:`ErrorDetail` is the job model's, :mod:`app.jobs`), the
response helper, and the status of each error code that is not a planner error (those answer 422)."""

from __future__ import annotations

from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel

from app.jobs import ErrorDetail
from planner.schema import error_details

__all__ = ["CODES_BY_STATUS", "RETRY_AFTER_BUSY_DOC", "ErrorDetail", "ErrorResponse", "error_response", "errors_doc",
           "validation_response"]

CODES_BY_STATUS = {400: "bad_request", 401: "unauthorized", 404: "not_found", 405: "method_not_allowed",
                   406: "not_acceptable", 409: "name_taken", 413: "too_large", 415: "unsupported_media_type",
                   422: "invalid_input", 503: "busy", 507: "storage_full"}

_DESCRIPTIONS = {400: "Bad request (e.g. a Host this server does not answer to)", 404: "Unknown id",
                 409: "Name already taken by another corridor", 413: "Body or stored object too large",
                 422: "Invalid input, too much work, or a planner error", 503: "Too many plans queued",
                 507: "The store is full", 500: "Internal error"}


#: the OpenAPI header of a busy answer (503)
RETRY_AFTER_BUSY_DOC = {"description": "Seconds until the first slot is expected to free (1-60): the least time left "
                        "of the work on the workers (each job's estimate less what it has run, or its measured time "
                        "per unit), 1 when unknown or when only the event loop's queue is full",
                        "schema": {"type": "integer", "minimum": 1, "maximum": 60}}


class ErrorResponse(BaseModel):
    error: ErrorDetail


def errors_doc(*statuses: int, descriptions: dict[int, str] | None = None) -> dict:
    """OpenAPI ``responses`` entries for these error statuses (``descriptions``: what a status
    means on these operations, where it says more than the service-wide text)."""
    texts = {**_DESCRIPTIONS, **(descriptions or {})}
    out: dict = {s: {"model": ErrorResponse, "description": texts.get(s, "Error")} for s in statuses}
    if 503 in out:
        out[503]["headers"] = {"Retry-After": RETRY_AFTER_BUSY_DOC}
    return out


def error_response(status: int, code: str, message: str, field: str | None = None,
                   details: list | None = None, headers: dict | None = None) -> JSONResponse:
    err = {"code": code, "message": message, "field": field}
    if details:
        err["details"] = details
    return JSONResponse({"error": err}, status_code=status, headers=headers)


def validation_response(exc: RequestValidationError) -> JSONResponse:
    """422 with the first failing field (planner.schema's paths: ``segments[3].lower``)."""
    details = error_details(exc.errors())
    first = details[0] if details else {"code": "invalid_input", "field": None, "message": "invalid input"}
    more = [{"field": d["field"], "message": d["message"]} for d in details] if len(details) > 1 else None
    return error_response(422, first["code"], first["message"], first["field"], more)
