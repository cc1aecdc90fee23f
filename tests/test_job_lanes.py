"""The service's lanes as a CAD tool meets them (issues 33 goal 2, 35 goal 6):

* ``Retry-After`` says when to come back: a job's (its 202, ``GET /v1/jobs/{id}`` while it
  runs) is its expected end, from its work estimate and progress and the work queued ahead of
  it over the jobs' workers, within 1-60 s; a busy 503's is when the first slot is expected to
  free (the running work's time left);
* a short synchronous ``POST /v1/contour`` is estimated before it is queued, on a synchronous
  worker, so it is answered 200 while long jobs hold the jobs' workers, and a 100 000-line
  program is estimated there with ``/health`` answering within 1 s throughout.

The long jobs are plans of Table I with ``fastest`` (estimated 17 s and 116 s; ~7 and ~46 CPU
s), killed when each test closes its pool or server.
"""

from __future__ import annotations

import math
import statistics
import threading
import time

import httpx
import pytest

from app.api import create_app
from app.job_progress import RETRY_MAX_S, first_free, job_wait, retry_after, row_left, time_left
from app.security import AccessPolicy
from app.storage import Store
from tests.support import api_client, load_example, with_settings
from tests.test_edges_stream import LATENCY_LIMIT_S, Probe
from tests.test_job_share import all_ready, long_job, wait_for
from tests.test_jobs_api import BODY
from tests.test_server_process import Server, free_port

ASYNC = {"Prefer": "respond-async"}


def medium_job() -> dict:
    """A plan admitted as a job, estimated at ~17 s (runs ~7 CPU s)."""
    return with_settings(load_example("table1"), fastest=True, Ts=0.002)


def row(id_: str, state: str, estimate_s: float | None, started: float | None = None, done: int = 0,
        total: int | None = None, updated: float | None = None) -> dict:
    return {"id": id_, "state": state, "estimate_s": estimate_s, "started": started, "done": done, "total": total,
            "updated": updated if updated is not None else started}


def test_the_wait_rule_counts_the_work_ahead_over_the_workers():
    now = 1000.0
    rows = [row("a", "running", 20.0, started=now - 5), row("b", "queued", 10.0), row("c", "queued", 4.0),
            row("d", "queued", None)]
    # a running job: its estimate less what it ran
    assert job_wait(rows, "a", 1, now) == pytest.approx(15.0)
    # queued: the work ahead (15 s left of a, 10 s of b) over the workers, then its own 4 s
    assert job_wait(rows, "c", 1, now) == pytest.approx(15 + 10 + 4)
    assert job_wait(rows, "c", 2, now) == pytest.approx((15 + 10) / 2 + 4)
    # unknown estimate: its own part counts 0, the queue ahead still counts
    assert job_wait(rows, "d", 1, now) == pytest.approx(15 + 10 + 4)
    assert job_wait(rows, "gone", 1, now) is None
    # a job with measured progress: the time per unit measured, not the estimate
    progressed = row("p", "running", 100.0, started=now - 10, done=5, total=10, updated=now)
    assert row_left(progressed, now) == pytest.approx(10 / 5 * (5 + 0.3 * 10))
    # the first slot to free: the least time left of the running jobs and of the synchronous requests
    assert first_free(rows, now) == pytest.approx(15.0)
    assert first_free(rows, now, [2.5, 7.0]) == pytest.approx(2.5)
    assert first_free([row("q", "queued", 9.0)], now) is None
    # the header: whole seconds, rounded up, 1-60 s
    assert [retry_after(s) for s in (None, math.nan, 0.0, 0.2, 1.0, 1.01, 59.5, 60.0, 1e9)] == \
        [1, 1, 1, 1, 1, 2, 60, 60, RETRY_MAX_S]
    # it grows with the estimate
    waits = [retry_after(job_wait([row("x", "running", e, started=now)], "x", 1, now)) for e in (0.5, 3, 17, 45, 116)]
    assert waits == sorted(waits) and waits[0] == 1 and waits[-1] == RETRY_MAX_S and len(set(waits)) == 5


def test_a_running_job_never_says_no_time_left():
    """A unit that takes longer than the mean keeps a positive time left (a tenth of a unit's
    time), where the measured rule alone gave 0 s while the job still ran (seen on a loaded
    machine: ``eta_s`` 0 before the last pass ended); the rule itself unchanged otherwise."""
    # 2 of 4 passes done in 2 s (1 s a pass), the last done at t = 2
    assert time_left(2, 4, 0.0, 2.0, 2.0, 8.0) == pytest.approx(1.0 * (2 + 0.3 * 4))
    assert time_left(2, 4, 0.0, 2.0, 3.0, 8.0) == pytest.approx(1.0 * (2 + 0.3 * 4) - 1.0)
    for late in (10.0, 100.0):  # the third pass overruns the mean by far
        assert time_left(2, 4, 0.0, 2.0, 2.0 + late, 8.0) == pytest.approx(0.1)
    assert time_left(4, 4, 0.0, 4.0, 50.0, 8.0) == pytest.approx(0.1)  # the join after the passes


def test_retry_after_says_when_a_job_ends_and_when_a_slot_frees(tmp_path):
    """One worker (the jobs' share is every worker). A short job's 202 says 1 s; a 17 s job's its
    estimate; a job queued behind it more; while the 17 s job runs, a synchronous plan is told
    busy with the time left of that job, not 1 s."""
    app = create_app(Store(tmp_path), workers=1, timeout_s=30, access=AccessPolicy())
    with api_client(app) as c:
        wait_for(lambda: all_ready(c, 1), what="a ready worker")
        short = c.post("/v1/plan", json=load_example("table1"), headers=ASYNC)
        assert short.status_code == 202, short.text
        assert short.headers["Retry-After"] == "1"  # estimated at 0.05 s
        wait_for(lambda: c.get(short.headers["Location"]).json()["state"] == "done", what="the short job")

        medium = c.post("/v1/plan", json=medium_job(), headers=ASYNC)
        assert medium.status_code == 202, medium.text
        est = medium.json()["estimate_s"]
        assert 10 < est < 30, est
        first = int(medium.headers["Retry-After"])
        assert est <= first <= est + 2, (first, est)  # its own estimate: nothing ahead of it

        long = c.post("/v1/plan", json=long_job(), headers=ASYNC)
        assert long.status_code == 202, long.text
        assert int(long.headers["Retry-After"]) == RETRY_MAX_S  # 116 s of its own, behind ~17 s

        wait_for(lambda: c.get(medium.headers["Location"]).json()["state"] == "running", what="the 17 s job")
        r = c.get(medium.headers["Location"])
        status = r.json()
        assert status["state"] == "running"
        running = int(r.headers["Retry-After"])
        assert 1 < running <= first and abs(running - math.ceil(status["eta_s"])) <= 1, (running, status)
        queued = c.get(long.headers["Location"])
        assert queued.json()["state"] == "queued" and int(queued.headers["Retry-After"]) == RETRY_MAX_S

        # every worker on a job: a synchronous plan is told busy, and when the 17 s job should end
        busy = c.post("/v1/plan", json=load_example("table1"))
        assert busy.status_code == 503 and busy.json()["error"]["code"] == "busy", busy.text
        left = c.get(medium.headers["Location"]).json()["eta_s"]
        assert 1 < int(busy.headers["Retry-After"]) and abs(int(busy.headers["Retry-After"]) - left) <= 2, \
            (busy.headers["Retry-After"], left)


def test_a_full_queue_says_when_the_synchronous_work_ends(tmp_path):
    """One worker and no queue (``max_queue`` 0): while a synchronous 17 s plan runs (``Prefer:
    wait=30``), the next plan finds no place and is told busy with the time left of the one
    running (its estimate less its time so far), not 1 s."""
    app = create_app(Store(tmp_path), workers=1, timeout_s=30, max_queue=0, access=AccessPolicy())
    with api_client(app) as c:
        wait_for(lambda: all_ready(c, 1), what="a ready worker")
        answers: list = []
        first = threading.Thread(target=lambda: answers.append(
            c.post("/v1/plan", json=medium_job(), headers={"Prefer": "wait=30"})))
        first.start()
        try:
            wait_for(lambda: app.state.service.stats()["in_flight"] == 1, what="the 17 s plan on the worker")
            busy = c.post("/v1/plan", json=load_example("table1"))
            left = app.state.service.sync_left()
            assert busy.status_code == 503 and busy.json()["error"]["code"] == "busy", busy.text
            assert len(left) == 1 and left[0] > 5, left
            assert 1 < int(busy.headers["Retry-After"]) and abs(int(busy.headers["Retry-After"]) - left[0]) <= 2, \
                (busy.headers["Retry-After"], left)
        finally:
            first.join(300)
        # it held the place throughout (200, or a timeout on a machine loaded beyond its 30 s)
        assert answers and answers[0].status_code in (200, 422), answers
        assert app.state.service.sync_left() == []


def hundred_thousand_lines() -> str:
    """A program of 100 000 rapid lines and a short pass (1.4 MB: within the 2 MB a program may
    have; its read and estimate take ~5 s, estimated at ~5.7 s of work)."""
    import numpy as np

    from tests.contour_programs import rapids

    return rapids(np.random.default_rng(0), 100_000).text


def test_a_contour_whose_read_outlasts_the_synchronous_limit_becomes_a_job(tmp_path):
    """A 1 s synchronous limit: reading the 100 000-line program on the synchronous worker
    outlasts it (~4 CPU s), so the contour becomes a job (202 at once, estimated and run by the
    job's worker under the jobs' limit), not a timeout."""
    app = create_app(Store(tmp_path), workers=1, timeout_s=1, access=AccessPolicy())
    with api_client(app) as c:
        wait_for(lambda: all_ready(c, 1), what="a ready worker")
        r = c.post("/v1/contour", json={"program": hundred_thousand_lines(), "feed": "program"})
        assert r.status_code == 202, r.text
        assert r.json()["kind"] == "contour" and "Preference-Applied" not in r.headers
        url = r.headers["Location"]
        wait_for(lambda: c.get(url).json()["estimate_s"] is not None, what="the job's worker to estimate it")
        status = c.get(url).json()
        assert status["state"] in ("running", "done") and status["estimate_s"] > 1, status


@pytest.mark.serial  # bounds the wall time of a synchronous contour and /health's latency
def test_a_short_contour_is_answered_while_jobs_hold_the_job_workers(tmp_path):
    """Two workers, one for jobs. With a long job running there and another queued, a short
    contour (the 4-pass square, ~2 s) is answered 200 within its own time plus a margin, far
    below the jobs' ~46 s; a 100 000-line program with ``Prefer: wait=1`` is estimated on a
    synchronous worker and answered 202 with its estimate, before the long job ends, with
    ``/health`` answering within 1 s throughout."""
    server = Server(tmp_path, free_port(), {"RANGEPLAN_WORKERS": "2", "RANGEPLAN_PLAN_TIMEOUT_S": "30"})
    try:
        with httpx.Client(base_url=server.url, timeout=120) as c:
            wait_for(lambda: all_ready(c, 2), what="two ready workers")
            alone = []
            for _ in range(3):
                t0 = time.perf_counter()
                r = c.post("/v1/contour", json=BODY)
                assert r.status_code == 200, r.text
                alone.append(time.perf_counter() - t0)
            own = statistics.median(alone)

            jobs = [c.post("/v1/plan", json=long_job(), headers=ASYNC) for _ in range(2)]
            assert all(j.status_code == 202 for j in jobs), [j.text for j in jobs]
            wait_for(lambda: c.get(jobs[0].headers["Location"]).json()["state"] == "running", what="the job to run")
            assert c.get(jobs[1].headers["Location"]).json()["state"] == "queued"

            with Probe(server.url, "/health") as health:
                t0 = time.perf_counter()
                r = c.post("/v1/contour", json=BODY)
                seconds = time.perf_counter() - t0
                assert r.status_code == 200, r.text  # (it waited behind the jobs and became a job: 202)
                assert r.json()["contour"]["cycle_time_s"] > 0
                assert seconds <= 2.0 * own + 2.0, (own, alone, seconds)

                t0 = time.perf_counter()
                big = c.post("/v1/contour", json={"program": hundred_thousand_lines(), "feed": "program"},
                             headers={"Prefer": "wait=1"})
                big_s = time.perf_counter() - t0
            assert big.status_code == 202, big.text
            est = big.json()["estimate_s"]
            assert est is not None and est > 1, big.json()  # estimated before it was queued
            assert big.json()["state"] == "queued"  # behind the two long jobs
            assert int(big.headers["Retry-After"]) == RETRY_MAX_S  # behind ~116 s of estimated work
            assert c.get(jobs[0].headers["Location"]).json()["state"] == "running", "the long job ended first"
            assert health.count > 0 and health.worst < LATENCY_LIMIT_S, (health.worst, health.count, big_s)
            print(f"contour alone {own:.2f} s, beside the jobs {seconds:.2f} s; 100 000 lines estimated in {big_s:.2f} "
                  f"s ({est:.2f} s of work); /health worst {health.worst:.3f} s of {health.count}")
    finally:
        server.stop()
