"""The batch CLI's inputs: request files, directories of them, JSON Lines files.

* ``*.json`` (or any file not ending in ``.jsonl``/``.ndjson``): one request; its key is
  the file name without the extension.
* ``*.jsonl`` / ``*.ndjson``: one request per line (blank lines skipped); keys
  ``<stem>-<line>`` with the 1-based line number (``study-000017``).
* a directory: its ``*.json``, ``*.jsonl`` and ``*.ndjson`` files, sorted by name (not
  recursive).

A request is a plan request (the body of ``POST /v1/plan``) or a contour request (the body of
``POST /v1/contour``: an object with ``program``, a G-code program's text, and its settings;
:func:`app.batch.engine.request_kind`). Requests are read lazily (a JSON Lines file of a
million corridors is not held in memory) and sent to the workers as text: they are validated
there, and an invalid one is that item's ``invalid_input`` error, not the batch's. A key
that repeats gets ``-2``, ``-3``...
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Iterator
from pathlib import Path

from .runner import Item

__all__ = ["InputError", "resolve_inputs", "iter_items", "request_sha"]

JSONL_SUFFIXES = (".jsonl", ".ndjson")


class InputError(Exception):
    """A user error (a missing input path, no requests at all): one line, exit status 2."""


def request_sha(text: str | bytes) -> str:
    """A short hash of a request's text (resume re-plans an item whose text changed)."""
    data = text.encode() if isinstance(text, str) else text
    return hashlib.sha256(data.strip()).hexdigest()[:16]


def _safe(stem: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", stem).strip("._") or "item"


def resolve_inputs(paths: list[str]) -> list[Path]:
    """The input files, in order; ``InputError`` for a path that does not exist or a
    directory with no request files."""
    files: list[Path] = []
    for raw in paths:
        p = Path(raw)
        if p.is_dir():
            found = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in (".json", *JSONL_SUFFIXES))
            if not found:
                raise InputError(f"{raw}: no *.json, *.jsonl or *.ndjson files in this directory")
            files.extend(found)
        elif p.is_file():
            files.append(p)
        else:
            raise InputError(f"{raw}: no such file or directory")
    return files


def _lines(path: Path) -> Iterator[tuple[int, str]]:
    with open(path, encoding="utf-8", errors="surrogateescape") as f:
        for n, line in enumerate(f, 1):
            if line.strip():
                yield n, line


def count_items(files: list[Path]) -> int:
    """How many items the files hold (one pass over each JSON Lines file)."""
    total = 0
    for f in files:
        if f.suffix.lower() in JSONL_SUFFIXES:
            total += sum(1 for _ in _lines(f))
        else:
            total += 1
    return total


def iter_items(files: list[Path]) -> Iterator[tuple[Item, str]]:
    """``(item, request_sha)`` for each request, in order. An unreadable file is an item
    with an error (reported without planning)."""
    seen: dict[str, int] = {}
    index = 0

    def unique(key: str) -> str:
        n = seen.get(key, 0) + 1
        seen[key] = n
        return key if n == 1 else f"{key}-{n}"

    for f in files:
        stem = _safe(f.stem)
        if f.suffix.lower() in JSONL_SUFFIXES:
            try:
                for n, line in _lines(f):
                    yield Item(index, unique(f"{stem}-{n:06d}"), request=line), request_sha(line)
                    index += 1
            except OSError as exc:
                raise InputError(f"{f}: cannot read: {exc.strerror or exc}") from None
            continue
        key = unique(stem)
        try:
            text = f.read_bytes().decode("utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            msg = f"cannot read {f}: {getattr(exc, 'strerror', None) or exc}"
            yield Item(index, key, error={"code": "invalid_input", "message": msg, "field_": None}), ""
        else:
            yield Item(index, key, request=text), request_sha(text)
        index += 1
