"""The pieces a drawing is read into: polylines in the drawing's coordinates, closed
(a shape by itself) or open (to be joined with others), with their layer and origin."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import PlannerError

__all__ = ["Piece", "Drawing", "check_finite", "not_finite"]


@dataclass
class Piece:
    points: np.ndarray  # (n, 2) [drawing units, or m once placed]; a closed piece without the repeated first point
    closed: bool
    layer: str
    source: str  # entity type: "LINE", "ARC", "LWPOLYLINE", "HATCH", "path", ...
    circle: tuple[float, float, float] | None = None  # (cx, cy, r) when the piece is a whole circle
    ref: str = ""  # the element or entity it came from, for messages: '<path id="p1">', 'LINE (handle 1F)'


def not_finite(ref: str, layer: str) -> PlannerError:
    """The ``invalid_drawing`` error of the element ``ref`` (on ``layer``) with a coordinate
    that is not a finite number."""
    return PlannerError("invalid_drawing", f"{ref} on layer {layer!r} has a coordinate that is not a finite number "
                        "(NaN, infinity, or too large once its transforms are applied)", "drawing")


def check_finite(pieces: list[Piece], ref: str, layer: str) -> None:
    """Raise :func:`not_finite` when a coordinate of ``pieces`` (read from ``ref``) is not finite."""
    for p in pieces:
        if not np.all(np.isfinite(p.points)) or (p.circle is not None and not np.all(np.isfinite(p.circle))):
            raise not_finite(ref, layer)


@dataclass
class Drawing:
    """What a reader found: the pieces, every layer with geometry, the entities that are
    not outlines (by type), the unit (name, metres per unit, where it came from)."""

    pieces: list[Piece]
    layers: list[str]
    ignored: dict[str, int] = field(default_factory=dict)
    unit: str = "mm"
    metres_per_unit: float = 1e-3
    units_source: str = "default"
