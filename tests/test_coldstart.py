"""The cold start (issue 24): while the kernels are not compiled, the CLI and the service plan
on the numpy reference and one detached background process compiles the kernels.

The real thing, made affordable: a kernel cache directory holding this machine's compiled
kernels but one (``simulate_constrained``, ~25 CPU s to compile, so the background compile runs long
enough to be seen at work), and without the done-marker. The background compile then really
compiles that kernel (and loads the others), once for the whole test; every process a test
starts is ended by it.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from planner._jit import kernel_cache_dir
from planner.orchestrator.background import LOCK, MARKER, kernels_ready

ROOT = Path(__file__).resolve().parent.parent
TABLE1_PATH = ROOT / "app" / "static" / "examples" / "table1.json"
TABLE1 = json.loads(TABLE1_PATH.read_text())
#: the kernel the background compile compiles (numba keeps it beside the copy of its module)
LEFT_OUT = "planner/orchestrator/__pycache__/kernels.simulate_constrained-"


def _pids(cache: Path) -> set[int]:
    """Processes of background compiles started for this cache (their command line names
    ``planner --background`` and their environment this cache directory)."""
    found = set()
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            cmd = (proc / "cmdline").read_bytes().split(b"\0")
            env = (proc / "environ").read_bytes()
        except OSError:
            continue
        if b"--background" in cmd and b"planner" in cmd and f"RANGEPLAN_KERNEL_CACHE={cache.parent}\0".encode() in env:
            found.add(int(proc.name))
    return found


def _kill(pids: set[int]) -> None:
    for pid in pids:
        try:
            os.killpg(pid, signal.SIGKILL)  # its own session (start_new_session): its group
        except OSError:
            pass


@pytest.fixture
def partial_cache(tmp_path):
    """(env, cache dir): RANGEPLAN_KERNEL_CACHE with every kernel compiled but one, no marker."""
    full = kernel_cache_dir()
    if not (full.is_dir() and kernels_ready()):
        import planner
        planner.warm_up()  # this machine's cache, as `make test` leaves it
    root = tmp_path / "kernels"
    cache = root / full.name
    shutil.copytree(full, cache, ignore=shutil.ignore_patterns(MARKER, LOCK, "compile.log"))
    left = [p for p in cache.rglob("*") if str(p.relative_to(cache)).startswith(LEFT_OUT)]
    assert left, "the machine's cache lacks simulate_constrained"
    for p in left:
        p.unlink()
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(RANGEPLAN_KERNEL_CACHE=str(root), OPENBLAS_NUM_THREADS="1")
    assert _py(env, "print(kernels_ready('constrained'), kernels_ready('paper'))") == "False True"
    yield env, cache
    _kill(_pids(cache))


def _py(env: dict, code: str) -> str:
    """Run ``code`` after importing the background module's names in a new interpreter with
    ``env`` (a process resolves its kernel cache once, at import); its standard output."""
    out = subprocess.run([sys.executable, "-c", "import json\nfrom planner.orchestrator.background import *\n" + code],
                         env=env, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def _start(env: dict) -> tuple[int | None, bool]:
    """compile_in_background() in a new process: (pid, started)."""
    b = json.loads(_py(env, "b = compile_in_background(); print(json.dumps([b.pid, b.started] if b else None))"))
    assert b is not None
    return b[0], b[1]


def _cli(env: dict, out: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "app.cli", "plan", str(TABLE1_PATH), "-o", str(out), *extra],
                            env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_compiled(cache: Path, timeout_s: float = 300.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not (cache / MARKER).exists():
        assert time.monotonic() < deadline, (cache / "compile.log").read_text()
        time.sleep(0.5)
    while _pids(cache) and time.monotonic() < deadline:  # the compile process ends after the marker
        time.sleep(0.1)


def test_a_killed_background_compile_does_not_block_the_next(partial_cache):
    env, cache = partial_cache
    pid, started = _start(env)
    assert started and pid in _pids(cache)  # it outlives the process that started it
    assert _start(env) == (pid, False)  # it runs: not started twice
    assert json.loads(_py(env, "print(json.dumps(running_compile().pid))")) == pid
    _kill({pid})
    deadline = time.monotonic() + 10
    while pid in _pids(cache) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _py(env, "print(running_compile())") == "None"  # the kernel released its lock: nothing stale
    second, started = _start(env)
    assert started and second != pid
    assert _pids(cache) == {second}
    assert (cache / "compile.log").exists()


@pytest.mark.slow
@pytest.mark.serial  # a plan within the 8 s compute limit (failed beside the browser tests)
def test_cli_and_service_plan_on_the_reference_while_the_kernels_compile(partial_cache, tmp_path):
    """Two CLI plans at once start one background compile and plan on the reference; a server
    started meanwhile starts none, serves on the reference (a request too big for it is refused
    saying when the kernels are ready) and renews its workers once the compile is done; then
    the CLI and the server plan compiled, the same trajectory to 1e-12 m, starting nothing."""
    env, cache = partial_cache
    a, b = _cli(env, tmp_path / "a.json"), _cli(env, tmp_path / "b.json")
    outs = [p.communicate(timeout=120) for p in (a, b)]
    assert a.returncode == 0 and b.returncode == 0, outs
    notes = [next((ln for ln in err.splitlines() if ln.startswith("kernels not compiled yet")), "") for _, err in outs]
    assert all("numpy reference" in n and " s for this plan" in n for n in notes), outs  # with its estimate
    assert sum("compiling them in the background" in n for n in notes) == 1, notes  # one started it
    pid = {n.split("(pid ")[1].split(",")[0] for n in notes}
    assert len(pid) == 1 and _pids(cache) <= {int(pid.pop())}
    ref = [json.loads((tmp_path / f"{x}.json").read_text()) for x in "ab"]
    assert all(r["settings"]["backend"] == "reference" for r in ref)

    import planner
    from tests.test_server_process import Server, free_port
    big = {**TABLE1, "settings": {"samples_per_segment": 20}}
    limit = 8.0
    while planner.estimate_work({**big, "settings": {**big["settings"], "backend": "reference"}}).seconds <= limit:
        big["settings"]["samples_per_segment"] *= 2
    assert planner.estimate_work(big).seconds < limit / 4  # compiled, it fits
    started = _pids(cache)
    srv = Server(tmp_path, free_port(), {**env, "RANGEPLAN_PLAN_TIMEOUT_S": str(limit), "RANGEPLAN_WORKERS": "1"})
    try:
        with httpx.Client(base_url=srv.url, timeout=120) as c:
            r = c.post("/v1/plan", json=TABLE1)
            assert r.status_code == 200, r.text
            assert r.json()["settings"]["backend"] == "reference"
            ready = c.get("/ready").json()
            assert ready["kernels"].startswith("compiling in the background"), ready
            refused = c.post("/v1/plan", json=big)
            error = refused.json()["error"]
            assert refused.status_code == 422 and error["code"] == "too_much_work", refused.text
            assert "compiling in the background, ready in about" in error["message"]
            assert _pids(cache) <= started  # the server started no compile of its own
            assert "compiling them in the background" in srv.output()

            _wait_compiled(cache)
            deadline = time.monotonic() + 60
            while True:  # the workers are renewed: the next plans run compiled
                r = c.post("/v1/plan", json=TABLE1)
                assert r.status_code == 200, r.text
                if r.json()["settings"]["backend"] == "compiled":
                    break
                assert time.monotonic() < deadline, srv.output()
                time.sleep(0.5)
            served = r.json()
            assert c.get("/ready").json()["kernels"] == "compiled"
            assert c.post("/v1/plan", json=big).status_code == 200
            assert "kernels compiled" in srv.output()
    finally:
        srv.stop()

    c = _cli(env, tmp_path / "c.json")
    out, err = c.communicate(timeout=120)
    assert c.returncode == 0 and "kernels not compiled" not in err and "compiling" not in err, err
    assert not _pids(cache) and _py(env, "print(running_compile())") == "None"  # nothing started
    done = json.loads((tmp_path / "c.json").read_text())
    assert done["settings"]["backend"] == "compiled"
    for other in (ref[0], ref[1], served):
        assert np.abs(np.array(other["pose"]) - np.array(done["pose"])).max() <= 1e-12
        assert other["metrics"]["steps"] == done["metrics"]["steps"]


def test_reference_backend_compiles_nothing(tmp_path):
    """A reference plan in an empty kernel cache compiles no kernel (numba's compile events)."""
    code = """
import json, sys
from numba.core import event
seen = []
class L(event.Listener):
    def on_start(self, e): seen.append(e.data["dispatcher"].py_func.__name__)
    def on_end(self, e): pass
event.register("numba:compile", L())
import planner
req = json.load(open(sys.argv[1]))
for mode in ("paper", "constrained"):
    planner.plan({**req, "settings": {"mode": mode, "backend": "reference"}})
planner.warm_up(backend="reference")
print(json.dumps(seen))
"""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["RANGEPLAN_KERNEL_CACHE"] = str(tmp_path)
    out = subprocess.run([sys.executable, "-c", code, str(TABLE1_PATH)], env=env, cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


def test_service_renews_its_workers_when_the_kernels_are_compiled():
    """KernelCompile calls back once the marker appears; the pool's renewal replaces every
    worker (forkserver: a new fork server) and the new ones plan."""
    from app.executors import on_reference
    from app.jobs import PlanJob
    from app.workers import PlanPool
    from planner.schema import PlanRequest

    job = PlanJob(PlanRequest.model_validate(TABLE1))
    moved = on_reference(job)
    assert isinstance(moved, PlanJob) and moved.request.settings.backend == "reference"
    assert job.request.settings.backend == "compiled"  # the job itself unchanged
    pool = PlanPool(workers=1, timeout_s=60, start="exec")
    try:
        old = list(pool._workers)
        t = threading.Thread(target=pool.renew)
        t.start()
        t.join(120)
        assert not t.is_alive() and pool.renewed == 1
        assert all(w not in old for w in pool._workers) and all(not w.alive() for w in old)
        out = pool.run(job)
        assert out.ok
    finally:
        pool.close()
