"""The Segments folder of the Edit tab: a segment-list corridor (the paper's Table I, the
API's main format) edited box by box.

Pick a box in the list (or click it in the view), then type its lower and upper corner
(x, y in m, psi in rad) or drag its edges and centre in the view; insert a copy after it,
remove it, or set the angle range of every box at once. The table lists all boxes. Every
edit goes through the session (undo, re-plan) as for layouts.
"""

from __future__ import annotations

from typing import Protocol

from ._fields import VectorField, format_number, syncing

__all__ = ["SegmentActions", "SegmentsPanel", "segment_label", "segments_table"]

_XY_PSI = ("x", "y", "ψ")


def segment_label(i: int, n: int, seg: dict) -> str:
    """The list entry of segment ``i`` of ``n``: its number and, for a point, its role."""
    point = all(float(a) == float(b) for a, b in zip(seg["lower"], seg["upper"]))
    role = " (start)" if point and i == 0 else " (end)" if point and i == n - 1 else " (point)" if point else ""
    return f"#{i + 1}{role}"


def segments_table(segments: list[dict], selected: int | None) -> str:
    """All boxes as a markdown table [m, m, rad]; the selected row in bold."""
    rows = ["| # | x (m) | y (m) | ψ (rad) |", "|---|---|---|---|"]
    for i, s in enumerate(segments):
        lo, hi = s["lower"], s["upper"]
        cells = [f"{format_number(float(lo[k]))} … {format_number(float(hi[k]))}" if float(lo[k]) != float(hi[k])
                 else format_number(float(lo[k])) for k in range(3)]
        mark = "**" if i == selected else ""
        rows.append(f"| {mark}{i + 1}{mark} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


class SegmentActions(Protocol):
    """What the Segments folder asks of its session (the segment-list edits of
    :class:`._session_segments.SegmentEdits`). Declared here so that this module never
    imports the session (the session imports it)."""

    def select_segment(self, i: int | None) -> None: ...

    def set_segment_corner(self, which: str, value) -> None: ...

    def insert_segment(self) -> None: ...

    def remove_segment(self) -> None: ...

    def set_psi_range_all(self, lo: float, hi: float) -> None: ...


class SegmentsPanel:
    """The widgets of the Segments folder for ``session`` (any :class:`SegmentActions`)."""

    def __init__(self, gui, session: SegmentActions):
        self._session = session
        self.folder = gui.add_folder("Segments (boxes of the corridor)")
        with self.folder:
            self.summary = gui.add_markdown("")
            self.choice = gui.add_dropdown("Box", ("#1",), hint="Or click a box in the view")
            self.choice.on_update(lambda _: None if syncing.active() else session.select_segment(self._index()))
            self.lower = VectorField(gui, "Lower x, y (m), ψ (rad)", (0.0, 0.0, 0.0),
                                     lambda v: session.set_segment_corner("lower", v), names=_XY_PSI)
            self.upper = VectorField(gui, "Upper x, y (m), ψ (rad)", (0.0, 0.0, 0.0),
                                     lambda v: session.set_segment_corner("upper", v), names=_XY_PSI)
            self.insert = gui.add_button("Insert a copy after it", hint="Then drag or type the new box")
            self.insert.on_click(lambda _: session.insert_segment())
            self.remove = gui.add_button("Remove this box", color="red")
            self.remove.on_click(lambda _: session.remove_segment())
            self.psi_all = VectorField(gui, "ψ range of every box (rad)", None, lambda v: None,
                                       names=("min", "max"), optional=True,
                                       hint="min, max; start and end points keep their angles")
            gui.add_button("Apply ψ range to every box").on_click(lambda _: self._apply_psi())
            with gui.add_folder("Table of all boxes", expand_by_default=False):
                self.table = gui.add_markdown("")

    def _index(self) -> int:
        try:
            return self.choice.options.index(self.choice.value)
        except ValueError:
            return 0

    def _apply_psi(self) -> None:
        value = self.psi_all.value
        if value is None:
            self.psi_all.show_error("type the range as min, max (rad)")
            return
        if value[0] > value[1]:
            self.psi_all.show_error(f"must be min, max with min <= max, got {value[0]:g}, {value[1]:g}")
            return
        self._session.set_psi_range_all(value[0], value[1])

    def show(self, segments: list[dict], selected: int) -> None:
        """Show ``segments`` with box ``selected`` in the fields."""
        n = len(segments)
        with syncing():
            options = tuple(segment_label(i, n, s) for i, s in enumerate(segments)) or ("#1",)
            if tuple(self.choice.options) != options:
                self.choice.options = options
            if 0 <= selected < n:
                self.choice.value = options[selected]
                self.lower.show(segments[selected]["lower"])
                self.upper.show(segments[selected]["upper"])
        self.remove.disabled = n <= 1
        self.summary.content = (f"{n} boxes, x, y in m and ψ in rad. Click a box in the view to pick it, "
                                "drag its edges or its centre square; or type its corners below.")
        self.table.content = segments_table(segments, selected)
