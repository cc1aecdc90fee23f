"""The admission gate (app/admission.py): a probe sent in the same instant as a burst of
requests is answered after at most a couple of them, not after all (without the gate: after
all, the control case); waiting is bounded (503 ``busy`` with ``Retry-After`` in the one error
shape); a client that leaves while waiting does not stall the ones behind it; the API's
service starts the threads its plans wait on before the first request."""

from __future__ import annotations

import asyncio
import json
import threading
import time

import httpx
import pytest

from app.admission import EXEMPT_PATHS, Admission, AdmissionGate

#: CPU time of one request's work between two waits [s] (a plan's validation is ~2-3 ms)
WORK_S = 0.01


def _app(order: list[str]):
    """An ASGI app: /ready answers at once, every other path works WORK_S on the loop
    without waiting (as parsing and validating a body does), then answers."""

    async def app(scope, receive, send):
        if scope["type"] != "http":
            return
        path = scope["path"]
        if path not in EXEMPT_PATHS:
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < WORK_S:
                pass
        order.append(path)
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"{}"})

    return app


async def _burst(app, n: int) -> None:
    """``n`` requests and one /ready started in the same turn (the probe last)."""
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://t") as c:
        await asyncio.gather(*(c.get(f"/v1/work/{i}") for i in range(n)), c.get("/ready"))


@pytest.mark.parametrize("gated", [True, False])
def test_a_probe_in_a_burst_waits_for_at_most_a_couple_of_requests(gated):
    order: list[str] = []
    app = _app(order)
    asyncio.run(_burst(AdmissionGate(app) if gated else app, 50))
    behind = order.index("/ready")  # requests answered before the probe
    if gated:
        assert behind <= 2, order[:10]
        assert len(order) == 51
    else:  # the control: every request of the turn runs first
        assert behind == 50


def test_requests_are_admitted_in_the_order_they_came():
    order: list[str] = []
    asyncio.run(_burst(AdmissionGate(_app(order)), 20))
    work = [p for p in order if p != "/ready"]
    assert work == [f"/v1/work/{i}" for i in range(20)]


def test_waiting_is_bounded_with_busy_and_retry_after():
    order: list[str] = []

    async def run():
        transport = httpx.ASGITransport(app=AdmissionGate(_app(order), Admission(queue=3)))
        async with httpx.AsyncClient(transport=transport, base_url="http://t") as c:
            return await asyncio.gather(*(c.get(f"/v1/work/{i}") for i in range(10)), c.get("/health"))

    answers = asyncio.run(run())
    codes = [r.status_code for r in answers[:10]]
    # the first goes on, three wait, the other six are told to come back
    assert codes.count(200) == 4 and codes.count(503) == 6, codes
    busy = next(r for r in answers if r.status_code == 503)
    assert busy.headers["retry-after"] == "1"
    body = busy.json()
    assert body["error"]["code"] == "busy" and body["error"]["field"] is None
    assert "3 requests are waiting" in body["error"]["message"]
    assert answers[10].status_code == 200  # the probe never waits, never refused


def test_a_client_that_leaves_while_waiting_does_not_stall_the_others():
    order: list[str] = []
    gate = AdmissionGate(_app(order))

    async def call(path: str):
        sent = []

        async def receive():
            return {"type": "http.request", "body": b"", "more_body": False}

        async def send(msg):
            sent.append(msg)

        await gate({"type": "http", "path": path, "method": "GET", "headers": []}, receive, send)
        return sent

    async def run():
        tasks = [asyncio.ensure_future(call(f"/v1/work/{i}")) for i in range(6)]
        await asyncio.sleep(0)  # all started: the first went on, five wait
        assert gate.admission.waiting == 5
        tasks[1].cancel()
        tasks[2].cancel()
        done = await asyncio.wait_for(asyncio.gather(*tasks, return_exceptions=True), 5)
        return done

    done = asyncio.run(run())
    assert isinstance(done[1], asyncio.CancelledError) and isinstance(done[2], asyncio.CancelledError)
    assert order == ["/v1/work/0", "/v1/work/3", "/v1/work/4", "/v1/work/5"]
    assert gate.admission.waiting == 0


def test_the_service_starts_the_threads_plans_wait_on_before_the_first_request(tmp_path):
    """Started in a burst instead, each new thread held the loop until the scheduler first ran
    it (~10 ms each under load: 0.7 s for 67 plans)."""
    from fastapi.testclient import TestClient

    from app.api import create_app
    from app.storage import Store

    app = create_app(Store(tmp_path), workers=1, max_queue=20, executor="thread")
    with TestClient(app):
        svc = app.state.service
        names = [t.name for t in threading.enumerate() if t.name.startswith("rangeplan-wait")]
        assert len(names) == svc.pool.capacity + 4 == 25


def test_the_api_answers_busy_in_its_error_shape_when_too_many_wait(tmp_path, monkeypatch):
    """The gate is installed in the API, configured by RANGEPLAN_ADMISSION_QUEUE."""
    from app.api import create_app
    from app.storage import Store

    monkeypatch.setenv("RANGEPLAN_ADMISSION_QUEUE", "1")
    app = create_app(Store(tmp_path), workers=1, executor="thread")

    async def run():
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://127.0.0.1") as c:
            return await asyncio.gather(*(c.get("/v1/robots") for _ in range(4)))

    answers = asyncio.run(run())
    codes = sorted(r.status_code for r in answers)
    assert codes == [200, 200, 503, 503], codes
    assert json.loads(answers[-1].content)["error"]["code"] == "busy"


def test_the_metrics_count_the_requests_waiting(tmp_path):
    from fastapi.testclient import TestClient

    from app.api import create_app
    from app.storage import Store

    class Five:
        waiting = 5

    app = create_app(Store(tmp_path), workers=1, executor="thread")
    with TestClient(app, base_url="http://127.0.0.1") as c:
        assert "rangeplan_http_requests_waiting 0.0" in c.get("/metrics").text
        app.state.admission = Five()
        assert "rangeplan_http_requests_waiting 5.0" in c.get("/metrics").text
