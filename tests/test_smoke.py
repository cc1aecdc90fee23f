"""The smoke suite: what users install, run as they run it (issue 30).

Run against an *installed* rangeplan, never the tree:

* ``RANGEPLAN_SMOKE_VENV=DIR``: a fresh virtual environment with the built wheel installed
  non-editable (``make smoke``);
* ``RANGEPLAN_CONTAINER_IMAGE=IMAGE``: the container image built from the Dockerfile, run
  ``--read-only --tmpfs /tmp`` under a random uid in group 0 (``make container-test``).

Without either, every test here is skipped (the rest of the suite tests the tree). Each check
compares with an independent computation where there is one: the installed plan of Table I
equals the tree's plan (same trajectory to 1 um), the HTTP and the CLI plans agree, the contour
plan keeps the program's tolerance and its forces within the robot's limits, the batch
writes the plans of its inputs.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import httpx
import numpy as np
import pytest

import planner

pytestmark = pytest.mark.smoke

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "app" / "static" / "examples"
TABLE1 = json.loads((EXAMPLES / "table1.json").read_text())
PROGRAM = (EXAMPLES / "contour-part.ngc").read_text()
#: where the example program fits the robot's reach (README "Contouring")
ORIGIN = [-0.013, -0.0075]
DRAWING = ROOT / "tests" / "data" / "drawings" / "Table-dining-E.dxf"
TOKEN = "smoke-test-token-0123456789abcdef"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
ENGINE = os.environ.get("CONTAINER_ENGINE", "podman")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Server:
    url: str
    editor_url: str
    started: float


class VenvTarget:
    """rangeplan installed from the wheel into a virtual environment of its own."""

    name = "wheel"

    def __init__(self, venv: Path):
        self.bin = venv / "bin"
        self.site = venv / "lib"

    def env(self, **extra: str) -> dict[str, str]:
        """The user's environment: no PYTHONPATH into the tree."""
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
        return {**env, **extra}

    def cli(self, args: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
        return subprocess.run([str(self.bin / "rangeplan"), *args], cwd=cwd, env=self.env(), capture_output=True,
                              text=True, timeout=timeout)

    def where(self, cwd: Path) -> tuple[str, str]:
        """(planner's file, version) as the installed Python imports them."""
        out = subprocess.run([str(self.bin / "python"), "-c", "import planner; print(planner.__file__); "
                              "print(planner.__version__)"], cwd=cwd, env=self.env(), capture_output=True, text=True,
                             timeout=60, check=True).stdout.split()
        return out[0], out[1]

    def installed_in(self) -> str:
        return str(self.site)

    @contextmanager
    def serve(self, data: Path) -> Iterator[Server]:
        port, editor = free_port(), free_port()
        t0 = time.monotonic()
        proc = subprocess.Popen([str(self.bin / "rangeplan"), "serve", "--port", str(port), "--editor-port",
                                 str(editor)], cwd=data, env=self.env(RANGEPLAN_DATA_DIR=str(data),
                                                                        RANGEPLAN_API_TOKEN=TOKEN,
                                                                        RANGEPLAN_WORKERS="2"),
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            yield Server(f"http://127.0.0.1:{port}", f"http://127.0.0.1:{editor}", t0)
        finally:
            proc.terminate()
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


class ImageTarget:
    """The container image, run ``--read-only --tmpfs /tmp --user UID:0`` with a random uid in
    group 0 (as Kubernetes runAsUser and OpenShift run it; one per test run, in the test ids'
    output)."""

    name = "image"
    user = f"{10000 + secrets.randbelow(50000)}:0"

    def __init__(self, image: str):
        self.image = image

    def engine(self, *args: str, check: bool = False, timeout: float = 300) -> subprocess.CompletedProcess:
        extra: list[str] = []
        if ENGINE == "podman" and args[0] == "run":  # crun refuses hybrid cgroups; default rlimits need a cap
            extra = ["--runtime", "runc", "--ulimit", "nofile=20000:20000", "--ulimit", "nproc=32768:32768"]
        return subprocess.run([ENGINE, args[0], *extra, *args[1:]], capture_output=True, text=True, check=check,
                              timeout=timeout)

    def cli(self, args: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
        os.chmod(cwd, 0o777)  # the container's user writes its outputs there
        return self.engine("run", "--rm", "--network", "none", "--read-only", "--tmpfs", "/tmp", "--user", self.user,
                           "-v", f"{cwd}:/work", "-w", "/work", self.image, "rangeplan", *args, timeout=timeout)

    def where(self, cwd: Path) -> tuple[str, str]:
        r = self.engine("run", "--rm", "--network", "none", "--user", self.user, self.image, "python", "-c",
                        "import planner; print(planner.__file__); print(planner.__version__)", check=True)
        out = r.stdout.split()
        return out[0], out[1]

    def installed_in(self) -> str:
        return "/opt/venv/lib"

    @contextmanager
    def serve(self, data: Path) -> Iterator[Server]:
        os.chmod(data, 0o777)
        port, editor = free_port(), free_port()
        name = f"rangeplan-smoke-{uuid.uuid4().hex[:8]}"
        t0 = time.monotonic()
        self.engine("run", "-d", "--name", name, "--network", "host", "--read-only", "--tmpfs", "/tmp", "--user",
                    self.user, "-v", f"{data}:/data", "-e", f"RANGEPLAN_API_TOKEN={TOKEN}", "-e",
                    f"RANGEPLAN_PORT={port}", "-e", f"RANGEPLAN_EDITOR_PORT={editor}", "-e", "RANGEPLAN_WORKERS=2",
                    self.image, check=True)
        try:
            yield Server(f"http://127.0.0.1:{port}", f"http://127.0.0.1:{editor}", t0)
        finally:
            self.engine("rm", "-f", "-t", "5", name)


def _targets() -> list:
    out = []
    if os.environ.get("RANGEPLAN_SMOKE_VENV"):
        out.append(pytest.param(VenvTarget(Path(os.environ["RANGEPLAN_SMOKE_VENV"]).resolve()), id="wheel"))
    if os.environ.get("RANGEPLAN_CONTAINER_IMAGE"):
        out.append(pytest.param(ImageTarget(os.environ["RANGEPLAN_CONTAINER_IMAGE"]), id="image"))
    return out or [pytest.param(None, id="none", marks=pytest.mark.skip(
        reason="the smoke suite runs against an installed rangeplan: make smoke (the wheel in a fresh venv) or "
               "make container-test (the image)"))]


@pytest.fixture(scope="module", params=_targets())
def target(request):
    return request.param


@pytest.fixture(scope="module")
def tree_table1() -> np.ndarray:
    """Table I planned by the tree's planner in this process: what the installed one must give."""
    return planner.plan(TABLE1).pose


@pytest.fixture(scope="module")
def server(target, tmp_path_factory):
    """One running service of the target for the HTTP checks; the seconds to its first /ready."""
    data = tmp_path_factory.mktemp(f"data-{target.name}")
    with target.serve(data) as srv:
        deadline = srv.started + 180
        while True:
            try:
                r = httpx.get(f"{srv.url}/ready", timeout=2)
                if r.status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline, f"{target.name}: /ready never answered 200"
            time.sleep(0.05)
        ready_s = time.monotonic() - srv.started
        print(f"\n{target.name}: /ready 200 {ready_s:.2f} s after start"
              f"{f' (user {target.user})' if isinstance(target, ImageTarget) else ''}", file=sys.stderr)
        yield srv, ready_s, r.json()


def same_path(pose: np.ndarray, reference: np.ndarray) -> None:
    """The same trajectory: same samples, every pose within 1 um / 1 urad (the image's kernels are
    compiled for a generic CPU, the tree's for this one)."""
    assert pose.shape == reference.shape
    assert np.max(np.abs(pose - reference)) < 1e-6


def test_installed_not_the_tree(target, tmp_path):
    path, version = target.where(tmp_path)
    assert path.startswith(target.installed_in()), path
    assert not path.startswith(str(ROOT / "planner")), path  # not the tree's own package
    assert version == planner.__version__
    r = target.cli(["--version"], tmp_path)
    assert r.returncode == 0 and r.stdout.strip() == f"rangeplan {planner.__version__}", r.stdout + r.stderr


def test_serve_ready_and_version(server):
    srv, ready_s, body = server
    assert body["status"] == "ready" and body["version"] == planner.__version__ and body["workers_ready"] >= 1
    assert body["kernels"] == "compiled", body  # loaded, not compiled at start
    assert httpx.get(f"{srv.url}/v1/robots").status_code == 401  # the token is asked for


def test_http_plan_table1_is_the_trees_plan(server, tree_table1):
    srv = server[0]
    r = httpx.post(f"{srv.url}/v1/plan", json=TABLE1, headers=AUTH, timeout=120)
    assert r.status_code == 200, r.text
    same_path(np.array(r.json()["pose"]), tree_table1)
    assert r.json()["metrics"]["within_limits"] is True


def test_http_contour_of_the_shipped_program(server):
    srv = server[0]
    r = httpx.post(f"{srv.url}/v1/contour", json={"program": PROGRAM, "origin": ORIGIN}, headers=AUTH, timeout=300)
    assert r.status_code == 200, r.text
    body = r.json()
    c = body["contour"]
    assert c["passes"] and c["cycle_time_s"] > 0
    assert 0 < c["max_deviation_m"] <= c["tolerance_m"]
    assert body["metrics"]["within_limits"] is True
    # the cut follows the program: its passes' programmed length is covered at no more than F
    assert all(p["max_speed_m_s"] <= p["max_programmed_feed_m_s"] * 1.001 for p in c["passes"])


def test_landing_page_examples_and_editor_page(server):
    """The package data the service opens: the landing page and its examples; the editor's page."""
    srv = server[0]
    page = httpx.get(f"{srv.url}/", timeout=10)
    assert page.status_code == 200 and "<title>rangeplan" in page.text
    example = httpx.get(f"{srv.url}/examples/table1.json", timeout=10)
    assert example.status_code == 200 and example.json() == TABLE1
    with httpx.Client(timeout=20, follow_redirects=True) as c:
        assert c.get(f"{srv.editor_url}/").status_code == 401  # the editor wants the token too
        editor = c.get(f"{srv.editor_url}/?token={TOKEN}")
    assert editor.status_code == 200 and "<html" in editor.text.lower() and "viser" in editor.text.lower()


def test_cli_plan_is_the_trees_plan(target, tmp_path, tree_table1):
    shutil.copy(EXAMPLES / "table1.json", tmp_path / "table1.json")
    r = target.cli(["plan", "table1.json", "-o", "table1-plan.json"], tmp_path)
    assert r.returncode == 0, r.stderr
    same_path(np.array(json.loads((tmp_path / "table1-plan.json").read_text())["pose"]), tree_table1)
    bad = target.cli(["plan", "missing.json"], tmp_path)
    assert bad.returncode == 2 and "missing.json: cannot read" in bad.stderr and "Traceback" not in bad.stderr


def test_cli_contour_writes_a_machine_program(target, tmp_path):
    (tmp_path / "part.ngc").write_text(PROGRAM)
    r = target.cli(["contour", "part.ngc", f"--origin={ORIGIN[0]},{ORIGIN[1]}", "-o", "part.json"], tmp_path)
    assert r.returncode == 0, r.stderr
    c = json.loads((tmp_path / "part.json").read_text())["contour"]
    assert 0 < c["max_deviation_m"] <= c["tolerance_m"] and c["passes"]
    r = target.cli(["contour", "part.ngc", f"--origin={ORIGIN[0]},{ORIGIN[1]}", "-o", "part-out.ngc"], tmp_path)
    assert r.returncode == 0, r.stderr
    text = (tmp_path / "part-out.ngc").read_text()
    assert "G93" in text and text.rstrip().endswith("M2")


def test_cli_import_a_drawing_then_plan_it(target, tmp_path):
    shutil.copy(DRAWING, tmp_path / "table.dxf")
    r = target.cli(["import", "table.dxf", "--scale", "0.05", "--offset", "0", "0.0225", "--margin", "0.03",
                    "--start", "-0.065", "0", "0", "--end", "0.065", "0", "0", "-o", "table.json"], tmp_path)
    assert r.returncode == 0, r.stderr
    assert "1 obstacle(s)" in r.stderr
    request = json.loads((tmp_path / "table.json").read_text())
    assert request["layout"]["start"] == [-0.065, 0.0, 0.0] and request["layout"]["end"] == [0.065, 0.0, 0.0]
    r = target.cli(["plan", "table.json", "-o", "table-plan.json"], tmp_path)
    assert r.returncode == 0, r.stderr
    pose = np.array(json.loads((tmp_path / "table-plan.json").read_text())["pose"])
    assert np.hypot(*(pose[-1, :2] - [0.065, 0.0])) < 1e-3  # arrived at the end point


def test_cli_batch_of_three(target, tmp_path, tree_table1):
    inputs = tmp_path / "in"
    inputs.mkdir()
    for i in range(3):
        shift = (i - 1) * 1e-3
        req = {**TABLE1, "name": f"shift {i}", "segments": [{k: [v[0] + shift, v[1], v[2]] for k, v in s.items()}
                                                            for s in TABLE1["segments"]]}
        (inputs / f"shift{i}.json").write_text(json.dumps(req))
    r = target.cli(["batch", "in", "-o", "out", "--workers", "2"], tmp_path)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert "3 ok, 0 failed of 3" in r.stderr
    plans = [json.loads((tmp_path / "out" / f"shift{i}.json").read_text()) for i in range(3)]
    assert [p["name"] for p in plans] == ["shift 0", "shift 1", "shift 2"]
    # each plan arrives at its own end point, 1 mm apart in x; the unshifted one is the tree's plan
    ends = [np.array(p["pose"])[-1, 0] for p in plans]
    assert np.allclose(np.diff(ends), 1e-3, atol=1e-4), ends
    same_path(np.array(plans[1]["pose"]), tree_table1)
    rows = (tmp_path / "out" / "summary.csv").read_text().splitlines()
    assert len(rows) == 4 and all(",ok," in row for row in rows[1:]), rows
