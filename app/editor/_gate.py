"""The access rules of :mod:`app.security` on the editor's port: every HTTP request and the
WebSocket handshake pass :func:`app.security.decide` before viser sees them (the Host
allow-list, the token or its cookie on every path, a login by ``?token=``, and no WebSocket
opened by a page of another origin).

viser (1.x) builds its websockets server inside :class:`viser.ViserServer` with a
``process_request`` hook of its own (it serves the client's files) and offers no way to add
one. :func:`start_guarded` therefore wraps ``websockets.asyncio.server.serve`` while a
viser server is being created, composing the rules in front of viser's hook, and restores
it right after (under a lock: editors are created one at a time). It fails closed: if no
server was started through the wrapper (a viser that no longer uses it), the editor is
stopped and :class:`RuntimeError` raised rather than serving without the rules.
"""

from __future__ import annotations

import http
import threading
from collections.abc import Callable
from typing import Any, TypeVar

import websockets.asyncio.server as ws_server
from websockets.datastructures import Headers
from websockets.http11 import Response

from app.security import AccessPolicy, Verdict, decide

__all__ = ["process_request", "start_guarded"]

_lock = threading.Lock()
T = TypeVar("T")

_LOGIN_PAGE = """<!doctype html><meta charset="utf-8"><title>rangeplan editor: sign in</title>
<body style="font-family: system-ui, sans-serif; max-width: 40rem; margin: 3rem auto">
<h1>rangeplan editor</h1><p>{message}.</p>
<p>Open the editor once with the server's token in the address:
<code>http://&lt;this host&gt;:&lt;port&gt;/?token=&lt;token&gt;</code>
(the token is then kept in a cookie and removed from the address).</p></body>"""


def _response(verdict: Verdict, websocket: bool) -> Response:
    if websocket or verdict.status not in (401,):
        body, ctype = verdict.json_body(), "application/json"
    else:
        body, ctype = _LOGIN_PAGE.format(message=verdict.message.split(":")[0]).encode(), "text/html; charset=utf-8"
    headers = Headers([("Content-Type", ctype), ("Content-Length", str(len(body))), *verdict.headers])
    return Response(verdict.status, http.HTTPStatus(verdict.status).phrase, headers, body)


def _closing(response: Response | None) -> Response | None:
    """``Connection: close`` on an HTTP response sent in place of a handshake: websockets closes
    the connection after it, and a client that was not told so sends its next request (the
    login's redirect, the page's assets) on the closed connection and fails."""
    if isinstance(response, Response) and "Connection" not in response.headers:
        response.headers["Connection"] = "close"
    return response


def process_request(policy: AccessPolicy, inner: Callable | None) -> Callable[[Any, Any], Any]:
    """A websockets ``process_request`` hook: the rules, then ``inner`` (viser's)."""

    def hook(connection, request):
        path, _, query = request.path.partition("?")
        headers = {k.lower(): v for k, v in request.headers.raw_items()}
        websocket = headers.get("upgrade", "").lower() == "websocket"
        verdict = decide(policy, path=path, query=query, headers=headers, protected=lambda p: True,
                         websocket=websocket, scheme="http")  # viser serves plain HTTP
        if verdict is not None:
            return _closing(_response(verdict, websocket))
        return _closing(inner(connection, request)) if inner is not None else None

    return hook


def start_guarded(policy: AccessPolicy, start: Callable[[], T]) -> T:
    """Call ``start()`` (which creates the editor and its viser server) with ``policy``
    applied to the viser server (see the module docstring). Fails closed: if no server was
    started through the hook, the editor is stopped and :class:`RuntimeError` raised."""
    original = ws_server.serve
    installed: list[bool] = []

    def serve(*args, **kwargs):
        kwargs["process_request"] = process_request(policy, kwargs.get("process_request"))
        installed.append(True)
        return original(*args, **kwargs)

    with _lock:
        ws_server.serve = serve  # type: ignore[assignment]
        try:
            editor = start()
        finally:
            ws_server.serve = original  # type: ignore[assignment]
    if not installed:
        stop = getattr(editor, "stop", None)
        if stop is not None:
            stop()
        raise RuntimeError("could not apply the access rules to the editor (this viser does not start its server "
                           "through websockets.asyncio.server.serve); refusing to serve it unprotected")
    return editor
