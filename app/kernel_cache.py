"""The compiled kernels of a read-only installation (the container image, issue 15).

The planner caches its compiled kernels in ``NUMBA_CACHE_DIR/rangeplan-<key>`` when that is set
(:mod:`planner._jit`; the key: the kernel sources' content; the tree holds no absolute path, so
it can be copied); a read-only one is copied into the user's private cache first. An image
built with ``NUMBA_CPU_NAME=generic`` (code for any x86-64, so the cache is not tied to the
build machine's CPU) compiles the kernels at build time into a read-only seed
(``RANGEPLAN_KERNEL_SEED``); at start :func:`seed_kernel_cache` copies it into
``NUMBA_CACHE_DIR`` (e.g. on a tmpfs ``/tmp``) before the planner is imported, so a container
started ``--read-only`` under any user loads the kernels in a second instead of compiling them
for minutes. The copy's directories
are made mode 0755 whatever the umask: the planner loads kernels only from a directory no one
but its owner (or root) can write (:mod:`planner._private`).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Mapping

__all__ = ["seed_kernel_cache"]


def seed_kernel_cache(environ: Mapping[str, str] | None = None) -> str | None:
    """Copy ``RANGEPLAN_KERNEL_SEED`` into ``NUMBA_CACHE_DIR`` (files it lacks only; both
    read through :func:`app.settings.settings`, of the environment or of ``environ``);
    returns what was done, for the log, or None when either is unset."""
    from app.settings import settings

    cfg = settings(environ)
    if cfg.kernel_seed is None or cfg.numba_cache_dir is None:
        return None
    src, dst = cfg.kernel_seed, cfg.numba_cache_dir
    if not src.is_dir():
        return f"kernel seed {src} not found: the kernels compile on first use"
    from planner._private import make_dirs

    copied = 0
    for path in src.rglob("*"):
        target = dst / path.relative_to(src)
        if path.is_dir():
            make_dirs(target)
        elif not os.path.lexists(target):
            make_dirs(target.parent)
            shutil.copy2(path, target)
            copied += 1
    return f"kernels: {copied} cache files copied from {src} to {dst}"
