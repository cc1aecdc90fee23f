"""Child processes end with the server (issue 21): ``kill -9`` of a real ``rangeplan serve``
that has planning workers, batch workers and multiprocessing's resource tracker running
leaves none of them alive 10 s later (before: the batch worker and the resource tracker
survived every crash). Also the JSON log lines of the real server, with request ids."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import psutil
import pytest

from app.lifeline import watch_parent
from tests.test_server_process import free_port

ROOT = Path(__file__).resolve().parent.parent
TABLE1 = json.loads((ROOT / "app" / "static" / "examples" / "table1.json").read_text())


def alive(pids: list[int]) -> list[int]:
    """The pids of ``pids`` still running (a zombie waiting for its new parent to reap it is not)."""
    out = []
    for pid in pids:
        try:
            if psutil.Process(pid).status() != psutil.STATUS_ZOMBIE:
                out.append(pid)
        except psutil.NoSuchProcess:
            pass
    return out


@pytest.mark.slow
def test_kill_9_of_the_server_leaves_no_child_alive(tmp_path):
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("RANGEPLAN_")}
    env.update({"RANGEPLAN_DATA_DIR": str(tmp_path), "RANGEPLAN_WORKERS": "1", "RANGEPLAN_BATCH_WORKERS": "1",
                "PYTHONPATH": str(ROOT)})
    log = open(tmp_path / "server.log", "w+")
    server = subprocess.Popen([sys.executable, "-m", "app.cli", "serve", "--port", str(port), "--no-editor"],
                              env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=log)
    url = f"http://127.0.0.1:{port}"
    children: list[int] = []
    try:
        deadline = time.monotonic() + 180
        while True:
            assert server.poll() is None and time.monotonic() < deadline, "the server did not become ready"
            try:
                if httpx.get(f"{url}/ready", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            time.sleep(0.3)
        # a batch starts the batch engine (its worker process and the resource tracker)
        r = httpx.post(f"{url}/v1/batches", json={"requests": [TABLE1, TABLE1]}, timeout=30,
                       headers={"X-Request-ID": "batch-1"})
        assert r.status_code == 202 and r.headers["x-request-id"] == "batch-1"
        while httpx.get(f"{url}/v1/batches/{r.json()['id']}", timeout=30).json()["state"] != "done":
            assert time.monotonic() < deadline + 120
            time.sleep(0.5)
        metrics = httpx.get(f"{url}/metrics", timeout=30).text
        assert 'rangeplan_batch_items{status="ok"} 2.0' in metrics
        children = [p.pid for p in psutil.Process(server.pid).children(recursive=True)]
        cmdlines = " | ".join(" ".join(psutil.Process(p).cmdline()) for p in children)
        # the planning workers are forks of multiprocessing's fork server (app.worker_template),
        # the batch workers fresh interpreters of the batch engine's PlanPool (start="exec")
        assert "forkserver" in cmdlines and "-m app.workers" in cmdlines, cmdlines
        fork_servers = [p for p in psutil.Process(server.pid).children() if "forkserver" in " ".join(p.cmdline())]
        assert len(fork_servers) == 1 and len(fork_servers[0].children()) == 1, cmdlines  # RANGEPLAN_WORKERS=1
        assert "resource_tracker" in cmdlines, cmdlines
    finally:
        server.send_signal(signal.SIGKILL)
        server.wait(10)
    t0 = time.monotonic()
    while alive(children) and time.monotonic() - t0 < 10:
        time.sleep(0.1)
    left = alive(children)
    for pid in left:  # do not leak them into the rest of the suite
        os.kill(pid, signal.SIGKILL)
    assert not left, f"alive 10 s after kill -9 of the server: {left}"
    # the log is JSON lines, the batch request's line with the client's request id
    log.seek(0)
    lines = [json.loads(ln) for ln in log.read().splitlines() if ln.startswith("{")]
    access = [ln for ln in lines if ln["logger"] == "rangeplan.access"]
    assert any(ln["request_id"] == "batch-1" and ln["route"] == "/v1/batches" and ln["status"] == 202
               for ln in access)
    assert any(ln["logger"].startswith("uvicorn") for ln in lines)  # uvicorn's own lines are JSON too
    log.close()


def test_watch_parent_ends_an_orphan(tmp_path):
    """A process whose parent dies while it works (a job that never returns to read its
    pipe) ends within a second: its watch thread, not the kernel's signal (not armed here)."""
    code = ("import os, sys, time; from app.lifeline import exit_with_parent; "
            "pid = os.fork()\n"
            "if pid == 0:\n"
            "    exit_with_parent(os.getppid()); print(os.getpid(), flush=True); time.sleep(60); sys.exit(0)\n"
            "time.sleep(1.0); os._exit(0)")  # the parent dies without a word to its child
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=30,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    orphan = int(p.stdout.split()[0])
    t0 = time.monotonic()
    while alive([orphan]) and time.monotonic() - t0 < 5:
        time.sleep(0.05)
    assert not alive([orphan]), "the orphan outlived its parent by 5 s"
    assert callable(watch_parent)
