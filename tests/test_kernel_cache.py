"""The kernel cache through numba's public API (issue 34 goal 5): numba's own ``cache=True``
keyed on a content-addressed copy of each kernel module (:mod:`planner._jit`), so another
checkout, venv or wheel install of the same source loads the kernels one compiled, and a
cache directory moved elsewhere still loads; the environment read once, in
``planner/_config.py``, mirrored by the settings object."""

from __future__ import annotations

import ast
import inspect
import json
import linecache
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numba
import pytest

from app.settings import Settings, env_name, settings
from planner import _jit
from planner.orchestrator import compiling
from tests.test_settings import _environment_uses

ROOT = Path(__file__).resolve().parent.parent

#: run a small kernel of planner/model/kernels.py in a new interpreter (``sys.path[0]``: the
#: checkout to import the planner from); print its cache hits and misses, the kernel module's
#: file and the file its compiled function names
PROBE = """
import json, sys
import numpy as np
from planner import _jit
from planner.model import kernels as k
d = k.smallest_singular_values
jitted = hasattr(d, "py_func")  # not with NUMBA_DISABLE_JIT=1
before = _jit.cached(d) if jitted else None
d(np.eye(3)[None])
s = d.stats if jitted else None
print(json.dumps({"hits": s and sum(s.cache_hits.values()), "misses": s and sum(s.cache_misses.values()),
                  "module": k.__file__, "code": (d.py_func if jitted else d).__code__.co_filename,
                  "cache_path": s and s.cache_path, "cached_before": before,
                  "cached_after": _jit.cached(d) if jitted else None}))
"""


def _probe(checkout: Path, cache_root: Path, **extra: str) -> dict:
    env = {**extra, "RANGEPLAN_KERNEL_CACHE": str(cache_root), "HOME": str(cache_root.parent), "PATH": "/usr/bin:/bin",
           "PYTHONPATH": str(checkout), "PYTHONDONTWRITEBYTECODE": "1", "OPENBLAS_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, cwd=checkout, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_another_checkout_and_a_moved_cache_load_what_one_compiled(tmp_path):
    """One checkout compiles a kernel; a second checkout of the same source at another path
    (its files with new mtimes, as a clone or a wheel install has) loads it without compiling,
    and so does either after the whole cache directory moved."""
    other = tmp_path / "other-checkout"
    shutil.copytree(ROOT / "planner", other / "planner", copy_function=shutil.copyfile,
                    ignore=shutil.ignore_patterns("__pycache__"))
    cache = tmp_path / "kernels"
    first = _probe(ROOT, cache)
    assert (first["hits"], first["misses"]) == (0, 1)  # a new cache: compiled
    assert (first["cached_before"], first["cached_after"]) == (False, True)
    copy = cache / _jit.kernel_key()[:16] / "planner" / "model" / "kernels.py"
    assert first["code"] == str(copy) and first["cache_path"] == str(copy.parent / "__pycache__")
    second = _probe(other, cache)
    assert second["module"] == str(other / "planner" / "model" / "kernels.py")  # the other checkout's module
    assert (second["hits"], second["misses"]) == (1, 0), second  # loaded, not compiled
    assert second["cached_before"] is True
    assert second["code"] == first["code"]
    moved = tmp_path / "elsewhere" / "kernels"
    moved.parent.mkdir()
    shutil.move(cache, moved)
    third = _probe(other, moved)
    assert (third["hits"], third["misses"]) == (1, 0), third
    assert third["code"] == str(moved / _jit.kernel_key()[:16] / "planner" / "model" / "kernels.py")


def test_a_changed_kernel_source_is_another_cache(tmp_path, monkeypatch):
    """Any change of any kernel module changes the key, so every kernel recompiles (numba alone
    would keep a kernel whose inlined callee's file changed)."""
    for rel in _jit.KERNEL_SOURCES:
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(ROOT / "planner" / rel, tmp_path / rel)
    monkeypatch.setattr(_jit, "_ROOT", tmp_path)
    _jit.kernel_key.cache_clear()
    try:
        same = _jit.kernel_key()
        for rel in _jit.KERNEL_SOURCES:
            with open(tmp_path / rel, "a") as f:
                f.write("# an edit\n")
            _jit.kernel_key.cache_clear()
            changed = _jit.kernel_key()
            assert changed != same, rel
            same = changed
    finally:
        monkeypatch.undo()
        _jit.kernel_key.cache_clear()


def test_each_kernel_names_a_faithful_copy_of_its_module():
    """Every cached kernel's code names the copy of its module in this process's kernel cache:
    the same bytes (so tracebacks and numba's messages show the checkout's lines), the fixed
    mtime, and numba keeps the kernel beside it; the function is the module's own otherwise
    (same bytecode, globals, name, module)."""
    kernels = compiling.kernel_dispatchers()
    assert len(kernels) >= 40
    cache = _jit.kernel_cache_dir()
    for name, d in kernels.items():
        module = sys.modules[d.py_func.__module__]
        original = Path(str(module.__file__))
        copy = Path(d.py_func.__code__.co_filename)
        assert copy == _jit.source_copy(original) == cache / "planner" / original.relative_to(ROOT / "planner")
        assert copy.read_bytes() == original.read_bytes(), name
        assert os.stat(copy).st_mtime == _jit.SOURCE_MTIME, name
        assert Path(d.stats.cache_path) == copy.parent / "__pycache__", name
        assert d.py_func.__globals__ is vars(module) and d.py_func.__qualname__ == name.split(".", 1)[1]
        first = d.py_func.__code__.co_firstlineno
        assert linecache.getline(str(copy), first) == original.read_text().splitlines(True)[first - 1], name
        assert inspect.getsource(d.py_func).lstrip().startswith(("@njit", "def "))


def test_cached_is_numbas_own_reading_of_its_index():
    """:func:`planner._jit.cached` (the index file exists) agrees with numba's own reading of the
    index (private, read by this test only) for every kernel after a warm-up, which compiled
    nearly all of them (not the few no plan calls)."""
    from planner.orchestrator.background import kernels_ready

    if not kernels_ready():
        import planner
        planner.warm_up()
    kernels = {n: d for n, d in compiling.kernel_dispatchers().items() if not compiling._inlined(d)}
    assert len(kernels) >= 40
    for name, d in kernels.items():
        assert _jit.cached(d) is bool(d._cache._cache_file._load_index()), name
    assert sum(_jit.cached(d) for d in kernels.values()) >= len(kernels) - 3


def test_without_the_jit_the_kernels_are_the_checkouts_functions(tmp_path):
    """``NUMBA_DISABLE_JIT=1`` (debugging a kernel in Python): the functions run as they are,
    their tracebacks naming the checkout's file."""
    got = _probe(ROOT, tmp_path / "kernels", NUMBA_DISABLE_JIT="1")
    assert got["code"] == got["module"] == str(ROOT / "planner" / "model" / "kernels.py")
    assert got["hits"] is None and got["cached_before"] is None  # a Python function, no dispatcher


def test_a_kernel_outside_the_keyed_modules_is_refused():
    def f(x):  # pragma: no cover - never compiled
        return x

    with pytest.raises(TypeError, match=r"test_kernel_cache\.py: not a module of planner\._jit\.KERNEL_SOURCES"):
        _jit.njit(cache=True)(f)
    assert _jit.njit(f).py_func is f  # without cache=True: numba's njit as it is


def test_jit_uses_numbas_public_api_only_and_leaves_its_setting():
    """planner/_jit.py imports no numba module but ``numba`` and reads no private attribute of
    numba's objects; numba's cache directory setting is the environment's after declaring."""
    tree = ast.parse((ROOT / "planner" / "_jit.py").read_text())
    imports = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imports |= {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert {m for m in imports if m.startswith("numba")} == {"numba"}
    private = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute) and n.attr.startswith("_")
               and not n.attr.startswith("__")}
    assert private == set(), private
    compiling.kernel_dispatchers()
    assert vars(numba.config)["CACHE_DIR"] == os.environ.get("NUMBA_CACHE_DIR", "")  # pyright: ignore[reportPrivateImportUsage]


def test_the_planner_reads_the_environment_only_in_its_config():
    """planner/ reads the environment in planner/_config.py alone (the planner cannot import
    app/settings.py)."""
    uses = [u for p in sorted((ROOT / "planner").rglob("*.py")) if p.name != "_config.py"
            for u in _environment_uses(p)]
    assert uses == []
    assert _environment_uses(ROOT / "planner" / "_config.py")  # the one reader (a test of the test)


def test_the_planners_variables_are_settings_of_the_same_meaning():
    """Every variable the planner reads but HOME is a field of the settings object (the table
    users read), and both read the same values from one environment."""
    from planner._config import ENV_VARS, read_config

    assert set(ENV_VARS) - {"HOME"} <= {env_name(k) for k in Settings.model_fields}
    env = {"NUMBA_CACHE_DIR": "/n", "RANGEPLAN_KERNEL_CACHE": "/k", "XDG_CACHE_HOME": "/x", "HOME": "/h"}
    s, c = settings(env), read_config(env)
    assert (s.numba_cache_dir, s.kernel_cache, s.xdg_cache_home) == (c.numba_cache_dir, c.kernel_cache,
                                                                     c.cache_home) == (Path("/n"), Path("/k"),
                                                                                       Path("/x"))
    assert read_config({"HOME": "/h"}).cache_home == Path("/h/.cache")  # XDG's default
    assert read_config({"RANGEPLAN_KERNEL_CACHE": ""}).kernel_cache is None  # empty: unset, as in settings
    assert _jit.chosen_kernel_cache(env) == (Path("/n") / f"rangeplan-{_jit.kernel_key()[:16]}", Path("/n"))
