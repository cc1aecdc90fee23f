"""Access control (issue 15): the token on /v1 and on the editor, the Host allow-list on both
ports, the editor's WebSocket Origin check, CORS with preflight, the cookie login, and
`rangeplan serve` refusing an open non-loopback bind."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
import viser
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from app.api import create_app
from app.editor import start_editor, start_guarded
from app.security import TOKEN_COOKIE, AccessPolicy, ConfigError, host_name, is_loopback, same_origin
from app.storage import Store
from tests.support import api_client

ROOT = Path(__file__).resolve().parent.parent
TABLE1 = json.loads((ROOT / "app" / "static" / "examples" / "table1.json").read_text())
TOKEN = "s3cret-token-for-the-tests-0123456789"
BEARER = {"Authorization": f"Bearer {TOKEN}"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# ---------------------------------------------------------------------------------------
# the policy

def test_policy_from_environment(tmp_path):
    p = AccessPolicy.from_env({"RANGEPLAN_ALLOWED_HOSTS": "cad.factory.local, .plant.example",
                               "RANGEPLAN_CORS_ORIGINS": "http://cad.factory.local:3000"}, bind_host="10.0.0.5")
    assert not p.auth_required
    for ok in ("localhost:8000", "127.0.0.1", "[::1]:8080", "cad.factory.local:8000", "a.plant.example",
               "plant.example", "10.0.0.5:8000", "LOCALHOST"):
        assert p.host_allowed(ok), ok
    for bad in ("evil.example", "plant.example.evil.com", "", None, "10.0.0.6"):
        assert not p.host_allowed(bad), bad
    assert p.cors_origins == ("http://cad.factory.local:3000",)
    assert AccessPolicy.from_env({}, bind_host="0.0.0.0").allowed_hosts == {"localhost", "127.0.0.1", "::1"}
    f = tmp_path / "token"
    f.write_text(TOKEN + "\n")
    assert AccessPolicy.from_env({"RANGEPLAN_API_TOKEN_FILE": str(f)}).token == TOKEN
    with pytest.raises(ConfigError, match="at least 16"):
        AccessPolicy.from_env({"RANGEPLAN_API_TOKEN": "short"})
    with pytest.raises(ConfigError, match="not both"):
        AccessPolicy.from_env({"RANGEPLAN_API_TOKEN": TOKEN, "RANGEPLAN_API_TOKEN_FILE": str(f)})
    with pytest.raises(ConfigError, match="cannot read"):
        AccessPolicy.from_env({"RANGEPLAN_API_TOKEN_FILE": str(tmp_path / "missing")})
    with pytest.raises(ConfigError, match="not an origin"):
        AccessPolicy.from_env({"RANGEPLAN_CORS_ORIGINS": "cad.factory.local"})
    assert host_name("[::1]:8000") == "::1" and host_name("Example.COM.:80") == "example.com"
    assert is_loopback("127.0.0.2") and is_loopback("::1") and not is_loopback("0.0.0.0")


# ---------------------------------------------------------------------------------------
# the API

@pytest.fixture(scope="module")
def secured(tmp_path_factory):
    policy = AccessPolicy(token=TOKEN, allowed_hosts=frozenset({"localhost", "127.0.0.1", "::1", "cad.local"}),
                          cors_origins=("http://cad.local:3000",))
    app = create_app(Store(tmp_path_factory.mktemp("sec")), workers=1, timeout_s=30, access=policy)
    with api_client(app) as c:
        yield c


def test_every_v1_endpoint_needs_the_token(secured):
    paths = [("GET", "/v1/robots"), ("GET", "/v1/robots/moving-slide"), ("POST", "/v1/plan"),
             ("POST", "/v1/segment"), ("GET", "/v1/corridors"), ("POST", "/v1/corridors"),
             ("GET", "/v1/corridors/x"), ("PUT", "/v1/corridors/x"), ("DELETE", "/v1/corridors/x"),
             ("POST", "/v1/corridors/x/plan"), ("GET", "/v1/plans/x")]
    for method, path in paths:
        for headers in ({}, {"Authorization": "Bearer wrong-token-wrong-token"}, {"Authorization": TOKEN}):
            r = secured.request(method, path, headers=headers, json=TABLE1 if method in ("POST", "PUT") else None)
            assert r.status_code == 401, (method, path, headers, r.text)
            assert r.json()["error"]["code"] == "unauthorized"
            assert r.headers["www-authenticate"].startswith("Bearer")
    r = secured.post("/v1/plan", json=TABLE1, headers=BEARER)
    assert r.status_code == 200 and r.json()["metrics"]["settled"]
    assert secured.get("/v1/corridors", headers=BEARER).status_code == 200


def test_health_ready_docs_and_landing_stay_open_and_show_no_data(secured):
    for path in ("/health", "/ready", "/docs", "/redoc", "/openapi.json", "/"):
        r = secured.get(path)
        assert r.status_code in (200, 503), (path, r.status_code)
    assert "corridor" not in secured.get("/health").text.lower()
    # alive and nothing else (issue 33): the pool and the editor's port are /ready's
    assert secured.get("/health").json() == {"status": "ok"}
    assert secured.get("/health").json()["status"] == "ok"
    # probes address the server by its pod IP: any Host is fine there
    assert secured.get("/health", headers={"Host": "10.1.2.3:8000"}).status_code == 200


def test_foreign_host_is_refused_on_every_path_but_the_probes(secured):
    for path in ("/", "/docs", "/v1/robots", "/openapi.json"):
        r = secured.get(path, headers={"Host": "attacker.example", **BEARER})
        assert r.status_code == 400 and r.json()["error"]["code"] == "invalid_host", path
    assert secured.get("/v1/robots", headers={"Host": "cad.local:8000", **BEARER}).status_code == 200


def test_cors_preflight_and_headers_for_allowed_origins_only(secured):
    pre = {"Origin": "http://cad.local:3000", "Access-Control-Request-Method": "POST",
           "Access-Control-Request-Headers": "authorization, content-type"}
    r = secured.options("/v1/plan", headers=pre)
    assert r.status_code == 200, r.text
    assert r.headers["access-control-allow-origin"] == "http://cad.local:3000"
    assert "POST" in r.headers["access-control-allow-methods"]
    assert "authorization" in r.headers["access-control-allow-headers"].lower()
    r = secured.post("/v1/plan", json=TABLE1, headers={"Origin": "http://cad.local:3000", **BEARER})
    assert r.status_code == 200 and r.headers["access-control-allow-origin"] == "http://cad.local:3000"
    assert "x-plan-id" in r.headers["access-control-expose-headers"].lower()
    # a 401 carries the CORS headers too, so the page can read why
    r = secured.get("/v1/robots", headers={"Origin": "http://cad.local:3000"})
    assert r.status_code == 401 and r.headers["access-control-allow-origin"] == "http://cad.local:3000"
    bad = secured.options("/v1/plan", headers={**pre, "Origin": "http://evil.example"})
    assert bad.status_code == 400 and "access-control-allow-origin" not in bad.headers


def test_no_cors_by_default(tmp_path):
    app = create_app(Store(tmp_path), workers=1, executor="thread", access=AccessPolicy())
    with api_client(app) as c:
        r = c.get("/v1/robots", headers={"Origin": "http://cad.local:3000"})
        assert r.status_code == 200 and "access-control-allow-origin" not in r.headers
        r = c.options("/v1/plan", headers={"Origin": "http://cad.local:3000", "Access-Control-Request-Method": "POST"})
        assert "access-control-allow-origin" not in r.headers


def test_token_in_the_address_becomes_a_cookie_for_same_origin_pages(secured):
    r = secured.get(f"/?token={TOKEN}&x=1", follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"] == "/?x=1"
    cookie = r.headers["set-cookie"]
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie and TOKEN not in cookie
    value = cookie.split(";")[0].split("=", 1)[1]
    jar = {"Cookie": f"{TOKEN_COOKIE}={value}"}
    assert secured.get("/v1/robots", headers=jar).status_code == 200
    assert secured.get("/v1/robots", headers={**jar, "Origin": "http://localhost"}).status_code == 200
    r = secured.get("/v1/robots", headers={**jar, "Origin": "http://evil.example"})
    assert r.status_code == 403 and r.json()["error"]["code"] == "forbidden_origin"
    assert secured.get("/?token=wrong-token-wrong-token", follow_redirects=False).status_code == 401
    secured.cookies.clear()


def test_openapi_declares_the_bearer_scheme_when_a_token_is_set(secured, tmp_path):
    doc = secured.get("/openapi.json").json()
    assert doc["components"]["securitySchemes"]["bearerAuth"]["scheme"] == "bearer"
    for path, ops in doc["paths"].items():
        for op in ops.values():
            assert ("security" in op) == path.startswith("/v1"), path
            if path.startswith("/v1"):
                assert "401" in op["responses"]
    app = create_app(Store(tmp_path), workers=1, executor="thread", access=AccessPolicy())
    with api_client(app) as c:
        assert "securitySchemes" not in c.get("/openapi.json").json().get("components", {})


def test_offline_docs_name_no_external_url(secured):
    for path in ("/docs", "/redoc"):
        r = secured.get(path)
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
        assert "http://" not in r.text and "https://" not in r.text, path
        assert "default-src 'self'" in r.headers["content-security-policy"]
        assets = [part.split('"')[0] for part in r.text.split('"/docs-assets/')[1:]]
        assert assets, path
        for a in assets:
            got = secured.get(f"/docs-assets/{a}")
            assert got.status_code == 200 and len(got.content) > 1000, a
    assert "swagger-ui-bundle.js" in secured.get("/docs").text
    assert "redoc.standalone.js" in secured.get("/redoc").text


# ---------------------------------------------------------------------------------------
# the editor's port

@pytest.fixture(scope="module")
def editor_url():
    policy = AccessPolicy(token=TOKEN, allowed_hosts=frozenset({"localhost", "127.0.0.1", "::1"}))
    port = free_port()
    handle = start_guarded(policy, lambda: start_editor("127.0.0.1", port, None))
    try:
        yield f"127.0.0.1:{port}"
    finally:
        handle.stop()


def _ws(hostport: str, **headers):
    return connect(f"ws://{hostport}/", subprotocols=[f"viser-v{viser.__version__}"], additional_headers=headers,
                   open_timeout=10)


def test_editor_page_and_websocket_need_the_token(editor_url):
    r = httpx.get(f"http://{editor_url}/")
    assert r.status_code == 401 and "?token=" in r.text
    login = httpx.get(f"http://{editor_url}/?token={TOKEN}", follow_redirects=False)
    assert login.status_code == 303 and login.headers["location"] == "/"
    cookie = login.headers["set-cookie"].split(";")[0]
    page = httpx.get(f"http://{editor_url}/", headers={"Cookie": cookie})
    assert page.status_code == 200 and "<html" in page.text.lower()
    with pytest.raises(InvalidStatus) as exc:
        _ws(editor_url).close()
    assert exc.value.response.status_code == 401
    same = f"http://{editor_url}"
    with _ws(editor_url, Cookie=cookie, Origin=same) as ws:
        assert ws.recv(timeout=10)  # viser starts sending the scene
    with _ws(editor_url, Authorization=f"Bearer {TOKEN}") as ws:
        assert ws.recv(timeout=10)


def test_editor_login_on_one_client_connection(editor_url):
    """A client that keeps its connection (httpx, a browser) follows the login's redirect: every
    HTTP answer of the editor's port says ``Connection: close`` (websockets closes it after
    one), so the next request goes on a new connection instead of failing on the closed one."""
    for _ in range(20):  # the failure was a race with the server's close: many tries
        with httpx.Client(follow_redirects=True, timeout=10) as c:
            assert c.get(f"http://{editor_url}/").status_code == 401
            page = c.get(f"http://{editor_url}/?token={TOKEN}")
            assert page.status_code == 200 and "<html" in page.text.lower()
            assert [r.headers["connection"] for r in page.history] == ["close"]
            assert page.headers["connection"] == "close"


def test_editor_refuses_foreign_origin_and_host(editor_url):
    port = editor_url.split(":")[1]
    with pytest.raises(InvalidStatus) as exc:
        _ws(editor_url, Authorization=f"Bearer {TOKEN}", Origin="http://evil.example").close()
    assert exc.value.response.status_code == 403
    with pytest.raises(InvalidStatus) as exc:  # DNS rebinding: the page's own name, pointed here
        _ws(editor_url, Authorization=f"Bearer {TOKEN}", Host=f"evil.example:{port}",
            Origin=f"http://evil.example:{port}").close()
    assert exc.value.response.status_code == 400
    r = httpx.get(f"http://{editor_url}/", headers={"Host": "evil.example", **BEARER})
    assert r.status_code == 400


# ---------------------------------------------------------------------------------------
# the edges of the Host and Origin checks (issue 33), on both ports

#: (Host header, allowed): exactly ``host [":" port]`` by RFC 3986 naming an allowed host
HOSTS = [
    ("[::1]evil.example", False),            # junk after the IPv6 literal
    ("[::1]@evil.example", False),           # userinfo: the host is evil.example
    ("localhost@evil.example", False),
    ("evil.example#@localhost", False),
    ("localhost:80x", False),                # a port is digits only
    ("localhost:", False),                   # an empty port (RFC 3986 allows it; no client sends it)
    ("localhost:65536", False),
    ("localhost:+80", False),
    ("localhost:" + "0" * 2000 + "80", False),
    ("127.0.0.1.evil.example", False),
    ("::1", False),                          # an IPv6 address in a Host is bracketed
    ("[::1", False),
    ("[fe80::1%25eth0]", False),             # zone ids: not this server's name
    ("[v1.localhost]", False),               # IPvFuture
    ("[::ffff:127.0.0.1]", False),           # a loopback address, but not one of the loopback names
    ("", False),
    ("lоcalhost", False),                    # a Cyrillic o
    ("localhöst", False),
    ("local%68ost", False),                  # percent-encoded: no DNS name needs it
    ("localhost..", False),
    (".localhost", False),
    ("local host", False),
    ("localhost\tevil", False),
    ("a" * 64 + ".localhost", False),       # a label is at most 63 characters
    ("x." * 200 + "localhost", False),
    ("[::1]:8000", True),
    ("[0:0:0:0:0:0:0:1]", True),             # ::1, written out
    ("LOCALHOST", True),
    ("localhost.", True),                    # the same DNS name, absolute
    ("localhost:8000", True),
    ("127.0.0.1:1", True),
    ("cad.local:65535", True),
]


def _policy_hosts():
    return frozenset({"localhost", "127.0.0.1", "::1", "cad.local"})


@pytest.mark.parametrize(("host", "allowed"), HOSTS)
def test_host_header_is_read_exactly(host, allowed):
    assert AccessPolicy(allowed_hosts=_policy_hosts()).host_allowed(host) is allowed


@pytest.mark.parametrize(("host", "allowed"), HOSTS)
def test_api_answers_exact_hosts_only(secured, host, allowed):
    r = secured.get("/v1/robots", headers={"Host": host.encode("utf-8"), **BEARER})
    assert r.status_code == (200 if allowed else 400), r.text


def _handshake(hostport: str, headers: dict[str, bytes | str]) -> int:
    """The status of a raw WebSocket handshake to the editor (bytes exactly as given)."""
    lines = [b"GET / HTTP/1.1", b"Upgrade: websocket", b"Connection: Upgrade",
             b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==", b"Sec-WebSocket-Version: 13",
             f"Sec-WebSocket-Protocol: viser-v{viser.__version__}".encode(), f"Authorization: Bearer {TOKEN}".encode()]
    lines += [k.encode() + b": " + (v if isinstance(v, bytes) else v.encode()) for k, v in headers.items()]
    host, port = hostport.rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=10) as sock:
        sock.sendall(b"\r\n".join(lines) + b"\r\n\r\n")
        status = sock.recv(64).split(b" ", 2)
    return int(status[1])


@pytest.mark.parametrize(("host", "allowed"), [(h, a) for h, a in HOSTS if h != "cad.local:65535"])
def test_editor_websocket_answers_exact_hosts_only(editor_url, host, allowed):
    assert _handshake(editor_url, {"Host": host.encode("utf-8")}) == (101 if allowed else 400)


@pytest.mark.parametrize(("origin", "same"), [
    ("https://localhost:{port}", False),     # the scheme is compared: the editor is http
    ("http://localhost:{other}", False),
    ("null", False),
    ("http://evil.example:{port}", False),
    ("http://user@localhost:{port}", False),
    ("http://localhost:{port}/", False),
    ("ws://localhost:{port}", False),
    ("http://[::1]evil.example:{port}", False),
    ("http://localhost:{port}", True),
    ("HTTP://LOCALHOST:{port}", True),
])
def test_editor_websocket_compares_scheme_host_and_port_of_the_origin(editor_url, origin, same):
    port = int(editor_url.rsplit(":", 1)[1])
    origin = origin.format(port=port, other=port + 1)
    assert _handshake(editor_url, {"Host": f"localhost:{port}", "Origin": origin}) == (101 if same else 403)


@pytest.mark.parametrize(("origin", "host", "same"), [
    ("https://localhost", "localhost", False),
    ("http://localhost:8081", "localhost:8080", False),
    ("null", "localhost", False),
    ("http://localhost", "localhost:80", True),      # default ports filled in
    ("https://localhost:443", "localhost", False),   # over http
    ("http://localhost:80", "localhost", True),
    ("http://[::1]:8080", "[0::1]:8080", True),
])
def test_same_origin_is_scheme_host_and_port(origin, host, same):
    assert same_origin(origin, host, "http") is same


def test_cookie_requests_on_the_api_compare_the_origin_exactly(secured):
    value = AccessPolicy(token=TOKEN).cookie_value
    jar = {"Cookie": f"{TOKEN_COOKIE}={value}"}
    assert secured.get("/v1/robots", headers={**jar, "Origin": "http://localhost:80"}).status_code == 200
    assert secured.get("/v1/robots", headers={**jar, "Origin": "http://cad.local:3000"}).status_code == 200
    for origin in ("https://localhost", "http://localhost:8081", "null", "http://cad.local:3001",
                   "https://cad.local:3000"):
        r = secured.get("/v1/robots", headers={**jar, "Origin": origin})
        assert r.status_code == 403, origin


# ---------------------------------------------------------------------------------------
# rangeplan serve

def _serve(*args: str, env: dict | None = None, timeout: float = 60) -> subprocess.CompletedProcess:
    e = {k: v for k, v in os.environ.items() if not k.startswith("RANGEPLAN_")}
    e.update({"RANGEPLAN_WORKERS": "1", "RANGEPLAN_ACCESS_LOG": "0", **(env or {})})
    return subprocess.run([sys.executable, "-m", "app.cli", "serve", *args], env=e, cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)


def test_serve_refuses_an_open_non_loopback_bind(tmp_path):
    t0 = time.monotonic()
    r = _serve("--host", "0.0.0.0", "--port", str(free_port()), "--no-editor",
               env={"RANGEPLAN_DATA_DIR": str(tmp_path)})
    assert r.returncode == 2 and "RANGEPLAN_API_TOKEN" in r.stderr and "--allow-unauthenticated" in r.stderr
    assert time.monotonic() - t0 < 30
    r = _serve("--port", str(free_port()), "--no-editor", env={"RANGEPLAN_API_TOKEN": "short"})
    assert r.returncode == 2 and "at least 16" in r.stderr


@pytest.mark.slow
def test_serve_reports_a_taken_editor_port_as_an_error(tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        r = _serve("--port", str(free_port()), "--editor-port", str(port), env={"RANGEPLAN_DATA_DIR": str(tmp_path)},
                   timeout=120)
    assert r.returncode == 1, r.stderr
    assert f"editor port {port} is taken" in r.stderr
