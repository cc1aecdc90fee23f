"""The one executor interface (app.executors.JobExecutor): ``submit`` answers what ``run``
answers, a future per job (what the batches' dispatcher keeps several of in flight); a local
pool's submitted job past its limit is a JobTimeout and its process replaced, a job not yet sent
can be withdrawn, a closed pool refuses. (On Dask: tests/test_batch_cluster.py.)"""

from __future__ import annotations

import json
import threading
from concurrent.futures import CancelledError

import pytest

from app.executors import InProcessExecutor, JobExecutor
from app.jobs import PlanJob, SleepJob
from app.workers import JobTimeout, PlanPool, PoolBusy
from planner.schema import PlanRequest
from tests.support import TABLE1


@pytest.fixture(scope="module")
def pool():
    p = PlanPool(1, timeout_s=30.0, memory_mb=0)
    try:
        yield p
    finally:
        p.close(cancel=True)


def _trajectory(done) -> dict:
    doc = json.loads(done.payload)
    return {k: doc[k] for k in ("pose", "velocity", "drives")}


@pytest.mark.parametrize("which", ["inline", "pool"])
def test_submit_answers_what_run_answers(which, pool):
    ex: JobExecutor = InProcessExecutor() if which == "inline" else pool
    assert isinstance(ex, JobExecutor)
    job = PlanJob(PlanRequest.model_validate(TABLE1))
    ran = ex.run(job)
    fut = ex.submit(job)
    got = fut.result(300)
    assert ran.ok and got.ok and fut.done()
    assert _trajectory(got) == _trajectory(ran)  # the same plan, the same serialisation
    assert {k: v for k, v in got.summary.items() if k != "compute_ms"} == \
        {k: v for k, v in ran.summary.items() if k != "compute_ms"}
    assert got.summary["duration_s"] > 0 and got.summary["steps"] > 0


@pytest.mark.slow
def test_pool_submit_cuts_a_job_at_its_limit_and_withdraws_one_not_sent():
    p = PlanPool(1, timeout_s=0.0, memory_mb=0)
    try:
        assert p.submit(SleepJob(0.01)).result(300).ok  # its worker started
        first = p._workers[0].pid
        slow = p.submit(SleepJob(60.0), 1.0)
        queued = p.submit(SleepJob(0.01))
        withdrawn = p.submit(SleepJob(0.01))
        assert withdrawn.cancel()  # one worker, one job sent at a time: the others wait here
        with pytest.raises(JobTimeout):
            slow.result(120)
        assert queued.result(120).ok  # run by the process that replaced the killed one
        assert p._workers[0].pid != first and p.replaced == 1
        with pytest.raises(CancelledError):
            withdrawn.result(0)
        assert p.jobs_run == 3  # the started one, the cut one, the queued one: never the withdrawn
    finally:
        p.close(cancel=True)
    with pytest.raises(PoolBusy, match="shutting down"):
        p.submit(SleepJob(0.01)).result(10)


def test_admission_reads_the_capacity_outside_its_lock():
    """A cluster's capacity asks its scheduler on the client's event loop, whose thread also
    releases finished jobs (DaskExecutor.submit's callback) under the admission's lock: reading
    the capacity under that lock deadlocked a batch on Dask (found by benchmarks/bench_batch_trees.py)."""
    from app.workers import Admission

    class Cluster(Admission):
        def __init__(self):
            self._lock, self._inflight, self._closed, self.jobs_run = threading.Lock(), 1, False, 0
            self.released_meanwhile = False

        @property
        def capacity(self):
            loop = threading.Thread(target=self._release)  # a job finishing while the capacity is asked
            loop.start()
            loop.join(5)
            self.released_meanwhile = not loop.is_alive()
            return 4

    c = Cluster()
    c._admit()
    assert c.released_meanwhile and c._inflight == 1 and c.jobs_run == 1
