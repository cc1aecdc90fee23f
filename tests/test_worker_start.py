"""Planning workers forked from a process that has loaded the planner (issue 24): what a
worker started by ``python -m app.workers`` does, it does too (the same plan, its memory
limit, ending with its parent), and the pool recovers when that template process dies."""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import psutil
import pytest

from app.jobs import Done, PlanJob
from app.workers import PlanPool
from planner import PlanRequest

ROOT = Path(__file__).resolve().parent.parent
TABLE1 = PlanRequest.model_validate(json.loads((ROOT / "app" / "static" / "examples" / "table1.json").read_text()))


def _ready(pool: PlanPool, timeout: float = 300.0) -> None:
    deadline = time.monotonic() + timeout
    while pool.readiness()["workers_ready"] < pool.n:
        state = pool.readiness()
        assert not state["failures"] and time.monotonic() < deadline, state
        time.sleep(0.01)


def _worker_pids(pool: PlanPool) -> list[int]:
    pids = [w.pid for w in pool._workers]
    assert all(pids), pids
    return [int(p) for p in pids if p]


def _timeless(doc):
    """``doc`` without the times the plan took (the only fields that may differ)."""
    if isinstance(doc, dict):
        return {k: _timeless(v) for k, v in doc.items() if k not in ("compute_ms", "qp_time_ms")}
    if isinstance(doc, list):
        return [_timeless(v) for v in doc]
    return doc


def test_start_method_is_checked():
    with pytest.raises(ValueError, match="start must be one of forkserver, exec"):
        PlanPool(workers=1, start="fork")


@pytest.mark.slow
def test_forked_workers_plan_as_exec_started_ones_under_the_same_limit():
    """The same Table I plan (byte for byte) from a forked worker and from a fresh interpreter;
    both run under the address-space limit; the forked one's parent is the fork server, which
    imported the template (the planner with its kernels loaded) and not the pool's process."""
    forked = PlanPool(workers=1, timeout_s=60, memory_mb=1500, start="forkserver")
    execd = PlanPool(workers=1, timeout_s=60, memory_mb=1500, start="exec")
    try:
        _ready(forked)
        _ready(execd)
        a, b = forked.run(PlanJob(TABLE1)), execd.run(PlanJob(TABLE1))
        assert isinstance(a, Done) and isinstance(b, Done)
        assert a.payload is not None and b.payload is not None
        assert _timeless(json.loads(a.payload)) == _timeless(json.loads(b.payload))
        assert len(json.loads(a.payload)["pose"]) > 100  # a whole trajectory compared
        for pid in _worker_pids(forked) + _worker_pids(execd):
            limits = Path(f"/proc/{pid}/limits").read_text()
            row = next(ln for ln in limits.splitlines() if ln.startswith("Max address space"))
            assert row.split()[3] == str(1500 * 1024 * 1024), row
        worker = psutil.Process(_worker_pids(forked)[0])
        template = worker.parent()
        assert template is not None and template.pid != os.getpid()
        assert "multiprocessing.forkserver" in " ".join(template.cmdline())
        assert worker.nice() == template.nice() > psutil.Process().nice()  # the workers' lower priority, once
        assert "numba" in " ".join(m.path for m in worker.memory_maps())  # numba's extensions mapped before any job
    finally:
        forked.close()
        execd.close()


@pytest.mark.slow
def test_workers_end_with_the_fork_server_and_the_pool_starts_another():
    """kill -9 of the fork server ends its workers (their parent died: app.lifeline); the
    pool's next job runs on a worker of a new fork server."""
    pool = PlanPool(workers=2, timeout_s=60, start="forkserver")
    try:
        _ready(pool)
        workers = [psutil.Process(pid) for pid in _worker_pids(pool)]
        template = workers[0].parent()
        assert template is not None and all(w.ppid() == template.pid for w in workers)
        os.kill(template.pid, signal.SIGKILL)
        gone, alive = psutil.wait_procs(workers, timeout=10)
        assert not alive, f"workers alive 10 s after their fork server died: {alive}"
        out = pool.run(PlanJob(TABLE1))
        assert isinstance(out, Done), out
        assert pool.replaced >= 1
        new_parent = psutil.Process(_worker_pids(pool)[0]).parent()
        assert new_parent is not None and new_parent.pid != template.pid
    finally:
        pool.close()


def test_a_worker_has_loaded_what_its_first_contour_needs_before_it_reports_ready():
    """The warm-up (``load_planner``, run by every worker before it reports ready) imports
    scipy.optimize (the contour's Z ramps' LP): the first ramp in a fresh worker paid ~0.1-0.2
    CPU s for it (benchmarks/bench_worker_preload.py). A fresh interpreter, as a worker is."""
    import subprocess
    import sys

    code = ("import sys, app.worker_process as w; assert 'scipy.optimize' not in sys.modules; "
            "print(w.load_planner(), 'scipy.optimize' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "('ready', None) True"
