"""Compiled code is loaded only from a place no one else can change (issue 30): numba's index
files are pickles, so a kernel cache another user can write runs their code as whoever plans
next. The rule (:mod:`planner._private`), the private cache the planner uses instead, and a
read-only cache that holds kernels (the container's root-owned seed read by another uid)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from planner import _jit
from planner._private import distrust, distrust_tree
from planner.orchestrator.background import kernels_ready

ROOT = Path(__file__).resolve().parent.parent
NOBODY = 65534
KERNEL = "kernels.smallest_singular_values-"  # a small kernel of planner/model/kernels.py

#: run the small kernel in a new interpreter; print its cache hits and misses and the cache used
#: (``DROP``: as uid/gid 65534, after importing as root what the interpreter's 0700 home hides,
#: numba's compiler included; the planner's kernels, whose cache is resolved when they are
#: declared, are imported after)
PROBE = """
import json, os, sys
import numpy as np
import numba
from planner import _jit
if os.environ.get("DROP"):
    import planner.schema  # pydantic (what the kernels module imports besides numpy)
    numba.njit(lambda x: x + 1)(1)  # numba loads its compiler's modules (the stdlib's included) as root
    os.setgroups([]); os.setgid(65534); os.setuid(65534)
from planner.model import kernels as k
d = k.smallest_singular_values
d(np.eye(3)[None])
s = d.stats
cache = _jit.kernel_cache()
print(json.dumps({"hits": sum(s.cache_hits.values()), "misses": sum(s.cache_misses.values()),
                  "path": str(cache.path), "copied_from": str(cache.copied_from), "later": cache.later(),
                  "numba_cache_dir": numba.config.CACHE_DIR}))
"""


def _probe(env: dict) -> tuple[dict, str]:
    out = subprocess.run([sys.executable, "-c", PROBE], env={**env, "PYTHONDONTWRITEBYTECODE": "1",
                                                               "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1",
                                                               "PATH": "/usr/bin:/bin"},
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1]), out.stderr


def _kernel_files(cache: Path) -> list[Path]:
    """The small kernel's index and object files in the kernel cache ``cache`` (numba's own
    layout beside the copy of its module: ``planner/model/__pycache__/kernels.<name>-<line>.py311
    [.n.nbc|.nbi]``)."""
    return list(cache.glob("planner/model/__pycache__/" + KERNEL + "*"))


def _plant(cache: Path) -> None:
    """Copy this machine's compiled small kernel (not the module copy: the probe writes it) into
    the kernel cache ``cache``."""
    if not kernels_ready():
        import planner
        planner.warm_up()
    files = _kernel_files(_jit.kernel_cache_dir())
    assert files, "the machine's cache lacks the kernel"
    for f in files:
        target = cache / f.relative_to(_jit.kernel_cache_dir())
        target.parent.mkdir(parents=True, mode=0o755, exist_ok=True)
        shutil.copy2(f, target)
    for d in (cache, *(p for p in cache.rglob("*") if p.is_dir())):
        os.chmod(d, 0o755)


def test_the_rule(tmp_path):
    d = tmp_path / "a" / "b"
    d.mkdir(parents=True, mode=0o755)
    os.chmod(tmp_path / "a", 0o755)
    assert distrust(d, tmp_path / "a") is None
    os.chmod(d, 0o777)
    assert distrust(d) == f"{d} is writable by others (mode 0777)"
    os.chmod(d, 0o755)
    os.chmod(tmp_path / "a", 0o775)  # a parent up to the chosen root counts
    assert distrust(d, tmp_path / "a") == f"{tmp_path / 'a'} is writable by others (mode 0775)"
    assert distrust(d, d) is None  # above the root: not looked at
    os.chmod(tmp_path / "a", 0o1777)  # sticky and root-owned (/tmp): others cannot replace ours
    assert distrust(d, tmp_path / "a") is None
    os.chown(d, NOBODY, NOBODY)
    assert distrust(d) == f"{d} belongs to uid {NOBODY}"
    os.chmod(tmp_path / "a", 0o755)
    os.chown(d, 0, 0)
    link = tmp_path / "a" / "link"
    link.symlink_to(d)
    assert distrust(link) == f"{link} is a symlink"
    assert distrust(link / "x") == f"{link / 'x'}: No such file or directory"
    assert distrust(d, owners=(os.geteuid(),), mask=0o077) == f"{d} is accessible by others (mode 0755)"
    # below: a file others can write is as bad as the directory
    (d / "x.nbi").write_bytes(b"")
    os.chmod(d / "x.nbi", 0o666)
    assert distrust_tree(tmp_path) == f"{d / 'x.nbi'} is writable by others (mode 0666)"


def test_a_cache_others_can_write_is_not_loaded(tmp_path):
    """A compiled kernel planted in a cache directory others can write is compiled, not loaded,
    into the private cache; one line on stderr names the directory and the cause."""
    shared, home = tmp_path / "shared", tmp_path / "home"
    home.mkdir()
    _plant(shared / _jit.kernel_key()[:16])
    env = {"RANGEPLAN_KERNEL_CACHE": str(shared), "HOME": str(home)}
    got, _ = _probe(env)
    assert (got["hits"], got["misses"]) == (1, 0)  # as it is, the kernel loads from there
    os.chmod(shared, 0o777)
    got, err = _probe(env)
    private = home / ".cache" / "rangeplan" / "kernels" / _jit.kernel_key()[:16]
    assert (got["hits"], got["misses"]) == (0, 1) and got["path"] == str(private), got
    lines = [ln for ln in err.splitlines() if "kernel" in ln]
    assert lines == [f"rangeplan: kernels not loaded from {shared / _jit.kernel_key()[:16]}: {shared} is writable "
                     f"by others (mode 0777); using private cache {private}"], err
    assert os.stat(private).st_mode & 0o777 == 0o700
    assert _kernel_files(private)  # saved there for the next run
    assert got["numba_cache_dir"] == ""  # numba's own setting is left as it was
    os.chmod(shared, 0o755)


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to run a process as another uid")
def test_a_read_only_seed_of_root_is_loaded_by_another_uid():
    """The container's case: a root-owned cache (mode 0755) holding the kernels is loaded, not
    compiled, by a process of another uid, which cannot write it: its kernels are copied into
    that user's private cache (numba loads only from a directory it can write)."""
    top = Path(tempfile.mkdtemp(prefix="rangeplan-seed-"))  # in /tmp: uid 65534 can reach it
    try:
        os.chmod(top, 0o755)
        cache = top / f"rangeplan-{_jit.kernel_key()[:16]}"
        _plant(cache)
        home = top / "home"
        home.mkdir(mode=0o755)
        os.chown(home, NOBODY, NOBODY)
        got, err = _probe({"NUMBA_CACHE_DIR": str(top), "HOME": str(home), "DROP": "1"})
        assert (got["hits"], got["misses"]) == (1, 0), (got, err)
        private = home / ".cache" / "rangeplan" / "kernels" / _jit.kernel_key()[:16]
        assert got["path"] == str(private) and got["copied_from"] == str(cache), got
        assert "kernels not loaded" not in err
        assert {f.name for f in _kernel_files(cache)} == {f.name for f in _kernel_files(private)}
    finally:
        shutil.rmtree(top)


def test_a_closed_directory_of_ours_is_trusted_whatever_the_umask(tmp_path):
    """numba writes its files with the umask's modes: with a umask that lets the group write,
    the kernels of a cache directory only this user may enter (mode 0700) still load (no one
    else can reach them), while the same files in an open directory are refused."""
    home = tmp_path / "home"
    home.mkdir()
    cache = tmp_path / "kernels"
    _plant(cache / _jit.kernel_key()[:16])
    for f in (cache / _jit.kernel_key()[:16]).rglob("*"):
        os.chmod(f, 0o775 if f.is_dir() else 0o664)
    env = {"RANGEPLAN_KERNEL_CACHE": str(cache), "HOME": str(home)}
    got, err = _probe(env)
    assert got["path"] != str(cache / _jit.kernel_key()[:16]) and "is writable by others (mode 0" in err, (got, err)
    os.chmod(cache / _jit.kernel_key()[:16], 0o700)
    got, err = _probe(env)
    assert (got["hits"], got["misses"]) == (1, 0) and got["path"] == str(cache / _jit.kernel_key()[:16]), (got, err)
    assert "kernels not loaded" not in err


#: makes the background compile's warm-up fail as on a full disk (sitecustomize of its interpreter)
FAIL_WARM_UP = """import sys
if sys.argv[1:2] == ["--background"]:
    import errno
    import planner.orchestrator

    def warm_up(backend="compiled"):
        raise OSError(errno.ENOSPC, "No space left on device")

    planner.orchestrator.warm_up = warm_up
"""


def test_a_failed_background_compile_is_not_started_again(tmp_path):
    """A background compile that fails (here its warm-up raises ENOSPC) records why; the next
    call starts none and says in one line that it failed and why, until the cause can have
    changed (here: an hour passed)."""
    import time

    inject, cache_root, home = tmp_path / "inject", tmp_path / "kernels", tmp_path / "home"
    inject.mkdir()
    home.mkdir()
    (inject / "sitecustomize.py").write_text(FAIL_WARM_UP)
    env = {"RANGEPLAN_KERNEL_CACHE": str(cache_root), "HOME": str(home), "PYTHONPATH": f"{inject}:{ROOT}",
           "OPENBLAS_NUM_THREADS": "1", "PATH": "/usr/bin:/bin", "PYTHONDONTWRITEBYTECODE": "1"}
    cache = cache_root / _jit.kernel_key()[:16]
    code = ("import json\nfrom planner.orchestrator.background import compile_in_background\n"
            "b = compile_in_background()\n"
            "print(json.dumps(b and {'pid': b.pid, 'started': b.started, 'failed': b.failed, 'note': b.note(1.0)}))")

    def start() -> dict:
        out = subprocess.run([sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True, text=True,
                             timeout=300)
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout.strip().splitlines()[-1])

    def wait_failed() -> dict:
        deadline = time.monotonic() + 120
        while not (cache / "compile.failed").exists() or "failed:" not in (cache / "compile.log").read_text():
            assert time.monotonic() < deadline, (cache / "compile.log").read_text()
            time.sleep(0.2)
        return json.loads((cache / "compile.failed").read_text())

    first = start()
    assert first["started"] and first["pid"] and first["failed"] is None
    record = wait_failed()
    assert record["cause"] == "OSError: [Errno 28] No space left on device" and record["key"] == _jit.kernel_key()
    assert record["writable"] is True and record["free_bytes"] > 0
    second = start()
    assert second["pid"] is None and not second["started"], second  # nothing started
    assert second["failed"].startswith("OSError: [Errno 28] No space left on device, ")
    assert second["note"].startswith("kernels not compiled: the background compile failed earlier (OSError: [Errno "
                                     "28] No space left on device, ") and "numpy reference" in second["note"]
    assert (cache / "compile.log").read_text().count("background compile (pid") == 1
    (cache / "compile.failed").write_text(json.dumps({**record, "time": record["time"] - 3601}))
    third = start()  # an hour later: tried again
    assert third["started"] and third["pid"]
    wait_failed()
    assert (cache / "compile.log").read_text().count("background compile (pid") == 2


def test_a_failure_holds_until_its_cause_can_have_changed():
    from planner.orchestrator.background import FREE_MARGIN_BYTES, RETRY_S, _applies

    record = {"key": "k", "writable": False, "free_bytes": 10, "time": 1000.0}
    now = {"key": "k", "writable": False, "free_bytes": 10}
    assert _applies(record, now, 1000.0 + RETRY_S - 1)
    assert not _applies(record, now, 1000.0 + RETRY_S)
    assert not _applies(record, {**now, "key": "other"}, 1001.0)
    assert not _applies(record, {**now, "writable": True}, 1001.0)
    assert not _applies(record, {**now, "free_bytes": 10 + FREE_MARGIN_BYTES}, 1001.0)
    assert _applies(record, {**now, "free_bytes": 9 + FREE_MARGIN_BYTES}, 1001.0)
