"""The editor's state, without viser: the edited plan request and the newest plan outcome.

The edited request is a plain dict in the one JSON shape of a plan request
(:class:`planner.schema.PlanRequest`, here with a ``layout``); every edit is a function
that changes that dict in place under the state's lock. The newest published result,
segmentation and error sit next to it, with the bookkeeping of which re-plan generation
produced them. The request edits the GUI makes are plain functions here, so they can be
tested without a browser. The request is either a layout (``layout``: bounds, obstacles,
start, end) or a segment list (``segments``: boxes [lower, upper] in x, y, psi, e.g. the
paper's Table I); both are edited here.

Units: m, rad, s, N (as in the request).
"""

from __future__ import annotations

import copy
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from . import _geometry as geo
from ._planning import DEFAULT_MODE, DEFAULT_ROBOT, MODE_DEFAULTS

if TYPE_CHECKING:
    from ._planning import ContourRequest, ErrorDetail, PlanRequest, PlanResult, SegmentationResult

__all__ = [
    "AUTO_SETTINGS",
    "DEFAULT_REQUEST",
    "EDGES",
    "EditorState",
    "StateViews",
    "add_obstacle",
    "clear_obstacles",
    "insert_segment",
    "mode_settings",
    "move_point",
    "move_segment",
    "remove_last_obstacle",
    "remove_segment",
    "set_layout_field",
    "set_name",
    "set_pose",
    "set_psi_range",
    "set_segment",
    "set_segment_edge",
    "set_setting",
    "switch_mode",
    "toggle_cell_obstacle",
    "with_new_layout",
]

#: settings the editor leaves out of the request unless the person typed a value: the planner
#: chooses them (the horizon N from the sample time and the robot, and from N's default the
#: samples a segment is held)
AUTO_SETTINGS = ("N", "samples_per_segment")

#: what the editor shows on first start: a wall with a gap between start and end
DEFAULT_REQUEST: dict[str, Any] = {
    "name": "editor example",
    "robot": "moving-slide",
    "layout": {
        "bounds": {"lower": [-0.16, -0.16], "upper": [0.16, 0.16]},
        "obstacles": [{"type": "rectangle", "lower": [-0.02, -0.12], "upper": [0.0, 0.04]}],
        "clearance": 0.0,
        "cell": {"shape": "square", "size": 0.02},
        "start": [-0.08, 0.0, 0.0],
        "end": [0.06, 0.04, 0.0],
    },
    # no N: the planner's default horizon follows Ts and the robot (the constrained mode's
    # 30 samples at Ts 10 ms, 100 at 2 ms); the person types one to fix it
    "settings": {"mode": DEFAULT_MODE, "Ts": 0.01,
                 **{k: v for k, v in MODE_DEFAULTS[DEFAULT_MODE].items() if k not in AUTO_SETTINGS}},
}

Edit = Callable[[dict], Any]  #: changes a request dict in place; its return value is ignored


class EditorState:
    """The edited request and the newest plan outcome of one editing session (one
    browser tab).

    ``lock`` guards all fields; :attr:`request` hands out copies, :meth:`apply` runs an
    edit on the real dict. The ``last_*`` fields are what the newest *current* re-plan
    published (a stale one only bumps :attr:`stale_discarded`).
    """

    def __init__(self, request: dict | None = None):
        self.lock = threading.RLock()
        self._request = copy.deepcopy(request if request is not None else DEFAULT_REQUEST)
        self.corridor_id: str | None = None  #: id of the stored corridor the design came from / was saved as
        self.plans_done = 0  #: number of plan results published
        self.last_result: PlanResult | None = None  #: newest published plan result
        self.last_result_robot: Any = None  #: robot spec (name or description) of last_result
        self.last_result_request: dict | None = None  #: the request draft last_result was planned for
        self.last_result_model: PlanRequest | ContourRequest | None = None  #: that request, validated
        self.last_segmentation: SegmentationResult | None = None  #: newest published segmentation
        self.last_error: ErrorDetail | None = None  #: newest error (code, message, field) or None
        self.last_plan_generation = 0  #: generation of the newest published result
        self.stale_discarded = 0  #: results dropped because a newer edit arrived

    @property
    def request(self) -> dict:
        """A copy of the current request (the one JSON shape)."""
        with self.lock:
            return copy.deepcopy(self._request)

    def replace(self, request: dict) -> None:
        """Replace the whole request (import, load, new layout)."""
        with self.lock:
            self._request = copy.deepcopy(request)

    def apply(self, edit: Edit) -> None:
        """Run ``edit(request)`` on the request itself, under the lock."""
        with self.lock:
            edit(self._request)

    def publish(self, gen: int, request: dict, segmentation: SegmentationResult | None,
                result: PlanResult | None, error: ErrorDetail | None,
                model: PlanRequest | ContourRequest | None = None) -> None:
        """Record the outcome of the current re-plan ``gen`` of ``request`` (the draft;
        ``model``: it validated). A failed plan keeps the last good result; a failed
        segmentation of a layout keeps the last segmentation (the cells stay clickable)."""
        with self.lock:
            if segmentation is not None or error is None or request.get("layout") is None:
                self.last_segmentation = segmentation
            self.last_error = error
            if result is not None:
                self.last_result = result
                self.last_result_robot = request.get("robot", DEFAULT_ROBOT)
                self.last_result_request = copy.deepcopy(request)
                self.last_result_model = model
                self.plans_done += 1
                self.last_plan_generation = gen

    def discard_stale(self) -> None:
        """Count a result dropped because a newer edit arrived while it was computed."""
        with self.lock:
            self.stale_discarded += 1


class StateViews:
    """Read-only views of an :class:`EditorState` ``state`` (mixed into
    :class:`app.editor._session.Session`, whose panels and tests read them)."""

    state: EditorState

    @property
    def request(self) -> dict:
        """A copy of the current request (the one JSON shape)."""
        return self.state.request

    @property
    def plans_done(self) -> int:
        """Number of plan results published."""
        return self.state.plans_done

    @property
    def last_result(self) -> PlanResult | None:
        """Newest published plan result."""
        return self.state.last_result

    @property
    def last_segmentation(self) -> SegmentationResult | None:
        """Newest published segmentation."""
        return self.state.last_segmentation

    @property
    def last_error(self) -> ErrorDetail | None:
        """Newest error (code, message, field), or None after a successful plan."""
        return self.state.last_error

    @property
    def last_plan_generation(self) -> int:
        """Re-plan generation of the newest published result (the plan number shown)."""
        return self.state.last_plan_generation

    @property
    def stale_discarded(self) -> int:
        """Results dropped because a newer edit arrived while they were computed."""
        return self.state.stale_discarded


# ---------------------------------------------------------------------------- request edits
def set_pose(request: dict, which: str, pose) -> None:
    """Set the layout's ``which`` ("start" | "end") pose to [x, y, psi] (m, m, rad)."""
    if request.get("layout") is not None:
        request["layout"][which] = [float(v) for v in pose]


def move_point(request: dict, which: str, x: float, y: float) -> None:
    """Move the layout's ``which`` point to (x, y) [m], keeping its angle psi."""
    layout = request.get("layout")
    if layout is not None:
        layout[which][0], layout[which][1] = float(x), float(y)


def set_layout_field(request: dict, path: tuple[str, ...], value) -> None:
    """Set ``layout[path[0]][path[1]]...`` to ``value`` (None removes the field)."""
    node = request.get("layout")
    if node is None:
        return
    for key in path[:-1]:
        node = node.setdefault(key, {})
    if value is None:
        node.pop(path[-1], None)
    else:
        node[path[-1]] = value


def set_setting(request: dict, key: str, value) -> None:
    """Set ``settings[key]`` to ``value`` (None removes it: the planner's default applies)."""
    settings = request.setdefault("settings", {})
    if value is None:
        settings.pop(key, None)
    else:
        settings[key] = value


def switch_mode(request: dict, mode: str) -> None:
    """Switch ``settings.mode``; N, k_r and k_u still at the old mode's defaults follow to
    the new mode's defaults (``MODE_DEFAULTS``), values the user changed stay, and one the
    request leaves out stays out (the new mode's default applies: an unset N stays auto)."""
    settings = request.setdefault("settings", {})
    old = MODE_DEFAULTS.get(settings.get("mode", DEFAULT_MODE), MODE_DEFAULTS[DEFAULT_MODE])
    settings["mode"] = mode
    for key, value in MODE_DEFAULTS[mode].items():
        if key in settings and settings[key] == old[key]:
            settings[key] = value


def mode_settings(request: dict) -> dict:
    """The request's N, k_r and k_u, each its mode's default where the request has none;
    N None where the request has none (the planner chooses it: :data:`AUTO_SETTINGS`)."""
    settings = request.get("settings", {})
    defaults = MODE_DEFAULTS.get(settings.get("mode", DEFAULT_MODE), MODE_DEFAULTS[DEFAULT_MODE])
    return {key: settings.get(key, None if key in AUTO_SETTINGS else value) for key, value in defaults.items()}


def set_name(request: dict, name: str | None) -> None:
    """Set the request's name (an empty name removes it)."""
    if name:
        request["name"] = name
    else:
        request.pop("name", None)


def add_obstacle(request: dict, obstacle: dict) -> None:
    """Append an obstacle (the layout's JSON shape, [m]) to the layout."""
    if request.get("layout") is not None:
        request["layout"]["obstacles"].append(obstacle)


def remove_last_obstacle(request: dict) -> None:
    """Remove the layout's newest obstacle, if any."""
    layout = request.get("layout")
    if layout is not None and layout["obstacles"]:
        layout["obstacles"].pop()


def clear_obstacles(request: dict) -> None:
    """Remove every obstacle of the layout."""
    if request.get("layout") is not None:
        request["layout"]["obstacles"].clear()


def toggle_cell_obstacle(request: dict, cell_polygon) -> None:
    """Toggle the obstacle of one cell (``cell_polygon``, [m]): remove the polygon
    obstacle inside it that an earlier toggle added, else add one covering the cell's
    middle (80 % of it, so that it blocks that cell only)."""
    layout = request.get("layout")
    if layout is None:
        return
    obstacles = layout["obstacles"]
    for i, ob in enumerate(obstacles):
        if ob.get("type") == "polygon" and all(geo.point_in_convex(p, cell_polygon) for p in ob["points"]):
            del obstacles[i]
            return
    obstacles.append({"type": "polygon", "points": geo.shrink(cell_polygon, 0.8)})


def with_new_layout(request: dict) -> dict:
    """A copy of ``request`` with the default layout in place of its corridor (of a G-code
    program's design: the default request with its robot and name)."""
    if "program" in request:
        out = copy.deepcopy(DEFAULT_REQUEST)
        out["robot"] = copy.deepcopy(request.get("robot", DEFAULT_ROBOT))
        return out
    out = copy.deepcopy(request)
    out["layout"] = copy.deepcopy(DEFAULT_REQUEST["layout"])
    out.pop("segments", None)
    out.pop("reference", None)
    return out


# ---------------------------------------------------------------------------- segment lists
#: the box edges a drag can move: (index into lower/upper, which one) by edge name
EDGES = {"left": (0, "lower"), "right": (0, "upper"), "bottom": (1, "lower"), "top": (1, "upper")}


def _segments(request: dict) -> list[dict]:
    return request.get("segments") or []


def _box_changed(seg: dict) -> None:
    # an exact cell polygon (made by a segmentation) no longer fits a box the person moved
    seg.pop("polygon", None)


def set_segment(request: dict, i: int, lower, upper) -> None:
    """Set segment ``i``'s box to [lower, upper] = [x, y, psi] each (m, m, rad)."""
    segs = _segments(request)
    if 0 <= i < len(segs):
        segs[i]["lower"], segs[i]["upper"] = [float(v) for v in lower], [float(v) for v in upper]
        _box_changed(segs[i])


def set_segment_edge(request: dict, i: int, edge: str, value: float) -> None:
    """Move one edge (``left``/``right``/``bottom``/``top``) of segment ``i``'s box to
    ``value`` [m]; it stops at the opposite edge (the box never turns inside out)."""
    segs = _segments(request)
    if not 0 <= i < len(segs):
        return
    k, side = EDGES[edge]
    seg = segs[i]
    if side == "lower":
        seg["lower"][k] = min(float(value), float(seg["upper"][k]))
    else:
        seg["upper"][k] = max(float(value), float(seg["lower"][k]))
    _box_changed(seg)


def move_segment(request: dict, i: int, lower_xy) -> None:
    """Move segment ``i``'s box so that its lower corner is ``lower_xy`` [m] (size and psi kept)."""
    segs = _segments(request)
    if not 0 <= i < len(segs):
        return
    seg = segs[i]
    for k in (0, 1):
        size = float(seg["upper"][k]) - float(seg["lower"][k])
        seg["lower"][k] = float(lower_xy[k])
        seg["upper"][k] = round(float(lower_xy[k]) + size, 10)
    _box_changed(seg)


def insert_segment(request: dict, after: int) -> int:
    """Insert a copy of segment ``after`` behind it (to be moved by the person); returns
    the new segment's index."""
    segs = _segments(request)
    if not segs:
        return -1
    after = min(max(after, 0), len(segs) - 1)
    new = {"lower": list(segs[after]["lower"]), "upper": list(segs[after]["upper"])}
    segs.insert(after + 1, new)
    return after + 1


def remove_segment(request: dict, i: int) -> None:
    """Remove segment ``i`` (the planner says so if too few are left)."""
    segs = _segments(request)
    if 0 <= i < len(segs):
        del segs[i]


def set_psi_range(request: dict, lo: float, hi: float, i: int | None = None) -> None:
    """Set the angle range [lo, hi] [rad] of segment ``i`` (None: of every segment that
    is not a point, i.e. the start and end keep their angles)."""
    segs = _segments(request)
    for j, seg in enumerate(segs):
        if i is not None and j != i:
            continue
        if i is None and all(float(a) == float(b) for a, b in zip(seg["lower"][:2], seg["upper"][:2])):
            continue
        seg["lower"][2], seg["upper"][2] = float(lo), float(hi)
