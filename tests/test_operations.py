"""Operations of the service (issue 21): GET /metrics (Prometheus text, behind the token),
request ids and JSON access lines on every response, no redirect off the service, 413 for
every oversized body (chunked multipart included), JSON Lines batches whose lines are not
objects, and JSON parse errors that name the limit they hit."""

from __future__ import annotations

import io
import json
import logging

import pytest
from prometheus_client.parser import text_string_to_metric_families

from app.api import create_app
from app.observability import JsonFormatter, RequestIdFilter
from app.security import AccessPolicy
from app.storage import Store
from tests.support import api_client, load_example

TOKEN = "s3cret-token-for-the-ops-tests-0123"
BEARER = {"Authorization": f"Bearer {TOKEN}"}
TABLE1 = load_example("table1")


@pytest.fixture(scope="module")
def secured(tmp_path_factory):
    app = create_app(Store(tmp_path_factory.mktemp("ops")), workers=1, executor="thread", max_body_bytes=64 * 1024,
                     timeout_s=120, access=AccessPolicy(token=TOKEN))

    @app.get("/v1/test-boom", include_in_schema=False)
    def boom():  # an endpoint bug: the 500 path
        raise RuntimeError("boom")

    with api_client(app, raise_server_exceptions=False) as c:
        yield c


def scrape(client) -> dict[tuple[str, tuple], float]:
    """Every sample of /metrics as {(name, sorted labels): value}, read by prometheus_client's parser."""
    r = client.get("/metrics", headers=BEARER)
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/plain")
    out = {}
    for family in text_string_to_metric_families(r.text):
        for s in family.samples:
            out[(s.name, tuple(sorted(s.labels.items())))] = s.value
    return out


def delta(before: dict, after: dict, name: str, **labels: str) -> float:
    key = (name, tuple(sorted(labels.items())))
    return after.get(key, 0.0) - before.get(key, 0.0)


# ---------------------------------------------------------------------------------------
# metrics

def test_metrics_need_the_token_like_v1(secured):
    r = secured.get("/metrics")
    assert r.status_code == 401 and r.json()["error"]["code"] == "unauthorized"
    assert secured.get("/metrics", headers={"Authorization": "Bearer wrong-token-wrong-token"}).status_code == 401
    assert secured.get("/metrics", headers={**BEARER, "Host": "evil.example"}).status_code == 400
    assert secured.get("/metrics", headers=BEARER).status_code == 200


def test_request_counters_move_by_exactly_the_requests_made(secured):
    before = scrape(secured)
    for _ in range(3):
        assert secured.get("/v1/robots", headers=BEARER).status_code == 200
    for i in range(2):
        assert secured.get(f"/v1/corridors/nope{i}", headers=BEARER).status_code == 404
    assert secured.post("/v1/plan", json={"segments": []}, headers=BEARER).status_code == 422
    assert secured.get("/v1/robots").status_code == 401  # refused by access control: still counted
    assert secured.get("/no/such/path", headers=BEARER).status_code == 404
    after = scrape(secured)
    req = "rangeplan_http_requests_total"
    assert delta(before, after, req, route="/v1/robots", method="GET", status="200") == 3
    assert delta(before, after, req, route="/v1/corridors/{corridor_id}", method="GET", status="404") == 2
    assert delta(before, after, req, route="/v1/plan", method="POST", status="422") == 1
    assert delta(before, after, req, route="(refused)", method="GET", status="401") == 1
    assert delta(before, after, req, route="(unmatched)", method="GET", status="404") == 1
    assert delta(before, after, req, route="/metrics", method="GET", status="200") == 1  # the first scrape
    # the latency histogram saw the same requests, each in every bucket at or above its time
    lat = "rangeplan_http_request_duration_seconds"
    assert delta(before, after, lat + "_count", route="/v1/robots", method="GET") == 3
    assert delta(before, after, lat + "_bucket", route="/v1/robots", method="GET", le="+Inf") == 3
    assert delta(before, after, lat + "_sum", route="/v1/robots", method="GET") > 0
    total = sum(v for (name, _), v in after.items() if name == req) - sum(
        v for (name, _), v in before.items() if name == req)
    assert total == 3 + 2 + 1 + 1 + 1 + 1


def test_plan_durations_by_mode_and_pool_state(secured):
    before = scrape(secured)
    paper = {**TABLE1, "settings": {**TABLE1.get("settings", {}), "mode": "paper"}}
    for req in (TABLE1, paper, TABLE1):
        r = secured.post("/v1/plan", json=req, headers=BEARER)
        assert r.status_code == 200, r.text
    after = scrape(secured)
    hist = "rangeplan_plan_duration_seconds"
    assert delta(before, after, hist + "_count", mode="constrained", outcome="ok") == 2
    assert delta(before, after, hist + "_count", mode="paper", outcome="ok") == 1
    # a plan's time in the pool is part of its request's time
    plan_s = sum(delta(before, after, hist + "_sum", mode=m, outcome="ok") for m in ("constrained", "paper"))
    http_s = delta(before, after, "rangeplan_http_request_duration_seconds_sum", route="/v1/plan", method="POST")
    assert 0 < plan_s <= http_s
    assert delta(before, after, "rangeplan_jobs_total", kind="plan", outcome="ok") == 3
    assert after[("rangeplan_plan_queue_depth", ())] == 0 and after[("rangeplan_plan_jobs_in_flight", ())] == 0
    assert after[("rangeplan_worker_restarts_total", (("pool", "plan"),))] == 0
    assert after[("rangeplan_plan_workers", (("state", "configured"),))] == 1


# ---------------------------------------------------------------------------------------
# request ids and logs

@pytest.fixture
def access_lines():
    stream = io.StringIO()
    handler = logging.StreamHandler(stream)
    handler.setFormatter(JsonFormatter())
    handler.addFilter(RequestIdFilter())
    logger = logging.getLogger("rangeplan")
    old = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        yield lambda: [json.loads(ln) for ln in stream.getvalue().splitlines()]
    finally:
        logger.removeHandler(handler)
        logger.setLevel(old)


def test_request_id_is_echoed_or_made_on_every_response(secured, access_lines):
    sent = "client-req.42:abc_DEF"
    cases = [("get", "/v1/robots", {}, 200), ("get", "/v1/corridors/x", {}, 404), ("get", "/v1/robots", None, 401),
             ("post", "/v1/plan", {"json": {}}, 422), ("get", "/v1/test-boom", {}, 500),
             ("post", "/v1/plan", {"content": b"x" * 70_000, "headers": {"Content-Type": "application/json"}}, 413),
             ("get", "/health", {}, 200), ("get", "/nowhere", {}, 404)]
    for method, path, kwargs, status in cases:
        headers = {**(BEARER if kwargs is not None else {}), "X-Request-ID": sent,
                   **((kwargs or {}).pop("headers", {}))}
        r = getattr(secured, method)(path, headers=headers, **(kwargs or {}))
        assert r.status_code == status, (path, r.text)
        assert r.headers["x-request-id"] == sent, path
    made = set()
    for bad in (b"has spaces in it", b"x" * 129, b"semi;colon", "new\u00e9".encode()):
        r = secured.get("/v1/robots", headers={**BEARER, "X-Request-ID": bad})
        assert r.status_code == 200 and r.headers["x-request-id"].encode() != bad
        made.add(r.headers["x-request-id"])
    r = secured.get("/v1/robots", headers=BEARER)
    made.add(r.headers["x-request-id"])
    assert len(made) == 5 and all(len(m) == 32 and int(m, 16) >= 0 for m in made)  # fresh uuid4 hex each
    lines = [ln for ln in access_lines() if ln["logger"] == "rangeplan.access"]
    assert len(lines) == len(cases) + 5
    for ln, (method, path, _, status) in zip(lines, cases):
        assert ln["request_id"] == sent and ln["status"] == status and ln["path"] == path
        assert ln["method"] == method.upper() and ln["duration_ms"] >= 0 and ln["level"] == "info"
    assert [ln["request_id"] for ln in lines[len(cases):]][-1] == r.headers["x-request-id"]
    boom = [ln for ln in access_lines() if ln["logger"] == "rangeplan.error"]
    assert len(boom) == 1 and boom[0]["request_id"] == sent and "RuntimeError: boom" in boom[0]["exc"]


def test_the_log_never_holds_the_token(secured, access_lines):
    secured.get(f"/docs?token={TOKEN}")
    secured.get("/v1/robots", headers=BEARER)
    text = json.dumps(access_lines())
    assert TOKEN not in text and "/docs" in text


# ---------------------------------------------------------------------------------------
# redirects, body limits, JSON Lines, JSON limits

@pytest.mark.parametrize("path, local", [("//evil.example/", "/evil.example/"),
                                         ("///evil.example/a", "/evil.example/a"),
                                         ("/%5Cevil.example/", "/evil.example/"), ("/docs", "/docs")])
def test_token_login_never_redirects_off_the_service(secured, path, local):
    r = secured.get(f"http://localhost{path}?token={TOKEN}&x=1", follow_redirects=False)
    assert r.status_code == 303
    loc = r.headers["location"]
    assert loc == local + "?x=1" and loc.startswith("/") and not loc.startswith(("//", "/\\"))
    assert TOKEN not in loc and r.headers["referrer-policy"] == "no-referrer"


def chunks(total: int, size: int = 8192):
    sent = 0
    while sent < total:
        n = min(size, total - sent)
        sent += n
        yield b"a" * n


@pytest.mark.parametrize("path, content_type", [("/v1/plan", "application/json"), ("/v1/corridors", "application/json"),
                                                ("/v1/batches", "application/x-ndjson"),
                                                ("/v1/import", "image/svg+xml")])
def test_every_oversized_chunked_body_is_413(secured, path, content_type):
    r = secured.post(path, content=chunks(200_000), headers={**BEARER, "Content-Type": content_type})
    assert r.status_code == 413, r.text
    assert r.json()["error"]["code"] == "too_large" and "65536" in r.json()["error"]["message"]


def test_oversized_chunked_multipart_upload_is_413(secured):
    boundary = "b0undary"
    head = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"big.svg\"\r\n"
            "Content-Type: image/svg+xml\r\n\r\n").encode()

    def body():
        yield head
        yield from chunks(300_000)
        yield f"\r\n--{boundary}--\r\n".encode()

    r = secured.post("/v1/import", content=body(),
                     headers={**BEARER, "Content-Type": f"multipart/form-data; boundary={boundary}"})
    assert r.status_code == 413, r.text
    assert r.json()["error"]["code"] == "too_large"


@pytest.mark.parametrize("lines, number, item, what", [
    (['{"segments": []}', "[1, 2]"], 2, 1, "array"),
    (["42"], 1, 0, "number"),
    (['{"a": 1}', "", '"text"'], 3, 1, "string"),
    (['{"a": 1}', "{oops"], 2, 1, "not valid JSON"),
    (["null"], 1, 0, "null"),
])
def test_json_lines_that_are_not_objects_are_a_422_naming_the_line(secured, lines, number, item, what):
    r = secured.post("/v1/batches", content="\n".join(lines) + "\n",
                     headers={**BEARER, "Content-Type": "application/x-ndjson"})
    assert r.status_code == 422, r.text
    err = r.json()["error"]
    assert err["code"] == "invalid_input" and err["field"] == f"requests[{item}]"
    assert f"line {number} " in err["message"] and what in err["message"]


def test_json_parse_errors_name_the_limit(secured):
    deep = "[" * 30_000 + "]" * 30_000  # 60 kB: within the body limit of this app
    r = secured.post("/v1/plan", content=deep, headers={**BEARER, "Content-Type": "application/json"})
    assert r.status_code == 422 and "nests arrays and objects deeper than the parser's limit" in r.json()["error"][
        "message"]
    r = secured.post("/v1/plan", content='{"name": ' + "9" * 5000 + "}",
                     headers={**BEARER, "Content-Type": "application/json"})
    assert r.status_code == 422 and "more than 4300 digits" in r.json()["error"]["message"]
    r = secured.post("/v1/plan", content=b'{"name": "\xff"}', headers={**BEARER, "Content-Type": "application/json"})
    assert r.status_code == 422 and "UTF-8" in r.json()["error"]["message"]
    r = secured.post("/v1/batches", content=deep, headers={**BEARER, "Content-Type": "application/json"})
    assert r.status_code == 422 and "limit of 1024 levels" in r.json()["error"]["message"]
    r = secured.post("/v1/batches", content='{"requests": [1e999]}', headers={**BEARER,
                                                                              "Content-Type": "application/json"})
    assert r.status_code == 422 and "larger than the parser's limit" in r.json()["error"]["message"]


def test_a_body_nested_500000_deep_names_the_depth_limit(tmp_path):
    """The issue's case at the default body limit (2 MiB): 1 MB of brackets."""
    app = create_app(Store(tmp_path), workers=1, executor="thread")
    with api_client(app) as c:
        r = c.post("/v1/plan", content="[" * 500_000 + "]" * 500_000, headers={"Content-Type": "application/json"})
    assert r.status_code == 422, r.text
    assert "deeper than the parser's limit" in r.json()["error"]["message"]
