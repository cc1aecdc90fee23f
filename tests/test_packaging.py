"""What ``pip install .`` and the Dockerfile install (issue 30): ``python -m build`` makes an sdist
and, from it, a wheel; the wheel holds every file of ``planner/`` and ``app/`` that git tracks
(every module and every data file the code opens: the robots, the landing page, the examples),
and installing the sdist gives the same files. A package left out of a hand-written list
(``app.routers`` and ``planner.contour`` once were) fails here, not at the user's start-up.

The installed wheel itself is run by the smoke suite (tests/test_smoke.py, ``make smoke``)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

import planner

ROOT = Path(__file__).resolve().parent.parent


def shipped_sources() -> set[str]:
    """The files of ``planner/`` and ``app/`` that must ship: every file git tracks there (the
    tree's files without caches where git is not available)."""
    try:
        out = subprocess.run(["git", "ls-files", "planner", "app"], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout
        files = {line for line in out.splitlines() if line}
    except (OSError, subprocess.CalledProcessError):
        files = {str(p.relative_to(ROOT)) for d in ("planner", "app") for p in (ROOT / d).rglob("*")
                 if p.is_file() and "__pycache__" not in p.parts}
    assert files, "no sources found"
    return files


@pytest.fixture(scope="module")
def dist(tmp_path_factory) -> Path:
    """``python -m build`` (sdist, then the wheel built from the sdist) of a copy of the files
    the build reads (as the Dockerfile's app stage copies them; the build writes into its
    source tree), into a fresh directory."""
    src, out = tmp_path_factory.mktemp("src"), tmp_path_factory.mktemp("dist")
    for rel in sorted(shipped_sources()) + ["pyproject.toml", "README.md"]:
        (src / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / rel, src / rel)
    proc = subprocess.run([sys.executable, "-m", "build", "--no-isolation", "--outdir", str(out), str(src)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return out


def test_wheel_holds_every_module_and_data_file(dist):
    wheels = list(dist.glob("rangeplan-*.whl"))
    assert [w.name for w in wheels] == [f"rangeplan-{planner.__version__}-py3-none-any.whl"]
    with zipfile.ZipFile(wheels[0]) as z:
        names = set(z.namelist())
    missing = shipped_sources() - names
    assert not missing, f"not in the wheel: {sorted(missing)}"
    # the packages the issue found missing, and the files the code opens by path
    for must in ("app/routers/__init__.py", "planner/contour/__init__.py", "planner/data/moving-slide.json",
                 "app/static/index.html", "app/static/examples/table1.json", "app/static/examples/contour-part.ngc"):
        assert must in names
    # nothing else at the top level: no tests, benchmarks or caches in users' site-packages
    assert {n.split("/")[0] for n in names} == {"planner", "app", f"rangeplan-{planner.__version__}.dist-info"}
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc")]


def test_sdist_installs_the_same_files(dist, tmp_path):
    sdists = list(dist.glob("rangeplan-*.tar.gz"))
    assert [s.name for s in sdists] == [f"rangeplan-{planner.__version__}.tar.gz"]
    with tarfile.open(sdists[0]) as t:
        members = {m.name.split("/", 1)[1] for m in t.getmembers() if "/" in m.name}
    assert {"pyproject.toml", "README.md"} <= members
    target = tmp_path / "site"
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                           "--no-compile", "--target", str(target), str(sdists[0])],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    installed = {str(p.relative_to(target)) for p in target.rglob("*") if p.is_file()}
    missing = shipped_sources() - installed
    assert not missing, f"not installed from the sdist: {sorted(missing)}"
    # the installed copy reports the version it was built with, without the tree on the path
    probe = subprocess.run([sys.executable, "-I", "-c", "import sys; sys.path.insert(0, sys.argv[1]); import planner; "
                            "print(planner.__version__, planner.__file__)", str(target)],
                           capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert probe.returncode == 0, probe.stderr
    version, path = probe.stdout.split()
    assert version == planner.__version__ and Path(path).is_relative_to(target)
