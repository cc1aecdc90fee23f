"""Undo and redo of the edited request (no viser, no planner).

The history keeps whole copies of the request (a plan request in the one JSON shape is a
few kB; a layout with a thousand obstacles some 100 kB), one per *step*. A step is what a
person thinks of as one edit: a click, a drag from press to release, the typing in one
field. Consecutive edits with the same ``key`` (the same field being typed) within
:data:`COALESCE_S` of each other join one step; a drag opens its step with
:meth:`History.begin` and every edit of its key joins it, however long the drag takes,
until :meth:`History.seal` (the mouse is released). Any edit with another key starts a new
step. Undo restores the request before
the step; redo re-applies it. A new step after an undo drops the redo branch, as in every
editor.
"""

from __future__ import annotations

import copy
import threading
import time

__all__ = ["COALESCE_S", "MAX_STEPS", "History"]

COALESCE_S = 1.0  #: edits of one key closer than this [s] are one undo step
MAX_STEPS = 200  #: oldest steps are dropped beyond this many


class History:
    """Undo / redo stacks of request snapshots; thread-safe (GUI callbacks run on
    viser's thread pool)."""

    def __init__(self, clock=time.monotonic):
        self._clock = clock
        self._lock = threading.Lock()
        self._undo: list[dict] = []  # the request before each step, oldest first
        self._redo: list[dict] = []  # the request after each undone step, newest undone last
        self._key: str | None = None  # key of the open step (None: closed)
        self._mode = "timed"  # "timed": joins within COALESCE_S; "pending" / "held": a drag's step
        self._last = 0.0  # clock time of the newest edit of the open step

    def record(self, before: dict, key: str | None = None) -> bool:
        """Note that an edit is about to change the request from ``before``. Returns True
        when this edit opened a new step (False: it joined the open step of ``key``)."""
        now = self._clock()
        with self._lock:
            if key is not None and key == self._key:
                if self._mode == "held" or (self._mode == "timed" and now - self._last <= COALESCE_S):
                    self._last = now
                    return False
                mode = "held" if self._mode == "pending" else "timed"
            else:
                mode = "timed"
            self._undo.append(copy.deepcopy(before))
            del self._undo[:-MAX_STEPS]
            self._redo.clear()
            self._key, self._mode, self._last = key, mode, now
            return True

    def begin(self, key: str) -> None:
        """Open a step for ``key`` that every edit of that key joins until :meth:`seal`
        (a drag, from press to release); it is recorded with its first change."""
        with self._lock:
            self._key, self._mode = key, "pending"

    def seal(self) -> None:
        """Close the open step: the next edit starts a new one (a drag ended)."""
        with self._lock:
            self._key, self._mode = None, "timed"

    def undo(self, current: dict) -> dict | None:
        """The request to show after undoing the newest step of ``current`` (None: nothing
        to undo)."""
        with self._lock:
            if not self._undo:
                return None
            self._redo.append(copy.deepcopy(current))
            self._key, self._mode = None, "timed"
            return self._undo.pop()

    def redo(self, current: dict) -> dict | None:
        """The request to show after redoing the newest undone step (None: nothing to redo)."""
        with self._lock:
            if not self._redo:
                return None
            self._undo.append(copy.deepcopy(current))
            self._key, self._mode = None, "timed"
            return self._redo.pop()

    @property
    def can_undo(self) -> bool:
        """Whether there is a step to undo."""
        with self._lock:
            return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        """Whether there is an undone step to redo."""
        with self._lock:
            return bool(self._redo)

    @property
    def depth(self) -> tuple[int, int]:
        """(steps to undo, steps to redo)."""
        with self._lock:
            return len(self._undo), len(self._redo)
