"""``njit`` for the planner's kernels: numba's, through its public API only (issue 34 goal 5),
with the on-disk cache in one place per machine keyed by the content of *all* the kernel
sources (issue 24), loaded only from a place no one else can change (issue 30).

numba keys a cached kernel by its own source file only: a kernel compiled with its callees
from other files inlined stays "valid" when only a callee's file changes. So the planner's
kernels are cached (``cache=True``) in a directory of their own, named by the hash of all the
kernel modules' sources (:data:`KERNEL_SOURCES`) and numba's version (:func:`kernel_key`),
which numba is given the public way: ``numba.config.CACHE_DIR`` (the value of numba's
``NUMBA_CACHE_DIR``) while the planner's kernels are declared, restored after (numba fixes a
kernel's cache directory when it is declared; other numba users of the process keep theirs).
The place (:func:`chosen_kernel_cache`, from :mod:`planner._config`):

1. ``$NUMBA_CACHE_DIR/rangeplan-<key>`` when ``NUMBA_CACHE_DIR`` is set (the container's
   copy of its kernel seed, ``app/kernel_cache.py``), else
2. ``$RANGEPLAN_KERNEL_CACHE/<key>``, else ``$XDG_CACHE_HOME/rangeplan/kernels/<key>``
   (``~/.cache/rangeplan/kernels/<key>``, made mode 0700).

Inside it numba keeps each kernel module's index and object files in a directory named
after the module's directory and a hash of its absolute path (numba's ``NUMBA_CACHE_DIR``
layout): another checkout or installation of the same source at another path compiles once
for itself.

numba's index files are pickles: whoever can write the cache runs code as whoever plans next.
So the chosen place is used (:func:`kernel_cache`) only when it, its parents up to the
variable's directory and everything in it belong to this user or root and no one else can
write them (:mod:`planner._private`; everything in a directory of this user that no one else
may enter, mode 0700, counts as such whatever its own mode bits), and this user can write it.
A trusted cache this user cannot write (the container's root-owned seed, read by another uid)
that holds kernels is copied into the private cache and loaded from there. Otherwise the
kernels go to the private cache (``~/.cache/rangeplan/kernels/<key>``, made mode 0700, or
when that is the rejected one or unusable a temporary directory of this process) and one line
on stderr names the rejected directory and why. numba's own places (beside the sources,
``~/.cache/numba``) are never used for the planner's kernels.

So a process loads the kernels another process compiled from the same source at the same
place, and any change of a kernel file recompiles every kernel. numba checks the CPU (and
its features) per entry, as for any cached function.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import stat
import sys
import tempfile
from collections.abc import Iterator, Mapping
from contextlib import contextmanager, suppress
from contextvars import ContextVar
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numba

from ._config import PlannerConfig, config, read_config
from ._private import distrust, distrust_tree, make_dirs

__all__ = ["njit", "KERNEL_SOURCES", "KernelCache", "chosen_kernel_cache", "kernel_cache", "kernel_cache_dir",
           "kernel_key", "numpy_only", "kernels_off"]

_ROOT = Path(__file__).resolve().parent
#: the kernel modules (relative to ``planner/``) whose content keys the cache
KERNEL_SOURCES = ("model/kernels.py", "horizon/kernels.py", "corridor/kernels.py", "constraints/kernels.py",
                  "constraints/dense_kernels.py", "constraints/stagewise_kernels.py",
                  "constraints/dual_kernels.py", "constraints/step_kernels.py", "constraints/registry.py",
                  "orchestrator/kernels.py")


def _numba_config() -> Any:
    """``numba.config``: numba's settings, public (its documented way to set them in code), but
    filled from the environment at run time, so untyped."""
    return numba.config  # pyright: ignore[reportPrivateImportUsage]


@lru_cache(maxsize=1)
def kernel_key() -> str:
    """sha256 of numba's and llvmlite's versions, a non-default ``NUMBA_OPT`` (numba's own cache
    ignores it) and every kernel source (hex, 64 digits)."""
    import llvmlite

    opt = int(getattr(_numba_config(), "OPT", 3))
    h = hashlib.sha256(f"numba {numba.__version__} llvmlite {llvmlite.__version__}{'' if opt == 3 else f' opt {opt}'}\n"
                       .encode())
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
    return next(d.glob("*/*.nbi"), None) is not None


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
            cache = KernelCache(d)
    if cache is None:
        t = Path(tempfile.mkdtemp(prefix=f"rangeplan-kernels-{kernel_key()[:16]}-"))
        atexit.register(shutil.rmtree, t, True)
        cache = KernelCache(t, temporary=True)
    if seed is not None:
        _copy_kernels(seed, cache.path)
        cache = KernelCache(cache.path, cache.temporary, copied_from=seed)
    return cache


@lru_cache(maxsize=1)
def kernel_cache() -> KernelCache:
    """This process's kernel cache (see the module docstring; resolved once, on first use, the
    chosen directory created if missing)."""
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
            return KernelCache(chosen)
        if _holds_kernels(chosen):
            return _private_cache(chosen, seed=chosen)
        why = f"{chosen} is not writable and holds no kernels"
    private = _private_cache(chosen)
    note = f"rangeplan: kernels not loaded from {chosen}: {why}; using private cache {private.path}"
    print(note, file=sys.stderr, flush=True)
    return KernelCache(private.path, private.temporary, note=note)


def kernel_cache_dir() -> Path:
    """The directory of this process's kernel cache (:func:`kernel_cache`)."""
    return kernel_cache().path


@contextmanager
def _numba_cache_dir(path: Path) -> Iterator[None]:
    """numba's cache directory (``numba.config.CACHE_DIR``, the value of ``NUMBA_CACHE_DIR``) is
    ``path`` within the block, and what it was after."""
    cfg = _numba_config()
    before = cfg.CACHE_DIR
    cfg.CACHE_DIR = str(path)
    try:
        yield
    finally:
        cfg.CACHE_DIR = before


def njit(*args: Any, **options: Any) -> Any:
    """``numba.njit`` (same arguments); with ``cache=True`` the kernel is cached in
    :func:`kernel_cache_dir` (numba's ``NUMBA_CACHE_DIR`` while it is declared)."""
    cache = options.pop("cache", False)

    def wrap(func: Any) -> Any:
        if not cache:
            return numba.njit(**options)(func)
        with _numba_cache_dir(kernel_cache_dir()):
            return numba.njit(cache=True, **options)(func)

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
