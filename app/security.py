"""Who may use the service and from where (issue 15): a token, a Host allow-list, origin
checks and CORS, the same rules on the API port and the editor port.

* **Token.** ``RANGEPLAN_API_TOKEN`` (or ``RANGEPLAN_API_TOKEN_FILE``, a file holding it:
  container secrets), at least 16 characters. When set, every ``/v1`` request needs
  ``Authorization: Bearer <token>`` (401 otherwise), and every request to the editor needs
  it too. A browser cannot set that header on a page load or a WebSocket, so a token in the
  first URL (``?token=...``) is exchanged for a cookie (HttpOnly, SameSite=Strict, derived
  from the token, not the token itself) and the browser is redirected to the same address
  without it. The cookie is good on both ports (cookies do not see ports); a request it
  authenticates must come from the same origin (or an allowed CORS origin).
* **Host allow-list.** The ``Host`` header must name this machine by a loopback name
  (``localhost``, ``127.0.0.1``, ``::1``), the address the server is bound to, or a name in
  ``RANGEPLAN_ALLOWED_HOSTS`` (comma-separated; ``.example.com`` allows its subdomains, ``*``
  any host): a page elsewhere that re-points its own name at this machine (DNS rebinding)
  is refused with 400. The header must be exactly a host and an optional port
  (:func:`parse_host`: ``[::1]evil.example``, ``localhost@evil.example`` or ``localhost:80x``
  are refused, not read as a loopback name). ``/health`` and ``/ready`` answer any Host
  (container and Kubernetes probes use the pod address) and show no stored data.
* **Origins.** The editor's WebSocket is refused (403) when the browser says it was opened
  by a page of another origin: scheme, host and port are compared (:func:`same_origin`,
  default ports filled in; ``null`` is another origin), so an ``https`` page cannot open the
  ``http`` editor's WebSocket. A request the session cookie authenticates obeys the same
  rule (or comes from a CORS origin). CORS: ``RANGEPLAN_CORS_ORIGINS`` (comma-separated origins,
  e.g. ``http://cad.example:3000``) may call the API from a browser, with preflight; none by
  default.

:func:`decide` holds the rules; :class:`AccessControl` applies them to the API (ASGI), the
editor applies them to viser's HTTP and WebSocket handshakes (:mod:`app.editor._gate`).
"""

from __future__ import annotations

import hashlib
import hmac
import ipaddress
import json
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from http.cookies import SimpleCookie
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qsl, quote, urlencode

if TYPE_CHECKING:
    from app.settings import Settings

__all__ = ["AccessPolicy", "AccessControl", "ConfigError", "Verdict", "decide", "host_name",
           "install_access_control", "is_loopback", "parse_host", "parse_origin", "protected_path", "same_origin",
           "LOOPBACK_HOSTS", "OPEN_PATHS", "TOKEN_COOKIE", "MIN_TOKEN_LENGTH"]

LOOPBACK_HOSTS = frozenset({"localhost", "127.0.0.1", "::1"})
#: answered for any Host and without a token (they show no data)
OPEN_PATHS = frozenset({"/health", "/ready"})
TOKEN_COOKIE = "rangeplan_session"
MIN_TOKEN_LENGTH = 16
_COOKIE_SALT = b"rangeplan session cookie v1"


class ConfigError(ValueError):
    """A security setting that cannot be used (the server refuses to start)."""


def is_loopback(host: str) -> bool:
    """Whether a bind address or host name stays on this machine."""
    host = host.strip("[]").lower()
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


#: the longest Host / Origin value looked at (a DNS name is at most 253 characters)
_MAX_HOST_LENGTH = 300
_PORT = re.compile(r"[0-9]{1,5}")
_LABEL = re.compile(r"[a-z0-9_~-]{1,63}")
_DEFAULT_PORTS = {"http": 80, "https": 443}


def parse_host(value: str | None) -> tuple[str, int | None] | None:
    """``(host, port)`` of a ``Host`` header (or an origin's authority), or None when it is
    not one exactly. RFC 3986 ``host [":" port]`` without userinfo: an IPv6 literal is
    ``[...]`` holding a valid address (no zone, no IPvFuture), written back compressed
    (``[0::1]`` -> ``::1``); a name or IPv4 address is ASCII ``unreserved`` characters in
    dot-separated labels of 1-63 (sub-delims and percent-encoding are reg-name syntax too,
    but no DNS name has them: refused), lower-cased, one trailing dot dropped (``localhost.``
    is ``localhost``, the same DNS name); the port is 1-5 ASCII digits up to 65535 (an empty
    one, ``localhost:``, is refused). Nothing may follow."""
    if not value or len(value) > _MAX_HOST_LENGTH or not value.isascii():
        return None
    if value.startswith("["):
        end = value.find("]")
        literal, rest = value[1:end], value[end + 1:]
        if end < 0 or "%" in literal or literal[:1] in ("v", "V"):
            return None
        try:
            host = ipaddress.IPv6Address(literal).compressed
        except ValueError:
            return None
    else:
        host, colon, port_text = value.partition(":")
        rest = colon + port_text
        host = host.lower()
        if host.endswith("."):
            host = host[:-1]
        if not all(_LABEL.fullmatch(label) for label in host.split(".")):
            return None
    if not rest:
        return host, None
    if rest[0] != ":" or not _PORT.fullmatch(rest[1:]) or int(rest[1:]) > 65535:
        return None
    return host, int(rest[1:])


def host_name(header: str | None) -> str | None:
    """The host name of a ``Host`` header (:func:`parse_host`), or None when it is not one."""
    parsed = parse_host(header)
    return parsed[0] if parsed else None


def parse_origin(value: str | None) -> tuple[str, str, int] | None:
    """``(scheme, host, port)`` of an ``Origin`` (``http`` or ``https``, the host as
    :func:`parse_host` reads it, the port with the scheme's default filled in), or None for
    anything else (``null``, a path, userinfo, another scheme)."""
    if not value:
        return None
    scheme, sep, authority = value.partition("://")
    scheme = scheme.lower()
    if not sep or scheme not in _DEFAULT_PORTS:
        return None
    parsed = parse_host(authority)
    if parsed is None:
        return None
    host, port = parsed
    return scheme, host, _DEFAULT_PORTS[scheme] if port is None else port


def _allowed_entry(entry: str) -> str:
    """An allow-list entry as :func:`parse_host` writes host names (``[::1]`` -> ``::1``)."""
    entry = entry.strip().lower()
    bare = entry[1:-1] if entry.startswith("[") and entry.endswith("]") else entry
    try:
        return ipaddress.ip_address(bare).compressed
    except ValueError:
        return entry[:-1] if entry.endswith(".") and len(entry) > 1 else entry


@dataclass(frozen=True)
class AccessPolicy:
    """The rules (module docstring). ``token`` None: no authentication."""

    token: str | None = None
    allowed_hosts: frozenset[str] = LOOPBACK_HOSTS
    cors_origins: tuple[str, ...] = ()
    cookie_value: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if self.token is not None and len(self.token) < MIN_TOKEN_LENGTH:
            raise ConfigError(f"the API token must be at least {MIN_TOKEN_LENGTH} characters (got {len(self.token)}); "
                              "make one with: python -c 'import secrets; print(secrets.token_urlsafe(32))'")
        if self.token is not None:
            derived = hmac.new(self.token.encode(), _COOKIE_SALT, hashlib.sha256).hexdigest()
            object.__setattr__(self, "cookie_value", derived)

    @classmethod
    def from_env(cls, environ: Mapping[str, str] | None = None, bind_host: str | None = None) -> AccessPolicy:
        """The policy of the settings (:func:`app.settings.settings` of the environment, or of
        ``environ``): ``RANGEPLAN_API_TOKEN`` / ``RANGEPLAN_API_TOKEN_FILE``,
        ``RANGEPLAN_ALLOWED_HOSTS`` and ``RANGEPLAN_CORS_ORIGINS``; ``bind_host`` (the
        server's address, unless a wildcard) is allowed as a Host too. Raises
        :class:`ConfigError`."""
        from app.settings import SettingsError, settings

        try:
            cfg = settings(environ)
        except SettingsError as exc:
            raise ConfigError(str(exc)) from None
        return cls.from_settings(cfg, bind_host)

    @classmethod
    def from_settings(cls, cfg: Settings, bind_host: str | None = None) -> AccessPolicy:
        """The policy of the settings object ``cfg`` (see :meth:`from_env`)."""
        token = cfg.api_token or None
        path = cfg.api_token_file
        if path:
            if token:
                raise ConfigError("set RANGEPLAN_API_TOKEN or RANGEPLAN_API_TOKEN_FILE, not both")
            try:
                token = Path(path).read_text().strip()
            except OSError as exc:
                raise ConfigError(f"RANGEPLAN_API_TOKEN_FILE: cannot read {path}: {exc.strerror or exc}") from None
            if not token:
                raise ConfigError(f"RANGEPLAN_API_TOKEN_FILE: {path} is empty")
        hosts = set(LOOPBACK_HOSTS)
        hosts |= {_allowed_entry(h) for h in cfg.allowed_hosts.split(",") if h.strip()}
        if bind_host and bind_host not in ("0.0.0.0", "::", ""):
            hosts.add(_allowed_entry(bind_host))
        origins = []
        for o in (o.strip().rstrip("/") for o in cfg.cors_origins.split(",")):
            if not o:
                continue
            if o != "*" and parse_origin(o) is None:
                raise ConfigError(f"RANGEPLAN_CORS_ORIGINS: {o!r} is not an origin (scheme://host[:port])")
            origins.append(o)
        return cls(token=token, allowed_hosts=frozenset(hosts), cors_origins=tuple(origins))

    @property
    def auth_required(self) -> bool:
        return self.token is not None

    def host_allowed(self, header: str | None) -> bool:
        """Whether a ``Host`` header is exactly one (:func:`parse_host`) naming an allowed host."""
        name = host_name(header)
        if name is None:
            return False
        if "*" in self.allowed_hosts or name in self.allowed_hosts:
            return True
        return any(p.startswith(".") and (name.endswith(p) or name == p[1:]) for p in self.allowed_hosts)

    def cors_allowed(self, origin: str) -> bool:
        """Whether ``origin`` is one of the CORS origins (scheme, host and port compared)."""
        parsed = parse_origin(origin)
        return parsed is not None and any(parse_origin(o) == parsed for o in self.cors_origins)

    def token_ok(self, presented: str | None) -> bool:
        return bool(self.token and presented and hmac.compare_digest(presented.encode(), self.token.encode()))

    def cookie_ok(self, presented: str | None) -> bool:
        return bool(self.cookie_value and presented and hmac.compare_digest(presented.encode(),
                                                                             self.cookie_value.encode()))


@dataclass(frozen=True)
class Verdict:
    """A refusal (``status`` >= 400) or a login redirect (303) instead of the request."""

    status: int
    code: str
    message: str
    headers: tuple[tuple[str, str], ...] = ()

    def json_body(self) -> bytes:
        return json.dumps({"error": {"code": self.code, "message": self.message, "field": None}}).encode()


def _cookie(headers: Mapping[str, str]) -> str | None:
    raw = headers.get("cookie")
    if not raw:
        return None
    jar: SimpleCookie = SimpleCookie()
    try:
        jar.load(raw)
    except Exception:
        return None
    morsel = jar.get(TOKEN_COOKIE)
    return morsel.value if morsel else None


def same_origin(origin: str, host: str | None, scheme: str) -> bool:
    """Whether the ``Origin`` header ``origin`` is the origin of a request to ``host`` (its
    ``Host`` header) over ``scheme`` (``http``, ``https``): scheme, host and port compared,
    default ports filled in."""
    mine = parse_host(host)
    theirs = parse_origin(origin)
    if mine is None or theirs is None or scheme not in _DEFAULT_PORTS:
        return False
    return theirs == (scheme, mine[0], _DEFAULT_PORTS[scheme] if mine[1] is None else mine[1])


def local_location(path: str) -> str:
    """A ``Location`` for a request path that stays on this server: one leading slash (a
    path ``//evil.example/`` or ``/\\evil.example`` is a network-path reference to another
    host in a browser), percent-encoded (no control characters in the header)."""
    return "/" + quote(path.lstrip("/\\"), safe="/!$&'()*+,;=:@")


def decide(policy: AccessPolicy, *, path: str, query: str, headers: Mapping[str, str],
           protected: Callable[[str], bool], websocket: bool = False, scheme: str = "http") -> Verdict | None:
    """Apply the rules to one request (``headers`` with lower-case names, ``scheme`` the
    request's: ``http`` or ``https``); None lets it through. ``protected(path)``: whether
    the path needs the token."""
    if path in OPEN_PATHS and not websocket:
        return None
    host = headers.get("host")
    if not policy.host_allowed(host):
        return Verdict(400, "invalid_host", f"this server does not answer to the host {host_name(host)!r}; add it "
                       "to RANGEPLAN_ALLOWED_HOSTS if it is this machine's name")
    origin = headers.get("origin")
    if websocket and origin and not same_origin(origin, host, scheme):
        return Verdict(403, "forbidden_origin", f"a WebSocket opened by a page of {origin} is refused: only pages "
                       "of this server may connect")
    if "token=" in query:
        pairs = parse_qsl(query, keep_blank_values=True)
        given = [v for k, v in pairs if k == "token"]
        if given:
            if policy.auth_required and not policy.token_ok(given[-1]):
                return Verdict(401, "unauthorized", "the token in the address is not this server's token",
                               (("www-authenticate", 'Bearer realm="rangeplan"'),))
            rest = urlencode([(k, v) for k, v in pairs if k != "token"])
            hdrs: list[tuple[str, str]] = [("location", local_location(path) + (f"?{rest}" if rest else "")),
                                           ("cache-control", "no-store"), ("referrer-policy", "no-referrer")]
            if policy.auth_required:
                hdrs.append(("set-cookie", f"{TOKEN_COOKIE}={policy.cookie_value}; HttpOnly; SameSite=Strict; "
                             "Path=/"))
            return Verdict(303, "login", "signed in; continue at the address without the token", tuple(hdrs))
    if not policy.auth_required or not protected(path):
        return None
    auth = headers.get("authorization", "")
    kind, _, presented = auth.partition(" ")
    if kind.lower() == "bearer" and policy.token_ok(presented.strip()):
        return None
    if policy.cookie_ok(_cookie(headers)):
        if origin and not same_origin(origin, host, scheme) and not policy.cors_allowed(origin):
            return Verdict(403, "forbidden_origin", f"a request from a page of {origin} cannot use this server's "
                           "session cookie; send the token as Authorization: Bearer")
        return None
    reason = "the token is wrong" if auth else "this server needs a token"
    return Verdict(401, "unauthorized", f"{reason}: send Authorization: Bearer <token> (RANGEPLAN_API_TOKEN), or "
                   "open a page once with ?token=<token> in its address",
                   (("www-authenticate", 'Bearer realm="rangeplan"'),))


def protected_path(path: str) -> bool:
    """Whether an API path needs the token: ``/v1`` and below, and ``/metrics``."""
    return path == "/v1" or path.startswith("/v1/") or path == "/metrics"


class AccessControl:
    """ASGI middleware applying :func:`decide` to the API: the token on ``/v1`` paths."""

    def __init__(self, app, policy: AccessPolicy, protected: Callable[[str], bool] | None = None):
        self.app, self.policy = app, policy
        self.protected = protected or protected_path

    async def __call__(self, scope, receive, send):
        if scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", ())}
        query = scope.get("query_string", b"").decode("latin-1")
        scheme = str(scope.get("scheme") or "http")
        scheme = {"ws": "http", "wss": "https"}.get(scheme, scheme)
        verdict = decide(self.policy, path=scope.get("path", ""), query=query, headers=headers,
                         protected=self.protected, websocket=scope["type"] == "websocket", scheme=scheme)
        if verdict is None:
            return await self.app(scope, receive, send)
        if scope["type"] == "websocket":
            return await send({"type": "websocket.close", "code": 1008})
        body = verdict.json_body()
        out = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]
        out += [(k.encode(), v.encode()) for k, v in verdict.headers]
        await send({"type": "http.response.start", "status": verdict.status, "headers": out})
        await send({"type": "http.response.body", "body": body})


def install_access_control(app: Any, policy: AccessPolicy) -> None:
    """Add to a FastAPI ``app``: the access rules, CORS (outermost, so that preflights are
    answered before authentication) and, with a token, the bearer scheme in the OpenAPI
    document (``/v1`` operations, with their 401). Call after the app's other middleware."""
    app.add_middleware(AccessControl, policy=policy)
    if policy.cors_origins:
        from starlette.middleware.cors import CORSMiddleware

        app.add_middleware(CORSMiddleware, allow_origins=list(policy.cors_origins),
                           allow_methods=["GET", "POST", "PUT", "DELETE"],
                           allow_headers=["Authorization", "Content-Type", "Accept", "Prefer"],
                           expose_headers=["Location", "X-Plan-Id", "Retry-After", "Preference-Applied"], max_age=600)
    if policy.auth_required:
        _document_bearer(app)


def _document_bearer(app: Any) -> None:
    base = app.openapi

    def openapi() -> dict:
        if app.openapi_schema is not None:
            return app.openapi_schema
        schema = base()
        schema.setdefault("components", {}).setdefault("securitySchemes", {})["bearerAuth"] = {
            "type": "http", "scheme": "bearer",
            "description": "The server's token (RANGEPLAN_API_TOKEN): Authorization: Bearer <token>"}
        for path, ops in schema.get("paths", {}).items():
            if path == "/v1" or path.startswith("/v1/"):
                for op in ops.values():
                    if isinstance(op, dict) and "responses" in op:
                        op["security"] = [{"bearerAuth": []}]
                        error = {"schema": {"$ref": "#/components/schemas/ErrorResponse"}}
                        op["responses"].setdefault("401", {"description": "No token or a wrong one",
                                                           "content": {"application/json": error}})
        app.openapi_schema = schema
        return schema

    app.openapi = openapi
