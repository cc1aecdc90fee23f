"""The container image run as a deployment would run it (issue 15); opt-in: `make
container-test` builds the image and runs these with RANGEPLAN_CONTAINER_IMAGE set (root,
podman or docker; skipped otherwise).

Checked: the image size; a cold start `--read-only --tmpfs /tmp --user 12345:0` (an arbitrary
uid in group 0, as Kubernetes runAsUser and OpenShift do) is ready in seconds with the kernels
loaded, not compiled; the token is required; Table I plans as on the host; the health check
asks /ready; corridors persist in a new container on the same volume; `stop` ends it with
status 0 in seconds; the service cannot write its own code; the image holds no test tool.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import time
import uuid
from pathlib import Path

import httpx
import numpy as np
import pytest

IMAGE = os.environ.get("RANGEPLAN_CONTAINER_IMAGE")
ENGINE = os.environ.get("CONTAINER_ENGINE", "podman")
pytestmark = [pytest.mark.container,
              pytest.mark.skipif(not IMAGE, reason="opt-in: make container-test (needs root and podman or docker)")]

ROOT = Path(__file__).resolve().parent.parent
TABLE1 = json.loads((ROOT / "app" / "static" / "examples" / "table1.json").read_text())
TOKEN = "container-test-token-0123456789"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
#: python:3.11-slim unpacked (the target is the whole image on it) [bytes]
SLIM_BASE_BYTES = 130e6
TARGET_BYTES = 600e6


def engine(*args: str, check: bool = True, timeout: float = 300) -> subprocess.CompletedProcess:
    extra = ["--runtime", "runc"] if ENGINE == "podman" and args[0] == "run" else []
    # podman here: crun refuses hybrid cgroups, and its default rlimits need CAP_SYS_RESOURCE
    limits = ["--ulimit", "nofile=20000:20000", "--ulimit", "nproc=32768:32768"] if ENGINE == "podman" \
        and args[0] == "run" else []
    cmd = [ENGINE, args[0], *extra, *limits, *args[1:]]
    return subprocess.run(cmd, capture_output=True, text=True, check=check, timeout=timeout)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Container:
    """A detached container on the host network (API and editor on free ports)."""

    def __init__(self, volume: str, *extra: str, user: str = "12345:0", read_only: bool = True):
        self.name = f"rangeplan-test-{uuid.uuid4().hex[:8]}"
        self.port, self.editor_port = free_port(), free_port()
        flags = ["--read-only", "--tmpfs", "/tmp"] if read_only else []
        self.started = time.monotonic()
        engine("run", "-d", "--name", self.name, "--network", "host", "--user", user, *flags,
               "-v", f"{volume}:/data", "-e", f"RANGEPLAN_API_TOKEN={TOKEN}", "-e", f"RANGEPLAN_PORT={self.port}",
               "-e", f"RANGEPLAN_EDITOR_PORT={self.editor_port}", "-e", "RANGEPLAN_WORKERS=2", *extra, IMAGE)
        self.url = f"http://127.0.0.1:{self.port}"

    def wait_ready(self, timeout: float = 120) -> float:
        """Seconds from `run` to the first 200 of /ready."""
        deadline = self.started + timeout
        while time.monotonic() < deadline:
            try:
                if httpx.get(f"{self.url}/ready", timeout=2).status_code == 200:
                    return time.monotonic() - self.started
            except httpx.HTTPError:
                pass
            time.sleep(0.1)
        raise AssertionError(f"not ready in {timeout} s: {self.logs()}")

    def logs(self) -> str:
        r = engine("logs", self.name, check=False)
        return r.stdout + r.stderr

    def stop(self) -> tuple[int, float]:
        """(exit status, seconds) of a graceful stop."""
        t0 = time.monotonic()
        engine("stop", "-t", "20", self.name, check=False)
        took = time.monotonic() - t0
        status = int(engine("inspect", "--format", "{{.State.ExitCode}}", self.name).stdout.strip())
        return status, took

    def remove(self) -> None:
        engine("rm", "-f", self.name, check=False)


@pytest.fixture(scope="module")
def volume():
    name = f"rangeplan-test-{uuid.uuid4().hex[:8]}"
    engine("volume", "create", name)
    yield name
    engine("volume", "rm", "-f", name, check=False)


def test_image_size_within_the_target():
    size = int(engine("image", "inspect", "--format", "{{.Size}}", IMAGE).stdout.strip())
    base_file = ROOT / ".container-base"
    base = base_file.read_text().strip() if base_file.exists() else "python:3.11-slim"
    base_size = int(engine("image", "inspect", "--format", "{{.Size}}", base).stdout.strip())
    ours = size - base_size
    print(f"\nimage {size / 1e6:.0f} MB on {base} ({base_size / 1e6:.0f} MB): rangeplan's layers {ours / 1e6:.0f} MB; "
          f"on python:3.11-slim (~{SLIM_BASE_BYTES / 1e6:.0f} MB) ~{(ours + SLIM_BASE_BYTES) / 1e6:.0f} MB")
    assert ours + SLIM_BASE_BYTES <= TARGET_BYTES


def test_read_only_any_user_cold_start_plans_and_persists(volume):
    first = Container(volume)
    try:
        ready_s = first.wait_ready()
        logs = first.logs()
        assert "cache files copied" in logs, logs
        print(f"\ncold start --read-only --user 12345:0: ready {ready_s:.1f} s after run")
        assert ready_s < 30, logs
        assert httpx.get(f"{first.url}/v1/robots").status_code == 401
        t0 = time.monotonic()
        r = httpx.post(f"{first.url}/v1/plan", json=TABLE1, headers=AUTH, timeout=120)
        plan_s = time.monotonic() - t0
        assert r.status_code == 200, r.text
        pose = np.array(r.json()["pose"])
        assert np.hypot(*(pose[-1, :2] - TABLE1["segments"][-1]["lower"][:2])) < 1e-3
        print(f"first plan {plan_s:.2f} s after ready (compute {r.json()['metrics']['compute_ms']:.0f} ms)")
        assert r.json()["metrics"]["compute_ms"] < 2000, "the kernels were compiled, not loaded"
        saved = httpx.post(f"{first.url}/v1/corridors", json={**TABLE1, "name": "kept"}, headers=AUTH).json()
        if ENGINE == "podman":
            assert engine("healthcheck", "run", first.name, check=False).returncode == 0
        editor = httpx.get(f"http://127.0.0.1:{first.editor_port}/", timeout=10)
        assert editor.status_code == 401  # the editor wants the token too
        status, took = first.stop()
        print(f"stop: exit status {status} in {took:.1f} s")
        assert status == 0 and took < 15
    finally:
        first.remove()
    second = Container(volume, user="10001:0")
    try:
        second.wait_ready()
        got = httpx.get(f"{second.url}/v1/corridors/{saved['id']}", headers=AUTH).json()
        assert got["name"] == "kept" and got["request"]["segments"] == TABLE1["segments"]
    finally:
        second.remove()


def test_the_service_cannot_write_its_code_and_the_image_has_no_test_tools():
    probe = ("import importlib.util as u, pathlib, planner, app\n"
             "tools = [m for m in ('pytest', 'schemathesis', 'playwright', 'hypothesis', 'pip') if u.find_spec(m)]\n"
             "targets = [pathlib.Path(planner.__file__), pathlib.Path(app.__file__).parent / 'api.py',\n"
             "           pathlib.Path('/opt/rangeplan/kernels')]\n"
             "writable = []\n"
             "for t in targets:\n"
             "    try:\n"
             "        (t / 'x').touch() if t.is_dir() else open(t, 'a').close()\n"
             "        writable.append(str(t))\n"
             "    except OSError:\n"
             "        pass\n"
             "print(tools, writable)\n")
    for user in ("10001:0", "12345:0"):
        out = engine("run", "--rm", "--network", "none", "--user", user, IMAGE, "python", "-c", probe).stdout.strip()
        assert out == "[] []", (user, out)


def test_open_bind_without_token_refuses_to_start():
    r = engine("run", "--rm", "--network", "none", "--read-only", "--tmpfs", "/tmp", IMAGE, check=False, timeout=120)
    assert r.returncode == 2 and "RANGEPLAN_API_TOKEN" in r.stderr + r.stdout
