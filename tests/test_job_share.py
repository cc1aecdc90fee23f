"""Jobs on their own share of the workers (issue 33): long jobs (202 Accepted, up to the job
limit) never starve a synchronous request. Real planning processes: a job is a plan of
Table I with ``fastest`` at Ts 2 ms, N 30 (estimated ~116 s, ~46 CPU s: admitted as a job,
and still running when each test ends and closes the pool, which kills it)."""

from __future__ import annotations

import re
import statistics
import threading
import time
from typing import Any

import pytest

from app.api import create_app
from app.jobs import PlanJob
from app.security import AccessPolicy
from app.storage import Store
from app.workers import JobsHoldEveryWorker, PlanPool
from planner.schema import PlanRequest
from tests.support import api_client, load_example, with_settings

ASYNC = {"Prefer": "respond-async"}


def long_job() -> dict:
    """A plan that runs for tens of CPU seconds and is admitted as a job."""
    return with_settings(load_example("table1"), fastest=True, Ts=0.002, N=30)


def wait_for(check, timeout_s: float = 120.0, what: str = "") -> None:
    deadline = time.monotonic() + timeout_s
    while not check():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)


def all_ready(c, workers: int) -> bool:
    r = c.get("/ready")
    return r.status_code == 200 and r.json()["workers_ready"] == workers


def metric(text: str, name: str, labels: str = "") -> float:
    m = re.search(rf"^{re.escape(name)}{re.escape(labels)} (\S+)$", text, re.M)
    assert m, f"{name}{labels} not in /metrics"
    return float(m.group(1))


def timed_plan(c, body: dict) -> tuple[int, float, Any]:
    t0 = time.perf_counter()
    r = c.post("/v1/plan", json=body)
    return r.status_code, time.perf_counter() - t0, r


@pytest.mark.serial  # bounds the wall time of a synchronous plan against its own
def test_a_synchronous_plan_does_not_wait_for_jobs_on_every_job_slot(tmp_path):
    """Two workers, the default share (one for jobs): with one job running and one queued,
    a synchronous Table I plan is answered within its own time (measured alone just before)
    plus a margin, far below a job's ~46 s; /ready and /metrics report the share."""
    table1 = load_example("table1")
    app = create_app(Store(tmp_path), workers=2, timeout_s=30, access=AccessPolicy())
    with api_client(app) as c:
        wait_for(lambda: all_ready(c, 2), what="two ready workers")
        assert c.get("/ready").json()["jobs"] == {"workers": 1, "running": 0, "queued": 0}
        alone = []
        for _ in range(5):
            status, seconds, r = timed_plan(c, table1)
            assert status == 200, r.text
            alone.append(seconds)
        own = statistics.median(alone)

        first = c.post("/v1/plan", json=long_job(), headers=ASYNC)
        second = c.post("/v1/plan", json=long_job(), headers=ASYNC)
        assert first.status_code == second.status_code == 202, (first.text, second.text)
        wait_for(lambda: c.get(first.headers["Location"]).json()["state"] == "running", what="the first job to run")
        # jobs on every job slot: the second one waits for the first, holding no worker
        time.sleep(0.5)
        assert c.get(second.headers["Location"]).json()["state"] == "queued"
        ready = c.get("/ready").json()
        assert ready["jobs"] == {"workers": 1, "running": 1, "queued": 1}, ready
        assert ready["pool"]["background_running"] == 1

        with_jobs = []
        for _ in range(5):
            status, seconds, r = timed_plan(c, table1)
            assert status == 200, r.text
            with_jobs.append(seconds)
        # one core plans the job meanwhile: the plan keeps the other (and the server's own share)
        assert max(with_jobs) <= 2.0 * own + 1.0, (own, with_jobs)
        assert c.get(first.headers["Location"]).json()["state"] == "running"  # the jobs were there throughout
        assert c.get(second.headers["Location"]).json()["state"] == "queued"

        text = c.get("/metrics").text
        assert metric(text, "rangeplan_job_workers") == 1
        assert metric(text, "rangeplan_jobs_in_flight", '{state="running"}') == 1
        assert metric(text, "rangeplan_jobs_in_flight", '{state="queued"}') == 1
        assert metric(text, "rangeplan_jobs_total", '{kind="plan",outcome="ok"}') == 10


@pytest.mark.serial  # bounds the time to a 503
def test_with_jobs_on_every_worker_a_synchronous_plan_is_told_busy_at_once(tmp_path):
    """One worker, so the jobs' share is every worker: a synchronous plan that finds the job on
    it is answered 503 busy with Retry-After at once (not after the job's ~46 s), counted as
    refused; a second job waits queued."""
    app = create_app(Store(tmp_path), workers=1, timeout_s=30, access=AccessPolicy())
    with api_client(app) as c:
        wait_for(lambda: all_ready(c, 1), what="a ready worker")
        job = c.post("/v1/plan", json=long_job(), headers=ASYNC)
        assert job.status_code == 202, job.text
        wait_for(lambda: c.get(job.headers["Location"]).json()["state"] == "running", what="the job to run")
        status, seconds, r = timed_plan(c, load_example("table1"))
        assert status == 503 and seconds < 1.0, (status, seconds, r.text)
        assert r.json()["error"]["code"] == "busy"
        # when the job on the worker should end (estimated ~116 s): the most a Retry-After says, not 1 s
        assert int(r.headers["Retry-After"]) == 60, r.headers["Retry-After"]
        assert "RANGEPLAN_JOB_WORKERS" in r.json()["error"]["message"]
        text = c.get("/metrics").text
        assert metric(text, "rangeplan_jobs_total", '{kind="plan",outcome="refused"}') == 1
        assert c.get("/ready").json()["jobs"] == {"workers": 1, "running": 1, "queued": 0}


def test_a_free_worker_goes_to_a_waiting_synchronous_request_before_a_waiting_job():
    """One planning process, busy; a background job starts waiting, then a synchronous request:
    when the worker is free the synchronous request runs first (the job came first), and the
    job runs after it."""
    pool = PlanPool(1, timeout_s=60, start="exec")
    try:
        wait_for(lambda: pool.readiness()["ready"], what="the worker")
        busy = PlanJob(PlanRequest.model_validate(with_settings(load_example("table1"), fastest=True, Ts=0.005)))
        short = PlanJob(PlanRequest.model_validate(load_example("table1")))
        finished: list[str] = []

        def run(name: str, job: PlanJob, background: bool) -> None:
            out = pool.run(job, background=background)
            assert out.ok, out
            finished.append(name)

        threads = [threading.Thread(target=run, args=("busy", busy, False))]
        threads[0].start()
        wait_for(lambda: pool.stats()["in_flight"] == 1, what="the busy plan")
        threads.append(threading.Thread(target=run, args=("job", short, True)))
        threads[1].start()
        wait_for(lambda: pool.stats()["background_waiting"] == 1, what="the job to wait")
        threads.append(threading.Thread(target=run, args=("sync", short, False)))
        threads[2].start()
        wait_for(lambda: pool.stats()["sync_waiting"] == 1, what="the synchronous request to wait")
        assert finished == [], "the busy plan ended before both waited: make it longer"
        for t in threads:
            t.join(60)
        assert finished == ["busy", "sync", "job"]
        assert pool.stats()["background_running"] == 0
    finally:
        pool.close()


def test_a_synchronous_request_is_refused_only_when_jobs_hold_every_worker():
    """PlanPool's rule: JobsHoldEveryWorker when every worker runs a background job, never
    while one worker runs synchronous work (then it waits its turn)."""
    pool = PlanPool(1, timeout_s=60, start="exec")
    try:
        wait_for(lambda: pool.readiness()["ready"], what="the worker")
        busy = PlanJob(PlanRequest.model_validate(with_settings(load_example("table1"), fastest=True, Ts=0.005)))
        short = PlanJob(PlanRequest.model_validate(load_example("table1")))
        job = threading.Thread(target=pool.run, args=(busy,), kwargs={"background": True})
        job.start()
        wait_for(lambda: pool.stats()["background_running"] == 1, what="the job")
        with pytest.raises(JobsHoldEveryWorker):
            pool.run(short)
        job.join(60)
        sync = threading.Thread(target=pool.run, args=(busy,))
        sync.start()
        wait_for(lambda: pool.stats()["in_flight"] == 1, what="the synchronous plan")
        assert pool.run(short).ok  # waited for the synchronous one, not refused
        sync.join(60)
    finally:
        pool.close()


def test_renewing_the_workers_waits_for_a_job_without_holding_a_worker():
    """renew() (after the background compile) waits for a running job before it takes any
    worker: a synchronous plan meanwhile is served by the free worker and ends before the
    job; no job starts while renew waits; afterwards every worker is new and plans."""
    pool = PlanPool(2, timeout_s=60, start="exec")
    try:
        wait_for(lambda: pool.readiness()["workers_ready"] == 2, what="the workers")
        busy = PlanJob(PlanRequest.model_validate(with_settings(load_example("table1"), fastest=True, Ts=0.005)))
        short = PlanJob(PlanRequest.model_validate(load_example("table1")))
        before = {w.pid for w in pool._workers}
        finished: list[str] = []

        def run(name: str, job: PlanJob, background: bool) -> None:
            assert pool.run(job, background=background).ok
            finished.append(name)

        job = threading.Thread(target=run, args=("job", busy, True))
        job.start()
        wait_for(lambda: pool.stats()["background_running"] == 1, what="the job")
        renew = threading.Thread(target=pool.renew)
        renew.start()
        time.sleep(0.2)
        second = threading.Thread(target=run, args=("second job", short, True))
        second.start()
        wait_for(lambda: pool.stats()["background_waiting"] == 1, what="the second job to wait")
        run("sync", short, False)
        assert finished == ["sync"], "the synchronous plan waited for the job (renew held the free worker)"
        assert pool.stats()["background_waiting"] == 1  # no job starts while renew waits
        for t in (job, renew, second):
            t.join(60)
        assert finished == ["sync", "job", "second job"] and pool.renewed == 1
        assert not before & {w.pid for w in pool._workers}
        assert pool.run(short).ok
    finally:
        pool.close()
