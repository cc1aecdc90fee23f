"""Batches on Dask: a real ``distributed.LocalCluster`` (2 worker processes) and a scheduler
and 2 workers started with the ``dask`` command line in separate processes on loopback. The
CLI and the HTTP API run on them; results equal ``rangeplan plan``; a worker killed
mid-batch loses no item; a bad item is reported with its code and the rest finish."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest

from app.api import create_app
from app.storage import Store
from tests.batch_support import (
    BAD_RANGE,
    CLI,
    UNREACHABLE,
    assert_same_plan,
    env,
    read_summary,
    single_plan,
    variant,
    write_jsonl,
)
from tests.support import api_client

distributed = pytest.importorskip("distributed")

pytestmark = pytest.mark.slow


def _dask_cmd() -> list[str]:
    import shutil
    import sys

    exe = Path(sys.executable).parent / "dask"
    if exe.exists():
        return [str(exe)]
    found = shutil.which("dask")
    assert found, "the dask command line (package distributed) is not installed"
    return [found]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def worker_pids(address: str) -> dict[str, int]:
    with distributed.Client(address, timeout="20s") as c:
        return c.run(os.getpid)


def kill_one_worker_after(outdir: Path, address: str, n_done: int, killed: list) -> threading.Thread:
    """A thread that SIGKILLs one worker process once ``n_done`` rows are in the summary, a
    worker that has finished items of this batch (a worker still starting under load, which
    the scheduler has given nothing yet, would test nothing); ``killed`` gets ``(address, pid,
    rows finished at that moment)``."""

    def run():
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            s = outdir / "summary.csv"
            if s.exists() and len(s.read_text().splitlines()) > n_done:
                working = {row["worker"] for row in read_summary(outdir)}
                busy = sorted((a, p) for a, p in worker_pids(address).items() if a in working)
                if busy:
                    addr, pid = busy[0]
                    os.kill(pid, signal.SIGKILL)
                    killed.append((addr, pid, len(s.read_text().splitlines()) - 1))
                    return
            time.sleep(0.05)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def check_batch(outdir: Path, n: int, bad: dict[str, str], tmp: Path, compare: dict[str, dict]) -> list[dict]:
    rows = read_summary(outdir)
    assert len(rows) == n
    for row in rows:
        if row["key"] in bad:
            assert row["status"] == "error" and row["error_code"] == bad[row["key"]], row
        else:
            assert row["status"] == "ok", row
            assert row["engine"] == "dask" and row["worker"].startswith("tcp://127.0.0.1:")
    for key, request in compare.items():
        assert_same_plan(json.loads((outdir / f"{key}.json").read_text()), single_plan(request, tmp))
    return rows


# ---------------------------------------------------------------------------------------
# a LocalCluster

@pytest.fixture(scope="module")
def local_cluster():
    from distributed import LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=None, env={"PYTHONPATH": env()["PYTHONPATH"],
                                                        "OPENBLAS_NUM_THREADS": "1"})
    try:
        yield cluster
    finally:
        cluster.close()


def test_cli_on_a_local_cluster_with_a_worker_killed_mid_batch(local_cluster, tmp_path):
    address = local_cluster.scheduler_address
    reqs = [variant(i % 6, "constrained") for i in range(20)]
    reqs[5], reqs[11] = BAD_RANGE, UNREACHABLE
    study = write_jsonl(tmp_path / "s.jsonl", reqs)
    out = tmp_path / "out"
    killed: list = []
    t = kill_one_worker_after(out, address, 4, killed)
    r = subprocess.run([*CLI, "batch", str(study), "-o", str(out), "--scheduler", address, "--progress", "lines"],
                       capture_output=True, text=True, env=env(), timeout=600)
    t.join(5)
    assert r.returncode == 1, r.stderr  # the two bad items
    assert killed and killed[0][2] < 20, killed  # killed while items were still to come
    rows = check_batch(out, 20, {"s-000006": "invalid_input", "s-000012": "unreachable"}, tmp_path,
                       {"s-000001": reqs[0], "s-000003": reqs[2]})
    assert {r_["worker"] for r_ in rows if r_["status"] == "ok"} >= {killed[0][0]} or len(
        {r_["worker"] for r_ in rows}) >= 2
    assert "on dask: " in r.stderr
    # the workers share this host's filesystem: they wrote every result themselves
    assert "18 result files written by the Dask workers" in r.stderr and "0 sent back" in r.stderr, r.stderr
    assert not list(out.glob(".rangeplan-staging-*"))


def test_warm_up_plugin_relaxes_the_nannys_malloc_trim(local_cluster):
    """Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536; the plugin raises glibc's
    thresholds there (a ~80 ms constrained plan took 93 ms of CPU before, 80 ms after, as in a
    pool; benchmarks/README.md)."""
    from app.batch import cluster as cl

    engine = cl.DaskEngine(local_cluster.scheduler_address)
    try:
        env = engine.client.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_"))
        state = engine.client.run(lambda: cl.STATE["malloc"])
    finally:
        engine.close()
    assert set(env.values()) == {"65536"}
    assert set(state.values()) == {True}


def test_a_job_past_its_limit_is_cut_on_a_dask_worker_which_plans_the_next(local_cluster):
    """On a Dask worker the job runs in a planning process of the worker (a child of it),
    killed at the limit; the worker (same pid, same address) plans the next item."""
    from app.batch.engine import plan_item
    from app.executors import run_bounded
    from app.jobs import SleepJob
    from tests.batch_support import planning_children, worker_pid

    with distributed.Client(local_cluster.scheduler_address, timeout="20s") as c:
        addr = sorted(local_cluster.scheduler_info["workers"])[0]

        def on(fn, *args):
            return c.submit(fn, *args, workers=[addr], pure=False).result(300)

        pid = on(worker_pid)
        assert on(run_bounded, SleepJob(0.05), 30.0).ok
        child = on(planning_children)
        assert child and pid not in child
        t0 = time.perf_counter()
        out = on(run_bounded, SleepJob(120.0), 1.0)
        assert not out.ok and out.error.code == "timeout", out
        assert time.perf_counter() - t0 < 20.0
        assert on(worker_pid) == pid and c.run(os.getpid)[addr] == pid
        assert not set(on(planning_children)) & set(child)
        res = on(plan_item, variant(3), "json", 60.0)
    assert res["status"] == "ok" and res["worker"] == addr and res["pid"] == pid
    assert_same_plan(json.loads(bytes(res["payload"])), json.loads(plan_item(variant(3))["payload"]))


def test_contour_items_on_a_local_cluster_equal_direct_plans_and_resume(local_cluster, tmp_path):
    """Contour requests (G-code programs) beside plan requests on Dask: each contour item's
    result is the program contoured directly (same contour metrics), the refused program is
    that item's error naming the line, and a second run skips every item done."""
    from app.batch.cli import run_batch
    from tests.batch_support import assert_same_contour, contour_items

    contours = contour_items()
    reqs = [contours[0], variant(4), contours[3], contours[1], contours[2]]
    study = write_jsonl(tmp_path / "cam.jsonl", reqs)
    out = tmp_path / "out"
    res = run_batch([str(study)], out, scheduler=local_cluster.scheduler_address, progress="none", timeout_s=120)
    assert (res["ok"], res["failed"], res["engine"]) == (4, 1, "dask"), res
    rows = {r["key"]: r for r in read_summary(out)}
    workers = set(local_cluster.scheduler_info["workers"])
    for i in (1, 4, 5):
        row = rows[f"cam-{i:06d}"]
        assert row["kind"] == "contour" and row["engine"] == "dask" and row["worker"] in workers, row
        result = json.loads((out / row["file"]).read_text())
        assert_same_contour(result, reqs[i - 1])
        assert float(row["max_deviation_m"]) == result["contour"]["max_deviation_m"]
    assert rows["cam-000002"]["kind"] == "plan" and rows["cam-000002"]["status"] == "ok"
    assert rows["cam-000003"]["error_code"] == "invalid_input" and "line 11" in rows["cam-000003"]["error_message"]
    again = run_batch([str(study)], out, scheduler=local_cluster.scheduler_address, progress="none", timeout_s=120)
    assert (again["skipped"], again["ok"], again["failed"]) == (5, 0, 0), again


def test_api_on_a_local_cluster(local_cluster, tmp_path, monkeypatch):
    monkeypatch.setenv("RANGEPLAN_DASK_SCHEDULER", local_cluster.scheduler_address)
    app = create_app(Store(tmp_path), workers=1)
    reqs = [variant(0), BAD_RANGE, variant(1, "constrained"), variant(2)]
    with api_client(app) as c:
        bid = c.post("/v1/batches", json={"requests": reqs}).json()["id"]
        items = [json.loads(ln) for ln in c.get(f"/v1/batches/{bid}/results?wait=true").text.splitlines()]
        p = c.get(f"/v1/batches/{bid}").json()
    assert p["state"] == "done" and p["ok"] == 3 and p["failed"] == 1
    assert [it["status"] for it in items] == ["ok", "error", "ok", "ok"]
    assert items[1]["error"]["code"] == "invalid_input" and items[1]["error"]["field"] == "segments[0].lower"
    workers = set(local_cluster.scheduler_info["workers"])
    assert all(it["engine"] == "dask" and it["worker"] in workers for it in items if it["status"] == "ok")
    assert_same_plan(items[2]["result"], single_plan(reqs[2], tmp_path))


# ---------------------------------------------------------------------------------------
# the service's jobs on the cluster (RANGEPLAN_EXECUTOR=dask)

def test_plans_over_http_run_on_dask_workers_with_the_local_result(local_cluster, tmp_path, monkeypatch):
    """POST /v1/plan and POST /v1/contour with RANGEPLAN_EXECUTOR=dask: planned on a Dask worker
    (in its planning process), the same result as planned here, stored as usual."""
    from planner import plan
    from planner.contour import plan_contour
    from tests.batch_support import assert_same_contour, contour_items, jobs_run_here

    monkeypatch.setenv("RANGEPLAN_DASK_SCHEDULER", local_cluster.scheduler_address)
    monkeypatch.setenv("RANGEPLAN_EXECUTOR", "dask")
    with distributed.Client(local_cluster.scheduler_address, timeout="20s") as c:
        before = c.run(jobs_run_here)
    app = create_app(Store(tmp_path), timeout_s=120)
    with api_client(app) as client:
        assert client.get("/ready").status_code == 200
        r = client.post("/v1/plan", json=variant(5, "constrained"))
        assert r.status_code == 200, r.text
        assert_same_plan(r.json(), plan(variant(5, "constrained")).to_json_dict())
        stored = client.get(f"/v1/plans/{r.headers['X-Plan-Id']}")
        assert stored.status_code == 200 and stored.json()["metrics"] == r.json()["metrics"]
        good = contour_items()[0]
        rc = client.post("/v1/contour", json=good)
        assert rc.status_code == 200, rc.text
        assert_same_contour(rc.json(), good)
        bad = client.post("/v1/plan", json=UNREACHABLE)  # the planner's error, from the worker
        assert bad.status_code == 422 and bad.json()["error"]["code"] == "unreachable", bad.text
        stats = app.state.service.stats()
    assert stats["mode"] == "dask" and stats["scheduler"] == local_cluster.scheduler_address
    with distributed.Client(local_cluster.scheduler_address, timeout="20s") as c:
        after = c.run(jobs_run_here)
    assert sum(after.values()) - sum(before.values()) == 3  # each job (plan, contour, unreachable) ran on a worker
    assert plan_contour(good).contour.max_deviation_m == rc.json()["contour"]["max_deviation_m"]


def test_service_on_dask_cuts_a_job_at_its_limit_and_plans_the_next(local_cluster):
    from app.cluster import DaskExecutor
    from app.jobs import PlanJob, SleepJob
    from app.service import JobService
    from planner.schema import PlanRequest

    svc = JobService(DaskExecutor(local_cluster.scheduler_address, timeout_s=2.0, max_queue=2))
    try:
        assert svc.readiness()["ready"] and svc.readiness()["workers"] == 2
        t0 = time.perf_counter()
        out = svc.run(SleepJob(60.0))
        assert not out.ok and out.error.code == "timeout" and "2 s" in out.error.message, out
        assert time.perf_counter() - t0 < 30
        done = svc.run(PlanJob(PlanRequest.model_validate(variant(6)), "none"))
        assert done.ok and done.summary["duration_s"] > 0
        # more jobs than the cluster's 2 threads + 2 waiting: the rest are busy (503), not queued forever
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(8) as ex:
            outs = list(ex.map(lambda _: svc.run(SleepJob(1.0)), range(8)))
        codes = sorted(o.error.code if not o.ok else "ok" for o in outs)
        assert codes.count("busy") >= 1 and codes.count("ok") >= 4, codes
    finally:
        svc.close()


def test_dask_executor_without_a_scheduler_is_a_clear_error(monkeypatch):
    from app.service import JobService

    monkeypatch.delenv("RANGEPLAN_DASK_SCHEDULER", raising=False)
    with pytest.raises(ValueError, match="RANGEPLAN_DASK_SCHEDULER"):
        JobService.start(1, 30.0, 4, mode="dask")
    with pytest.raises(OSError, match=f"cannot reach the Dask scheduler at {UNREACHABLE_ADDRESS}"):
        JobService.start(1, 30.0, 4, mode="dask", scheduler=UNREACHABLE_ADDRESS)


UNREACHABLE_ADDRESS = "tcp://127.0.0.1:9"


# ---------------------------------------------------------------------------------------
# a scheduler and workers started with the dask command line

@pytest.fixture(scope="module")
def dask_cli_cluster(tmp_path_factory):
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    log = tmp_path_factory.mktemp("dask")
    e = env()
    procs = [subprocess.Popen([*_dask_cmd(), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], env=e, stdout=subprocess.DEVNULL,
                              stderr=open(log / "scheduler.log", "w"))]
    procs.append(subprocess.Popen([*_dask_cmd(), "worker", address, "--nworkers", "2", "--nthreads", "1",
                                   "--host", "127.0.0.1", "--no-dashboard", "--memory-limit", "0"],
                                  env=e, stdout=subprocess.DEVNULL, stderr=open(log / "workers.log", "w")))
    try:
        deadline = time.monotonic() + 120
        while True:
            try:
                with distributed.Client(address, timeout="5s") as c:
                    c.wait_for_workers(2, timeout=max(1, deadline - time.monotonic()))
                break
            except (OSError, TimeoutError):
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        yield address
    finally:
        for p in reversed(procs):
            p.send_signal(signal.SIGINT)
        for p in reversed(procs):
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def test_cli_on_dask_cli_processes_with_a_worker_killed_mid_batch(dask_cli_cluster, tmp_path):
    reqs = [variant(i % 6, "constrained" if i % 2 else "paper") for i in range(24)]
    reqs[3] = UNREACHABLE
    study = write_jsonl(tmp_path / "s.jsonl", reqs)
    out = tmp_path / "out"
    killed: list = []
    t = kill_one_worker_after(out, dask_cli_cluster, 3, killed)
    r = subprocess.run([*CLI, "batch", str(study), "-o", str(out), "--progress", "lines"], capture_output=True,
                       text=True, env={**env(), "RANGEPLAN_DASK_SCHEDULER": dask_cli_cluster}, timeout=600)
    t.join(5)
    assert r.returncode == 1, r.stderr
    assert killed and killed[0][2] < 24, killed
    check_batch(out, 24, {"s-000004": "unreachable"}, tmp_path, {"s-000001": reqs[0], "s-000002": reqs[1]})
    assert "23 result files written by the Dask workers" in r.stderr and "0 sent back" in r.stderr, r.stderr
    # the nanny restarted the killed worker: the cluster is whole again, and warm
    with distributed.Client(dask_cli_cluster, timeout="20s") as c:
        c.wait_for_workers(2, timeout=60)
        assert killed[0][1] not in c.run(os.getpid).values()


def test_api_on_dask_cli_processes(dask_cli_cluster, tmp_path, monkeypatch):
    monkeypatch.setenv("RANGEPLAN_DASK_SCHEDULER", dask_cli_cluster)
    app = create_app(Store(tmp_path), workers=1)
    reqs = [variant(i) for i in range(6)]
    with api_client(app) as c:
        r = c.post("/v1/batches", content="".join(json.dumps(q) + "\n" for q in reqs),
                   headers={"Content-Type": "application/x-ndjson"})
        assert r.status_code == 202
        items = [json.loads(ln) for ln in c.get(f"/v1/batches/{r.json()['id']}/results?wait=true").text.splitlines()]
        ready = c.get("/ready").json()
    assert [it["item"] for it in items] == list(range(6)) and all(it["status"] == "ok" for it in items)
    assert all(it["engine"] == "dask" for it in items)
    assert ready["pool"]["in_flight"] == 0
    assert_same_plan(items[4]["result"], single_plan(reqs[4], tmp_path))
