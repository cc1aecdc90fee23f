"""The segment-list edits of an editing session (a corridor given as boxes, e.g. the
paper's Table I): pick a box, type its corners, drag its edges or its centre in the view
(snapped), insert and remove boxes, set the angle range of every box. Each goes through
:meth:`app.editor._session.Session.edit` (undo, re-plan) like the layout edits.

Units: m, rad.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from . import _state

if TYPE_CHECKING:
    from ._gui import EditorGui
    from ._history import History

__all__ = ["SegmentEdits"]


class SegmentEdits:
    """Mixed into :class:`app.editor._session.Session` (which provides what is declared here)."""

    state: _state.EditorState
    history: History
    gui: EditorGui
    selected_segment: int
    _drag: tuple[dict, float, float] | None
    edit: Callable[..., bool]
    snap_xy: Callable[[float, float], list[float]]
    _show_drawing: Callable[[], Any]

    def segment_at(self, x: float, y: float) -> int | None:
        """The segment box under (x, y) [m] (the smallest; a point within 2 % of the view)."""
        segs = self.state.request.get("segments") or []
        if not segs:
            return None
        lo = np.array([s["lower"][:2] for s in segs], float)
        hi = np.array([s["upper"][:2] for s in segs], float)
        tol = 0.02 * max(float(np.max(hi.max(axis=0) - lo.min(axis=0))), 0.02)
        area = np.prod(hi - lo, axis=1)
        inside = np.all((lo - tol <= (x, y)) & ((x, y) <= hi + tol), axis=1)
        if not inside.any():
            return None
        idx = np.nonzero(inside)[0]
        return int(idx[np.argmin(area[idx])])

    def select_segment(self, i: int | None) -> None:
        """Edit segment box ``i`` (fields and drag handles follow)."""
        n = len(self.state.request.get("segments") or [])
        if i is None or n == 0:
            return
        self.selected_segment = int(np.clip(i, 0, n - 1))
        self._show_segments()

    def set_segment_corner(self, which: str, value) -> None:
        """Set the selected box's ``which`` ("lower" | "upper") corner [x, y, psi] (m, m, rad)."""
        i = self.selected_segment
        seg = (self.state.request.get("segments") or [None] * (i + 1))[i]
        if seg is None:
            return
        lower, upper = (value, seg["upper"]) if which == "lower" else (seg["lower"], value)
        self.edit(lambda r: _state.set_segment(r, i, lower, upper), key=f"field:segments[{i}].{which}")
        self._show_segments()

    def insert_segment(self) -> None:
        """Insert a copy of the selected box after it and select the copy."""
        i = self.selected_segment
        self.edit(lambda r: _state.insert_segment(r, i))
        self.select_segment(i + 1)

    def remove_segment(self) -> None:
        """Remove the selected box."""
        i = self.selected_segment
        self.edit(lambda r: _state.remove_segment(r, i))
        self.select_segment(min(i, len(self.state.request.get("segments") or []) - 1))

    def set_psi_range_all(self, lo: float, hi: float) -> None:
        """Let every box (not the start and end points) turn within [lo, hi] [rad]."""
        self.edit(lambda r: _state.set_psi_range(r, lo, hi))
        self._show_segments()

    def drag_segment(self, handle: str, phase: str, x: float, y: float) -> None:
        """A drag of the selected box's ``handle`` (an edge, or "centre": the whole box) with
        the pointer at (x, y) [m]; snapped; one undo step per drag."""
        i = self.selected_segment
        segs = self.state.request.get("segments") or []
        if not 0 <= i < len(segs):
            return
        key = f"drag:segments[{i}].{handle}"
        if phase == "start" or self._drag is None:
            self.history.begin(key)
            self._drag = (segs[i], x, y)
        seg0, x0, y0 = self._drag
        if handle == "centre":
            corner = self.snap_xy(float(seg0["lower"][0]) + x - x0, float(seg0["lower"][1]) + y - y0)
            self.edit(lambda r: _state.move_segment(r, i, corner), key=key)
        else:
            k = _state.EDGES[handle][0]
            value = self.snap_xy(x, y)[k]
            self.edit(lambda r: _state.set_segment_edge(r, i, handle, value), key=key)
        if phase == "end":
            self.history.seal()
            self._drag = None
        self._show_segments()

    def _show_segments(self) -> None:
        segs = self.state.request.get("segments") or []
        if segs and self.state.request.get("layout") is None:
            self.gui.segments.show(segs, self.selected_segment)
            self._show_drawing()
