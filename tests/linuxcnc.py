"""LinuxCNC's own G-code interpreter for the tests: every program a test produces is run
through ``rs274`` (Debian linuxcnc-uspace; ``make test`` installs it)."""

from __future__ import annotations

import fcntl
import subprocess
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

RS274 = "/usr/bin/rs274"
#: rs274 processes share one memory segment: two at once (pytest-xdist's processes) die with a
#: bus error in about 2 of 3 tries; a lock taken by every caller on this machine runs one at a time
LOCK = Path(tempfile.gettempdir()) / "rangeplan-rs274.lock"


@contextmanager
def one_at_a_time() -> Iterator[None]:
    """Hold the machine-wide lock of LinuxCNC's tools (:data:`LOCK`) for the block."""
    with open(LOCK, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


def rs274(program: str) -> list[str]:
    """The canonical commands LinuxCNC's interpreter makes of ``program``; fails the test
    (AssertionError with the interpreter's output) when it reports an error."""
    assert Path(RS274).exists(), "LinuxCNC's rs274 is missing: `make test` installs linuxcnc-uspace"
    with tempfile.TemporaryDirectory(prefix="rangeplan-rs274-") as tmp:
        (Path(tmp) / "plan.ngc").write_text(program)
        with one_at_a_time():
            r = subprocess.run([RS274, "-g", "plan.ngc", "plan.canon"], cwd=tmp, capture_output=True, text=True,
                               timeout=120, stdin=subprocess.DEVNULL)
        out = (Path(tmp) / "plan.canon").read_text() if (Path(tmp) / "plan.canon").exists() else ""
    assert r.returncode == 0, f"rs274 rejected the program: {r.stdout[-2000:]} {r.stderr[-2000:]}"
    assert "PROGRAM_END()" in out
    return out.splitlines()
