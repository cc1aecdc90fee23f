"""Browser corridor editor (viser): the :class:`Editor` that ties its parts together.

A person designs a corridor in the browser (top-down view of the workspace) and sees the
robot move through it. The editor's state *is* a plan request in the one JSON shape
(:class:`planner.schema.PlanRequest`, with a ``layout``); every edit changes that dict
(:mod:`._state`) and asks for a re-plan. Planning runs on a worker thread with a debounce
and a generation counter (:mod:`._planning`): GUI callbacks return at once, a stale result
never overwrites a newer one, and a slow plan never freezes the page. Errors (no path,
unreachable end, bad input) are shown as notifications naming the cause.

The parts: :mod:`._scene` (3-D scene, nodes kept and updated in place), :mod:`._gui`
(panel, playback), :mod:`._files` (store, JSON, CSV), :mod:`._geometry` (numpy only).
Units: m, rad, s, N.

Entry point: :func:`start_editor` (used by ``app.server.serve``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any, cast

import numpy as np
import viser

from . import _geometry as geo
from . import _state
from ._files import EditorFiles
from ._gui import EditorGui, error_body, error_title
from ._planning import PlanWorker, RobotCache, compute_plan
from ._scene import EditorScene

__all__ = ["DEBOUNCE_S", "Editor", "start_editor"]

log = logging.getLogger("rangeplan.editor")

DEBOUNCE_S = 0.3  #: quiet time after the last edit before a re-plan starts [s]


class Editor:
    """The editor: one shared design (all browser tabs see and edit the same request).

    ``store`` is an :class:`app.storage.Store` (or None: no saving); ``debounce`` [s] is
    the quiet time after an edit before a re-plan starts; ``request`` the initial design
    (default :data:`app.editor._state.DEFAULT_REQUEST`).
    """

    def __init__(self, host: str, port: int, store=None, *, debounce: float = DEBOUNCE_S,
                 request: dict | None = None, verbose: bool = False):
        self.state = _state.EditorState(request)
        self.robots = RobotCache()
        self.notifications: list[tuple[str, str]] = []  #: every notification sent (title, body)
        self._stopped = False
        self.server = viser.ViserServer(host=host, port=port, label="rangeplan editor", verbose=verbose)
        self.host, self.port = host, self.server.get_port()
        self.scene = EditorScene(self.server, on_click=self._on_scene_click, on_rect_select=self._on_rect_select,
                                 on_handle_moved=self.move_handle)
        self.files = EditorFiles(self, store)
        self.gui = EditorGui(self.server, self, has_store=store is not None)
        self.files.refresh_stored()
        self.place_cameras()
        self.gui.show_request(self.state.request)
        self._show_layout()
        self.worker = PlanWorker(self._run_plan, self._on_plan_crash, debounce)
        self.worker.start()
        self.server.on_client_connect(self._on_connect)
        self.worker.schedule(immediate=True)

    # ------------------------------------------------------------------ public API
    @property
    def url(self) -> str:
        """The page's address."""
        return f"http://{self.host}:{self.port}/"

    @property
    def store(self):
        """The corridor store (or None)."""
        return self.files.store

    @property
    def request(self) -> dict:
        """A copy of the current request (the one JSON shape)."""
        return self.state.request

    @property
    def plans_done(self) -> int:
        """Number of plan results published."""
        return self.state.plans_done

    @property
    def last_result(self) -> dict | None:
        """Newest published plan result."""
        return self.state.last_result

    @property
    def last_segmentation(self) -> dict | None:
        """Newest published segmentation (``Segmentation.to_dict()``)."""
        return self.state.last_segmentation

    @property
    def last_error(self) -> dict | None:
        """Newest error ``{code, message, field}``, or None after a successful plan."""
        return self.state.last_error

    @property
    def last_plan_generation(self) -> int:
        """Re-plan generation of the newest published result."""
        return self.state.last_plan_generation

    @property
    def stale_discarded(self) -> int:
        """Results dropped because a newer edit arrived while they were computed."""
        return self.state.stale_discarded

    def set_request(self, request: dict, *, replan: bool = True, immediate: bool = False) -> None:
        """Replace the whole request (import / load), update the GUI and re-plan."""
        self.state.replace(request)
        self.gui.show_request(self.state.request)
        self._show_layout()
        if replan:
            self.worker.schedule(immediate=immediate)

    def edit(self, fn: Callable[[dict], object], *, immediate: bool = False) -> None:
        """Apply ``fn(request_dict)`` (in place) under the lock, redraw the layout and
        schedule a debounced re-plan (when re-planning on every edit is on, or
        ``immediate``). Every GUI edit goes through here."""
        self.state.apply(fn)
        self._show_layout()
        if self.gui.auto_replan.value or immediate:
            self.worker.schedule(immediate=immediate)

    def plan_now(self) -> int:
        """Re-plan at once (the Plan button); returns the generation asked for."""
        return self.worker.schedule(immediate=True)

    def move_handle(self, which: str, x: float, y: float) -> None:
        """Move the start or end point to (x, y) [m] (what dragging its gizmo does)."""
        self.edit(lambda r: _state.move_point(r, which, x, y))
        layout = self.state.request.get("layout")
        if layout is not None:
            self.gui.show_point(which, layout[which])

    def toggle_cell_at(self, x: float, y: float) -> bool:
        """Toggle an obstacle on the cell under (x, y) [m]: add a polygon obstacle covering
        the cell's middle (blocks that cell only), or remove the one a previous toggle added.
        Returns False when no cell of the newest segmentation contains the point."""
        seg = self.state.last_segmentation
        if not seg:
            return False
        cell = next((c for c in seg["cells"] if geo.point_in_convex((x, y), c["polygon"])), None)
        if cell is None:
            return False
        polygon = np.asarray(cell["polygon"], dtype=float)
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
        """Switch the planner mode ("paper" | "constrained"); N, k_r and k_u at the old
        mode's defaults follow to the new mode's (:func:`app.editor._state.switch_mode`)."""
        self.edit(lambda r: _state.switch_mode(r, mode))
        self.gui.show_mode_settings(_state.mode_settings(self.state.request))

    def set_robot(self, name: str) -> None:
        """Plan for the built-in robot ``name``; the view follows its workspace."""
        self.edit(lambda r: r.__setitem__("robot", name))
        self.place_cameras()

    def new_layout(self) -> None:
        """Start over from the default layout (keeps robot and settings)."""
        self.set_request(_state.with_new_layout(self.state.request))

    def show_time(self, t: float) -> None:
        """Show the robot of the newest result at time ``t`` [s] (clamped to the plan)."""
        with self.state.lock:
            res, robot_spec = self.state.last_result, self.state.last_result_robot
        if res is None:
            return
        robot = self.robots.get(robot_spec)  # the robot it was planned for, even if changed since
        time_ = np.asarray(res["time"], float)
        pose = geo.sample_at(time_, np.asarray(res["pose"], float), t)
        k = int(np.clip(round(t / res["settings"]["Ts"]), 0, len(time_) - 1))
        self.scene.show_robot(robot, pose, np.asarray(res["drives"]["force"][k], float))

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Wait up to ``timeout`` [s] until no re-plan is pending or running."""
        return self.worker.wait_idle(timeout)

    def stop(self) -> None:
        """Stop the planner thread, the playback and the viser server."""
        if self._stopped:
            return
        self._stopped = True
        self.gui.playback.close()
        self.worker.stop()
        self.worker.join(timeout=5.0)
        self.server.stop()

    # ------------------------------------------------------------------ notifications, camera
    def notify(self, title: str, body: str, color: str = "red", client=None) -> None:
        """Show a notification to ``client``, or to every client (None); red ones stay."""
        self.notifications.append((title, body))
        clients = [client] if client is not None else list(self.server.get_clients().values())
        for c in clients:
            try:
                c.add_notification(title, body, color=cast(Any, color),
                                   auto_close_seconds=8.0 if color != "red" else None)
            except Exception:  # a client that went away must not break the editor
                log.debug("notification to a client failed", exc_info=True)

    def place_cameras(self) -> None:
        """Frame the workspace bounds and the robot's base in every client's view (and in
        the initial view of clients that connect later)."""
        self._place_camera(None)
        for client in self.server.get_clients().values():
            self._place_camera(client)

    def _place_camera(self, client) -> None:
        r = self.state.request
        layout = r.get("layout")
        if layout is not None:
            lo, hi = layout["bounds"]["lower"], layout["bounds"]["upper"]
        else:
            segs = r.get("segments") or []
            pts = np.array([s["lower"][:2] for s in segs] + [s["upper"][:2] for s in segs] or [[0, 0]])
            lo, hi = pts.min(axis=0), pts.max(axis=0)
        centre, half = geo.view_extent(lo, hi, self.robots.of_request(r, fallback=True))
        self.scene.place_camera(centre, half, client)

    def _on_connect(self, client) -> None:
        self._place_camera(client)
        error = self.state.last_error
        if error is not None:
            self.notify(error_title(error), error_body(error), client=client)

    # ------------------------------------------------------------------ scene input
    def _on_scene_click(self, event) -> None:
        """A click on the view toggles the obstacle of the cell under it (in that mode)."""
        if self.gui.click_mode.value != "toggle obstacle":
            return
        origin, direction = np.asarray(event.ray_origin, float), np.asarray(event.ray_direction, float)
        if abs(direction[2]) < 1e-12:
            return
        s = -origin[2] / direction[2]
        if s <= 0:
            return
        p = (origin + s * direction)[:2]
        self.toggle_cell_at(float(p[0]), float(p[1]))

    def _on_rect_select(self, event) -> None:
        """Shift + drag on the view adds the rectangle obstacle it spans."""
        cam = event.client.camera
        aspect = cam.image_width / max(cam.image_height, 1)
        a = geo.screen_to_plane(event.screen_min, cam.position, cam.wxyz, cam.fov, aspect)
        b = geo.screen_to_plane(event.screen_max, cam.position, cam.wxyz, cam.fov, aspect)
        if a is None or b is None:
            return
        self.add_rectangle(np.minimum(a, b), np.maximum(a, b))

    # ------------------------------------------------------------------ drawing, planning
    def _show_layout(self) -> None:
        """Redraw the layout (no planning); nothing when the request's robot is invalid."""
        r = self.state.request
        robot = self.robots.of_request(r)
        if robot is not None:
            self.scene.show_layout(r.get("layout"), robot)

    def _run_plan(self, gen: int) -> None:
        """Plan generation ``gen`` (on the worker thread) and show it, unless a newer edit
        arrived meanwhile."""
        request = self.state.request
        self.gui.show_status("planning…")
        outcome = compute_plan(request, self.robots)
        if not self.worker.is_current(gen):  # a newer edit arrived: drop this stale result
            self.state.discard_stale()
            return
        self.state.publish(gen, request, outcome.segmentation, outcome.result, outcome.error)
        robot = self.robots.of_request(request)
        seg, result, error = outcome.segmentation, outcome.result, outcome.error
        self.scene.show_segmentation(seg)
        if error is not None:
            self.scene.show_result(None)
            self.gui.show_result(None, robot)
            self.gui.show_status(f"**{error['code']}** — {error['message']}")
            self.notify(error_title(error), error_body(error))
            return
        assert result is not None  # a plan without an error has a result
        self.scene.show_result(result)
        if request.get("layout") is None:  # the corridor the planner used: the request's segments
            self.scene.show_corridor(result["corridor"].get("segments") or [])
        self.gui.show_result(result, robot)
        self.show_time(float(result["time"][-1]))
        m = result["metrics"]
        self.gui.show_status(f"planned in {outcome.seconds:.2f} s — duration {m['duration_s']:.2f} s, "
                             f"{len(seg['path']) if seg else 0} cells in the corridor")

    def _on_plan_crash(self, exc: Exception) -> None:
        self.notify("Internal error", f"{type(exc).__name__}: {exc}", color="red")


def start_editor(host: str, port: int, store=None, **kwargs) -> Editor:
    """Start the editor's viser server on ``host:port`` (own thread) and return its handle;
    ``handle.stop()`` shuts it down. ``store`` is an :class:`app.storage.Store` (or None:
    no saving); ``kwargs`` go to :class:`Editor`."""
    return Editor(host, port, store, **kwargs)
