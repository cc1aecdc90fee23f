"""The pieces a drawing is read into: polylines in the drawing's coordinates, closed
(a shape by itself) or open (to be joined with others), with their layer and origin."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Piece", "Drawing"]


@dataclass
class Piece:
    points: np.ndarray  # (n, 2) [drawing units, or m once placed]; a closed piece without the repeated first point
    closed: bool
    layer: str
    source: str  # entity type: "LINE", "ARC", "LWPOLYLINE", "HATCH", "path", ...
    circle: tuple[float, float, float] | None = None  # (cx, cy, r) when the piece is a whole circle


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
