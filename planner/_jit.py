"""``njit`` for the planner's kernels: numba's, with the on-disk cache keyed by the content of
*all* the kernel sources and kept in one place per machine (issue 24).

numba (>= 0.61) keys a cached kernel by the content of its own source file only: a kernel
compiled with its callees from other files inlined stays "valid" when only a callee's file
changes, and the cache lives beside the sources, so every new venv, clone or worktree
compiles again (a minute or more). Here the cache of every kernel is keyed by the hash of
all the kernel modules' sources (:data:`KERNEL_SOURCES`) and numba's version, and lives in

1. ``$NUMBA_CACHE_DIR/rangeplan-<key>`` when ``NUMBA_CACHE_DIR`` is set (the container's
   read-only seed, ``app/kernel_cache.py``), else
2. ``$RANGEPLAN_KERNEL_CACHE/<key>``, else ``$XDG_CACHE_HOME/rangeplan/kernels/<key>``
   (``~/.cache/rangeplan/kernels/<key>``), else
3. beside the sources (numba's default) when neither is writable.

So a fresh install of the same source on a machine that compiled it once loads the kernels
instead of compiling them, and any change of a kernel file recompiles every kernel. numba
still checks the CPU (and its features) per entry, as for its own cache.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from functools import lru_cache
from pathlib import Path
from typing import Any

import numba
from numba.core import caching

__all__ = ["njit", "KERNEL_SOURCES", "kernel_cache_dir", "kernel_key", "STRICT_REFRESH", "numpy_only", "kernels_off"]

#: numba's own order: refresh the whole target context before loading a cached kernel
#: (``RANGEPLAN_KERNEL_REFRESH=1``; measured by ``benchmarks/bench_start.py``)
STRICT_REFRESH = os.environ.get("RANGEPLAN_KERNEL_REFRESH", "") == "1"

_ROOT = Path(__file__).resolve().parent
#: the kernel modules (relative to ``planner/``) whose content keys the cache
KERNEL_SOURCES = ("model/kernels.py", "horizon/kernels.py", "corridor/kernels.py", "constraints/kernels.py",
                  "constraints/dense_kernels.py", "constraints/stagewise_kernels.py",
                  "constraints/dual_kernels.py", "constraints/step_kernels.py", "orchestrator/kernels.py")


@lru_cache(maxsize=1)
def kernel_key() -> str:
    """sha256 of numba's and llvmlite's versions, a non-default ``NUMBA_OPT`` (numba's own cache
    ignores it) and every kernel source (hex, 64 digits)."""
    import llvmlite
    from numba.core import config

    opt = int(getattr(config, "OPT", 3))
    h = hashlib.sha256(f"numba {numba.__version__} llvmlite {llvmlite.__version__}{'' if opt == 3 else f' opt {opt}'}\n"
                       .encode())
    for rel in KERNEL_SOURCES:
        h.update(rel.encode() + b"\0" + (_ROOT / rel).read_bytes() + b"\0")
    return h.hexdigest()


def kernel_cache_dir(environ: dict | None = None) -> Path:
    """The directory of this source's kernel cache (not created)."""
    env = os.environ if environ is None else environ
    tag = kernel_key()[:16]
    if env.get("NUMBA_CACHE_DIR"):
        return Path(env["NUMBA_CACHE_DIR"]) / f"rangeplan-{tag}"
    if env.get("RANGEPLAN_KERNEL_CACHE"):
        return Path(env["RANGEPLAN_KERNEL_CACHE"]) / tag
    base = env.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "rangeplan" / "kernels" / tag


class _KernelLocator(caching._SourceFileBackedLocatorMixin, caching._CacheLocator):
    """The planner's kernels: cache in :func:`kernel_cache_dir`, stamped by :func:`kernel_key`."""

    def __init__(self, py_func: Any, py_file: str) -> None:
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        rel = Path(py_file).resolve().relative_to(_ROOT)
        self._cache_path = str(kernel_cache_dir() / rel.parent)

    def get_cache_path(self) -> str:
        return self._cache_path

    def get_source_stamp(self) -> str:
        return kernel_key()

    @classmethod
    def from_function(cls, py_func: Any, py_file: str) -> Any:
        try:
            Path(py_file).resolve().relative_to(_ROOT)
        except ValueError:
            return None
        self = cls(py_func, py_file)
        try:
            self.ensure_cache_path()
        except OSError:
            return None  # not writable: numba's own locators (beside the sources)
        return self


class _KernelCacheImpl(caching.CompileResultCacheImpl):
    _locator_classes = [_KernelLocator, *caching.CompileResultCacheImpl._locator_classes]


class _KernelCache(caching.FunctionCache):
    _impl_class = _KernelCacheImpl

    def load_overload(self, sig: Any, target_context: Any) -> Any:
        """numba's load of a cached kernel without its ``target_context.refresh()``: that imports
        and installs every typing and lowering registry of numba (~0.4 CPU s, the largest part
        of a warm plan's start, issue 24) which only compiling needs; a cached kernel is object
        code linked against numba's runtime (NRT), which is all this sets up first. A
        kernel that is not in the cache compiles, and numba's compiler refreshes the context
        itself first (``CompilerBase.__init__``)."""
        if not STRICT_REFRESH:
            from numba.core.runtime.nrt import rtsys

            rtsys.initialize(target_context)  # numba's runtime (NRT): what refresh() sets up first
            try:
                with self._guard_against_spurious_io_errors():
                    return self._load_overload(sig, target_context)
            except Exception:  # e.g. a symbol only a registry provides: load it the way numba does
                pass
        return super().load_overload(sig, target_context)


def njit(*args: Any, **options: Any) -> Any:
    """``numba.njit`` (same arguments); with ``cache=True`` the cache described above."""
    cache = options.pop("cache", False)

    def wrap(func: Any) -> Any:
        dispatcher: Any = numba.njit(**options)(func)
        if cache:
            dispatcher._cache = _KernelCache(dispatcher.py_func)
        return dispatcher

    if args and callable(args[0]) and len(args) == 1:
        return wrap(args[0])
    if args:
        raise TypeError("planner._jit.njit takes no positional signature; declare none (one dispatch per call)")
    return wrap


_NUMPY_ONLY: ContextVar[bool] = ContextVar("rangeplan_numpy_only", default=False)


def kernels_off() -> bool:
    """Whether the current plan runs on the numpy reference only (``settings.backend =
    "reference"``): the few helpers that call a compiled kernel whatever the backend (the
    singularity measure, the corridor distances, the paper mode's Riccati solve) use their
    numpy twins instead, so that a reference plan compiles nothing (issue 24)."""
    return _NUMPY_ONLY.get()


@contextmanager
def numpy_only(on: bool = True) -> Iterator[None]:
    """Within the block (this thread / task), :func:`kernels_off` is ``on``."""
    token = _NUMPY_ONLY.set(on)
    try:
        yield
    finally:
        _NUMPY_ONLY.reset(token)
