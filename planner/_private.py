"""Whether a directory is one only this user (or root) can change (issue 30): the one check of
the places the planner loads compiled code from (:mod:`planner._jit`). Standard library only.

The rule (:func:`distrust`): the directory and each of its parents up to the root the user
chose are real directories (``lstat``: no symlink to swap; the chosen root itself may be one),
owned by this user or by root (root can change anything anyway, so a root-owned read-only
directory, such as the container's kernel seed, is as trustworthy as one's own), and no one
else may write them (no group or other write bit), except a parent that is root-owned and
sticky (``/tmp``): there others can add entries but neither rename nor remove ours.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

__all__ = ["distrust", "distrust_tree", "make_dirs"]


def _problem(path: Path, st: os.stat_result, owners: tuple[int, ...], mask: int, directory: bool,
             sticky_ok: bool) -> str | None:
    """Why one entry (its ``lstat``) fails the rule, or None."""
    if stat.S_ISLNK(st.st_mode):
        return f"{path} is a symlink"
    if directory and not stat.S_ISDIR(st.st_mode):
        return f"{path} is not a directory"
    if not directory and not stat.S_ISREG(st.st_mode) and not stat.S_ISDIR(st.st_mode):
        return f"{path} is not a regular file"
    if st.st_uid not in owners:
        return f"{path} belongs to uid {st.st_uid}"
    mode = stat.S_IMODE(st.st_mode)
    if mode & mask and not (sticky_ok and st.st_uid == 0 and mode & stat.S_ISVTX):
        return f"{path} is {'accessible' if mask & 0o055 else 'writable'} by others (mode {mode:04o})"
    return None


def distrust(path: Path, root: Path | None = None, *, owners: tuple[int, ...] | None = None,
             mask: int = 0o022) -> str | None:
    """Why ``path`` is not a directory only its owner can change (see the module docstring),
    or None when it is. Checked: ``path`` and its parents up to ``root`` (inclusive; None:
    ``path`` only); ``owners``: the uids allowed (default: this user and root); ``mask``: the
    mode bits no one may have (default: write by group and others; 0o077: no access at all)."""
    owners = (os.geteuid(), 0) if owners is None else owners
    path = Path(os.path.abspath(path))
    top = Path(os.path.abspath(root)) if root is not None else path
    if top != path and top not in path.parents:
        top = path
    p = path
    while True:
        try:
            st = os.stat(p) if p == top and p != path else os.lstat(p)
        except OSError as exc:
            return f"{p}: {exc.strerror}"
        why = _problem(p, st, owners, mask, True, sticky_ok=p != path)
        if why is not None:
            return why
        if p == top:
            return None
        p = p.parent


def distrust_tree(path: Path, *, owners: tuple[int, ...] | None = None, mask: int = 0o022) -> str | None:
    """Why some entry below the directory ``path`` (not followed into symlinks) is not a
    directory or regular file only its owner can change, or None."""
    owners = (os.geteuid(), 0) if owners is None else owners
    try:
        entries = list(os.scandir(path))
    except OSError as exc:
        return f"{path}: {exc.strerror}"
    for entry in entries:
        p = Path(entry.path)
        try:
            st = entry.stat(follow_symlinks=False)
        except OSError as exc:
            return f"{p}: {exc.strerror}"
        why = _problem(p, st, owners, mask, False, sticky_ok=False)
        if why is None and stat.S_ISDIR(st.st_mode):
            why = distrust_tree(p, owners=owners, mask=mask)
        if why is not None:
            return why
    return None


def make_dirs(path: Path, mode: int = 0o755) -> None:
    """Create ``path`` and its missing parents, each with ``mode`` (narrowed by the umask; unlike
    ``os.makedirs``, whose parents get the umask's default)."""
    path = Path(os.path.abspath(path))
    missing = []
    while not os.path.lexists(path):
        missing.append(path)
        path = path.parent
    for p in reversed(missing):
        try:
            os.mkdir(p, mode)
        except FileExistsError:
            pass
