"""Number entry for the editor: text fields that keep what the person types.

Why not viser's number widget: ``gui.add_number`` / ``add_vector2`` / ``add_vector3``
render Mantine's ``NumberInput`` as a *controlled* input whose value is the number the
server holds. Typing ``-0.09`` sends ``-0`` after the second keystroke; the field then
re-renders that number as ``0`` and the sign is gone before the digits arrive (the same
happens to ``1e-5`` at ``1e``). Its ``precision`` (from ``step``) also rounds what is shown
and sent (``0.0005`` with step 0.001 became ``0.000``), and a value outside ``min``/``max``
is clamped without a word.

So every number here is a plain text input (``gui.add_text``): the browser keeps the
typed characters, the server parses them on each keystroke (sign, decimals, exponents,
the Unicode minus), and checks the field's bounds. A valid entry edits the request; an
invalid one edits nothing and is shown *on the field*: a warning sign in the label, a red
border and a line under the field saying what is wrong (``must be > 0, got -1``), in the
planner's words. Errors the planner reports for a field (``layout.cell.size``: too many
cells) are shown the same way. Labels carry the unit.

:func:`parse_number` and :func:`parse_vector` are pure and tested without a browser.
"""

from __future__ import annotations

import html
import math
import re
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["Bounds", "NumberField", "VectorField", "format_number", "parse_number", "parse_vector", "syncing"]

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_INTEGER = re.compile(r"[+-]?\d+")
_MINUS = str.maketrans({"\u2212": "-", "\u2013": "-", "\u00a0": " "})  # Unicode minus, en dash, nbsp

_local = threading.local()


class syncing:
    """Within ``with syncing():`` on this thread, values the editor writes into fields
    do not count as input. Thread-local: a user's keystroke handled on another thread
    at the same time is never mistaken for the editor's own write."""

    def __enter__(self) -> None:
        _local.depth = getattr(_local, "depth", 0) + 1

    def __exit__(self, *exc) -> None:
        _local.depth -= 1

    @staticmethod
    def active() -> bool:
        """Whether this thread is inside a ``syncing()`` block."""
        return getattr(_local, "depth", 0) > 0


@dataclass(frozen=True)
class Bounds:
    """Valid range of a number: ``gt`` / ``ge`` (lower, exclusive / inclusive) and ``lt`` /
    ``le`` (upper); None = no bound. Taken from the request schema's own field bounds
    (:func:`app.editor._planning.field_bounds`), so the editor checks what the planner checks."""

    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None

    def check(self, v: float, typed: str | None = None, integer: bool = False) -> str | None:
        """The message validation gives for ``v`` (as ``typed``) outside the range (the
        bound in the field's type, as pydantic prints it: ``must be > 0.0, got -1``), or None."""
        for bound, op, bad in ((self.gt, ">", lambda b: v <= b), (self.ge, ">=", lambda b: v < b),
                               (self.lt, "<", lambda b: v >= b), (self.le, "<=", lambda b: v > b)):
            if bound is not None and bad(bound):
                return f"must be {op} {int(bound) if integer else float(bound)}, got {typed or format_number(v)}"
        return None


def format_number(v: float) -> str:
    """A number as the fields show it: up to 10 significant digits, no ``-0``."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return str(v)
    if isinstance(v, int):
        return str(v)
    if v == 0:
        return "0"
    return f"{v:.10g}"


def parse_number(text: str, *, integer: bool = False, bounds: Bounds = Bounds(),
                 optional: bool = False) -> tuple[float | int | None, str | None]:
    """Parse what a person typed: ``(value, None)`` or ``(None, message)``. Accepts a sign
    (also the Unicode minus), decimals (``.5``, ``5.``) and exponents (``1e-5``);
    ``integer`` asks for a whole number. An empty field is ``(None, None)`` when
    ``optional`` (the request then leaves the value out), else an error."""
    s = text.translate(_MINUS).strip()
    if not s:
        return (None, None) if optional else (None, "a number is required")
    if integer:
        if not _INTEGER.fullmatch(s):
            if _NUMBER.fullmatch(s):
                return None, f"must be a whole number, got {s}"
            return None, f"not a number: '{s}'"
        value: float | int = int(s)
    else:
        if not _NUMBER.fullmatch(s):
            hint = " (use a point as the decimal separator)" if re.fullmatch(r"[+-]?\d*,\d+", s) else ""
            return None, f"not a number: '{s}'{hint}"
        value = float(s)
        if not math.isfinite(value):
            return None, f"must be finite, got {s}"
        if value == 0:
            value = 0.0  # -0 is 0
    message = bounds.check(float(value), s, integer)
    return (None, message) if message else (value, None)


def parse_vector(text: str, names: Sequence[str], bounds: Sequence[Bounds] | None = None, *,
                 optional: bool = False) -> tuple[list[float] | None, str | None]:
    """Parse ``len(names)`` comma-separated numbers (``"-0.08, 0.04, 0"``): ``(values,
    None)`` or ``(None, message naming the component)``; an empty ``optional`` field is
    ``(None, None)``."""
    s = text.translate(_MINUS).strip()
    if not s and optional:
        return None, None
    parts = [p.strip() for p in s.split(",")] if s else []
    if len(parts) != len(names):
        return None, (f"needs {len(names)} numbers separated by commas ({', '.join(names)}), got {len(parts)}")
    out = []
    for i, (part, name) in enumerate(zip(parts, names)):
        v, err = parse_number(part, bounds=bounds[i] if bounds else Bounds())
        if err is not None:
            return None, f"{name}: {err}"
        assert v is not None
        out.append(float(v))
    return out, None


def _error_html(uuid: str, message: str) -> str:
    # The red border (also while the field has the focus): the label of a viser input is
    # <label for=uuid> in a <p> in a <div>, beside the <div> of the <input>; :has() finds that row.
    return (f"<style>div:has(> div > p > label[for='{uuid}']) input {{border-color: #e03131 !important; "
            f"background: #fff5f5}}</style>"
            f"<div class='rangeplan-field-error' style='color:#c92a2a;font-size:0.78em;line-height:1.25;"
            f"margin:-0.35em 0.75em 0.4em 0.75em'>&#9888; {html.escape(message)}</div>")


class _Field:
    """A text input plus its error line; subclasses parse."""

    def __init__(self, gui, label: str, text: str, on_value: Callable[[Any], Any], hint: str | None):
        self.label = label
        self._on_value = on_value
        self.text = gui.add_text(label, text, hint=hint)
        self._error_line = gui.add_html("", visible=False)
        self.error: str | None = None  #: the message shown on the field (None: valid)
        self._error_source: str | None = None  # "input" (parse / bounds) or "plan" (the planner's)
        self.text.on_update(self._changed)

    # ------------------------------------------------------------------ input
    def _parse(self, text: str) -> tuple[Any, str | None]:
        raise NotImplementedError

    def _changed(self, _event) -> None:
        if syncing.active():
            return
        value, err = self._parse(self.text.value)
        if err is not None:
            self.show_error(err, source="input")
            return
        self.clear_error()
        self._on_value(value)

    # ------------------------------------------------------------------ showing
    def show_text(self, text: str) -> None:
        """Show ``text`` (the request's value) without editing the request; clears an input error."""
        with syncing():
            self.text.value = text
        if self._error_source == "input":
            self.clear_error()

    def show_error(self, message: str, source: str = "input") -> None:
        """Show ``message`` on the field (label, border, line under it)."""
        if self.error == message and self._error_source == source:
            return
        self.error, self._error_source = message, source
        self.text.label = f"\u26a0 {self.label}"
        self._error_line.content = _error_html(self.text._impl.uuid, message)
        self._error_line.visible = True

    def set_label(self, label: str) -> None:
        """Change the label (e.g. the default an empty field stands for), keeping an error's mark."""
        if label == self.label:
            return
        self.label = label
        self.text.label = f"\u26a0 {label}" if self.error is not None else label

    def clear_error(self, source: str | None = None) -> None:
        """Remove the error (only one from ``source``, when given)."""
        if self.error is None or (source is not None and source != self._error_source):
            return
        self.error = self._error_source = None
        self.text.label = self.label
        self._error_line.visible = False

    @property
    def visible(self) -> bool:
        return self.text.visible

    @visible.setter
    def visible(self, value: bool) -> None:
        self.text.visible = value
        self._error_line.visible = value and self.error is not None


class NumberField(_Field):
    """One number typed as text (see the module docstring). ``on_value(value)`` gets every
    valid entry (int with ``integer``; None for an empty ``optional`` field)."""

    def __init__(self, gui, label: str, value: float | None, on_value: Callable[[Any], Any], *,
                 integer: bool = False, bounds: Bounds = Bounds(), optional: bool = False, hint: str | None = None):
        self.integer, self.bounds, self.optional = integer, bounds, optional
        super().__init__(gui, label, "" if value is None else format_number(value), on_value, hint)

    def _parse(self, text: str):
        return parse_number(text, integer=self.integer, bounds=self.bounds, optional=self.optional)

    @property
    def value(self) -> float | int | None:
        """The number the field says now (None: empty or invalid)."""
        return self._parse(self.text.value)[0]

    def show(self, value: float | None) -> None:
        """Show ``value`` (None: empty) unless the field already says the same number."""
        current, err = self._parse(self.text.value)
        if err is None and current == value and (value is None or self.text.value.strip()):
            if self._error_source == "input":
                self.clear_error()
            return
        self.show_text("" if value is None else format_number(value))


class VectorField(_Field):
    """Several numbers typed in one field, separated by commas (``x, y`` or ``x, y, ψ``);
    ``names`` name the components in the messages."""

    def __init__(self, gui, label: str, value: Sequence[float] | None, on_value: Callable[[Any], Any], *,
                 names: Sequence[str], bounds: Sequence[Bounds] | None = None, optional: bool = False,
                 hint: str | None = None):
        self.names, self.bounds, self.optional = tuple(names), bounds, optional
        super().__init__(gui, label, self.format(value), on_value, hint)

    @staticmethod
    def format(value: Sequence[float] | None) -> str:
        return "" if value is None else ", ".join(format_number(float(v)) for v in value)

    def _parse(self, text: str):
        return parse_vector(text, self.names, self.bounds, optional=self.optional)

    @property
    def value(self) -> list[float] | None:
        """The numbers the field says now (None: empty or invalid)."""
        return self._parse(self.text.value)[0]

    def show(self, value: Sequence[float] | None) -> None:
        """Show ``value`` (None: empty) unless the field already says the same numbers."""
        current, err = self._parse(self.text.value)
        same = (current is None and value is None) if (current is None or value is None) else (
            len(current) == len(value) and all(a == float(b) for a, b in zip(current, value)))
        if err is None and same:
            if self._error_source == "input":
                self.clear_error()
            return
        self.show_text(self.format(value))
