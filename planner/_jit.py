"""``njit`` for the planner's kernels: numba's, through its public API only (issue 34 goal 5),
with one on-disk cache per machine keyed by the content of *all* the kernel sources (issue 24)
that every checkout, venv, wheel install and image of the same source shares, loaded only from
a place no one else can change (issue 30).

numba's public cache (``cache=True``) keys a kernel by its own source file only (its content
since numba 0.68, its mtime and size before) and keeps it beside that file (``__pycache__``)
or under ``NUMBA_CACHE_DIR`` in a directory named by a hash of the file's absolute path: a
kernel compiled with its callees from other files inlined stays "valid" when only a callee's
file changes, and every checkout, venv or wheel install compiles its own kernels (3-4 minutes
on a 2-core machine). So the source numba keys on is made content-addressed:

* the cache directory (:func:`kernel_cache`) is named by :func:`kernel_key`, the hash of all
  the kernel modules' sources (:data:`KERNEL_SOURCES`), numba's and llvmlite's versions;
* it holds a copy of each kernel module (``<cache>/planner/<module path>``, the same bytes,
  modification time :data:`SOURCE_MTIME`: :func:`source_copy`);
* :func:`njit` hands numba each cached kernel as the same function whose code names that copy
  as its file (``CodeType.replace(co_filename=...)``: same bytecode, globals, closure and line
  numbers), with ``cache=True`` and ``numba.config.CACHE_DIR`` unset while it is declared, so
  numba's own locator keeps the kernel beside the copy (``<cache>/planner/<package>/__pycache__``).

The copy's path, content and mtime are the same for every installation of the same source on
the machine, so numba's index is too: a second checkout, a venv or a wheel install loads the
kernels the first compiled; the tree holds no absolute path, so it can be moved or copied
(the container's seed, ``app/kernel_cache.py``); any change of a kernel file is a new
directory, so every kernel recompiles. Tracebacks and numba's error messages through a
compiled kernel name the copy, a file with the checkout's lines (``NUMBA_DISABLE_JIT=1``
leaves the functions as they are). numba checks the CPU (and its features) per entry.

The environment (:mod:`planner._config`) chooses the place (:func:`chosen_kernel_cache`):

1. ``$NUMBA_CACHE_DIR/rangeplan-<key>`` when ``NUMBA_CACHE_DIR`` is set (the container's
   copy of its kernel seed, ``app/kernel_cache.py``), else
2. ``$RANGEPLAN_KERNEL_CACHE/<key>``, else ``$XDG_CACHE_HOME/rangeplan/kernels/<key>``
   (``~/.cache/rangeplan/kernels/<key>``, made mode 0700).

numba's index files are pickles: whoever can write the cache runs code as whoever plans next.
So the chosen place is used only when it, its parents up to the variable's directory and
everything in it belong to this user or root and no one else can write them
(:mod:`planner._private`; everything in a directory of this user that no one else may enter,
mode 0700, counts as such whatever its own mode bits), and this user can write it (numba
saves and loads only where it can write). A trusted cache this user cannot write that holds
kernels (the container's root-owned seed read by another uid) is copied into the private
cache and loaded from there. Otherwise the kernels go to the private cache
(``~/.cache/rangeplan/kernels/<key>``, made mode 0700, or when that is the rejected one or
unusable a temporary directory of this process) and one line on stderr names the rejected
directory and why. numba's own places (beside the checkout's sources, ``~/.cache/numba``)
are never used for the planner's kernels.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import stat
import sys
import tempfile
import threading
import types
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager, suppress
from contextvars import ContextVar
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numba

from ._config import PlannerConfig, config, read_config
from ._private import distrust, distrust_tree, make_dirs

__all__ = ["njit", "KERNEL_SOURCES", "SOURCE_MTIME", "KernelCache", "chosen_kernel_cache", "kernel_cache",
           "kernel_cache_dir", "kernel_key", "source_copy", "cached", "numpy_only", "kernels_off"]

_ROOT = Path(__file__).resolve().parent
#: the kernel modules (relative to ``planner/``) whose content keys the cache
KERNEL_SOURCES = ("model/kernels.py", "horizon/kernels.py", "corridor/kernels.py", "constraints/kernels.py",
                  "constraints/dense_kernels.py", "constraints/stagewise_kernels.py",
                  "constraints/dual_kernels.py", "constraints/step_kernels.py", "constraints/registry.py",
                  "orchestrator/kernels.py")
#: the modification time of every source copy (2001-09-09; numba < 0.68 stamps a source by
#: its mtime and size, so the copies of every installation stamp alike)
SOURCE_MTIME = 1_000_000_000
#: the layout of a cache directory (part of its key: a directory of another layout is another
#: directory, never half-read)
_LAYOUT = "source copies 1"


def _numba_config() -> Any:
    """``numba.config``: numba's settings (each a ``NUMBA_*`` variable; numba documents setting
    them in code), filled from the environment at run time, so untyped."""
    return numba.config  # pyright: ignore[reportPrivateImportUsage]


@lru_cache(maxsize=1)
def kernel_key() -> str:
    """sha256 of the cache layout, numba's and llvmlite's versions, a non-default ``NUMBA_OPT``
    (numba's own cache ignores it) and every kernel source (hex, 64 digits)."""
    import llvmlite

    opt = int(getattr(_numba_config(), "OPT", 3))
    h = hashlib.sha256(f"{_LAYOUT}\nnumba {numba.__version__} llvmlite {llvmlite.__version__}"
                       f"{'' if opt == 3 else f' opt {opt}'}\n".encode())
    for rel in KERNEL_SOURCES:
        h.update(rel.encode() + b"\0" + (_ROOT / rel).read_bytes() + b"\0")
    return h.hexdigest()


def chosen_kernel_cache(cfg: PlannerConfig | Mapping[str, str] | None = None) -> tuple[Path, Path]:
    """The kernel cache directory the configuration chooses (not created, not checked) and the
    directory of the variable that chose it (checked from the cache up to there); ``cfg``: this
    process's configuration (None), another one, or the variables of another environment."""
    cfg = config() if cfg is None else cfg if isinstance(cfg, PlannerConfig) else read_config(cfg)
    tag = kernel_key()[:16]
    if cfg.numba_cache_dir is not None:
        return cfg.numba_cache_dir / f"rangeplan-{tag}", cfg.numba_cache_dir
    if cfg.kernel_cache is not None:
        return cfg.kernel_cache / tag, cfg.kernel_cache
    return cfg.cache_home / "rangeplan" / "kernels" / tag, cfg.cache_home


@dataclass(frozen=True)
class KernelCache:
    """Where this process loads the planner's kernels from and saves them to: ``path``;
    ``temporary``: a private directory of this process, removed at its exit; ``copied_from``:
    the trusted read-only cache whose kernels were copied there (None: none); ``note``: the
    line that said why the chosen directory is not used (None: it is, or its copy)."""

    path: Path
    temporary: bool = False
    copied_from: Path | None = None
    note: str | None = None

    @property
    def lasting(self) -> bool:
        """Whether kernels compiled now are there for later processes."""
        return not self.temporary

    def later(self) -> str:
        """What becomes of the kernels compiled now (for the progress line)."""
        if self.temporary:
            return f"for this process only: in the temporary cache {self.path}"
        return f"once for this version on this machine, later runs load them from {self.path}"


def _holds_kernels(d: Path) -> bool:
    return next(d.glob("planner/*/__pycache__/*.nbi"), None) is not None


def _closed(d: Path) -> bool:
    """Whether ``d`` is a real directory of this user that no one else may enter (mode 0700)."""
    try:
        st = os.lstat(d)
    except OSError:
        return False
    return stat.S_ISDIR(st.st_mode) and st.st_uid == os.geteuid() and not stat.S_IMODE(st.st_mode) & 0o077


def _distrust_contents(d: Path) -> str | None:
    """Why something in ``d`` could have been changed by someone else (None: nothing could).
    In a closed directory (:func:`_closed`) nothing could: numba writes its files with the
    umask's modes, which may grant the group write access to files no one else can reach."""
    return None if _closed(d) else distrust_tree(d)


def _copy_kernels(src: Path, dst: Path) -> None:
    """Copy the kernel files of the trusted cache ``src`` into ``dst`` (not through symlinks)."""
    for path in src.rglob("*"):
        if path.is_file() and not path.is_symlink() and path.suffix in (".nbi", ".nbc"):
            target = dst / path.relative_to(src)
            make_dirs(target.parent, 0o700)
            if not os.path.lexists(target):
                shutil.copyfile(path, target, follow_symlinks=False)


def _write_sources(cache: Path) -> None:
    """Make ``cache/planner/<rel>`` the copy of each kernel module (:data:`KERNEL_SOURCES`): the
    same bytes, mode 0644, mtime :data:`SOURCE_MTIME`; a copy that is already so is left (its
    index files stay valid), any other file there is replaced (atomically, never through a
    symlink)."""
    for rel in KERNEL_SOURCES:
        data = (_ROOT / rel).read_bytes()
        target = cache / "planner" / rel
        with suppress(OSError):
            st = os.lstat(target)
            if stat.S_ISREG(st.st_mode) and st.st_mtime == SOURCE_MTIME and target.read_bytes() == data:
                continue
        make_dirs(target.parent)
        tmp = target.with_name(f"{target.name}.tmp.{os.getpid()}.{threading.get_ident()}")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o644)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            os.utime(tmp, (SOURCE_MTIME, SOURCE_MTIME))
            os.replace(tmp, target)
        except BaseException:
            with suppress(OSError):
                os.unlink(tmp)
            raise


def _private_cache(rejected: Path, seed: Path | None = None) -> KernelCache:
    """``~/.cache/rangeplan/kernels/<key>`` (new directories mode 0700) unless that is the
    rejected one or fails the check, else a new temporary directory (removed at exit); the
    kernels of ``seed`` (a trusted cache this user cannot write) copied into it."""
    home = config().home / ".cache"
    d = home / "rangeplan" / "kernels" / kernel_key()[:16]
    cache = None
    if d != rejected:
        with suppress(OSError):
            make_dirs(d, 0o700)
            if distrust(d, home) is None and _distrust_contents(d) is None and os.access(d, os.W_OK):
                if seed is not None:
                    _copy_kernels(seed, d)
                _write_sources(d)
                cache = KernelCache(d, copied_from=seed)
    if cache is None:
        t = Path(tempfile.mkdtemp(prefix=f"rangeplan-kernels-{kernel_key()[:16]}-"))
        atexit.register(shutil.rmtree, t, True)
        if seed is not None:
            _copy_kernels(seed, t)
        _write_sources(t)
        cache = KernelCache(t, temporary=True, copied_from=seed)
    return cache


@lru_cache(maxsize=1)
def kernel_cache() -> KernelCache:
    """This process's kernel cache, its source copies written (see the module docstring;
    resolved once, on first use, the chosen directory created if missing)."""
    cfg = config()
    chosen, root = chosen_kernel_cache(cfg)
    default = cfg.numba_cache_dir is None and cfg.kernel_cache is None
    why = None
    try:
        make_dirs(chosen, 0o700) if default and not os.path.lexists(chosen) else make_dirs(chosen)
    except OSError as exc:
        why = f"{chosen} cannot be created ({exc.strerror})"
    why = why or distrust(chosen, root) or _distrust_contents(chosen)
    if why is None:
        if os.access(chosen, os.W_OK):
            try:
                _write_sources(chosen)
                return KernelCache(chosen)
            except OSError as exc:
                why = f"the kernel sources cannot be written there ({exc.strerror or exc})"
        elif _holds_kernels(chosen):
            return _private_cache(chosen, seed=chosen)
        else:
            why = f"{chosen} is not writable and holds no kernels"
    private = _private_cache(chosen)
    note = f"rangeplan: kernels not loaded from {chosen}: {why}; using private cache {private.path}"
    print(note, file=sys.stderr, flush=True)
    return KernelCache(private.path, private.temporary, note=note)


def kernel_cache_dir() -> Path:
    """The directory of this process's kernel cache (:func:`kernel_cache`)."""
    return kernel_cache().path


def source_copy(py_file: str | Path) -> Path:
    """The copy in this process's kernel cache of the kernel module ``py_file`` (a file of
    :data:`KERNEL_SOURCES`; ``TypeError`` for any other: its kernels would be cached under a
    key that ignores its content)."""
    path = Path(py_file).resolve()
    rel = path.relative_to(_ROOT).as_posix() if path.is_relative_to(_ROOT) else None
    if rel not in KERNEL_SOURCES:
        raise TypeError(f"planner._jit.njit(cache=True) in {py_file}: not a module of planner._jit.KERNEL_SOURCES "
                        "(the cache key); add it there")
    return kernel_cache_dir() / "planner" / rel


def cached(dispatcher: Any) -> bool:
    """Whether this process's kernel cache holds numba's index of the kernel ``dispatcher`` (one
    declared here with ``cache=True``): the file numba names ``<module>.<qualname>-<first
    line>.py<XY><abiflags>.nbi`` beside the copy of its module (numba's documented layout). The
    directory is keyed by the content of every kernel source and numba's version, so an index
    there is one of this source: a kernel that has one loads, one that has none compiles."""
    func = dispatcher.py_func
    copy = Path(func.__code__.co_filename)
    name = (f"{copy.stem}.{func.__qualname__.replace('<', '').replace('>', '')}-{func.__code__.co_firstlineno}"
            f".py{sys.version_info[0]}{sys.version_info[1]}{getattr(sys, 'abiflags', '')}.nbi")
    return (copy.parent / "__pycache__" / name).is_file()


def _code_in(code: types.CodeType, filename: str) -> types.CodeType:
    """``code`` and the code objects it holds (nested functions), naming ``filename``."""
    consts = tuple(_code_in(c, filename) if isinstance(c, types.CodeType) else c for c in code.co_consts)
    return code.replace(co_filename=filename, co_consts=consts)


def _relocated(func: Callable[..., Any], filename: str) -> Callable[..., Any]:
    """The function ``func`` (same bytecode, globals, closure, defaults, names and lines) whose
    code names ``filename`` as its source file."""
    f: Any = func
    new: Any = types.FunctionType(_code_in(f.__code__, filename), f.__globals__, f.__name__, f.__defaults__,
                                  f.__closure__)
    new.__kwdefaults__ = f.__kwdefaults__
    new.__qualname__, new.__module__, new.__doc__ = f.__qualname__, f.__module__, f.__doc__
    new.__annotations__ = dict(f.__annotations__)
    new.__dict__.update(f.__dict__)
    return new


_declaring = threading.Lock()


@contextmanager
def _in_tree_cache() -> Iterator[None]:
    """numba's ``CACHE_DIR`` (``NUMBA_CACHE_DIR``) unset within the block, as it was after: a
    kernel declared then is cached beside its source (the copy), whatever the environment
    sets for other numba users of the process."""
    cfg = _numba_config()
    with _declaring:
        before = cfg.CACHE_DIR
        cfg.CACHE_DIR = ""
        try:
            yield
        finally:
            cfg.CACHE_DIR = before


def njit(*args: Any, **options: Any) -> Any:
    """``numba.njit`` (same arguments); with ``cache=True`` the kernel is cached in
    :func:`kernel_cache_dir` beside the copy of its module (see the module docstring)."""
    cache = options.pop("cache", False)

    def wrap(func: Any) -> Any:
        if not cache or _numba_config().DISABLE_JIT:
            return numba.njit(**options)(func)
        relocated = _relocated(func, str(source_copy(func.__code__.co_filename)))
        with _in_tree_cache():
            return numba.njit(cache=True, **options)(relocated)

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
