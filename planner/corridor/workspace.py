"""The workspace of a layout: its bounds, its obstacles as shapely geometry and their
outlines grown by the clearance (the part of the plane the tool point must avoid), and the
checks that the start and end poses are usable. Lengths in m, angles in rad.

Growing (:meth:`Workspace.grown_parts`): flat sides are offset exactly by the clearance;
circular arcs, of circles and of rounded corners, are replaced by polygons *circumscribing*
them (:func:`discs`), so conservative by at most 0.13 % of the radius.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import ValidationError

from ..errors import invalid
from ..model import RobotModel
from ..model.reach import check_pose
from ..schema import Layout, planner_error

__all__ = ["QUAD_SEGS", "Workspace", "check_endpoint", "discs", "format_point", "parse_layout"]

#: segments of a quarter circle in grown outlines (circumscribed: conservative by <= 0.13 %)
QUAD_SEGS = 16
_GROW = 1.0 / math.cos(math.pi / (4 * QUAD_SEGS))  # circumradius / inradius of the polygon


@dataclass
class Workspace:
    """A validated layout with its obstacles as shapely polygons (SI: m, rad)."""

    lower: np.ndarray  # (2,) workspace lower corner [m]
    upper: np.ndarray  # (2,) workspace upper corner [m]
    obstacles: list  # shapely Polygons (exact obstacles; circles circumscribed)
    clearance: float  # [m]
    shape: str  # cell shape: "square" | "triangle"
    size: float | None  # cell edge [m]; None = the default rule (planner.corridor.cells)
    start: np.ndarray  # (3,) [m, m, rad]
    end: np.ndarray  # (3,)
    psi_range: np.ndarray  # (2,) allowed platform angle [rad]
    circles: dict = field(default_factory=dict)  # obstacle index -> (centre (2,), radius) [m]
    shape_given: bool = True  # the request gave the cell shape (False: the default, square)

    def grown_parts(self) -> tuple[np.ndarray, np.ndarray]:
        """The obstacles grown by the clearance, as pieces whose union is each grown obstacle
        (no union computed: the cell test checks each piece): ``(pieces, owner)``, shapely
        polygons and the obstacle index of each. Flat sides are exact (offset by the clearance);
        circles and the rounded corners (circles about each vertex) are circumscribed polygons,
        conservative by at most 0.13 % of their radius."""
        pieces, owner, centres, cowner = [], [], [], []
        for i, ob in enumerate(self.obstacles):
            if i in self.circles:
                c, r = self.circles[i]
                pieces.append(discs(c[None], r + self.clearance)[0])
            elif self.clearance > 0:
                pieces.append(ob.buffer(self.clearance, quad_segs=QUAD_SEGS))
                v = np.concatenate([np.asarray(ring.coords)[:-1] for ring in (ob.exterior, *ob.interiors)])
                centres.append(v)
                cowner.append(np.full(len(v), i))
            else:
                pieces.append(ob)
            owner.append(i)
        pieces = np.array(pieces, dtype=object)
        owner = np.array(owner, dtype=np.int64)
        if centres:
            pieces = np.concatenate((pieces, discs(np.concatenate(centres), self.clearance)))
            owner = np.concatenate((owner, np.concatenate(cowner)))
        return pieces, owner


def discs(centres: np.ndarray, radius: float) -> np.ndarray:
    """Regular ``4 QUAD_SEGS``-gons circumscribing circles of ``radius`` [m] about ``centres``
    (k, 2) [m]: their edges touch the circle at multiples of ``pi / (2 QUAD_SEGS)``, so the
    extreme sides (left, right, bottom, top) are exact. Returns (k,) shapely polygons."""
    a = (np.arange(4 * QUAD_SEGS) + 0.5) * (math.pi / (2 * QUAD_SEGS))
    ring = (radius * _GROW) * np.column_stack((np.cos(a), np.sin(a)))
    import shapely  # loaded on first use: plans of given segments never need it
    return np.asarray(shapely.polygons(centres[:, None, :] + ring[None]))


def parse_layout(raw: Layout | dict[str, Any], path: str = "layout") -> Workspace:
    """The workspace of a layout: a :class:`planner.schema.Layout`, or a dict validated here
    (a :class:`~planner.errors.PlannerError` names the failing field under ``path``)."""
    if not isinstance(raw, Layout):
        try:
            raw = Layout.model_validate(raw)
        except ValidationError as exc:
            raise planner_error(exc, path) from None
    obstacles, circles = [], {}
    import shapely  # loaded on first use: plans of given segments never need it
    for i, o in enumerate(raw.obstacles):
        if o.type == "rectangle":
            obstacles.append(shapely.box(o.lower[0], o.lower[1], o.upper[0], o.upper[1]))
        elif o.type == "circle":
            obstacles.append(discs(np.asarray(o.center, float)[None], float(o.radius))[0])  # circumscribes it
            circles[i] = (np.array(o.center, dtype=float), float(o.radius))
        else:
            obstacles.append(o.shape)  # with its holes
    return Workspace(np.array(raw.bounds.lower, float), np.array(raw.bounds.upper, float), obstacles,
                     float(raw.clearance), raw.cell.shape, raw.cell.size, np.array(raw.start_pose, float),
                     np.array(raw.end_pose, float), np.array(raw.angle_range, float), circles,
                     "shape" in raw.cell.model_fields_set)


def format_point(p: np.ndarray) -> str:
    """``(x m, y m)`` of a point or pose, for messages."""
    return f"({p[0]:.4f} m, {p[1]:.4f} m)"


def check_endpoint(ws: Workspace, model: RobotModel, key: str, path: str = "layout") -> None:
    """Raise a :class:`~planner.errors.PlannerError` naming ``{path}.{key}`` if the start or
    end pose (``key``) is outside the bounds, inside an obstacle or within the clearance of
    one (distances exact, circles too), or not reachable and regular for the robot."""
    pose = ws.start if key == "start" else ws.end
    x, y = pose[0], pose[1]
    if not (ws.lower[0] <= x <= ws.upper[0] and ws.lower[1] <= y <= ws.upper[1]):
        raise invalid(f"{path}.{key}", f"the {key} {format_point(pose)} is outside the bounds "
                      f"{format_point(ws.lower)} .. {format_point(ws.upper)}")
    import shapely  # loaded on first use: plans of given segments never need it
    for i, ob in enumerate(ws.obstacles):
        if i in ws.circles:  # exact circle
            c, r = ws.circles[i]
            dist = max(float(np.hypot(x - c[0], y - c[1])) - r, 0.0)
            inside = dist == 0.0 and np.hypot(x - c[0], y - c[1]) < r
        else:
            dist = float(shapely.distance(ob, shapely.Point(x, y)))
            inside = bool(shapely.contains_xy(ob, x, y))
        if inside or dist < ws.clearance:
            why = "inside" if inside else f"within the clearance ({ws.clearance:g} m) of"
            raise invalid(f"{path}.{key}", f"the {key} {format_point(pose)} is {why} obstacle {i} "
                          f"({path}.obstacles[{i}])")
    check_pose(model, pose, f"{path}.{key}")
