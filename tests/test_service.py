"""The service's bounds over HTTP (issue 15): readiness, storage quotas and duplicate names
as status codes, list pages, the memory cap of a worker, and the editor planning on the
API's pool under the same limits."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

import planner
from app.api import create_app
from app.security import AccessPolicy
from app.storage import Store
from app.workers import PlanPool
from tests.support import api_client

ROOT = Path(__file__).resolve().parent.parent
TABLE1 = json.loads((ROOT / "app" / "static" / "examples" / "table1.json").read_text())


def client_for(app) -> TestClient:
    return api_client(app)


def test_ready_only_once_the_workers_can_plan(tmp_path):
    """/ready is 503 'starting' while the workers load the planner, then 200; /health is 200
    throughout."""
    app = create_app(Store(tmp_path), workers=2, timeout_s=30, access=AccessPolicy())
    with client_for(app) as c:
        first = c.get("/ready")
        assert c.get("/health").status_code == 200
        if first.status_code == 503:
            assert first.json()["status"] == "starting" and first.json()["workers_ready"] < 2
        deadline = time.monotonic() + 120
        while c.get("/ready").status_code != 200:
            assert time.monotonic() < deadline, "workers never became ready"
            time.sleep(0.05)
        body = c.get("/ready").json()
        assert body == {"status": "ready", "version": planner.__version__, "workers_ready": body["workers_ready"],
                        "workers": 2, "failures": [], "kernels": "compiled", "pool": body["pool"], "editor_port": None,
                        "jobs": {"workers": 1, "running": 0, "queued": 0}}  # jobs may hold one of the two workers
        assert body["pool"]["workers"] == 2 and body["pool"]["in_flight"] == 0
        assert body["workers_ready"] >= 1
        assert c.post("/v1/plan", json=TABLE1).status_code == 200


def test_ready_reports_workers_that_cannot_plan(monkeypatch):
    """A warm-up that fails (e.g. kernels that cannot be loaded or compiled) keeps /ready at
    503 'failed' with the reason."""
    import planner

    def broken():
        raise RuntimeError("cannot cache function 'step': no locator available")

    monkeypatch.setattr(planner, "warm_up", broken)
    pool = PlanPool(workers=1, mode="thread")
    try:
        deadline = time.monotonic() + 10
        while pool.readiness()["failures"] == [] and time.monotonic() < deadline:
            time.sleep(0.01)
        state = pool.readiness()
        assert state["ready"] is False and state["failures"]
    finally:
        pool.close()


def test_quotas_and_names_over_http(tmp_path):
    one = len(json.dumps(TABLE1).encode())
    store = Store(tmp_path, max_corridor_bytes=2 * one, max_total_bytes=3 * one)
    app = create_app(store, workers=1, executor="thread", access=AccessPolicy())
    with client_for(app) as c:
        first = c.post("/v1/corridors", json={**TABLE1, "name": "a"})
        assert first.status_code == 201
        r = c.post("/v1/corridors", json={**TABLE1, "name": "a"})
        assert r.status_code == 409 and r.json()["error"]["code"] == "name_taken"
        assert r.json()["error"]["field"] == "name" and first.json()["id"] in r.json()["error"]["message"]
        b = c.post("/v1/corridors", json={**TABLE1, "name": "b"}).json()
        assert c.put(f"/v1/corridors/{b['id']}", json={**TABLE1, "name": "a"}).status_code == 409
        big = {**TABLE1, "name": "big", "segments": TABLE1["segments"] * 3}
        r = c.post("/v1/corridors", json=big)
        assert r.status_code == 413 and r.json()["error"]["code"] == "too_large"
        assert "RANGEPLAN_MAX_CORRIDOR_BYTES" in r.json()["error"]["message"]
        assert c.post("/v1/corridors", json={**TABLE1, "name": "c"}).status_code == 201
        r = c.post("/v1/corridors", json={**TABLE1, "name": "d"})
        assert r.status_code == 507 and r.json()["error"]["code"] == "storage_full"
        assert c.delete(f"/v1/corridors/{b['id']}").status_code == 204
        assert c.post("/v1/corridors", json={**TABLE1, "name": "d"}).status_code == 201


def test_list_pages_over_http(tmp_path):
    store = Store(tmp_path)
    ids = [store.create_corridor({"i": i}, name=f"n{i}")["id"] for i in range(7)]
    app = create_app(store, workers=1, executor="thread", access=AccessPolicy())
    with client_for(app) as c:
        page = c.get("/v1/corridors", params={"limit": 3}).json()
        assert [x["id"] for x in page["items"]] == ids[:3] and page["next_cursor"]
        page2 = c.get("/v1/corridors", params={"limit": 3, "cursor": page["next_cursor"]}).json()
        assert [x["id"] for x in page2["items"]] == ids[3:6]
        page3 = c.get("/v1/corridors", params={"limit": 3, "cursor": page2["next_cursor"]}).json()
        assert [x["id"] for x in page3["items"]] == ids[6:] and page3["next_cursor"] is None
        assert len(c.get("/v1/corridors").json()["items"]) == 7  # default page of 50
        r = c.get("/v1/corridors", params={"cursor": "not-a-cursor"})
        assert r.status_code == 422 and r.json()["error"]["field"] == "cursor"
        r = c.get("/v1/corridors", params={"limit": 201})
        assert r.status_code == 422 and r.json()["error"]["field"] == "limit"


@pytest.mark.slow
def test_memory_cap_stops_a_plan_with_a_clear_error_and_the_worker_is_replaced():
    """A worker limited to 700 MiB of address space (~0.5 GiB is the interpreter with the
    planner) runs the largest corridor the schema accepts (200 000 steps; ~0.8 GiB): it
    answers too_much_memory, the worker is replaced, the next plan succeeds."""
    from app.jobs import Done, Failed, PlanJob
    from app.service import JobService
    from planner import PlanRequest
    from tests.test_api import long_corridor

    pool = PlanPool(workers=1, timeout_s=120, memory_mb=700)
    service = JobService(pool)
    try:
        # numpy's MemoryError is reported by the worker, an allocation abort (Rust) by the
        # pool: the service answers both alike
        out = service.run(PlanJob(PlanRequest.model_validate(long_corridor())))
        assert isinstance(out, Failed) and out.status == 422, out
        error = out.error
        assert error.code == "too_much_memory", error
        assert "700 MiB" in error.message and "RANGEPLAN_WORKER_MEMORY_MB" in error.message
        assert pool.replaced == 1
        ok = service.run(PlanJob(PlanRequest.model_validate(TABLE1)))
        assert isinstance(ok, Done)
    finally:
        pool.close()


def test_editor_reads_drawings_on_the_pool_under_the_same_limits():
    """Under `rangeplan serve` the editor's Files tab reads a drawing on the API's workers
    (their compute limit and memory cap), with the answer it gets in-process and the same
    errors (a curve too fine for a shape: too_large naming flatten_tolerance)."""
    from app.editor import _planning
    from planner.errors import PlannerError
    from tests.drawings import DRAWINGS

    data = (DRAWINGS / "Table-dining-E.dxf").read_bytes()
    options = {"scale": 0.05, "offset": [0.0, 0.0225], "margin": 0.03}
    inline, _ = _planning.drawing_request(data, "table.dxf", TABLE1, options)
    pool = PlanPool(workers=1, timeout_s=30.0)
    _planning.use_pool(pool)
    try:
        pooled, summary = _planning.drawing_request(data, "table.dxf", TABLE1, options)
        assert pool.jobs_run == 1 and pooled == inline and "1 obstacle(s)" in summary
        with pytest.raises(PlannerError) as e:
            _planning.drawing_request(data, "table.dxf", TABLE1, {**options, "flatten_tolerance": 1e-9,
                                                                  "scale": 100.0})
        assert (e.value.code, e.value.field) == ("too_large", "flatten_tolerance") and pool.jobs_run == 2
        with pytest.raises(PlannerError) as e:  # options are validated before a job is queued
            _planning.drawing_request(data, "table.dxf", TABLE1, {"scale": -1})
        assert (e.value.code, e.value.field) == ("invalid_input", "scale") and pool.jobs_run == 2
    finally:
        _planning.use_pool(None)
        pool.close()


def test_editor_plans_on_the_pool_under_the_same_limits():
    """With a pool (as under `rangeplan serve`) the editor's re-plans are jobs of that pool:
    a plan arrives, the pool counts the job, and too much work is the API's too_much_work."""
    from app.editor import _planning

    pool = PlanPool(workers=1, timeout_s=5.0)
    _planning.use_pool(pool)
    try:
        robots = _planning.RobotCache()
        layout = {"layout": {"bounds": {"lower": [-0.08, -0.06], "upper": [0.08, 0.06]}, "obstacles": [],
                             "cell": {"shape": "square", "size": 0.01}, "start": [-0.06, -0.04, 0.0],
                             "end": [0.06, -0.04, 0.0]}}
        out = _planning.compute_plan(layout, robots)
        assert out.error is None and out.segmentation is not None and pool.jobs_run == 1
        pose = np.array(out.result.pose)
        assert np.hypot(*(pose[-1, :2] - [0.06, -0.04])) < 1e-3
        heavy = {**TABLE1, "settings": {"mode": "constrained", "N": 150, "backend": "reference"}}
        out = _planning.compute_plan(heavy, robots)
        assert out.error.code == "too_much_work" and out.error.field == "settings.N"
        assert "limit of 5 s" in out.error.message
        bad = _planning.compute_plan({**TABLE1, "settings": {"Ts": -1}}, robots)
        assert bad.error.code == "invalid_input"
    finally:
        _planning.use_pool(None)
        pool.close()


def test_on_reference_is_the_one_rule_of_jobs_submitted_while_the_kernels_compile():
    """A planning job moves to the numpy reference (a copy: the job itself unchanged); a job
    asked on another backend, a contour on a solver the reference lacks and a job that plans
    nothing stay as they are. The service and the CLI take the rule from app.executors."""
    import app.cli
    import app.service
    from app.executors import on_reference
    from app.jobs import ContourJob, PlanJob, SleepJob
    from planner.schema import ContourRequest, PlanRequest

    table1 = json.loads((Path(__file__).resolve().parent.parent / "app/static/examples/table1.json").read_text())
    plan = PlanJob(PlanRequest.model_validate(table1))
    moved = on_reference(plan)
    assert isinstance(moved, PlanJob)
    assert moved.request.settings.backend == "reference" and plan.request.settings.backend == "compiled"
    assert moved.request.segments == plan.request.segments and moved.format == plan.format
    asked = PlanJob(PlanRequest.model_validate({**table1, "settings": {"backend": "reference"}}))
    assert on_reference(asked) is asked
    contour = ContourJob(ContourRequest.model_validate({"program": "G1 X1 F100\n"}))
    moved_contour = on_reference(contour)
    assert isinstance(moved_contour, ContourJob) and moved_contour.request.settings == {"backend": "reference"}
    dense = ContourJob(ContourRequest.model_validate({"program": "G1 X1 F100\n", "settings": {"solver": "qr"}}))
    assert on_reference(dense) is dense
    sleep = SleepJob(0.0)
    assert on_reference(sleep) is sleep
    assert app.service.on_reference is on_reference and "def on_reference" not in Path(app.cli.__file__).read_text()
