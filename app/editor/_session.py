"""One editing session: what one browser tab edits, sees and plans.

Every tab that connects gets its own :class:`Session` (made by :class:`app.editor.Editor`
when viser reports the client): its own request (:mod:`._state`), undo history
(:mod:`._history`), re-plan worker (:mod:`._planning`), scene (``client.scene``) and panel
(``client.gui``). Two tabs never see or change each other's design; sharing is explicit,
by saving a corridor under a name and loading it in the other tab (the store is shared).

Every edit goes through :meth:`Session.edit` (or :meth:`Session.set_request` for a
whole new request): it is recorded for undo, the drawing is updated at once, and a
debounced re-plan is scheduled on the session's worker thread. GUI callbacks therefore
return at once; a stale result never overwrites a newer one. Dragged handles, box edges
and drawn rectangles snap to the grid (default: the cell size) when snapping is on.
Errors (no path, an unreachable end, a bad value) are one notification per error state,
updated in place while the person types, and shown on the field they concern.

Units: m, rad, s, N.
"""

from __future__ import annotations

import logging
import re
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol, cast

import numpy as np

from . import _geometry as geo
from . import _state
from ._files import EditorFiles
from ._gui import EditorGui, error_body, error_title
from ._history import History
from ._placement import reachable_region
from ._planning import PlannerError, PlanWorker, RobotCache, compute_plan, is_contour, program_toolpath, tube_cells
from ._preview import Previewer
from ._result import leg_legend_html
from ._scene import EditorScene
from ._session_segments import SegmentEdits
from ._state import StateViews

if TYPE_CHECKING:
    from ._planning import ErrorDetail, PlanResult, Toolpath

__all__ = ["Session", "SessionHost"]

log = logging.getLogger("rangeplan.editor")
#: where a validation message lists the next field ("; settings.N: ..."); a "; " inside one
#: field's message (an out-of-reach origin's "; an origin that fits: ...") is not cut there
_OTHER_FIELD = re.compile(r"; (?=[A-Za-z_][\w.\[\]]*: )")


class SessionHost(Protocol):
    """What a session takes of the server that made it (:class:`app.editor.Editor`): the
    robots loaded once for every tab, the corridor store (an :class:`app.storage.Store`, or
    None: no saving), the quiet time after an edit before a re-plan [s], and
    :meth:`stored_changed`. Declared here, so the session never imports the server."""

    robots: RobotCache
    store: Any
    debounce: float

    def stored_changed(self) -> None:
        """Re-read every tab's list of stored corridors (after a save)."""
        ...


class Session(StateViews, SegmentEdits):
    """The editing session of one viser ``client`` (a browser tab) of ``editor`` (the
    :class:`SessionHost` that made it), starting from ``request`` (the one JSON shape).

    The session owns the tab's state (read through :class:`._state.StateViews`) and builds
    its collaborators, handing each itself: the files, the G-code preview, the panel and its
    folders. Each declares the few session members it uses as a protocol of its own module
    (``FilesHost``, ``PreviewHost``, ``PanelActions``, ``ProgramActions``,
    ``SegmentActions``), so the imports run one way: they never import this module."""

    def __init__(self, editor: SessionHost, client, request: dict):
        self.editor = editor
        self.client = client
        self.robots = editor.robots
        self.state = _state.EditorState(request)
        self.history = History()
        self.selected_segment = 0  #: index of the segment box being edited (segment-list corridors)
        self.notifications: list[tuple[str, str]] = []  #: every notification sent (title, body)
        self._error_note: Any = None  # the one notification of the current plan error
        self._error_state: tuple | None = None  # (code, field) it shows
        self._draw_lock = threading.Lock()
        self._drag: tuple[dict, float, float] | None = None  # segment at drag start, pointer x, y [m]
        self._closed = False
        #: the opened G-code program's path as drawn (program frame) and program zero [x, y] (robot
        #: frame, m) it was drawn at; None: no program drawn
        self.program_drawn: tuple[Toolpath, list[float]] | None = None
        self._frame_program = False  # a program was just opened: the view frames it once it is placed
        self.scene = EditorScene(client, on_click=self._on_scene_click, on_rect_select=self._on_rect_select,
                                 on_handle_moved=self.move_handle, on_segment_drag=self.drag_segment)
        self.files = EditorFiles(self, editor.store)
        self.preview = Previewer(self)
        self.gui = EditorGui(client.gui, self, has_store=editor.store is not None)
        self.files.refresh_stored()
        self.place_cameras()
        self._show_all()
        self.worker = PlanWorker(self._run_plan, self._on_plan_crash, editor.debounce)
        self.worker.start()
        client.camera.on_update(self._on_camera)
        self._on_camera(client.camera)
        self.worker.schedule(immediate=True)

    # ------------------------------------------------------------------ read-only views (more: StateViews)
    @property
    def store(self):
        """The corridor store shared by all sessions (or None)."""
        return self.files.store

    # ------------------------------------------------------------------ edits
    def edit(self, fn: Callable[[dict], object], *, immediate: bool = False, key: str | None = None) -> bool:
        """Apply ``fn(request_dict)`` (in place) under the lock as one undo step (edits with
        the same ``key`` in quick succession join one step: the typing in one field, one
        drag), schedule a debounced re-plan (when re-planning on every edit is on, or
        ``immediate``) and redraw. An edit that changes nothing is not recorded. Returns
        whether the request changed."""
        with self.state.lock:  # the re-plan is asked for under the lock: see wait_idle
            before = self.state.request
            self.state.apply(fn)
            changed = self.state.request != before
            if changed:
                self.history.record(before, key)
                self._schedule(immediate)
        if changed:
            self._show_drawing()
            self.gui.show_auto_horizon(self.state.request)  # Ts, robot or mode may have changed
            self.gui.show_history(self.history.can_undo, self.history.can_redo)
        return changed

    def set_request(self, request: dict, *, replan: bool = True, immediate: bool = False) -> None:
        """Replace the whole request (import / load / new layout) as one undo step, show it
        (nothing of the old drawing stays) and re-plan."""
        with self.state.lock:
            self.history.record(self.state.request)
            self.state.replace(request)
            self.selected_segment = 0
            if replan:
                self._schedule(immediate, always=True)
        self.scene.show_result(None)
        self._show_all()

    def open_design(self, request: dict) -> None:
        """Open a G-code program's design (a contour request dict, see
        :meth:`app.editor._files.EditorFiles.open_program`) as one undo step, plan it at once;
        the view frames the program when the plan has placed it."""
        self._frame_program = True
        self.set_request(request, immediate=True)
        self.place_cameras()

    def undo(self) -> bool:
        """Undo the newest edit step; returns False when there is none."""
        return self._restore(self.history.undo)

    def redo(self) -> bool:
        """Redo the newest undone step; returns False when there is none."""
        return self._restore(self.history.redo)

    def _restore(self, step: Callable[[dict], dict | None]) -> bool:
        with self.state.lock:
            request = step(self.state.request)
            if request is None:
                return False
            self.state.replace(request)
            self._schedule(False)
        self._show_all()
        return True

    def _schedule(self, immediate: bool, always: bool = False) -> None:
        """Ask for a re-plan after an edit (when re-planning on every edit is on)."""
        if always or immediate or self.gui.auto_replan.value:
            self._mark_outdated()
            self.worker.schedule(immediate=immediate)

    def plan_now(self) -> int:
        """Re-plan at once (the Plan button); returns the generation asked for."""
        self._mark_outdated()
        return self.worker.schedule(immediate=True)

    # ------------------------------------------------------------------ layout edits
    def snap_grid(self) -> tuple[float, tuple[float, float]] | None:
        """The snapping grid (step [m], origin (x, y) [m]) or None when snapping is off. The
        default step is the layout's cell size (the segmentation's when automatic) from the
        bounds' lower corner, or for a segment list its smallest box side from (0, 0)."""
        if not self.gui.snap.value:
            return None
        step = cast(float | None, self.gui.grid.value)
        r = self.state.request
        layout = r.get("layout")
        if layout is not None:
            origin = (float(layout["bounds"]["lower"][0]), float(layout["bounds"]["lower"][1]))
            seg = self.state.last_segmentation
            step = step or (layout.get("cell") or {}).get("size") or (seg.cell.get("size") if seg else None) or 0.01
            return float(step), origin
        sides = [float(s["upper"][k]) - float(s["lower"][k]) for s in r.get("segments") or [] for k in (0, 1)]
        sides = [d for d in sides if d > 1e-9]
        return float(step or (min(sides) if sides else 0.01)), (0.0, 0.0)

    def snap_xy(self, x: float, y: float) -> list[float]:
        """(x, y) [m] on the snapping grid (to 0.1 mm when snapping is off)."""
        grid = self.snap_grid()
        return geo.snap_point((x, y), grid[0] if grid else None, grid[1] if grid else (0.0, 0.0))

    def grid_changed(self) -> None:
        """Snapping was switched or its grid changed: redraw the grid and the readout."""
        self._show_drawing()

    def move_handle(self, which: str, x: float, y: float, phase: str = "update") -> None:
        """Move the start or end point to (x, y) [m], snapped (what dragging its gizmo
        does; one undo step per drag, from ``phase`` "start" to "end")."""
        if phase == "start":
            self.history.begin(f"drag:{which}")
        sx, sy = self.snap_xy(x, y)
        self.edit(lambda r: _state.move_point(r, which, sx, sy), key=f"drag:{which}")
        layout = self.state.request.get("layout")
        if layout is not None:
            self.gui.show_point(which, layout[which])
        if phase == "end":
            self.history.seal()
            self.scene.end_drag(which, sx, sy)

    def toggle_cell_at(self, x: float, y: float) -> bool:
        """Toggle an obstacle on the cell under (x, y) [m] (see
        :func:`app.editor._state.toggle_cell_obstacle`). Returns False when no cell of the
        newest segmentation contains the point."""
        seg = self.state.last_segmentation
        if not seg:
            return False
        cell = next((c for c in seg.cells if geo.point_in_convex((x, y), c.polygon)), None)
        if cell is None:
            return False
        polygon = cell.polygon
        self.edit(lambda r: _state.toggle_cell_obstacle(r, polygon))
        return True

    def add_rectangle(self, lower, upper) -> None:
        """Add a rectangle obstacle with corners ``lower``, ``upper`` (x, y) [m] (any order)."""
        lo, hi = np.minimum(lower, upper), np.maximum(lower, upper)
        if np.any(hi - lo <= 0):
            self.notify("Rectangle not added", "the rectangle has zero width or height (m)", color="yellow")
            return
        obstacle = {"type": "rectangle", "lower": [float(lo[0]), float(lo[1])], "upper": [float(hi[0]), float(hi[1])]}
        self.edit(lambda r: _state.add_obstacle(r, obstacle))

    def set_mode(self, mode: str) -> None:
        """Switch the planner mode (see :func:`app.editor._state.switch_mode`)."""
        self.edit(lambda r: _state.switch_mode(r, mode))
        self.gui.show_mode_settings(_state.mode_settings(self.state.request))

    def set_robot(self, name: str) -> None:
        """Plan for the built-in robot ``name``; the view follows its workspace."""
        self.edit(lambda r: r.__setitem__("robot", name))
        self.place_cameras()

    def new_layout(self) -> None:
        """Start over from the default layout (keeps robot and settings)."""
        self.set_request(_state.with_new_layout(self.state.request))

    # ------------------------------------------------------------------ showing
    def _show_all(self) -> None:
        """The request in the panel and the view, the undo buttons."""
        self.gui.show_request(self.state.request, self.selected_segment)
        self._show_drawing()
        self.gui.show_history(self.history.can_undo, self.history.can_redo)

    def _show_drawing(self) -> None:
        """Redraw the layout or the segment boxes (no planning); the newest request wins
        when several threads draw at once."""
        with self._draw_lock:
            r = self.state.request
            layout = r.get("layout")
            grid = self.snap_grid()
            self.gui.cursor.set_grid(grid[0] if grid else None, grid[1] if grid else (0.0, 0.0))
            robot = self.robots.of_request(r)
            if is_contour(r):
                self._show_program_design(r, robot)
                self.show_downloads()
                return
            self.program_drawn = None
            self.scene.show_program(None)
            self.scene.show_tube(None)
            self.scene.set_flat(False)
            if robot is not None:
                self.scene.show_layout(layout, robot)
                if layout is not None:
                    psi = float(layout["start"][2])
                    lo, hi, _ = reachable_region(robot, psi)
                    text = (f"Reachable at ψ {psi:g} rad (red outline): x {lo[0] * 1e3:.0f}…{hi[0] * 1e3:.0f} mm, "
                            f"y {lo[1] * 1e3:.0f}…{hi[1] * 1e3:.0f} mm")
                    if self.gui.reach_note.content != text:
                        self.gui.reach_note.content = text
            if layout is None:
                segs = r.get("segments") or []
                self.scene.show_segmentation(None)
                self.scene.show_segments(segs, self.selected_segment, grid)
                pts = np.array([g[k][:2] for g in segs for k in ("lower", "upper")] or [[0.0, 0.0]], float)
                self.scene.set_view_span(max(float(np.max(pts.max(axis=0) - pts.min(axis=0))), 0.05))
            else:
                self.scene.show_segments(None)
                self.scene.set_view_span(float(np.max(np.subtract(layout["bounds"]["upper"],
                                                                  layout["bounds"]["lower"]))))
        self.show_downloads()

    def _show_program_design(self, request: dict, robot) -> None:
        """A G-code program's design (called under the draw lock): no layout, no boxes; the
        region the robot reaches (where "fit" places the program) and, when the program was
        read and its origin is typed, its path at that origin at once (with "fit" the plan
        says where: :meth:`_show_contour`)."""
        self.scene.show_segmentation(None)
        self.scene.show_segments(None)
        self.scene.set_flat(True)
        if robot is not None:
            self.scene.show_layout(None, robot)
            self.scene.show_reach(robot, 0.0)
            lo, hi, _ = reachable_region(robot, 0.0)
            text = (f"Reachable at ψ 0 rad (red outline), where the program is placed: x {lo[0] * 1e3:.0f}…"
                    f"{hi[0] * 1e3:.0f} mm, y {lo[1] * 1e3:.0f}…{hi[1] * 1e3:.0f} mm")
            if self.gui.reach_note.content != text:
                self.gui.reach_note.content = text
        origin = request.get("origin", [0.0, 0.0])
        drawn = self.program_drawn
        if drawn is not None and origin != "fit" and list(map(float, origin)) != drawn[1]:
            self._draw_program(drawn[0], [float(v) for v in origin])
        pts = drawn[0].points if drawn is not None else np.zeros((1, 2))
        self.scene.set_view_span(max(float(np.max(np.ptp(pts, axis=0))), 0.005))

    def _draw_program(self, path: Toolpath | None, origin: list[float] | None) -> None:
        self.program_drawn = (path, origin) if path is not None and origin is not None else None
        self.scene.show_program(path, origin)

    def _show_contour(self, request: dict, result: PlanResult | None) -> None:
        """After a contour plan (on the worker): the programmed path, read as the contour job
        reads it, at the origin the plan used (a typed one when the plan failed), the tube the
        passes were planned through, and, once after a program was opened, the view on it."""
        try:
            path: Toolpath | None = program_toolpath(request)
        except PlannerError:  # the plan's error names the line
            path = None
        origin = request.get("origin", [0.0, 0.0])
        if result is not None and result.contour is not None:
            at: list[float] | None = [float(v) for v in result.contour.origin]
        else:
            at = None if origin == "fit" else [float(v) for v in origin]
        with self._draw_lock:
            self._draw_program(path, at)
            self.scene.show_tube(tube_cells(result) if result is not None else None)
            if path is not None and at is not None:
                self.scene.set_view_span(max(float(np.max(np.ptp(path.points, axis=0))), 0.005))
        if self._frame_program and path is not None and at is not None:
            self._frame_program = False
            pts = path.points + np.asarray(at)
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            self.scene.place_camera(0.5 * (lo + hi), max(0.7 * float(np.max(hi - lo)), 0.005), self.client)

    def show_downloads(self) -> None:
        """Machine-file downloads and the G-code preview on only for the plan of the design on
        screen (else the reason)."""
        files = self.files.machine_files()
        self.gui.show_downloads(files.result is not None, files.reason)
        self.preview.refresh()  # the G-code preview follows the same rule

    def show_time(self, t: float) -> None:
        """Show the robot of the newest result at time ``t`` [s] (clamped to the plan)."""
        with self.state.lock:
            res, robot_spec = self.state.last_result, self.state.last_result_robot
            failed = self.state.last_error is not None
        if res is None or failed:
            return
        robot = self.robots.get(robot_spec)  # the robot it was planned for, even if changed since
        pose = geo.sample_at(res.time, res.pose, t)
        k = int(np.clip(round(t / res.settings.Ts), 0, len(res.time) - 1))
        self.scene.show_robot(robot, pose, res.drives.force[k])

    def _mark_outdated(self) -> None:
        shown = self.gui.result.plan
        if shown is not None:
            self.gui.result.header.content = (f"**Plan #{shown}** is shown; the design has changed since — "
                                              "re-planning…")
        self.gui.show_status("edited — re-planning…" + (f" (plots: plan #{shown})" if shown is not None else ""))

    # ------------------------------------------------------------------ notifications, camera
    def notify(self, title: str, body: str, color: str = "red", client=None) -> None:
        """Show a notification in this tab (``client`` is accepted for the file actions'
        sake: it is always this tab); red ones stay until closed."""
        del client
        self.notifications.append((title, body))
        try:
            self.client.add_notification(title, body, color=cast(Any, color),
                                         auto_close_seconds=8.0 if color != "red" else None)
        except Exception:  # a tab that went away must not break the session
            log.debug("notification failed", exc_info=True)

    def _show_plan_error(self, error: ErrorDetail) -> None:
        """The one notification of the current plan error: updated in place while the
        error state (code, field) stays, replaced when it changes; and on its field."""
        self.gui.clear_plan_errors()
        self._show_error_on_field(error)
        title, body = error_title(error), error_body(error)
        state = (error.code, error.field)
        note = self._error_note
        if note is not None and state == self._error_state:
            if (note.title, note.body) != (title, body):
                note.title, note.body = title, body
                self.notifications.append((title, body))
            return
        self._clear_error_note()
        self.notifications.append((title, body))
        self._error_note = self.client.add_notification(title, body, color="red", with_close_button=True)
        self._error_state = state

    def _show_error_on_field(self, error: ErrorDetail) -> None:
        field, message = error.field or "", error.message
        message = _OTHER_FIELD.split(message)[0]  # the field's own message (validation may list more fields)
        if field.startswith("segments["):
            try:
                i = int(field[len("segments["):field.index("]")])
            except ValueError:
                return
            self.select_segment(i)
            which = "upper" if field.endswith(".upper") else "lower"
            getattr(self.gui.segments, which).show_error(message, source="plan")
            return
        self.gui.show_field_error(field, message)

    def _clear_error_note(self) -> None:
        if self._error_note is not None:
            try:
                self._error_note.remove()
            except Exception:
                log.debug("notification removal failed", exc_info=True)
        self._error_note, self._error_state = None, None

    def place_cameras(self, fit_layout: bool = False) -> None:
        """Frame the design in this tab: a layout's bounds and the robot's base (only the
        bounds with ``fit_layout``: an imported drawing fills the view); a segment
        list's boxes with a margin (boxes of 2 cm next to a base of 50 cm would be too small
        to edit; scroll out to see the whole robot)."""
        r = self.state.request
        layout = r.get("layout")
        if is_contour(r):  # a program: its reach until the plan places it (then the program: _show_contour)
            robot = self.robots.of_request(r, fallback=True)
            assert robot is not None
            lo, hi, _ = reachable_region(robot, 0.0)
            centre, half = 0.5 * (lo + hi), 0.6 * float(np.max(hi - lo))
        elif layout is not None and fit_layout:
            lo, hi = np.asarray(layout["bounds"]["lower"], float), np.asarray(layout["bounds"]["upper"], float)
            side = float(np.max(hi - lo))  # the bounds and, under them, the axis labels and the scale bar
            centre, half = 0.5 * (lo + hi) - np.array([0.0, 0.03 * side]), 0.6 * side
        elif layout is not None:
            lo, hi = layout["bounds"]["lower"], layout["bounds"]["upper"]
            centre, half = geo.view_extent(lo, hi, self.robots.of_request(r, fallback=True))
        else:
            segs = r.get("segments") or []
            pts = np.array([s["lower"][:2] for s in segs] + [s["upper"][:2] for s in segs] or [[0, 0]], float)
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            centre, half = 0.5 * (lo + hi), max(0.8 * float(np.max(hi - lo)), 0.05)
        self.scene.place_camera(centre, half, self.client)

    def _on_camera(self, camera) -> None:
        try:
            self.gui.cursor.set_camera(camera.position, camera.wxyz, camera.fov)
        except Exception:  # before the first camera message there is no camera state
            log.debug("no camera yet", exc_info=True)

    def stored_changed(self) -> None:
        """A corridor was saved: every tab's list of stored corridors is re-read."""
        self.editor.stored_changed()

    # ------------------------------------------------------------------ scene input
    def _plane_point(self, event) -> np.ndarray | None:
        origin, direction = np.asarray(event.ray_origin, float), np.asarray(event.ray_direction, float)
        if abs(direction[2]) < 1e-12:
            return None
        s = -origin[2] / direction[2]
        return (origin + s * direction)[:2] if s > 0 else None

    def _on_scene_click(self, event) -> None:
        """A click toggles the obstacle of the cell under it (layout), or picks the box
        under it (segment list)."""
        p = self._plane_point(event)
        if p is None:
            return
        if self.state.request.get("layout") is None:
            self.select_segment(self.segment_at(float(p[0]), float(p[1])))
        elif self.gui.click_mode.value == "toggle obstacle":
            self.toggle_cell_at(float(p[0]), float(p[1]))

    def _on_rect_select(self, event) -> None:
        """Shift + drag on the view adds the rectangle obstacle it spans (corners snapped)."""
        cam = event.client.camera
        aspect = cam.image_width / max(cam.image_height, 1)
        a = geo.screen_to_plane(event.screen_min, cam.position, cam.wxyz, cam.fov, aspect)
        b = geo.screen_to_plane(event.screen_max, cam.position, cam.wxyz, cam.fov, aspect)
        if a is None or b is None:
            return
        self.add_rectangle(self.snap_xy(*np.minimum(a, b)), self.snap_xy(*np.maximum(a, b)))

    # ------------------------------------------------------------------ planning
    def _run_plan(self, gen: int) -> None:
        """Plan generation ``gen`` (on the worker thread) and show it, unless a newer edit
        arrived meanwhile."""
        request = self.state.request
        shown = self.gui.result.plan
        self.gui.show_status(f"planning #{gen}…" + (f" (plots: plan #{shown})" if shown is not None else ""))
        outcome = compute_plan(request, self.robots)
        if not self.worker.is_current(gen) or self._closed:  # a newer edit arrived: drop this stale result
            self.state.discard_stale()
            return
        self.state.publish(gen, request, outcome.segmentation, outcome.result, outcome.error, outcome.request)
        self.show_downloads()
        robot = self.robots.of_request(request)
        seg, result, error = outcome.segmentation, outcome.result, outcome.error
        contour = is_contour(request)
        if contour:
            self._show_contour(request, result)
        self.scene.show_segmentation(seg if request.get("layout") is not None else None)
        grid = self.snap_grid()  # an automatic cell size is known now: the readout's grid follows
        self.gui.cursor.set_grid(grid[0] if grid else None, grid[1] if grid else (0.0, 0.0))
        if error is not None:
            self.scene.show_result(None)
            message = error.message
            self.gui.result.clear(f"**No plan**: plan #{gen} failed — {error_title(error)}: {message}. "
                                  "The plots stay empty until a plan succeeds.")
            self.gui.show_status(f"**plan #{gen} failed** ({error.code}) — {message}")
            self._show_plan_error(error)
            return
        assert result is not None  # a plan without an error has a result
        self._clear_error_note()
        self.gui.clear_plan_errors()
        self.scene.show_result(result)
        duration = float(result.time[-1])
        self.gui.show_time_range(duration, result.settings.Ts)
        if robot is not None:
            self.gui.result.show(result, robot, gen)
            self.gui.leg_legend.content = leg_legend_html(robot.n_legs, float(np.min(robot.force_max)))
        self.gui.result.header.content = (f"**Plan #{gen}** (the current design): planned in {outcome.seconds:.2f} s, "
                                          f"duration {result.metrics.duration_s:.2f} s")
        self.show_time(duration)
        c = result.contour
        if contour and c is not None:
            what = (f"{len(c.passes)} pass(es), deviation {c.max_deviation_m * 1e3:.4f} mm of the tolerance "
                    f"{c.tolerance_m * 1e3:g} mm, program zero at [{c.origin[0]:.4f}, {c.origin[1]:.4f}] m"
                    + (" (fit)" if request.get("origin") == "fit" else ""))
        elif seg:
            what = f"{len(seg.path)} cells in the corridor"
        else:
            what = f"{len(request.get('segments') or [])} boxes in the corridor"
        self.gui.show_status(f"plan #{gen} in {outcome.seconds:.2f} s — duration {result.metrics.duration_s:.2f} s, "
                             f"{what}")

    def _on_plan_crash(self, exc: Exception) -> None:
        self.notify("Internal error", f"{type(exc).__name__}: {exc}", color="red")

    # ------------------------------------------------------------------ lifetime
    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Wait up to ``timeout`` [s] until every edit made before this call is planned (no
        re-plan pending or running). An edit asks for its re-plan under the state lock, so
        taking the lock first waits for an edit that is half-way."""
        with self.state.lock:
            pass
        return self.worker.wait_idle(timeout)

    def close(self) -> None:
        """The tab went away: stop the playback and the worker (the scene and panel went
        with the client)."""
        if self._closed:
            return
        self._closed = True
        self.gui.playback.close()
        self.worker.stop()
