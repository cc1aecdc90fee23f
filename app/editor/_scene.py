"""The editor's 3-D scene (viser): every node is created once and updated in place.

Each browser tab has its own scene (``client.scene``: nodes local to that client), made by
its editing session. :class:`EditorScene` adds all of its scene nodes in its constructor
(hidden until there is something to show) and keeps viser's handles. Showing a new layout, segmentation,
plan or robot pose assigns the handles' properties (``points``, ``colors``,
``vertices``/``faces``, ``position``/``wxyz``, ``text``, ``visible``, ...): viser sends
an update message for a changed property only, and never removes or re-adds a node.
Playback therefore moves the platform frame and the legs of the existing robot per
frame. An empty layer (no obstacles, no corridor, no result) is hidden with
``visible = False``; its last geometry stays on the handle.

Top-down view of the workspace plane z = 0; x right, y up; units m, rad, s, N. Each
layer sits a little above the plane (:data:`app.editor._geometry.Z`) so later layers
draw on top. Cells and the reachable outline are clipped to the workspace bounds.

A segment-list corridor (no layout) is drawn as its boxes; the selected box gets four edge
handles and a centre handle, meshes the person drags with the mouse (viser's ``on_drag``:
``on_segment_drag(handle, phase, x, y)`` gets ``left``/``right``/``bottom``/``top``/``centre``
and the pointer on the plane [m]).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from . import _geometry as geo
from ._planning import MAX_LEGS, Robot, reachable_mask, reachable_region, robot_geometry

if TYPE_CHECKING:
    from ._planning import PlanResult, SegmentationResult, Toolpath
    from ._preview import GcodePreview

__all__ = ["PREVIEW_COLOURS", "PROGRAM_COLOURS", "ROBOT_STYLES", "TICK_EVERY_S", "EditorScene", "axis_ticks"]

TICK_EVERY_S = 0.1  #: spacing of the time ticks on the trajectory [s]
EDGE_HANDLE = 0.014  #: width of a segment edge handle, as a fraction of the larger view side
SEGMENT_HANDLES = ("left", "right", "bottom", "top", "centre")
REACH_SAMPLES = 120  #: grid samples per side of the reachable-workspace outline
HANDLE_SCALE = 0.12  #: size of a start/end gizmo, as a fraction of the larger bounds side
DOT_RADIUS = 0.01  #: radius of a start/end dot, as a fraction of the larger bounds side
MAX_TICK_LABELS = 8  #: axis labels per axis (a label node each, made once)
#: how the robot is drawn: legs' width [px], platform fill shown, platform edge width [px]
ROBOT_STYLES = {"solid": (5.0, True, 2.0), "outline": (1.5, False, 1.0), "hidden": (0.0, False, 0.0)}

# Placeholder geometry of a node created before there is anything to show (it is hidden).
_NO_SEGMENTS = np.zeros((1, 2, 3))
_NO_POINTS = np.zeros((1, 3))
_NO_VERTICES, _NO_FACES = np.zeros((3, 3)), np.array([[0, 1, 2]], np.int32)
#: outline of the reachable workspace at the start / end angle (RGB 0-255)
_PIVOTS_ABOVE_PLATFORM = geo.Z["pivots"] - geo.Z["robot"]  #: z of pivots and tool in the platform frame [m]
_REACH_COLOURS = {"start": (210, 20, 20), "end": (230, 110, 0)}
#: the G-code preview: feed moves and (dashed) rapids, as AXIS draws a program (RGB 0-255)
PREVIEW_COLOURS = {"feed": (0, 170, 170), "rapid": (220, 0, 0)}
#: the factor on the z of the layers a G-code program is compared on (:meth:`EditorScene.set_flat`):
#: 3.7 mm becomes 7.4 um, 0.4 um of parallax at 7 mm from the centre of a view 13 mm above
FLAT_Z = 0.002
#: an opened G-code program: its programmed path (feed moves, rapids) and tolerance tube (RGB 0-255)
PROGRAM_COLOURS = {"feed": (0, 0, 0), "rapid": (150, 150, 150), "tube": (255, 190, 90),
                   "tube_edges": (220, 120, 0)}


def _show_lines(handle: viser.LineSegmentsHandle, segments: np.ndarray) -> None:
    """Show ``segments`` (M, 2, 3) [m] on a line node (its one colour), or hide it when M = 0."""
    if len(segments):
        handle.points = segments
    handle.visible = bool(len(segments))


def _show_mesh(handle: viser.MeshHandle, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Show the mesh ``vertices`` (V, 3) [m], ``faces`` (F, 3), or hide the node when F = 0."""
    if len(faces):
        handle.vertices, handle.faces = vertices, faces
    handle.visible = bool(len(faces))


def _leg_colours(force_ratio: np.ndarray) -> np.ndarray:
    """Per-vertex colours (n, 2, 3) of the legs: blue at no force, red at the force limit
    (the legend's gradient, :data:`app.editor._result.LEG_GRADIENT`). viser's line material
    treats per-vertex colours as linear and converts them to sRGB on screen (they came out
    pale: (60, 60, 200) as (133, 133, 230)); they are sent linearised so that the legs show
    the legend's colours."""
    r = np.clip(force_ratio, 0.0, 1.0)
    srgb = np.column_stack((60 + 195 * r, np.full_like(r, 60.0), 200 - 160 * r)) / 255.0
    linear = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    rgb = np.round(255 * linear).astype(np.uint8)
    return np.repeat(rgb[:, None, :], 2, axis=1)


class EditorScene:
    """The scene of one browser tab (``client``: a viser ``ClientHandle``, or the server
    for a scene every client sees).

    ``on_click(event)`` and ``on_rect_select(event)`` get viser's scene click and
    shift+drag rectangle events; ``on_handle_moved(which, x, y, phase)`` gets the start
    ("start") or end ("end") gizmo's position [m] while the user drags it (``phase``
    "start" | "update" | "end"); ``on_segment_drag(handle, phase, x, y)`` the drag of a
    segment handle.
    """

    def __init__(self, client, *, on_click: Callable[[Any], Any],
                 on_rect_select: Callable[[Any], Any],
                 on_handle_moved: Callable[[str, float, float, str], Any],
                 on_segment_drag: Callable[[str, str, float, float], Any] | None = None):
        self._client = client
        self._on_handle_moved = on_handle_moved
        self._on_segment_drag = on_segment_drag
        self._dragging = {"start": False, "end": False}  # a gizmo the user holds
        self._reach_cache: dict[tuple, np.ndarray] = {}  # outline segments by (robot, bounds, psi)
        self._robot_drawn: Robot | None = None  # robot whose structure the robot nodes show
        self._robot_lock = threading.Lock()  # one pose at a time: legs and platform of the same frame
        self.robot_style = "solid"
        self._flat = False  # see set_flat
        scene = client.scene  # up direction and world axes: the server's, set by the editor
        scene.on_click()(on_click)
        scene.on_rect_select(modifier="shift")(on_rect_select)
        self._add_nodes(scene)

    # ------------------------------------------------------------------ node creation (once)
    def _add_nodes(self, scene) -> None:
        def lines(name, colour, thickness_px):
            return scene.add_line_segments(name, _NO_SEGMENTS, colors=colour, thickness=thickness_px,
                                           thickness_units="screen", visible=False)

        def mesh(name, colour, opacity, **kwargs):
            return scene.add_mesh_simple(name, _NO_VERTICES, _NO_FACES, color=colour, opacity=opacity,
                                         side="double", visible=False, **kwargs)

        def points(name, colour, size_m, shape):
            return scene.add_point_cloud(name, _NO_POINTS, colors=colour, point_size=size_m, point_shape=shape,
                                         visible=False)

        # segmentation: cells by state, grid, the corridor the path runs through
        self.cells = {state: mesh(f"/seg/cells_{state}", colour, 1.0, flat_shading=True)
                      for state, colour in geo.CELL_COLOURS.items()}
        self.grid = lines("/seg/grid", (170, 170, 170), 0.5)
        self.corridor_fill = mesh("/seg/corridor_fill", (150, 220, 150), 0.8, flat_shading=True)
        self.corridor = lines("/seg/corridor", (0, 120, 0), 1.5)
        # layout: bounds, obstacles, reachable workspace at the start / end angle
        self.bounds = lines("/layout/bounds", (30, 30, 30), 2.0)
        self.obstacles = mesh("/layout/obstacles", (60, 60, 60), 0.85, flat_shading=True)
        self.obstacle_edges = lines("/layout/obstacle_edges", (0, 0, 0), 1.5)
        self.reachable = {which: lines(f"/layout/reachable_{which}", _REACH_COLOURS[which], 2.0)
                          for which in ("start", "end")}
        # axes along the bounds' lower and left edges, mm ticks, and a scale bar
        self.axes = lines("/view/axes", (40, 40, 40), 1.2)
        self.axis_labels = {axis: [scene.add_label(f"/view/{axis}_tick_{i}", "", visible=False)
                                   for i in range(MAX_TICK_LABELS)] for axis in ("x", "y")}
        self.scale_bar = lines("/view/scale_bar", (0, 0, 0), 4.0)
        self.scale_label = scene.add_label("/view/scale_label", "", visible=False)
        # result: trajectory and its time ticks
        self.trajectory = lines("/result/trajectory", (20, 60, 220), 3.0)
        self.ticks = points("/result/ticks", (255, 140, 0), 0.0035, "circle")
        # an opened G-code program (a contour design): the tolerance tube (the cells its passes
        # were planned through, filled and outlined) and the programmed path, feed moves and rapids
        self.tube = mesh("/contour/tube", PROGRAM_COLOURS["tube"], 0.6, flat_shading=True)
        self.tube_edges = lines("/contour/tube_edges", PROGRAM_COLOURS["tube_edges"], 0.8)
        self.program_feed = lines("/contour/program_feed", PROGRAM_COLOURS["feed"], 1.5)
        self.program_rapid = lines("/contour/program_rapid", PROGRAM_COLOURS["rapid"], 1.0)
        # the G-code preview (the exported program read back): feed moves, rapids dashed
        self.preview_feed = lines("/preview/feed", PREVIEW_COLOURS["feed"], 2.0)
        self.preview_rapid = lines("/preview/rapid", PREVIEW_COLOURS["rapid"], 2.0)
        # segment-list corridor: boxes, the selected box and its drag handles, snapping grid
        self.seg_grid = lines("/segments/grid", (205, 205, 205), 0.5)
        self.seg_boxes = lines("/segments/boxes", (0, 120, 0), 1.5)
        self.seg_selected = mesh("/segments/selected", (255, 200, 120), 0.45, flat_shading=True)
        self.seg_label = scene.add_label("/segments/label", "", visible=False)
        self.seg_handles = {}
        for handle in SEGMENT_HANDLES:
            node = mesh(f"/segments/handle_{handle}", (230, 120, 0) if handle != "centre" else (200, 60, 0),
                        0.9, flat_shading=True)
            node.on_drag(self._segment_drag_callback(handle))
            self.seg_handles[handle] = node
        # robot: one group; the platform is a frame moved per pose, its drawing fixed in it.
        # Pivots and tool sit a little above the legs and the platform edge (Z["pivots"]).
        self.robot = scene.add_frame("/robot", show_axes=False, visible=False)
        self.legs = scene.add_line_segments("/robot/legs", _NO_SEGMENTS, colors=_leg_colours(np.zeros(1)),
                                            thickness=5.0, thickness_units="screen")
        self.base_pivots = points("/robot/base_pivots", (20, 20, 20), 0.008, "circle")
        self.platform = scene.add_frame("/robot/platform", show_axes=False)
        self.platform_fill = mesh("/robot/platform/fill", (120, 120, 220), 0.15)
        self.platform_edge = lines("/robot/platform/edge", (40, 40, 160), 2.0)
        self.platform_pivots = points("/robot/platform/pivots", (20, 20, 20), 0.008, "circle")
        # leg numbers at the base pivots (= F1, F2, ... of the plots); one label per possible leg
        self.leg_labels = [scene.add_label(f"/robot/leg_{i + 1}", str(i + 1), visible=False)
                           for i in range(MAX_LEGS)]
        self.tool = scene.add_point_cloud("/robot/platform/tool", np.array([[0.0, 0.0, _PIVOTS_ABOVE_PLATFORM]]),
                                          colors=(220, 0, 0), point_size=0.01, point_shape="diamond")
        # start and end: planar gizmo (x, y only), dot and label
        self.gizmos, self.dots, self.labels = {}, {}, {}
        for which, colour in (("start", (0, 150, 0)), ("end", (200, 0, 150))):
            gizmo = scene.add_transform_controls(f"/handles/{which}", active_axes=(True, True, False),
                                                 disable_rotations=True, depth_test=False, visible=False)
            gizmo.on_update(self._gizmo_callback(which))
            self.gizmos[which] = gizmo
            self.dots[which] = scene.add_icosphere(f"/handles/{which}/dot", radius=0.001, color=colour,
                                                   visible=False)
            self.labels[which] = scene.add_label(f"/handles/{which}/label", which, visible=False)

    def set_view_span(self, span: float) -> None:
        """Size the dots (time ticks, pivots, tool) for a design ``span`` [m] across: the
        same on screen for a 0.3 m layout and a 0.1 m segment list."""
        sizes = ((self.ticks, 0.011), (self.base_pivots, 0.02), (self.platform_pivots, 0.02), (self.tool, 0.03))
        for node, fraction in sizes:
            size = round(fraction * max(span, 1e-3), 6)
            if node.point_size != size:
                node.point_size = size

    def _gizmo_callback(self, which: str):
        # async: viser awaits it on its event loop, so start, updates and end arrive in order
        async def on_update(event) -> None:
            phase = getattr(event, "phase", "update")
            self._dragging[which] = phase in ("start", "update")
            pos = event.target.position
            self._on_handle_moved(which, float(pos[0]), float(pos[1]), phase)
        return on_update

    def _segment_drag_callback(self, handle: str):
        async def on_drag(event) -> None:
            if self._on_segment_drag is not None:
                p = event.end_position
                self._on_segment_drag(handle, event.phase, float(p[0]), float(p[1]))
        return on_drag

    def end_drag(self, which: str, x: float, y: float) -> None:
        """Put the ``which`` gizmo at (x, y) [m] (the snapped point) after the drag ended."""
        self._dragging[which] = False
        self.gizmos[which].position = (float(x), float(y), geo.Z["handles"])

    # ------------------------------------------------------------------ camera
    @staticmethod
    def place_camera(centre, half_size: float, client=None, initial=None) -> None:
        """Look straight down at ``centre`` (x, y) [m] so that a square of half-size
        ``half_size`` [m] fills the view's height; for one ``client``, or the initial
        camera of clients that connect later (``client`` None, ``initial`` the server's
        ``initial_camera``)."""
        cam = initial if client is None else client.camera
        if cam is None:
            return
        height = geo.camera_height(half_size, cam.fov)
        cx = float(centre[0]) + 0.36 * half_size  # the control panel covers the right of the page
        pos, look = (cx, float(centre[1]), height), (cx, float(centre[1]), 0.0)
        if client is None:
            cam.position, cam.look_at, cam.up = pos, look, (0.0, 1.0, 0.0)
            cam.near, cam.far = 0.001, 100.0
        else:
            with client.atomic():
                client.camera.up_direction = (0.0, 1.0, 0.0)
                client.camera.position = pos
                client.camera.look_at = look

    # ------------------------------------------------------------------ layout
    def show_layout(self, layout: dict | None, robot: Robot) -> None:
        """Bounds, obstacles, start/end gizmos and the reachable outline of ``layout`` (the
        request's ``layout`` dict, or None for a request without one: all hidden)."""
        marker_nodes = [*self.gizmos.values(), *self.dots.values(), *self.labels.values()]
        if layout is None:
            for node in (self.bounds, self.obstacles, self.obstacle_edges, *self.reachable.values(), *marker_nodes,
                         self.axes, self.scale_bar, self.scale_label, *self.axis_labels["x"], *self.axis_labels["y"]):
                node.visible = False
            return
        lo = np.asarray(layout["bounds"]["lower"], float)
        hi = np.asarray(layout["bounds"]["upper"], float)
        span = max(float(np.max(hi - lo)), 1e-3)  # > 0 even while the user types inverted bounds
        _show_lines(self.bounds, geo.polygon_edges([geo.rectangle(lo, hi)], geo.Z["grid"]))
        self._show_axes(lo, hi)
        shapes = geo.clip_shapes([geo.obstacle_shape(ob) for ob in layout.get("obstacles", [])], lo, hi)
        _show_mesh(self.obstacles, *geo.shape_mesh(shapes, geo.Z["obstacles"]))  # exact: holes stay open
        _show_lines(self.obstacle_edges, geo.shape_edges(shapes, geo.Z["obstacle_edges"]))  # outlines on top
        psi_start, psi_end = float(layout["start"][2]), float(layout["end"][2])
        # one colour per node (per-vertex colours are drawn paler: the outline vanished on the
        # pink unreachable cells)
        _show_lines(self.reachable["start"], self._reach_outline(robot, lo, hi, psi_start))
        if abs(psi_end - psi_start) < 1e-9:  # same angle: one outline is enough
            self.reachable["end"].visible = False
        else:
            _show_lines(self.reachable["end"], self._reach_outline(robot, lo, hi, psi_end))
        limits = ((float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1])), (0.0, 0.0))
        for which in ("start", "end"):
            p = layout[which]
            gizmo = self.gizmos[which]
            gizmo.scale = HANDLE_SCALE * span
            gizmo.translation_limits = limits
            if not self._dragging[which]:  # never fight the user's drag
                gizmo.position = (float(p[0]), float(p[1]), geo.Z["handles"])
            self.dots[which].radius = DOT_RADIUS * span
            self.labels[which].text = f"{which} (ψ {float(p[2]):.2f} rad)"
        for node in marker_nodes:
            node.visible = True

    def _show_axes(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """x and y axes just outside the bounds' lower and left edges with ticks in mm (a
        label every major tick) and a scale bar under the lower right corner."""
        span = float(np.max(hi - lo))
        minor, major = axis_ticks(span)
        z, t = geo.Z["grid"], 0.012 * span
        y0, x0 = lo[1] - 0.02 * span, lo[0] - 0.02 * span
        segs = [[[lo[0], y0, z], [hi[0], y0, z]], [[x0, lo[1], z], [x0, hi[1], z]]]
        labels = {"x": [], "y": []}
        for axis, a, b in (("x", lo[0], hi[0]), ("y", lo[1], hi[1])):
            for v in minor * np.arange(np.ceil(a / minor - 1e-9), np.floor(b / minor + 1e-9) + 1):
                is_major = abs(v / major - round(v / major)) < 1e-6
                length = t * (2.0 if is_major else 1.0)
                if axis == "x":
                    segs.append([[v, y0, z], [v, y0 - length, z]])
                else:
                    segs.append([[x0, v, z], [x0 - length, v, z]])
                if is_major:
                    labels[axis].append(float(v))
        _show_lines(self.axes, np.asarray(segs, float))
        for axis, values in labels.items():
            for i, node in enumerate(self.axis_labels[axis]):
                if i < len(values):
                    v = values[i]
                    node.text = f"{v * 1e3:.0f} mm" if abs(v) > 1e-12 else "0"
                    node.position = (v, y0 - 3.5 * t, z) if axis == "x" else (x0 - 6.0 * t, v, z)
                node.visible = i < len(values)
        bar = major  # one major tick long
        yb = y0 - 9.0 * t
        _show_lines(self.scale_bar, np.array([[[hi[0] - bar, yb, z], [hi[0], yb, z]]]))
        self.scale_label.text = f"{bar * 1e3:.0f} mm"
        self.scale_label.position = (hi[0] - 0.5 * bar, yb - 2.5 * t, z)
        self.scale_label.visible = True

    def _reach_outline(self, robot: Robot, lo: np.ndarray, hi: np.ndarray, psi: float) -> np.ndarray:
        """Outline (M, 2, 3) [m] of the poses reachable at angle ``psi`` [rad] over the bounds
        plus a 5 % margin; the last few are kept (a drag of start/end redraws the layout on
        every move, with the same robot, bounds and angles)."""
        key = (id(robot), *lo.tolist(), *hi.tolist(), psi)
        outline = self._reach_cache.get(key)
        if outline is None:
            margin = 0.05 * (hi - lo)
            xs, ys, mask = reachable_mask(robot, lo - margin, hi + margin, psi, n=REACH_SAMPLES)
            outline = geo.clip_segments(geo.mask_boundary(xs, ys, mask, geo.Z["reach"]), lo, hi)
            if len(self._reach_cache) >= 8:
                self._reach_cache.pop(next(iter(self._reach_cache)))
            self._reach_cache[key] = outline
        return outline

    # ------------------------------------------------------------------ segmentation
    def show_segmentation(self, seg: SegmentationResult | None) -> None:
        """Cells (by state), grid and corridor of a segmentation, or hide them (None)."""
        if seg is None:
            for node in (*self.cells.values(), self.grid, self.corridor_fill, self.corridor):
                node.visible = False
            return
        cells = seg.cells
        lo, hi = seg.bounds["lower"], seg.bounds["upper"]
        for state, node in self.cells.items():
            polys = geo.clip_polygons([c.polygon for c in cells if c.state == state], lo, hi)
            _show_mesh(node, *geo.polygon_mesh(polys, geo.Z["cells"]))
        _show_lines(self.grid, geo.polygon_edges(geo.clip_polygons([c.polygon for c in cells], lo, hi),
                                                 geo.Z["grid"]))
        by_id = {c.id: c for c in cells}
        path = geo.clip_polygons([by_id[i].polygon for i in seg.path if i in by_id], lo, hi)
        _show_mesh(self.corridor_fill, *geo.polygon_mesh(path, geo.Z["corridor"]))
        self.show_corridor(seg.segments)

    def show_corridor(self, segments: list[dict]) -> None:
        """Outline the corridor's boxes (``[{lower, upper}, ...]``, [m, m, rad]) in x, y."""
        boxes = [geo.rectangle(s["lower"][:2], s["upper"][:2]) for s in segments]
        _show_lines(self.corridor, geo.polygon_edges(boxes, geo.Z["corridor"]))

    # ------------------------------------------------------------------ segment-list corridor
    def show_segments(self, segments: list[dict] | None, selected: int | None = None,
                      grid: tuple[float, Any] | None = None) -> None:
        """The boxes of a segment-list corridor (``[{lower, upper}, ...]``, [m, m, rad]), the
        ``selected`` one filled with its edge and centre handles, and the snapping ``grid``
        (step [m], origin (x, y) [m]) under them; None hides them (a layout)."""
        nodes = (self.seg_boxes, self.seg_selected, self.seg_label, self.seg_grid, *self.seg_handles.values())
        if not segments:
            for node in nodes:
                node.visible = False
            return
        boxes = [geo.rectangle(s["lower"][:2], s["upper"][:2]) for s in segments]
        _show_lines(self.seg_boxes, geo.polygon_edges(boxes, geo.Z["corridor"]))
        pts = np.array([p for b in boxes for p in b], float)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        span = max(float(np.max(hi - lo)), 0.02)
        self._show_snap_grid(lo - 0.1 * span, hi + 0.1 * span, grid)
        if selected is None or not 0 <= selected < len(segments):
            for node in (self.seg_selected, self.seg_label, *self.seg_handles.values()):
                node.visible = False
            return
        s = segments[selected]
        (x0, y0), (x1, y1) = s["lower"][:2], s["upper"][:2]
        _show_mesh(self.seg_selected, *geo.polygon_mesh([geo.rectangle((x0, y0), (x1, y1))], geo.Z["obstacles"]))
        w = EDGE_HANDLE * span
        xm, ym = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        hx, hy = max(0.5 * (x1 - x0), w), max(0.5 * (y1 - y0), w)
        rects = {"left": ((x0 - w / 2, ym - hy), (x0 + w / 2, ym + hy)),
                 "right": ((x1 - w / 2, ym - hy), (x1 + w / 2, ym + hy)),
                 "bottom": ((xm - hx, y0 - w / 2), (xm + hx, y0 + w / 2)),
                 "top": ((xm - hx, y1 - w / 2), (xm + hx, y1 + w / 2)),
                 "centre": ((xm - 0.8 * w, ym - 0.8 * w), (xm + 0.8 * w, ym + 0.8 * w))}
        point = x1 - x0 <= 1e-12 and y1 - y0 <= 1e-12
        for handle, (a, b) in rects.items():
            z = geo.Z["handles"] + (0.0005 if handle == "centre" else 0.0)
            node = self.seg_handles[handle]
            if point and handle != "centre":  # a start / end point: only the centre moves it
                node.visible = False
                continue
            _show_mesh(node, *geo.polygon_mesh([geo.rectangle(a, b)], z))
        self.seg_label.position = (xm, y1 + 1.5 * w, geo.Z["handles"])
        a, b = float(s["lower"][2]), float(s["upper"][2])
        psi = f"ψ {a:g} rad" if a == b else f"ψ {a:g}…{b:g} rad"
        self.seg_label.text = f"segment {selected + 1}: {psi}"
        self.seg_label.visible = True

    def _show_snap_grid(self, lo, hi, grid) -> None:
        if grid is None or grid[0] <= 0 or np.any((hi - lo) / grid[0] > 200):
            self.seg_grid.visible = False
            return
        step, (ox, oy) = grid[0], grid[1]
        xs = ox + step * np.arange(np.ceil((lo[0] - ox) / step), np.floor((hi[0] - ox) / step) + 1)
        ys = oy + step * np.arange(np.ceil((lo[1] - oy) / step), np.floor((hi[1] - oy) / step) + 1)
        z = geo.Z["cells"]
        v = [[[x, lo[1], z], [x, hi[1], z]] for x in xs] + [[[lo[0], y, z], [hi[0], y, z]] for y in ys]
        _show_lines(self.seg_grid, np.asarray(v, float).reshape(-1, 2, 3))

    # ------------------------------------------------------------------ result
    def show_result(self, result: PlanResult | None) -> None:
        """The planned trajectory and its time ticks (every :data:`TICK_EVERY_S` s), or
        hide them and the robot (None). The robot's pose is :meth:`show_robot`'s."""
        if result is None:
            self.trajectory.visible = self.ticks.visible = False
            self.hide_robot()
            return
        t, pose = result.time, result.pose
        pts = np.column_stack((pose[:, :2], np.full(len(pose), geo.Z["trajectory"])))
        _show_lines(self.trajectory, np.stack((pts[:-1], pts[1:]), axis=1))
        ticks = geo.time_ticks(t, pose, TICK_EVERY_S)
        self.ticks.points = np.column_stack((ticks, np.full(len(ticks), geo.Z["ticks"])))
        self.ticks.visible = not self._flat

    def set_flat(self, flat: bool) -> None:
        """Draw the program, the tube, the planned cut, its ticks and the G-code preview nearly
        in the plane (their z scaled by :data:`FLAT_Z`, their order kept) or at their layers'
        heights. The view is a perspective one: a layer drawn 3.7 mm above the plane shows
        r dz / h too far out at r from the view's centre seen from h above, a few pixels for a
        0.3 m layout but 0.2 mm beside a 10 mm program framed from 13 mm: the tube then seemed
        to miss the programmed path it is built around by 4 tolerances. The time ticks are
        hidden while flat (0.1 s apart they are a dot every 0.5 mm at a cut's feed of 300 mm/min)."""
        if flat == self._flat:
            return
        self._flat = flat
        if flat:
            self.ticks.visible = False
        scale = (1.0, 1.0, FLAT_Z) if flat else 1.0
        for node in (self.trajectory, self.preview_feed, self.preview_rapid, self.tube, self.tube_edges,
                     self.program_feed, self.program_rapid):
            node.scale = scale

    def show_program(self, path: Toolpath | None, origin=None) -> None:
        """An opened G-code program's programmed path (:func:`planner.exchange.toolpath`, program
        frame) with program zero at ``origin`` [x, y] (robot frame, m): its feed moves (cuts and
        feed moves above the material) and its rapids as line segments between the path's
        points, pieces of length 0 (dwells, plunges) left out; None hides it."""
        if path is None or origin is None:
            self.program_feed.visible = self.program_rapid.visible = False
            return
        pts = np.asarray(path.points, float) + np.asarray(origin, float)[:2]
        a, b = pts[:-1], pts[1:]
        moves = np.any(a != b, axis=1)
        z = geo.Z["program"]
        for node, rapid in ((self.program_feed, False), (self.program_rapid, True)):
            keep = moves & (path.rapid == rapid)
            segs = np.stack((a[keep], b[keep]), axis=1)
            _show_lines(node, np.concatenate((segs, np.full((*segs.shape[:2], 1), z)), axis=2))

    def show_tube(self, cells: list[np.ndarray] | None) -> None:
        """The tolerance tube of a contour plan: its convex cells (each (m, 2) [m]) filled and
        outlined; None (or none) hides it."""
        cells = cells or []
        _show_mesh(self.tube, *geo.polygon_mesh(cells, geo.Z["tube"]))
        _show_lines(self.tube_edges, geo.polygon_edges(cells, geo.Z["tube"] + 1e-4))

    def show_reach(self, robot: Robot | None, psi: float = 0.0) -> None:
        """The outline of the region ``robot`` reaches at ``psi`` [rad] over its whole reach
        (a G-code program has no layout bounds: where ``origin: "fit"`` places it); None hides it."""
        if robot is None:
            self.reachable["start"].visible = False
            return
        lo, hi, _ = reachable_region(robot, psi)
        margin = 0.02 * (hi - lo)
        _show_lines(self.reachable["start"], self._reach_outline(robot, lo - margin, hi + margin, psi))
        self.reachable["end"].visible = False

    def show_preview(self, preview: GcodePreview | None) -> None:
        """The G-code preview over the trajectory: the read-back program's feed moves as
        line segments through its points, its rapids dashed; None hides it."""
        if preview is None:
            self.preview_feed.visible = self.preview_rapid.visible = False
            return
        z = geo.Z["preview"]

        def lift(segs: np.ndarray) -> np.ndarray:
            return np.concatenate((segs, np.full((*segs.shape[:2], 1), z)), axis=2)

        feed, rapid = preview.segments(rapid=False), preview.segments(rapid=True)
        span = float(np.max(np.ptp(preview.points, axis=0))) if len(preview.points) > 1 else 0.0
        _show_lines(self.preview_feed, lift(feed))
        _show_lines(self.preview_rapid, lift(geo.dashes(rapid, max(span, 0.01) / 60.0)))

    # ------------------------------------------------------------------ robot
    def hide_robot(self) -> None:
        """Hide the robot (no plan to show)."""
        self.robot.visible = False

    def show_robot(self, robot: Robot, pose, force=None) -> None:
        """``robot`` at ``pose`` = [x, y, psi] (tool point; m, m, rad), legs coloured by
        ``force`` (n,) [N] relative to the robot's force limit. Per call only the platform
        frame's pose and the legs' points and colours change; the robot's drawing is redone
        only when ``robot`` differs from the last one shown."""
        with self._robot_lock, self._client.atomic():  # legs, colours and platform: one pose, one update
            if robot is not self._robot_drawn:
                self._show_robot_structure(robot)
            z = geo.Z["robot"]
            g = robot_geometry(robot, pose)
            ends = np.stack((np.column_stack((g["base"], np.full(robot.n_legs, z))),
                             np.column_stack((g["pivots"], np.full(robot.n_legs, z)))), axis=1)
            ratio = np.zeros(robot.n_legs) if force is None else np.abs(force) / robot.force_max
            self.legs.colors = _leg_colours(ratio)
            self.legs.points = ends
            self.platform.position = (float(pose[0]), float(pose[1]), z)
            self.platform.wxyz = geo.yaw_quaternion(float(pose[2]))
            self.robot.visible = self.robot_style != "hidden"

    def set_robot_style(self, style: str) -> None:
        """Draw the robot ``solid`` (platform filled, thick legs), as an ``outline`` (thin legs,
        no fill: the corridor under it stays readable) or ``hidden``."""
        legs, fill, edge = ROBOT_STYLES[style]
        with self._robot_lock:
            self.robot_style = style
            if legs > 0:
                self.legs.thickness = legs
                self.platform_edge.thickness = edge
            self.platform_fill.visible = fill and self._robot_drawn is not None
            if style == "hidden":
                self.robot.visible = False
            elif self._robot_drawn is not None and self.legs.points.shape[0] > 1:
                self.robot.visible = True

    def _show_robot_structure(self, robot: Robot) -> None:
        """What changes only with the robot: base pivots (world) and the platform's
        drawing in its own frame (origin at the tool point)."""
        self.base_pivots.points = np.column_stack((robot.base, np.full(robot.n_legs, geo.Z["pivots"])))
        local = robot.r0  # platform pivots about the tool point, platform frame
        _show_mesh(self.platform_fill, *geo.polygon_mesh([local], 0.0))
        self.platform_fill.visible = ROBOT_STYLES[self.robot_style][1]
        _show_lines(self.platform_edge, geo.polygon_edges([local], 0.0))
        self.platform_pivots.points = np.column_stack((local, np.full(robot.n_legs, _PIVOTS_ABOVE_PLATFORM)))
        for node in (self.base_pivots, self.platform_pivots):
            node.visible = True
        for i, label in enumerate(self.leg_labels):
            if i < robot.n_legs:
                label.position = (float(robot.base[i, 0]), float(robot.base[i, 1]), geo.Z["pivots"])
            label.visible = i < robot.n_legs
        self._robot_drawn = robot


def axis_ticks(span: float) -> tuple[float, float]:
    """Minor and major tick spacing [m] for an axis ``span`` [m] long: minor ticks 1, 2 or
    5 x 10^k mm with 10-40 of them, a major tick (labelled, the scale bar's length) every 5
    minor ticks (2 for a 5 spacing)."""
    raw = max(span, 1e-6) / 25.0
    k = 10.0 ** np.floor(np.log10(raw))
    minor = next(m * k for m in (1.0, 2.0, 5.0, 10.0) if m * k >= raw)
    factor = 2.0 if round(minor / k) == 5 else 5.0
    return float(minor), float(minor * factor)
