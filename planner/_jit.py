"""``njit`` for the planner's kernels: numba's, with the on-disk cache keyed by the content of
*all* the kernel sources and kept in one place per machine (issue 24), loaded only from a
place no one else can change (issue 30).

numba (>= 0.61) keys a cached kernel by the content of its own source file only: a kernel
compiled with its callees from other files inlined stays "valid" when only a callee's file
changes, and the cache lives beside the sources, so every new venv, clone or worktree
compiles again (a minute or more). Here the cache of every kernel is keyed by the hash of
all the kernel modules' sources (:data:`KERNEL_SOURCES`) and numba's version, and the
environment chooses its place (:func:`chosen_kernel_cache`):

1. ``$NUMBA_CACHE_DIR/rangeplan-<key>`` when ``NUMBA_CACHE_DIR`` is set (the container's
   copy of its kernel seed, ``app/kernel_cache.py``), else
2. ``$RANGEPLAN_KERNEL_CACHE/<key>``, else ``$XDG_CACHE_HOME/rangeplan/kernels/<key>``
   (``~/.cache/rangeplan/kernels/<key>``).

numba's index files are pickles: whoever can write the cache runs code as whoever plans next.
So the chosen place is used (:func:`kernel_cache`) only when it, its parents up to the
variable's directory and everything in it belong to this user or root and no one else can
write them (:mod:`planner._private`), and either this user can write it or it holds
kernels already (a read-only cache, such as the container's root-owned seed, is loaded
from; kernels it lacks compile for this process only). Otherwise the kernels go to a private
cache (``~/.cache/rangeplan/kernels/<key>``, made mode 0700, or when that is the rejected one
or unusable a temporary directory of this process) and one line on stderr names the
rejected directory and why. numba's own places (beside the sources, ``~/.cache/numba``)
are never used.

So a fresh install of the same source on a machine that compiled it once loads the kernels
instead of compiling them, and any change of a kernel file recompiles every kernel. numba
still checks the CPU (and its features) per entry, as for its own cache.
"""

from __future__ import annotations

import atexit
import errno
import hashlib
import os
import shutil
import sys
import tempfile
import uuid
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from contextvars import ContextVar
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numba
from numba.core import caching

from ._private import distrust, distrust_tree, make_dirs

__all__ = ["njit", "KERNEL_SOURCES", "KernelCache", "chosen_kernel_cache", "kernel_cache", "kernel_cache_dir",
           "kernel_key", "STRICT_REFRESH", "numpy_only", "kernels_off", "save_error"]

#: numba's own order: refresh the whole target context before loading a cached kernel
#: (``RANGEPLAN_KERNEL_REFRESH=1``; measured by ``benchmarks/bench_start.py``)
STRICT_REFRESH = os.environ.get("RANGEPLAN_KERNEL_REFRESH", "") == "1"

_ROOT = Path(__file__).resolve().parent
#: the kernel modules (relative to ``planner/``) whose content keys the cache
KERNEL_SOURCES = ("model/kernels.py", "horizon/kernels.py", "corridor/kernels.py", "constraints/kernels.py",
                  "constraints/dense_kernels.py", "constraints/stagewise_kernels.py",
                  "constraints/dual_kernels.py", "constraints/step_kernels.py", "constraints/registry.py",
                  "orchestrator/kernels.py")


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


def chosen_kernel_cache(environ: dict | None = None) -> tuple[Path, Path]:
    """The kernel cache directory the environment chooses (not created, not checked) and the
    directory of the variable that chose it (checked from the cache up to there)."""
    env = os.environ if environ is None else environ
    tag = kernel_key()[:16]
    if env.get("NUMBA_CACHE_DIR"):
        root = Path(env["NUMBA_CACHE_DIR"])
        return root / f"rangeplan-{tag}", root
    if env.get("RANGEPLAN_KERNEL_CACHE"):
        root = Path(env["RANGEPLAN_KERNEL_CACHE"])
        return root / tag, root
    root = Path(env.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"))
    return root / "rangeplan" / "kernels" / tag, root


@dataclass(frozen=True)
class KernelCache:
    """Where this process loads the planner's kernels from and saves them to: ``path``;
    ``writable``: kernels compiled now are saved there (False: a read-only cache holding
    kernels, loaded from; the ones it lacks compile for this process only); ``temporary``: a
    private directory of this process, removed at its exit; ``note``: the line that said why
    the chosen directory is not used (None: it is)."""

    path: Path
    writable: bool = True
    temporary: bool = False
    note: str | None = None

    @property
    def lasting(self) -> bool:
        """Whether kernels compiled now are there for later processes."""
        return self.writable and not self.temporary

    def later(self) -> str:
        """What becomes of the kernels compiled now (for the progress line)."""
        if not self.writable:
            return f"for this process only: {self.path} cannot be written"
        if self.temporary:
            return f"for this process only: in the temporary cache {self.path}"
        return f"once for this version on this machine, later runs load them from {self.path}"


def _holds_kernels(d: Path) -> bool:
    return next(d.glob("*/*.nbi"), None) is not None


def _private_cache(rejected: Path) -> KernelCache:
    """``~/.cache/rangeplan/kernels/<key>`` (new directories mode 0700) unless that is the
    rejected one or fails the check, else a new temporary directory (removed at exit)."""
    home = Path(os.path.expanduser("~")) / ".cache"
    d = home / "rangeplan" / "kernels" / kernel_key()[:16]
    if d != rejected:
        with suppress(OSError):
            make_dirs(d, 0o700)
        if distrust(d, home) is None and distrust_tree(d) is None and os.access(d, os.W_OK):
            return KernelCache(d)
    t = Path(tempfile.mkdtemp(prefix=f"rangeplan-kernels-{kernel_key()[:16]}-"))
    atexit.register(shutil.rmtree, t, True)
    return KernelCache(t, temporary=True)


@lru_cache(maxsize=1)
def kernel_cache() -> KernelCache:
    """This process's kernel cache (see the module docstring; resolved once, on first use, the
    chosen directory created if missing)."""
    chosen, root = chosen_kernel_cache()
    why = None
    try:
        make_dirs(chosen)
    except OSError as exc:
        why = f"{chosen} cannot be created ({exc.strerror})"
    why = why or distrust(chosen, root) or distrust_tree(chosen)
    if why is None:
        if os.access(chosen, os.W_OK):
            return KernelCache(chosen)
        if _holds_kernels(chosen):
            return KernelCache(chosen, writable=False)
        why = f"{chosen} is not writable and holds no kernels"
    private = _private_cache(chosen)
    note = f"rangeplan: kernels not loaded from {chosen}: {why}; using private cache {private.path}"
    print(note, file=sys.stderr, flush=True)
    return KernelCache(private.path, private.writable, private.temporary, note)


def kernel_cache_dir() -> Path:
    """The directory of this process's kernel cache (:func:`kernel_cache`)."""
    return kernel_cache().path


_save_error: list[OSError] = []  # the first error saving a compiled kernel in this process


def save_error() -> OSError | None:
    """The first error saving a compiled kernel in this process (None: none)."""
    return _save_error[0] if _save_error else None


def _save_failed(exc: OSError) -> None:
    """Note a kernel that could not be saved; the first time, one line on stderr (not for a
    read-only cache: the progress line said the kernels compile for this process only)."""
    if not _save_error:
        _save_error.append(exc)
        if kernel_cache().writable:
            print(f"rangeplan: compiled kernels cannot be saved in {kernel_cache().path} ({exc.strerror or exc}): "
                  "they compile for this process only", file=sys.stderr, flush=True)


class _KernelLocator(caching._SourceFileBackedLocatorMixin, caching._CacheLocator):
    """The planner's kernels: cache in :func:`kernel_cache`, stamped by :func:`kernel_key`."""

    def __init__(self, py_func: Any, py_file: str) -> None:
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        rel = Path(py_file).resolve().relative_to(_ROOT)
        self._cache_path = str(kernel_cache().path / rel.parent)

    def get_cache_path(self) -> str:
        return self._cache_path

    def get_source_stamp(self) -> str:
        return kernel_key()

    def ensure_cache_path(self) -> None:
        """Make this kernel's directory before a save (numba's test write left out: a read-only
        cache is loaded from); a read-only cache raises ``PermissionError`` (the save is skipped)."""
        if not kernel_cache().writable:
            raise PermissionError(errno.EACCES, "the kernel cache is read-only", self._cache_path)
        make_dirs(Path(self._cache_path))

    @classmethod
    def from_function(cls, py_func: Any, py_file: str) -> Any:
        try:
            Path(py_file).resolve().relative_to(_ROOT)
        except ValueError:
            return None
        return cls(py_func, py_file)


class _KernelCacheFile(caching.IndexDataCacheFile):
    """numba's index and data files, written mode 0644 whatever the umask, never through a symlink."""

    @contextmanager
    def _open_for_write(self, filepath: str) -> Iterator[Any]:
        tmp = f"{filepath}.tmp.{uuid.uuid4().hex[:16]}"
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
        try:
            with os.fdopen(fd, "wb") as f:
                yield f
            os.replace(tmp, filepath)
        except BaseException:
            with suppress(OSError):
                os.unlink(tmp)
            raise


class _KernelCacheImpl(caching.CompileResultCacheImpl):
    _locator_classes = [_KernelLocator]


class _KernelCache(caching.FunctionCache):
    _impl_class = _KernelCacheImpl

    def __init__(self, py_func: Any) -> None:
        super().__init__(py_func)
        self._cache_file.__class__ = _KernelCacheFile

    def save_overload(self, sig: Any, data: Any) -> None:
        """numba's save; a kernel that cannot be saved (read-only cache, full disk) stays
        compiled in this process (:func:`_save_failed`)."""
        try:
            super().save_overload(sig, data)
        except OSError as exc:
            _save_failed(exc)

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
