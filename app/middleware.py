"""Request body size limit (before parsing): the one ASGI middleware of the API besides
access control (:mod:`app.security`)."""

from __future__ import annotations

from starlette.exceptions import HTTPException as StarletteHTTPException

from app.errors import error_response

__all__ = ["BodySizeLimit"]


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
