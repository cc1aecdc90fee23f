"""The exception handlers of the HTTP API: every error answers the one body shape of
:mod:`app.errors` (validation 422 naming the field, HTTP errors with their code, quotas 409 /
413 / 507, planner errors 422, anything else 500 without a traceback)."""

from __future__ import annotations

import json

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.errors import CODES_BY_STATUS, error_response, validation_response
from app.json_limits import body_error_text
from app.storage import NameTaken, QuotaError, StoreFull, TooLarge
from planner.errors import PlannerError

__all__ = ["install_error_handlers"]


async def _on_validation(request: Request, exc: Exception):
    assert isinstance(exc, RequestValidationError)
    return validation_response(exc)


async def _on_http(request: Request, exc: Exception):
    assert isinstance(exc, StarletteHTTPException)
    if exc.status_code == 400 and exc.detail == "There was an error parsing the body":
        # FastAPI's answer to a body that is not UTF-8, nested too deep or with a too long
        # number: invalid JSON like any other, naming the limit it hit (app.json_limits)
        return error_response(422, "invalid_input", body_error_text(exc.__cause__))
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


async def _on_quota(request: Request, exc: Exception):
    if isinstance(exc, NameTaken):
        return error_response(409, "name_taken", str(exc), "name")
    if isinstance(exc, TooLarge):
        return error_response(413, "too_large", str(exc))
    assert isinstance(exc, StoreFull)
    return error_response(507, "storage_full", str(exc))


async def _on_planner(request: Request, exc: Exception):
    assert isinstance(exc, PlannerError)
    return error_response(422, exc.code, exc.message, exc.field)


async def _on_internal(request: Request, exc: Exception):
    return error_response(500, "internal_error", f"internal error: {type(exc).__name__}")


def install_error_handlers(app: FastAPI) -> None:
    app.add_exception_handler(RequestValidationError, _on_validation)
    app.add_exception_handler(StarletteHTTPException, _on_http)
    app.add_exception_handler(QuotaError, _on_quota)
    app.add_exception_handler(PlannerError, _on_planner)
    app.add_exception_handler(Exception, _on_internal)
