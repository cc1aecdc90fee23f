"""Long contours and plans as HTTP jobs (issue 35 goal 6; app/routers/jobs.py): 202 Accepted
with the job's URL, progress read from the worker process's rows while it runs, the same
result as the synchronous call, failures naming the line, bounded and token-protected."""

from __future__ import annotations

import sqlite3
import time

import numpy as np
import pytest

from app.api import create_app
from app.routers.jobs import JobLimits, parse_prefer
from app.security import AccessPolicy
from app.storage import Store
from tests.support import api_client, load_example
from tests.test_contour import ORIGIN

#: four cut passes of a 20 x 20 mm square with a rounded corner, at four depths
PASSES = 4
PROGRAM = "G21 G90 G17\nG64 P0.05\nF1200\nG0 X0 Y0 Z2\n" + "".join(
    f"G1 Z-{d} F300\nG1 X20 F1200\nG3 X25 Y5 I0 J5\nG1 Y20\nG1 X0\nG1 Y0\nG0 Z2\n" for d in range(1, PASSES + 1)) \
    + "G0 X-10 Y-10\nM2\n"
BODY = {"program": PROGRAM, "origin": ORIGIN, "feed": "program"}
ASYNC = {"Prefer": "respond-async"}
TOKEN = "t" * 32


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    app = create_app(Store(tmp_path_factory.mktemp("data")), workers=1, timeout_s=120)
    with api_client(app) as c:
        yield c


def poll(client, url: str, timeout_s: float = 300.0, headers: dict | None = None) -> list[dict]:
    """Every status of the job at ``url`` until it ends (polled every 10 ms)."""
    seen = []
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        r = client.get(url, headers=headers)
        assert r.status_code == 200, r.text
        seen.append(r.json())
        if seen[-1]["state"] in ("done", "failed"):
            assert "Retry-After" not in r.headers
            return seen
        assert 1 <= int(r.headers["Retry-After"]) <= 60
        time.sleep(0.01)
    raise AssertionError(f"the job did not end in {timeout_s} s: {seen[-1]}")


def job(store: Store, id_: str) -> dict:
    row = store.get_job(id_)
    assert row is not None, id_
    return row


def jobs_kept(store: Store) -> int:
    with sqlite3.connect(store.path) as con:
        return con.execute("SELECT count(*) FROM jobs").fetchone()[0]


@pytest.fixture(scope="module")
def synchronous(client):
    r = client.post("/v1/contour", json=BODY)  # estimated ~2 s: under the 10 s threshold
    assert r.status_code == 200, r.text
    return r.json()


def test_async_contour_reports_progress_and_the_synchronous_result(client, synchronous):
    r = client.post("/v1/contour", json=BODY, headers=ASYNC)
    assert r.status_code == 202, r.text
    assert r.headers["Preference-Applied"] == "respond-async"
    url = r.headers["Location"]
    assert url == f"/v1/jobs/{r.json()['id']}" and r.json()["kind"] == "contour"
    seen = poll(client, url)
    states = [s["state"] for s in seen]
    order = {"queued": 0, "running": 1, "done": 2}
    assert states[-1] == "done" and [order[s] for s in states] == sorted(order[s] for s in states)
    running = [s for s in seen if s["state"] == "running"]
    assert running, "never seen running"
    done = [s["progress"]["done"] for s in seen]
    assert done == sorted(done), "progress went backwards"
    assert {s["progress"]["total"] for s in running} == {PASSES}
    assert seen[-1]["progress"] == {"done": PASSES, "total": PASSES, "unit": "passes"}
    assert any(0 < d < PASSES for d in done), f"no progress seen between start and end: {done}"
    # the estimate, and a time left from it that shrinks to 0
    print([(s["state"], s["progress"]["done"], s["elapsed_s"] and round(s["elapsed_s"], 2),
            s["eta_s"] and round(s["eta_s"], 2)) for s in seen[::5]], seen[0]["estimate_s"])
    assert all(s["estimate_s"] > 0 and s["eta_s"] is not None and s["eta_s"] >= 0 for s in running)
    assert all(s["eta_s"] > 0 for s in running if s["progress"]["done"] < PASSES)
    assert seen[-1]["eta_s"] == 0 and seen[-1]["elapsed_s"] > 0
    # the result: the stored plan, equal to the synchronous answer
    final = seen[-1]
    assert final["result"] == f"/v1/plans/{final['plan_id']}" and final["error"] is None
    res = client.get(final["result"])
    assert res.status_code == 200
    job_plan = res.json()
    assert job_plan["contour"]["passes"] == synchronous["contour"]["passes"]
    for k in ("cycle_time_s", "cut_time_s", "max_deviation_m", "tolerance_m"):
        assert job_plan["contour"][k] == synchronous["contour"][k], k
    assert np.allclose(job_plan["pose"], synchronous["pose"], atol=1e-12)
    assert len(job_plan["contour"]["passes"]) == PASSES


def test_a_failing_program_ends_failed_naming_the_line(client):
    bad = {**BODY, "program": PROGRAM.replace("G1 Y20", "G41 Y20", 1)}
    r = client.post("/v1/contour", json=bad, headers=ASYNC)
    assert r.status_code == 202, r.text
    final = poll(client, r.headers["Location"])[-1]
    assert final["state"] == "failed" and final["result"] is None and final["plan_id"] is None
    err = final["error"]
    assert err["code"] == "invalid_input" and "line 8" in err["message"] and "G41" in err["message"], err
    # the synchronous call answers the same error
    sync = client.post("/v1/contour", json=bad)
    assert sync.status_code == 422 and sync.json()["error"]["message"] == err["message"]


def test_the_server_answers_202_by_itself_over_the_threshold(tmp_path):
    app = create_app(Store(tmp_path), workers=1, timeout_s=120)
    with api_client(app) as c:
        from app.routers.jobs import job_limits

        limits = job_limits(app)
        assert (limits.async_after_s, limits.sync_limit_s, limits.job_timeout_s) == (10.0, 120.0, 600.0)
        # a threshold below this program's estimate: a job without asking
        app.state.job_limits = JobLimits(0.05, 120.0, 600.0, 100, 3600.0)
        r = c.post("/v1/contour", json=BODY)
        assert r.status_code == 202 and "Preference-Applied" not in r.headers, r.text
        est = r.json()["estimate_s"]
        assert est is not None and est > 0.05
        final = poll(c, r.headers["Location"])[-1]
        assert final["state"] == "done" and final["estimate_s"] == est
        # the client says it waits longer than the estimate: answered synchronously, no job left behind
        jobs = jobs_kept(app.state.store)
        r = c.post("/v1/contour", json=BODY, headers={"Prefer": f"wait={2 * est + 1:.0f}"})
        assert r.status_code == 200 and r.json()["contour"]["cycle_time_s"] > 0
        assert jobs_kept(app.state.store) == jobs
        # a plan: the server estimates it before it is queued
        plan = load_example("table1")
        r = c.post("/v1/plan", json=plan)
        assert r.status_code == 202, r.text
        assert r.json()["kind"] == "plan" and r.json()["progress"]["unit"] == "plans"
        final = poll(c, r.headers["Location"])[-1]
        assert final["state"] == "done" and final["progress"] == {"done": 1, "total": 1, "unit": "plans"}
        # the typed client follows a job to its plan
        from app.client import Client, RangeplanError

        jobs = jobs_kept(app.state.store)
        with Client(str(c.base_url), transport=c._transport) as rp:
            res = rp.contour(PROGRAM, origin=ORIGIN)
            assert jobs_kept(app.state.store) == jobs + 1  # it was a job
            assert res.contour is not None and len(res.contour.passes) == PASSES and res.plan_id
            with pytest.raises(RangeplanError) as err:
                rp.contour(PROGRAM.replace("G1 Y20", "G41 Y20", 1), origin=ORIGIN)
            assert err.value.code == "invalid_input" and "line 8" in err.value.message
        app.state.job_limits = JobLimits(10.0, 120.0, 600.0, 100, 3600.0)
        sync = c.post("/v1/plan", json=plan)
        assert sync.status_code == 200
        stored = c.get(final["result"]).json()
        assert stored["metrics"]["duration_s"] == sync.json()["metrics"]["duration_s"]
        assert np.allclose(stored["pose"], sync.json()["pose"], atol=1e-12)


def test_unknown_job_is_404(client):
    r = client.get("/v1/jobs/0123456789abcdef0123456789abcdef")
    assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"


def test_jobs_need_the_token(tmp_path):
    app = create_app(Store(tmp_path), workers=1, executor="thread",
                     access=AccessPolicy(token=TOKEN, cors_origins=("http://cad.local:3000",)))
    with api_client(app) as c:
        # a browser page of an allowed origin may send Prefer and read Preference-Applied
        pre = c.options("/v1/contour", headers={"Origin": "http://cad.local:3000", "Access-Control-Request-Method":
                                                "POST", "Access-Control-Request-Headers": "prefer, content-type"})
        assert pre.status_code == 200 and "prefer" in pre.headers["access-control-allow-headers"].lower()
        assert c.get("/v1/jobs/abc").status_code == 401
        assert c.post("/v1/contour", json=BODY, headers=ASYNC).status_code == 401
        auth = {"Authorization": f"Bearer {TOKEN}"}
        assert c.get("/v1/jobs/abc", headers=auth).status_code == 404
        r = c.post("/v1/contour", json=BODY, headers={**ASYNC, **auth, "Origin": "http://cad.local:3000"})
        assert r.status_code == 202
        assert "preference-applied" in r.headers["access-control-expose-headers"].lower()
        assert c.get(r.headers["Location"]).status_code == 401
        assert poll(c, r.headers["Location"], headers=auth)[-1]["state"] == "done"


def test_jobs_are_bounded_in_count_and_age(tmp_path):
    st = Store(tmp_path)
    assert st.create_job("a", "contour", "passes", max_jobs=2)
    assert st.create_job("b", "contour", "passes", max_jobs=2)
    assert not st.create_job("c", "contour", "passes", max_jobs=2)  # two unfinished: refused
    st.job_finished("a", plan_id="p")
    assert st.create_job("c", "contour", "passes", max_jobs=2)  # the finished one made room
    assert st.get_job("a") is None and job(st, "b")["state"] == "queued"
    st.job_finished("b", error={"code": "timeout", "message": "m", "field": None})
    assert st.create_job("d", "contour", "passes", max_jobs=10, max_age_s=0.0)  # finished ones of any age dropped
    assert st.get_job("b") is None and st.get_job("c") is not None
    # progress only moves forwards
    st.job_started("c", total=5, estimate_s=1.0)
    st.job_progress("c", 3)
    st.job_progress("c", 2)
    assert job(st, "c")["done"] == 3
    # a server starting ends the jobs of the one before it
    assert st.abandon_jobs("stopped") == 2 and job(st, "c")["state"] == "failed"
    assert job(st, "c")["error"]["message"] == "stopped"


def test_prefer_header():
    assert parse_prefer(["respond-async, wait=10"]) == parse_prefer(["wait=10", "Respond-Async"])
    p = parse_prefer(['respond-async; foo=bar, wait="7.5"', "handling=lenient"])
    assert p.respond_async and p.wait_s == 7.5
    assert parse_prefer([]) == parse_prefer(["wait=soon"]) and not parse_prefer([]).respond_async


def test_openapi_documents_the_job(client):
    doc = client.get("/openapi.json").json()
    for path in ("/v1/contour", "/v1/plan"):
        op = doc["paths"][path]["post"]
        assert op["responses"]["202"]["content"]["application/json"]["schema"]["$ref"].endswith("/JobStatus")
        assert "Location" in op["responses"]["202"]["headers"]
        assert any(p["name"] == "prefer" and p["in"] == "header" for p in op["parameters"])
    get = doc["paths"]["/v1/jobs/{job_id}"]["get"]
    assert set(get["responses"]) >= {"200", "404"}
    model = doc["components"]["schemas"]["JobStatus"]
    assert set(model["properties"]["state"]["enum"]) == {"queued", "running", "done", "failed"}
    assert {"progress", "eta_s", "result", "error", "estimate_s"} <= set(model["properties"])
    assert set(doc["components"]["schemas"]["JobProgress"]["properties"]) == {"done", "total", "unit"}
