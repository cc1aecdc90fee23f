"""No Docker engine runs here, so check the Dockerfile statically: its install steps are
exactly the Makefile's (what `make run` and CI run), it runs as a non-root user, exposes the
API and editor ports, health-checks /health and starts `rangeplan serve` on all interfaces."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _dockerfile_instructions() -> list[tuple[str, str]]:
    text = (ROOT / "Dockerfile").read_text()
    text = re.sub(r"\\\n", " ", text)  # join continuation lines
    out = []
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            op, _, rest = line.partition(" ")
            out.append((op.upper(), rest.strip()))
    return out


def _makefile():
    text = (ROOT / "Makefile").read_text()
    variables = {"PYTHON": "python"}  # the image's interpreter, as PYTHON=python make would use
    for m in re.finditer(r"^(?:export\s+)?(\w+)\s*[:?]?=\s*(.+)$", text, re.M):
        variables.setdefault(m.group(1), m.group(2).strip())
    exports = dict(re.findall(r"^export\s+(\w+)\s*:?=\s*(\S+)", text, re.M))

    def expand(s: str) -> str:
        for _ in range(5):
            s = re.sub(r"\$\((\w+)\)", lambda m: variables[m.group(1)], s)
        return s

    recipe = re.search(r"^\$\(STAMP\):.*\n((?:\t.*\n)+)", text, re.M).group(1)
    steps = [expand(line.strip()) for line in recipe.splitlines()]
    steps = [s for s in steps if not s.startswith("touch ")]
    run_line = re.search(r"^run:.*\n\t(.+)$", text, re.M).group(1)
    return steps, exports, expand(run_line)


def _norm(cmd: str) -> list[str]:
    return shlex.split(cmd)


def test_install_steps_identical_to_makefile():
    steps, _, _ = _makefile()
    assert any("pip install" in s and "-e" in s for s in steps)
    runs = [rest for op, rest in _dockerfile_instructions() if op == "RUN"]
    install = [r for r in runs if "pip install" in r]
    assert len(install) == 1, install
    docker_steps = [s.strip() for s in install[0].split("&&")]
    assert [_norm(s) for s in docker_steps] == [_norm(s) for s in steps]


def test_environment_matches_makefile_exports():
    _, exports, _ = _makefile()
    env = " ".join(rest for op, rest in _dockerfile_instructions() if op == "ENV")
    for k, v in exports.items():
        assert re.search(rf"\b{k}={re.escape(v)}\b", env), k


def test_image_shape():
    ins = _dockerfile_instructions()
    ops = [op for op, _ in ins]
    assert ins[0] == ("FROM", "python:3.11-slim")
    user = [rest for op, rest in ins if op == "USER"]
    assert user and user[-1] not in ("root", "0")
    # the install runs as that user (after USER), not as root
    assert ops.index("USER") < max(i for i, (op, rest) in enumerate(ins) if op == "RUN" and "pip install" in rest)
    exposed = " ".join(rest for op, rest in ins if op == "EXPOSE").split()
    assert {"8000", "8080"} <= set(exposed)
    health = [rest for op, rest in ins if op == "HEALTHCHECK"]
    assert len(health) == 1 and "/health" in health[0] and "urllib" in health[0]
    cmd = [rest for op, rest in ins if op == "CMD"][-1]
    assert cmd.startswith("[")  # exec form: the server is PID 1 and gets SIGTERM
    _, _, run_line = _makefile()
    assert "rangeplan serve" in run_line
    assert '"rangeplan", "serve", "--host", "0.0.0.0"' in cmd


def test_dockerignore_keeps_venv_and_git_out():
    lines = {line.strip() for line in (ROOT / ".dockerignore").read_text().splitlines()}
    assert {".git", ".venv"} <= lines
