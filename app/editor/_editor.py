"""Browser corridor editor (viser).

A person designs a corridor in the browser (top-down view of the workspace) and sees the
robot move through it. The editor's state *is* a plan request in the one JSON shape
(:class:`app.schema.PlanRequestModel`, with a ``layout``); every edit changes that dict and
asks for a re-plan. Planning runs on a worker thread with a debounce and a generation
counter: GUI callbacks return at once, a stale result never overwrites a newer one, and a
slow plan never freezes the page. Errors (no path, unreachable end, bad input) are shown as
notifications naming the cause.

Entry point: :func:`start_editor` (used by ``app.server.serve``).
"""

from __future__ import annotations

import copy
import json
import logging
import threading
import time
from typing import Any

import numpy as np
import viser
from pydantic import ValidationError


from ..schema import PlanRequestModel, format_validation_error, request_dict
from . import _geometry as geo
from ._planning import (
    HAS_SPEED_SETTING,
    MODE_DEFAULTS,
    SINGULAR_TOL,
    PlannerError,
    PlanWorker,
    RobotCache,
    builtin_robot_names,
    compute_plan,
    to_csv,
)

log = logging.getLogger("rangeplan.editor")

DEBOUNCE_S = 0.3  #: quiet time after the last edit before a re-plan starts [s]
TICK_EVERY_S = 0.1  #: spacing of the time ticks on the trajectory [s]
PLAY_FPS = 30.0  #: playback frame rate [1/s]

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
    "settings": {"mode": "paper", "Ts": 0.01, **MODE_DEFAULTS["paper"]},
}

class Editor:
    """The editor: one shared design (all browser tabs see and edit the same request)."""

    def __init__(self, host: str, port: int, store=None, *, debounce: float = DEBOUNCE_S,
                 request: dict | None = None, verbose: bool = False):
        self.store = store
        self._lock = threading.RLock()  # guards self._request and the result fields
        self._request = copy.deepcopy(request or DEFAULT_REQUEST)
        self._corridor_id: str | None = None
        self._syncing = False  # True while the editor itself sets GUI values
        self.plans_done = 0  #: number of plan results published
        self.last_result: dict | None = None  #: newest published plan result
        self.last_segmentation: dict | None = None  #: newest published segmentation (to_dict)
        self.last_error: dict | None = None  #: newest error ({code, message, field}) or None
        self.last_plan_generation = 0
        self.stale_discarded = 0  #: results dropped because a newer edit arrived
        self.notifications: list[tuple[str, str]] = []  #: every notification sent (title, body)
        self._robots = RobotCache()
        self._playing = False
        self._play_thread: threading.Thread | None = None
        self._stopped = False

        self.server = viser.ViserServer(host=host, port=port, label="rangeplan editor", verbose=verbose)
        self.host, self.port = host, self.server.get_port()
        self._setup_scene()
        self._build_gui()
        self._sync_gui_from_request()
        self._draw_layout()
        self.worker = PlanWorker(self._replan, self._on_plan_crash, debounce)
        self.worker.start()
        self.server.on_client_connect(self._on_connect)
        self.worker.schedule(immediate=True)

    # ------------------------------------------------------------------ public API
    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    @property
    def request(self) -> dict:
        """A copy of the current request (the one JSON shape)."""
        with self._lock:
            return copy.deepcopy(self._request)

    def set_request(self, request: dict, *, replan: bool = True, immediate: bool = False) -> None:
        """Replace the whole request (import / load), update the GUI and re-plan."""
        with self._lock:
            self._request = copy.deepcopy(request)
        self._sync_gui_from_request()
        self._draw_layout()
        if replan:
            self.worker.schedule(immediate=immediate)

    def edit(self, fn, *, immediate: bool = False) -> None:
        """Apply ``fn(request_dict)`` (in place) under the lock, redraw the layout and
        schedule a debounced re-plan. Every GUI edit goes through here."""
        with self._lock:
            fn(self._request)
        self._draw_layout()
        if self._auto.value or immediate:
            self.worker.schedule(immediate=immediate)

    def plan_now(self) -> int:
        """Re-plan at once (the Plan button); returns the generation asked for."""
        return self.worker.schedule(immediate=True)

    def move_handle(self, which: str, x: float, y: float) -> None:
        """Move the start or end point to (x, y) [m] (what dragging its handle does)."""
        def fn(r):
            lay = r.get("layout")
            if lay is not None:
                lay[which][0], lay[which][1] = float(x), float(y)
        self.edit(fn)
        self._syncing = True
        try:
            lay = self.request.get("layout")
            if lay is not None:
                getattr(self, f"_gui_{which}").value = tuple(float(v) for v in lay[which])
        finally:
            self._syncing = False

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Wait until no re-plan is pending or running (for tests and scripts)."""
        return self.worker.wait_idle(timeout)

    def stop(self) -> None:
        """Stop the planner thread, the playback and the viser server."""
        if self._stopped:
            return
        self._stopped = True
        self._playing = False
        self.worker.stop()
        self.worker.join(timeout=5.0)
        self.server.stop()

    # ------------------------------------------------------------------ notifications
    def _notify(self, title: str, body: str, color: str = "red", client=None) -> None:
        self.notifications.append((title, body))
        clients = [client] if client is not None else list(self.server.get_clients().values())
        for c in clients:
            try:
                c.add_notification(title, body, color=color, auto_close_seconds=8.0 if color != "red" else None)
            except Exception:  # a client that went away must not break the editor
                log.debug("notification to a client failed", exc_info=True)

    # ------------------------------------------------------------------ scene setup
    def _robot(self, spec):
        return self._robots.get(spec)

    def _setup_scene(self) -> None:
        scene = self.server.scene
        scene.set_up_direction("+z")
        scene.world_axes.visible = False
        self._place_camera()

        @scene.on_click()
        def _(event):  # noqa: ANN001
            self._on_scene_click(event)

        @scene.on_rect_select(modifier="shift")
        def _(event):  # noqa: ANN001
            self._on_rect_select(event)

    def _view(self):
        r = self.request
        lay = r.get("layout")
        try:
            robot = self._robot(r.get("robot", "moving-slide"))
        except PlannerError:
            robot = self._robot("moving-slide")
        if lay is not None:
            lo, hi = lay["bounds"]["lower"], lay["bounds"]["upper"]
        else:
            segs = r.get("segments") or []
            pts = np.array([s["lower"][:2] for s in segs] + [s["upper"][:2] for s in segs] or [[0, 0]])
            lo, hi = pts.min(axis=0), pts.max(axis=0)
        return geo.view_extent(lo, hi, robot)

    def _place_camera(self, client=None) -> None:
        centre, half = self._view()
        cam = self.server.initial_camera
        fov = cam.fov
        h = geo.camera_height(half, fov)
        cx = float(centre[0]) + 0.36 * half  # the control panel covers the right of the page
        pos = (cx, float(centre[1]), h)
        look = (cx, float(centre[1]), 0.0)
        if client is None:
            cam.position, cam.look_at, cam.up = pos, look, (0.0, 1.0, 0.0)
            cam.near, cam.far = 0.001, 100.0
        else:
            with client.atomic():
                client.camera.up_direction = (0.0, 1.0, 0.0)
                client.camera.position = pos
                client.camera.look_at = look

    def _on_connect(self, client) -> None:
        self._place_camera(client)
        if self.last_error is not None:
            e = self.last_error
            self._notify(_error_title(e), _error_body(e), client=client)

    # ------------------------------------------------------------------ GUI
    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.configure_theme(control_width="large", dark_mode=False, show_logo=False, show_share_button=False)
        gui.add_markdown("**rangeplan corridor editor** — x right, y up, units m, rad, s, N")
        self._plan_btn = gui.add_button("Plan", color="blue", hint="Re-plan now")
        self._plan_btn.on_click(lambda _: self.plan_now())
        self._auto = gui.add_checkbox("Re-plan on every edit", True)
        self._status = gui.add_markdown("Status: starting")
        self._time = gui.add_slider("Time (s)", min=0.0, max=1.0, step=0.01, initial_value=0.0)
        self._time.on_update(lambda _: self._draw_robot_at(self._time.value))
        self._play = gui.add_button("Play", hint="Animate the robot along the trajectory")
        self._play.on_click(lambda _: self._toggle_play())

        tabs = gui.add_tab_group()
        # --- edit tab
        with tabs.add_tab("Edit"):
            self._gui_start = gui.add_vector3("Start x, y (m), ψ (rad)", (0.0, 0.0, 0.0), step=0.001)
            self._gui_end = gui.add_vector3("End x, y (m), ψ (rad)", (0.0, 0.0, 0.0), step=0.001)
            self._gui_start.on_update(lambda e: self._on_pose_input("start", self._gui_start.value))
            self._gui_end.on_update(lambda e: self._on_pose_input("end", self._gui_end.value))
            self._click_mode = gui.add_dropdown("Click on a cell", ("toggle obstacle", "nothing"),
                                                initial_value="toggle obstacle",
                                                hint="Shift + drag on the view adds a rectangle obstacle")
            with gui.add_folder("Rectangle obstacle"):
                self._rect_lo = gui.add_vector2("Lower x, y (m)", (0.02, -0.10), step=0.005)
                self._rect_hi = gui.add_vector2("Upper x, y (m)", (0.04, -0.02), step=0.005)
                add = gui.add_button("Add rectangle")
                add.on_click(lambda _: self._add_rectangle(self._rect_lo.value, self._rect_hi.value))
            rm = gui.add_button("Remove last obstacle")
            rm.on_click(lambda _: self.edit(lambda r: r["layout"]["obstacles"].pop()
                                            if r.get("layout") and r["layout"]["obstacles"] else None))
            clr = gui.add_button("Clear obstacles")
            clr.on_click(lambda _: self.edit(lambda r: r["layout"]["obstacles"].clear() if r.get("layout") else None))
            self._cell_shape = gui.add_dropdown("Cell shape", ("square", "triangle"), initial_value="square")
            self._cell_shape.on_update(lambda _: self._on_layout_field(("cell", "shape"), self._cell_shape.value))
            self._cell_size = gui.add_number("Cell size (m), 0 = auto", 0.02, min=0.0, max=1.0, step=0.001)
            self._cell_size.on_update(lambda _: self._on_layout_field(
                ("cell", "size"), float(self._cell_size.value) or None))
            self._clearance = gui.add_number("Clearance (m)", 0.0, min=0.0, max=1.0, step=0.001)
            self._clearance.on_update(lambda _: self._on_layout_field(("clearance",), float(self._clearance.value)))
            self._bounds_lo = gui.add_vector2("Bounds lower x, y (m)", (-0.16, -0.16), step=0.01)
            self._bounds_hi = gui.add_vector2("Bounds upper x, y (m)", (0.16, 0.16), step=0.01)
            self._bounds_lo.on_update(lambda _: self._on_layout_field(("bounds", "lower"), list(self._bounds_lo.value)))
            self._bounds_hi.on_update(lambda _: self._on_layout_field(("bounds", "upper"), list(self._bounds_hi.value)))
            new = gui.add_button("New layout (default)")
            new.on_click(lambda _: self._new_layout())
        # --- settings tab
        with tabs.add_tab("Settings"):
            self._robot_dd = gui.add_dropdown("Robot", tuple(builtin_robot_names()), initial_value="moving-slide")
            self._robot_dd.on_update(lambda _: self._on_robot(self._robot_dd.value))
            self._mode = gui.add_dropdown("Mode", ("paper", "constrained"), initial_value="paper",
                                          hint="paper: soft range criterion; constrained: hard corridor and drive limits")
            self._mode.on_update(lambda _: self._on_mode(self._mode.value))
            self._Ts = gui.add_number("Sample time Ts (s)", 0.01, min=0.001, max=0.1, step=0.001)
            self._Ts.on_update(lambda _: self._on_setting("Ts", float(self._Ts.value)))
            paper = MODE_DEFAULTS["paper"]
            self._N = gui.add_number("Horizon N (samples)", paper["N"], min=1, max=200, step=1)
            self._N.on_update(lambda _: self._on_setting("N", int(self._N.value)))
            self._k_r = gui.add_number("k_r, range penalty (1/m)", paper["k_r"], min=1e-9, max=1e12, step=0.1)
            self._k_r.on_update(lambda _: self._on_setting("k_r", float(self._k_r.value)))
            self._k_u = gui.add_number("k_u, force penalty (1/N)", paper["k_u"], min=1e-12, max=1e12, step=1e-5)
            self._k_u.on_update(lambda _: self._on_setting("k_u", float(self._k_u.value)))
            if HAS_SPEED_SETTING:
                self._speed = gui.add_number("Speed (m/s)", 0.1, min=0.0, max=10.0, step=0.01)
                self._speed.on_update(lambda _: self._on_setting("speed_m_s", float(self._speed.value) or None))
            else:
                self._speed = None
        # --- result tab
        with tabs.add_tab("Result"):
            self._metrics = gui.add_markdown("No plan yet.")
            self._force_plot = gui.add_uplot((np.zeros(2), np.zeros(2)), ({"label": "t (s)"}, {"label": "F (N)"}),
                                             title="Drive forces (N) over time (s)", aspect=1.6)
            self._length_plot = gui.add_uplot((np.zeros(2), np.zeros(2)), ({"label": "t (s)"}, {"label": "l (m)"}),
                                              title="Leg lengths (m) over time (s)", aspect=1.6)
        # --- files tab
        with tabs.add_tab("Files"):
            self._name = gui.add_text("Corridor name", "editor example")
            self._name.on_update(lambda _: self._on_name())
            if self.store is not None:
                save_new = gui.add_button("Save as new corridor")
                save_new.on_click(lambda e: self._save(new=True, client=e.client))
                save = gui.add_button("Save (overwrite loaded)")
                save.on_click(lambda e: self._save(new=False, client=e.client))
                self._stored = gui.add_dropdown("Stored corridors", ("(none)",))
                load = gui.add_button("Load selected")
                load.on_click(lambda e: self._load(client=e.client))
                refresh = gui.add_button("Refresh list")
                refresh.on_click(lambda _: self._refresh_stored())
                self._refresh_stored()
            else:
                gui.add_markdown("No corridor store configured: saving is off.")
            up = gui.add_upload_button("Import request JSON", mime_type="application/json")
            up.on_upload(lambda e: self._import(up.value, client=e.client))
            exp = gui.add_button("Export request JSON")
            exp.on_click(lambda e: self._download(e.client, "corridor.json",
                                                  json.dumps(self.request, indent=2).encode()))
            csv_btn = gui.add_button("Download trajectory CSV")
            csv_btn.on_click(lambda e: self._download_csv(e.client))

    def _sync_gui_from_request(self) -> None:
        """Show the request's values in the GUI without triggering edits."""
        r = self.request
        self._syncing = True
        try:
            st = r.get("settings", {})
            lay = r.get("layout")
            if lay is not None:
                self._gui_start.value = tuple(float(v) for v in lay["start"])
                self._gui_end.value = tuple(float(v) for v in lay["end"])
                cell = lay.get("cell") or {}
                self._cell_shape.value = cell.get("shape", "square")
                self._cell_size.value = float(cell.get("size") or 0.0)
                self._clearance.value = float(lay.get("clearance", 0.0))
                self._bounds_lo.value = tuple(lay["bounds"]["lower"])
                self._bounds_hi.value = tuple(lay["bounds"]["upper"])
            if isinstance(r.get("robot", "moving-slide"), str) and r.get("robot", "moving-slide") in builtin_robot_names():
                self._robot_dd.value = r.get("robot", "moving-slide")
            self._mode.value = st.get("mode", "paper")
            self._Ts.value = float(st.get("Ts", 0.01))
            defaults = MODE_DEFAULTS.get(st.get("mode", "paper"), MODE_DEFAULTS["paper"])
            self._N.value = int(st.get("N", defaults["N"]))
            self._k_r.value = float(st.get("k_r", defaults["k_r"]))
            self._k_u.value = float(st.get("k_u", defaults["k_u"]))
            if self._speed is not None and st.get("speed_m_s") is not None:
                self._speed.value = float(st["speed_m_s"])
            self._name.value = r.get("name") or ""
        finally:
            self._syncing = False

    # ------------------------------------------------------------------ GUI callbacks (fast)
    def _on_pose_input(self, which: str, value) -> None:
        if self._syncing:
            return

        def fn(r):
            if r.get("layout") is not None:
                r["layout"][which] = [float(v) for v in value]
        self.edit(fn)

    def _on_layout_field(self, path: tuple, value) -> None:
        if self._syncing:
            return

        def fn(r):
            d = r.get("layout")
            if d is None:
                return
            for key in path[:-1]:
                d = d.setdefault(key, {})
            if value is None:
                d.pop(path[-1], None)
            else:
                d[path[-1]] = value
        self.edit(fn)

    def _on_setting(self, key: str, value) -> None:
        if self._syncing:
            return

        def fn(r):
            st = r.setdefault("settings", {})
            if value is None:
                st.pop(key, None)
            else:
                st[key] = value
        self.edit(fn)

    def _on_mode(self, mode: str) -> None:
        """Switch the mode; N, k_r and k_u still at the old mode's defaults follow to the new
        mode's defaults (planner.request.MODE_DEFAULTS), values the user changed stay."""
        if self._syncing:
            return
        widgets = {"N": (self._N, int), "k_r": (self._k_r, float), "k_u": (self._k_u, float)}

        def fn(r):
            st = r.setdefault("settings", {})
            old = MODE_DEFAULTS.get(st.get("mode", "paper"), MODE_DEFAULTS["paper"])
            st["mode"] = mode
            for key, value in MODE_DEFAULTS[mode].items():
                if st.get(key, old[key]) == old[key]:
                    st[key] = value

        self.edit(fn)
        st = self.request["settings"]
        self._syncing = True
        try:
            for key, (widget, cast) in widgets.items():
                widget.value = cast(st[key])
        finally:
            self._syncing = False

    def _on_robot(self, name: str) -> None:
        if self._syncing:
            return
        self.edit(lambda r: r.__setitem__("robot", name))
        self._place_camera()
        for c in self.server.get_clients().values():
            self._place_camera(c)

    def _on_name(self) -> None:
        if self._syncing:
            return
        with self._lock:
            self._request["name"] = self._name.value or None
            if self._request["name"] is None:
                self._request.pop("name")

    def _new_layout(self) -> None:
        req = self.request
        req["layout"] = copy.deepcopy(DEFAULT_REQUEST["layout"])
        req.pop("segments", None)
        req.pop("reference", None)
        self.set_request(req)

    def _add_rectangle(self, lo, hi) -> None:
        lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
        if np.any(hi - lo <= 0):
            self._notify("Rectangle not added", "the rectangle has zero width or height (m)", color="yellow")
            return
        ob = {"type": "rectangle", "lower": [float(lo[0]), float(lo[1])], "upper": [float(hi[0]), float(hi[1])]}
        self.edit(lambda r: r["layout"]["obstacles"].append(ob) if r.get("layout") else None)

    def _on_scene_click(self, event) -> None:
        if self._click_mode.value != "toggle obstacle":
            return
        o, d = np.asarray(event.ray_origin, float), np.asarray(event.ray_direction, float)
        if abs(d[2]) < 1e-12:
            return
        s = -o[2] / d[2]
        if s <= 0:
            return
        p = (o + s * d)[:2]
        self.toggle_cell_at(float(p[0]), float(p[1]))

    def toggle_cell_at(self, x: float, y: float) -> bool:
        """Toggle an obstacle on the cell under (x, y) [m]: add a polygon obstacle covering
        the cell's middle (blocks that cell only), or remove the one a previous toggle added.
        Returns False when no cell of the newest segmentation contains the point."""
        seg = self.last_segmentation
        if not seg:
            return False
        cell = next((c for c in seg["cells"] if geo.point_in_convex((x, y), c["polygon"])), None)
        if cell is None:
            return False
        poly = np.asarray(cell["polygon"], dtype=float)

        def fn(r):
            lay = r.get("layout")
            if lay is None:
                return
            obs = lay["obstacles"]
            for i, ob in enumerate(obs):  # a toggled obstacle: a polygon inside this cell
                if ob.get("type") == "polygon" and all(geo.point_in_convex(p, poly) for p in ob["points"]):
                    del obs[i]
                    return
            obs.append({"type": "polygon", "points": geo.shrink(poly, 0.8)})
        self.edit(fn)
        return True

    def _on_rect_select(self, event) -> None:
        cam = event.client.camera
        aspect = cam.image_width / max(cam.image_height, 1)
        a = geo.screen_to_plane(event.screen_min, cam.position, cam.wxyz, cam.fov, aspect)
        b = geo.screen_to_plane(event.screen_max, cam.position, cam.wxyz, cam.fov, aspect)
        if a is None or b is None:
            return
        self._add_rectangle(np.minimum(a, b), np.maximum(a, b))

    def _toggle_play(self) -> None:
        if self._playing:
            self._playing = False
            return
        if self.last_result is None:
            return
        self._playing = True
        self._play.label = "Pause"
        self._play_thread = threading.Thread(target=self._play_loop, daemon=True, name="rangeplan-editor-play")
        self._play_thread.start()

    def _play_loop(self) -> None:
        t_end = self._time.max
        t = 0.0 if self._time.value >= t_end - 1e-9 else self._time.value
        t0 = time.monotonic() - t
        try:
            while self._playing and not self._stopped:
                t = time.monotonic() - t0
                if t >= t_end:
                    self._time.value = t_end
                    break
                self._time.value = round(t, 2)
                time.sleep(1.0 / PLAY_FPS)
        finally:
            self._playing = False
            if not self._stopped:
                self._play.label = "Play"

    # ------------------------------------------------------------------ files
    def _refresh_stored(self) -> None:
        try:
            rows = self.store.list_corridors()
        except Exception as exc:
            self._notify("Could not list corridors", str(exc))
            return
        self._stored_ids = {f"{r.get('name') or '(unnamed)'} · {r['id'][:8]}": r["id"] for r in rows}
        self._stored.options = tuple(self._stored_ids) or ("(none)",)

    def _save(self, new: bool, client=None) -> None:
        req = self.request
        try:
            PlanRequestModel.model_validate(req)
            if new or self._corridor_id is None:
                rec = self.store.create_corridor(req, name=req.get("name"))
            else:
                rec = self.store.update_corridor(self._corridor_id, req, name=req.get("name"))
                if rec is None:
                    rec = self.store.create_corridor(req, name=req.get("name"))
        except ValidationError as exc:
            self._notify("Not saved", format_validation_error(exc), client=client)
            return
        except Exception as exc:
            self._notify("Not saved", f"{type(exc).__name__}: {exc}", client=client)
            return
        self._corridor_id = rec["id"]
        self._refresh_stored()
        self._notify("Saved", f"corridor '{rec.get('name') or ''}' id {rec['id']}", color="green", client=client)

    def _load(self, client=None) -> None:
        cid = getattr(self, "_stored_ids", {}).get(self._stored.value)
        if cid is None:
            self._notify("Nothing to load", "choose a stored corridor first", color="yellow", client=client)
            return
        rec = self.store.get_corridor(cid)
        if rec is None:
            self._notify("Not found", f"corridor {cid} no longer exists", client=client)
            self._refresh_stored()
            return
        self._corridor_id = cid
        self._load_request(rec["request"], client, f"corridor {cid}")

    def _import(self, upload, client=None) -> None:
        try:
            data = json.loads(upload.content.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            self._notify("Import failed", f"{upload.name}: not valid JSON ({exc})", client=client)
            return
        self._corridor_id = None
        self._load_request(data, client, upload.name)

    def _load_request(self, data, client, origin: str) -> None:
        try:
            model = PlanRequestModel.model_validate(data)
        except ValidationError as exc:
            self._notify("Import failed", f"{origin}: {format_validation_error(exc)}", client=client)
            return
        req = request_dict(model)
        if req.get("layout") is None:
            self._notify("No layout", f"{origin} has no layout (segments or a reference only): it is planned and "
                         "shown, but the layout tools do nothing until you start a new layout", color="yellow",
                         client=client)
        self.set_request(req, immediate=True)
        self._place_camera()
        for c in self.server.get_clients().values():
            self._place_camera(c)

    def _download(self, client, filename: str, content: bytes) -> None:
        if client is None:
            return
        client.send_file_download(filename, content, save_immediately=True)

    def _download_csv(self, client) -> None:
        res = self.last_result
        if res is None:
            self._notify("No trajectory", "plan a corridor first", color="yellow", client=client)
            return
        self._download(client, "trajectory.csv", to_csv(res).encode())

    # ------------------------------------------------------------------ planning (worker thread)
    def _replan(self, gen: int) -> None:
        request = self.request
        self._status.content = "Status: planning…"
        outcome = compute_plan(request, self._robots)
        seg, result, error, dt = outcome.segmentation, outcome.result, outcome.error, outcome.seconds
        if not self.worker.is_current(gen):  # a newer edit arrived: drop this stale result
            with self._lock:
                self.stale_discarded += 1
            return
        with self._lock:
            if seg is not None or error is None or request.get("layout") is None:
                self.last_segmentation = seg
            self.last_error = error
            if result is not None:
                self.last_result = result
                self.plans_done += 1
                self.last_plan_generation = gen
        self._draw_segmentation(seg if seg is not None else None, request)
        if error is not None:
            self._draw_result(None)
            self._status.content = f"Status: **{error['code']}** — {error['message']}"
            self._notify(_error_title(error), _error_body(error))
        else:
            self._draw_result(result)
            m = result["metrics"]
            self._status.content = (f"Status: planned in {dt:.2f} s — duration {m['duration_s']:.2f} s, "
                                    f"{len(seg['path']) if seg else 0} cells in the corridor")

    def _on_plan_crash(self, exc: Exception) -> None:
        self._notify("Internal error", f"{type(exc).__name__}: {exc}", color="red")

    # ------------------------------------------------------------------ drawing
    def _draw_layout(self) -> None:
        """Bounds, obstacles, start/end handles and the reachable boundary (no planning)."""
        r = self.request
        scene = self.server.scene
        lay = r.get("layout")
        try:
            robot = self._robot(r.get("robot", "moving-slide"))
        except PlannerError:
            return
        if lay is None:
            for name in ("/layout/bounds", "/layout/obstacles", "/layout/obstacle_edges", "/layout/reachable",
                         "/handles/start", "/handles/end"):
                scene.remove_by_name(name)
            self._handle_start = self._handle_end = None
            return
        lo, hi = lay["bounds"]["lower"], lay["bounds"]["upper"]
        scene.add_line_segments("/layout/bounds", geo.polygon_edges([geo.rectangle(lo, hi)], geo.Z["grid"]),
                                colors=(30, 30, 30), thickness=2.0, thickness_units="screen")
        polys = [geo.obstacle_polygon(ob) for ob in lay.get("obstacles", [])]
        verts, faces = geo.polygon_mesh(polys, geo.Z["obstacles"])
        if len(faces):
            scene.add_mesh_simple("/layout/obstacles", verts, faces, color=(60, 60, 60), opacity=0.85,
                                  flat_shading=True, side="double")
            scene.add_line_segments("/layout/obstacle_edges", geo.polygon_edges(polys, geo.Z["obstacles"]),
                                    colors=(0, 0, 0), thickness=1.5, thickness_units="screen")
        else:
            scene.add_line_segments("/layout/obstacles", np.zeros((1, 2, 3)), colors=(0, 0, 0), thickness=0.0, thickness_units="screen")
            scene.add_line_segments("/layout/obstacle_edges", np.zeros((1, 2, 3)), colors=(0, 0, 0), thickness=0.0, thickness_units="screen")
        # reachable workspace boundary at the start (and end) angle
        span = np.asarray(hi, float) - np.asarray(lo, float)
        margin = 0.05 * span
        segs, colours = [], []
        for psi, col in ((lay["start"][2], (200, 30, 30)), (lay["end"][2], (200, 100, 0))):
            if segs and abs(psi - lay["start"][2]) < 1e-9:
                continue
            xs, ys, mask = geo.reachable_mask(robot, np.asarray(lo) - margin, np.asarray(hi) + margin, psi, n=120,
                                                singular_tol=SINGULAR_TOL)
            b = geo.mask_boundary(xs, ys, mask, geo.Z["reach"])
            segs.append(b)
            colours.append(np.tile(np.array(col, np.uint8), (len(b), 2, 1)))
        b = np.concatenate(segs)
        if len(b):
            scene.add_line_segments("/layout/reachable", b, colors=np.concatenate(colours), thickness=2.0, thickness_units="screen")
        # start and end: markers, labels and planar transform handles
        size = 0.12 * float(max(span))
        limits = ((lo[0], hi[0]), (lo[1], hi[1]), (0.0, 0.0))
        for which, col in (("start", (0, 150, 0)), ("end", (200, 0, 150))):
            p = lay[which]
            pos = (float(p[0]), float(p[1]), geo.Z["handles"])
            h = getattr(self, f"_handle_{which}", None)
            if h is None:
                h = scene.add_transform_controls(f"/handles/{which}", scale=size, active_axes=(True, True, False),
                                                 disable_rotations=True, depth_test=False, position=pos,
                                                 translation_limits=limits)
                h.on_update(self._make_handle_cb(which))
                setattr(self, f"_handle_{which}", h)
                scene.add_icosphere(f"/handles/{which}/dot", radius=0.01 * float(max(span)), color=col)
                scene.add_label(f"/handles/{which}/label", f"{which} (ψ {p[2]:.2f} rad)")
            else:
                if not self._dragging(which):
                    h.position = pos
                scene.add_label(f"/handles/{which}/label", f"{which} (ψ {p[2]:.2f} rad)")

    def _dragging(self, which: str) -> bool:
        return getattr(self, f"_drag_{which}", False)

    def _make_handle_cb(self, which: str):
        def cb(event) -> None:
            phase = getattr(event, "phase", "update")
            setattr(self, f"_drag_{which}", phase in ("start", "update"))
            pos = event.target.position
            self.move_handle(which, float(pos[0]), float(pos[1]))
        return cb

    def _draw_segmentation(self, seg: dict | None, request: dict) -> None:
        scene = self.server.scene
        if seg is None:
            for name in ("cells_free", "cells_blocked", "cells_unreachable"):
                scene.add_mesh_simple(f"/seg/{name}", np.zeros((3, 3)), np.array([[0, 1, 2]], np.int32),
                                      color=(255, 255, 255), opacity=0.0)
            scene.add_line_segments("/seg/grid", np.zeros((1, 2, 3)), colors=(0, 0, 0), thickness=0.0, thickness_units="screen")
            scene.add_line_segments("/seg/corridor", np.zeros((1, 2, 3)), colors=(0, 0, 0), thickness=0.0, thickness_units="screen")
            return
        cells = seg["cells"]
        for state, col in geo.CELL_COLOURS.items():
            polys = [c["polygon"] for c in cells if c["state"] == state]
            v, f = geo.polygon_mesh(polys, geo.Z["cells"])
            if not len(f):
                v, f = np.zeros((3, 3)), np.array([[0, 1, 2]], np.int32)
            scene.add_mesh_simple(f"/seg/cells_{state}", v, f, color=col, opacity=1.0 if len(polys) else 0.0,
                                  flat_shading=True, side="double")
        scene.add_line_segments("/seg/grid", geo.polygon_edges([c["polygon"] for c in cells], geo.Z["grid"]),
                                colors=(170, 170, 170), thickness=0.5, thickness_units="screen")
        by_id = {c["id"]: c for c in cells}
        path_polys = [by_id[i]["polygon"] for i in seg.get("path", []) if i in by_id]
        v, f = geo.polygon_mesh(path_polys, geo.Z["corridor"])
        if len(f):
            scene.add_mesh_simple("/seg/corridor_fill", v, f, color=(150, 220, 150), opacity=0.8,
                                  flat_shading=True, side="double")
        boxes = [geo.rectangle(s["lower"][:2], s["upper"][:2]) for s in seg.get("segments", [])]
        e = geo.polygon_edges(boxes, geo.Z["corridor"])
        scene.add_line_segments("/seg/corridor", e if len(e) else np.zeros((1, 2, 3)),
                                colors=(0, 120, 0), thickness=1.5, thickness_units="screen")

    def _draw_result(self, result: dict | None) -> None:
        scene = self.server.scene
        if result is None:
            scene.add_line_segments("/result/trajectory", np.zeros((1, 2, 3)), colors=(0, 0, 0), thickness=0.0, thickness_units="screen")
            scene.add_point_cloud("/result/ticks", np.zeros((1, 3)), colors=(0, 0, 0), point_size=0.0)
            self._metrics.content = "No plan: see the status line."
            self._draw_robot(None)
            return
        t = np.asarray(result["time"])
        pose = np.asarray(result["pose"])
        pts = np.column_stack((pose[:, :2], np.full(len(pose), geo.Z["trajectory"])))
        scene.add_line_segments("/result/trajectory", np.stack((pts[:-1], pts[1:]), axis=1),
                                colors=(20, 60, 220), thickness=3.0, thickness_units="screen")
        ticks = geo.time_ticks(t, pose, TICK_EVERY_S)
        scene.add_point_cloud("/result/ticks", np.column_stack((ticks, np.full(len(ticks), geo.Z["ticks"]))),
                              colors=(255, 140, 0), point_size=0.0035, point_shape="circle")
        # corridor the planner used (the request's segments when there is no layout)
        if result["corridor"].get("segments") and self.request.get("layout") is None:
            boxes = [geo.rectangle(s["lower"][:2], s["upper"][:2]) for s in result["corridor"]["segments"]]
            scene.add_line_segments("/seg/corridor", geo.polygon_edges(boxes, geo.Z["corridor"]),
                                    colors=(0, 120, 0), thickness=1.5, thickness_units="screen")
        # time slider and plots
        self._syncing = True
        try:
            self._time.max = float(t[-1])
            self._time.step = float(result["settings"]["Ts"]) if t[-1] > 0 else 0.01
            self._time.value = float(t[-1])
        finally:
            self._syncing = False
        self._draw_robot_at(float(t[-1]))
        self._draw_plots(result)
        self._metrics.content = _metrics_markdown(result, self._robot(self.request.get("robot", "moving-slide")))

    def _draw_plots(self, result: dict) -> None:
        t = np.asarray(result["time"], float)
        F = np.asarray(result["drives"]["force"], float)
        L = np.asarray(result["drives"]["length"], float)
        robot = self._robot(self.request.get("robot", "moving-slide"))
        n = F.shape[1]
        colours = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"]
        fmax = float(robot.force_max.min())
        self._force_plot.series = ({"label": "t (s)"},
                                   *({"label": f"F{i + 1} (N)", "stroke": colours[i % 6], "width": 1.5} for i in range(n)),
                                   {"label": "+limit (N)", "stroke": "#888", "dash": [4, 4]},
                                   {"label": "-limit (N)", "stroke": "#888", "dash": [4, 4]})
        self._force_plot.data = (t, *(F[:, i] for i in range(n)), np.full_like(t, fmax), np.full_like(t, -fmax))
        self._length_plot.series = ({"label": "t (s)"},
                                    *({"label": f"l{i + 1} (m)", "stroke": colours[i % 6], "width": 1.5} for i in range(n)),
                                    {"label": "min (m)", "stroke": "#888", "dash": [4, 4]},
                                    {"label": "max (m)", "stroke": "#888", "dash": [4, 4]})
        self._length_plot.data = (t, *(L[:, i] for i in range(n)), np.full_like(t, float(robot.length_min.max())),
                                  np.full_like(t, float(robot.length_max.min())))

    def _draw_robot_at(self, t: float) -> None:
        res = self.last_result
        if res is None:
            return
        time_ = np.asarray(res["time"], float)
        pose = geo.sample_at(time_, np.asarray(res["pose"], float), t)
        k = int(np.clip(round(t / res["settings"]["Ts"]), 0, len(time_) - 1))
        force = np.asarray(res["drives"]["force"][k], float)
        self._draw_robot(pose, force)

    def _draw_robot(self, pose, force=None) -> None:
        scene = self.server.scene
        if pose is None:
            scene.add_line_segments("/robot/legs", np.zeros((1, 2, 3)), colors=(0, 0, 0), thickness=0.0, thickness_units="screen")
            return
        try:
            robot = self._robot(self.request.get("robot", "moving-slide"))
        except PlannerError:
            return
        g = geo.robot_geometry(robot, pose)
        z = geo.Z["robot"]
        base = np.column_stack((g["base"], np.full(robot.n_legs, z)))
        piv = np.column_stack((g["pivots"], np.full(robot.n_legs, z)))
        ratio = np.zeros(robot.n_legs) if force is None else np.clip(np.abs(force) / robot.force_max, 0, 1)
        leg_col = np.stack([np.array([60 + 195 * r, 60, 200 - 160 * r]) for r in ratio]).astype(np.uint8)
        scene.add_line_segments("/robot/legs", np.stack((base, piv), axis=1),
                                colors=np.repeat(leg_col[:, None, :], 2, axis=1), thickness=5.0, thickness_units="screen")
        v, f = geo.polygon_mesh([g["pivots"]], z)
        scene.add_mesh_simple("/robot/platform", v, f, color=(120, 120, 220), opacity=0.15, side="double")
        scene.add_line_segments("/robot/platform_edge", geo.polygon_edges([g["pivots"]], z),
                                colors=(40, 40, 160), thickness=2.0, thickness_units="screen")
        scene.add_point_cloud("/robot/pivots", np.vstack((base, piv)), colors=(20, 20, 20),
                              point_size=0.008, point_shape="circle")
        scene.add_point_cloud("/robot/tool", np.array([[pose[0], pose[1], z]]), colors=(220, 0, 0),
                              point_size=0.01, point_shape="diamond")


def _error_title(e: dict) -> str:
    return {"no_path": "No path", "unreachable": "Unreachable", "invalid_input": "Invalid input",
            "too_large": "Too large", "singular": "Singular pose", "not_settled": "Not settled",
            "diverged": "Diverged"}.get(e.get("code"), str(e.get("code") or "Error"))


def _error_body(e: dict) -> str:
    field = f" (field {e['field']})" if e.get("field") else ""
    return f"{e.get('message', '')}{field}"


def _metrics_markdown(result: dict, robot) -> str:
    m = result["metrics"]
    lines = [
        "| metric | value |", "|---|---|",
        f"| duration | {m['duration_s']:.3f} s |",
        f"| end error | {m['end_error_m']:.2e} m, {m['end_error_rad']:.2e} rad |",
        f"| max drive force | {m['max_drive_force_n']:.1f} N of {m['force_limit_n']:.0f} N "
        f"({100 * m['max_force_ratio']:.0f} %) |",
        f"| max drive speed | {m['max_drive_speed_m_s']:.3f} m/s ({100 * m['max_speed_ratio']:.0f} % of limit) |",
        f"| corridor violation | {m['max_corridor_violation_m']:.2e} m |",
        f"| time-indexed range violation | {m['time_indexed_violation_m']:.2e} m |",
        f"| stroke violation | {m['max_stroke_violation_m']:.2e} m |",
        f"| overshoot | {m['overshoot_m']:.2e} m |",
        f"| path length | {m['path_length_m']:.3f} m |",
        f"| mode, compute | {result.get('mode', 'paper')}, {m['compute_ms']:.0f} ms |",
    ]
    warn = []
    if m["max_force_ratio"] > 1:
        warn.append("drive force above the limit")
    if m["max_corridor_violation_m"] > 1e-3:
        warn.append("leaves the corridor by more than 1 mm")
    if m["max_stroke_violation_m"] > 0:
        warn.append("a leg leaves its stroke")
    if warn:
        lines.append("\n**Violations:** " + "; ".join(warn))
    else:
        lines.append("\nNo violations (forces within limits, corridor kept within 1 mm).")
    return "\n".join(lines)


def start_editor(host: str, port: int, store=None, **kwargs) -> Editor:
    """Start the editor's viser server on ``host:port`` (own thread) and return its handle;
    ``handle.stop()`` shuts it down. ``store`` is an :class:`app.storage.Store` (or None:
    no saving)."""
    return Editor(host, port, store, **kwargs)
