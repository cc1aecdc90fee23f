"""The Dockerfile and its lock file, checked statically (the image itself is built and run by
the opt-in `make container-test`, tests/test_container.py): multi-stage on ``ARG
BASE_IMAGE``; the runtime dependencies installed from container/requirements.lock, hashes
checked, in a layer before any source is copied; the lock matches pyproject.toml (every
runtime dependency pinned within its specifier, no test tool) and is what the test
environment runs; root owns the install, the service user only /data; kernels compiled
for a generic CPU into a read-only seed; the health check asks /ready."""

from __future__ import annotations

import re
import tomllib
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parent.parent
LOCK = ROOT / "container" / "requirements.lock"


def instructions() -> list[tuple[str, str]]:
    text = re.sub(r"\\\n", " ", (ROOT / "Dockerfile").read_text())  # join continuation lines
    out = []
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            op, _, rest = line.partition(" ")
            out.append((op.upper(), rest.strip()))
    return out


def stages() -> dict[str, list[tuple[str, str]]]:
    out: dict[str, list] = {}
    current = None
    for op, rest in instructions():
        if op == "FROM":
            current = rest.split(" AS ")[-1].strip() if " AS " in rest else rest
            out[current] = []
        elif current is not None:
            out[current].append((op, rest))
    return out


def pins() -> dict[str, str]:
    return {canonicalize_name(n): v for n, v in re.findall(r"^([A-Za-z0-9_.-]+)==([^ \\\n]+)", LOCK.read_text(), re.M)}


def pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_lock_matches_pyproject():
    """Every runtime dependency is pinned, within its specifier; the lock was compiled from
    pyproject.toml with hashes; it holds no test-only tool."""
    text = LOCK.read_text()
    header = text.split("\n\n")[0] if "\n\n" in text else text[:800]
    assert "pyproject.toml" in header and "--generate-hashes" in header
    locked = pins()
    for dep in pyproject()["project"]["dependencies"]:
        req = Requirement(dep)
        name = canonicalize_name(req.name)
        assert name in locked, f"{req.name} is a dependency but not in the lock: run `make lock`"
        assert req.specifier.contains(locked[name], prereleases=True), (dep, locked[name])
    blocks = re.split(r"\n(?=[A-Za-z0-9_.-]+==)", text)
    assert len(blocks) > len(locked) and all("--hash=sha256:" in b for b in blocks[1:])
    extras = pyproject()["project"]["optional-dependencies"]
    test_tools = {canonicalize_name(Requirement(d).name) for d in extras["test"]}
    # a test tool may be in the lock only as what a runtime package needs (packaging: dask),
    # never because the lock was compiled with the test extras
    via = {canonicalize_name(b.split("==")[0]): re.findall(r"#\s+(?:via\s+)?([A-Za-z0-9_.-]+)", b) for b in blocks[1:]}
    test_only = {n for n in test_tools & set(locked)
                 if not {canonicalize_name(v) for v in via.get(n, [])} & (set(locked) - test_tools)}
    assert not test_only, test_only
    assert {"pytest", "schemathesis", "playwright", "hypothesis", "ruff"}.isdisjoint(locked)


def test_tests_run_the_locked_versions():
    """`make install` installs the lock first, so the suite tests what the image runs."""
    wrong = {}
    for name, pinned in pins().items():
        try:
            got = version(name)
        except PackageNotFoundError:
            got = None
        if got != pinned:
            wrong[name] = (pinned, got)
    assert not wrong, f"installed versions differ from container/requirements.lock: {wrong}"
    make = (ROOT / "Makefile").read_text()
    assert make.index("requirements.lock") < make.index("-e '.[test]'")


def test_multi_stage_on_a_base_image_argument():
    ins = instructions()
    assert ins[0] == ("ARG", "BASE_IMAGE=python:3.11-slim")
    froms = [rest for op, rest in ins if op == "FROM"]
    assert len(froms) >= 3 and all(f.startswith("${BASE_IMAGE}") for f in froms)
    assert list(stages())[-1] == "runtime"


def test_dependencies_install_from_the_lock_before_any_source():
    st = stages()
    deps = st["deps"]
    copies = [rest for op, rest in deps if op == "COPY"]
    assert copies == ["container/requirements.lock /tmp/requirements.lock"], "the deps stage sees only the lock"
    install = " ".join(rest for op, rest in deps if op == "RUN")
    assert "--require-hashes" in install and "-r /tmp/requirements.lock" in install and "--no-deps" in install
    runtime = st["runtime"]
    order = [(op, rest) for op, rest in runtime if op in ("COPY", "RUN")]
    first_deps = next(i for i, (op, rest) in enumerate(order) if op == "COPY" and "--from=deps" in rest)
    first_source = next(i for i, (op, rest) in enumerate(order) if op == "COPY" and "--from=app" in rest)
    assert first_deps < first_source
    # no test extra, no editable install anywhere
    runs = " ".join(rest for op, rest in instructions() if op == "RUN")
    assert "[test]" not in runs and " -e " not in runs and "pytest" not in runs


def test_root_owns_the_install_the_user_only_data():
    runtime = stages()["runtime"]
    users = [rest for op, rest in runtime if op == "USER"]
    assert users == ["10001:0"]
    user_at = runtime.index(("USER", "10001:0"))
    assert all(op != "RUN" for op, _ in runtime[user_at:]), "everything is installed as root, before USER"
    runs = " ".join(rest for op, rest in runtime if op == "RUN")
    assert "chown 10001:0 /data" in runs and "chmod 2775 /data" in runs
    assert "--chown" not in " ".join(rest for op, rest in runtime if op == "COPY")
    assert "go-w /opt/rangeplan" in runs


def test_kernels_compiled_for_a_generic_cpu_into_a_read_only_seed():
    runtime = stages()["runtime"]
    env = " ".join(rest for op, rest in runtime if op == "ENV")
    assert "NUMBA_CPU_NAME=generic" in env
    assert "NUMBA_CACHE_DIR=/tmp/" in env and "RANGEPLAN_KERNEL_SEED=/opt/rangeplan/kernels" in env
    runs = [rest for op, rest in runtime if op == "RUN"]
    compile_run = next(r for r in runs if "-m planner" in r)
    # compiled in the build's cache mount (kept between builds), copied into the seed
    assert compile_run.startswith("--mount=type=cache,target=/var/cache/rangeplan-kernels")
    assert "NUMBA_CACHE_DIR=/var/cache/rangeplan-kernels /opt/venv/bin/python -m planner" in compile_run
    assert "/opt/rangeplan/kernels/" in compile_run and "go-w /opt/rangeplan" in compile_run


def test_the_image_is_labelled_with_the_version_the_wheel_has():
    """The label's version is planner/_version.py's, and the build checks the installed wheel's."""
    import planner

    ins = instructions()
    assert ("ARG", f"RANGEPLAN_VERSION={planner.__version__}") in ins
    runtime = stages()["runtime"]
    labels = " ".join(rest for op, rest in runtime if op == "LABEL")
    assert 'org.opencontainers.image.version="${RANGEPLAN_VERSION}"' in labels
    runs = " ".join(rest for op, rest in runtime if op == "RUN")
    assert "print(planner.__version__)')\" = \"${RANGEPLAN_VERSION}\"" in runs


def test_health_check_start_command_and_ports():
    ins = instructions()
    health = [rest for op, rest in ins if op == "HEALTHCHECK"]
    assert len(health) == 1 and "/ready" in health[0] and "urllib" in health[0]
    cmd = [rest for op, rest in ins if op == "CMD"][-1]
    assert cmd.startswith("[") and '"rangeplan", "serve", "--host", "0.0.0.0"' in cmd
    assert {"8000", "8080"} <= set(" ".join(rest for op, rest in ins if op == "EXPOSE").split())
    env = " ".join(rest for op, rest in ins if op == "ENV")
    for k, v in {"OPENBLAS_NUM_THREADS": "1", "RANGEPLAN_DATA_DIR": "/data", "HOME": "/tmp",
                 "PATH": "/opt/venv/bin:$PATH"}.items():
        assert f"{k}={v}" in env


def test_dockerignore_keeps_venv_git_and_caches_out():
    lines = {line.strip() for line in (ROOT / ".dockerignore").read_text().splitlines()}
    assert {".git", ".venv", "**/__pycache__", "tests"} <= lines
