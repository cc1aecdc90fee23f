"""The editor's control panel (viser GUI): widgets, their callbacks, the result panel and
the playback of the planned motion.

Widget callbacks return at once: each one turns the user's input into an edit of the
request (:mod:`app.editor._state`) through the editor, which schedules a debounced
re-plan. While the editor itself shows values in the widgets (:meth:`EditorGui.syncing`)
their callbacks do nothing, so showing a request never edits it.

Labels state units: m, rad, s, N.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from . import _state
from ._planning import (
    DEFAULT_ROBOT,
    HAS_SPEED_SETTING,
    MODE_DEFAULTS,
    Robot,
    builtin_robot_names,
)

if TYPE_CHECKING:
    from ._editor import Editor

__all__ = ["PLAY_FPS", "EditorGui", "Playback", "error_body", "error_title", "metrics_markdown"]

PLAY_FPS = 30.0  #: playback frame rate [1/s]
_PLOT_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")


class Playback:
    """Animates the robot along the trajectory: advances the ``time_slider`` [s] in real
    time at :data:`PLAY_FPS` (the slider's callback shows the robot at that time) and shows
    "Pause" on ``button`` while playing. ``can_play()`` says whether there is a plan."""

    def __init__(self, time_slider, button, can_play: Callable[[], bool]):
        self._time = time_slider
        self._button = button
        self._can_play = can_play
        self._playing = False
        self._closed = False
        self._thread: threading.Thread | None = None

    @property
    def playing(self) -> bool:
        """Whether the animation runs."""
        return self._playing

    def toggle(self) -> None:
        """Play (from the start when the slider is at the end), or pause while playing."""
        if self._playing:
            self._playing = False
            return
        if self._closed or not self._can_play():
            return
        self._playing = True
        self._button.label = "Pause"
        self._thread = threading.Thread(target=self._run, daemon=True, name="rangeplan-editor-play")
        self._thread.start()

    def close(self) -> None:
        """Stop for good (the editor stops)."""
        self._closed = True
        self._playing = False

    def _run(self) -> None:
        t_end = self._time.max
        t = 0.0 if self._time.value >= t_end - 1e-9 else self._time.value
        t0 = time.monotonic() - t
        try:
            while self._playing and not self._closed:
                t = time.monotonic() - t0
                if t >= t_end:
                    self._time.value = t_end
                    break
                self._time.value = round(t, 2)
                time.sleep(1.0 / PLAY_FPS)
        finally:
            self._playing = False
            if not self._closed:
                self._button.label = "Play"


class EditorGui:
    """The panel of one editor server: the widgets (public attributes, for the editor and
    tests) and their callbacks into ``editor``."""

    def __init__(self, server: viser.ViserServer, editor: Editor, *, has_store: bool):
        self._editor = editor
        self._syncing = False  # True while the editor shows values in the widgets
        gui = server.gui
        gui.configure_theme(control_width="large", dark_mode=False, show_logo=False, show_share_button=False)
        gui.add_markdown("**rangeplan corridor editor** — x right, y up, units m, rad, s, N")
        self.plan_button = gui.add_button("Plan", color="blue", hint="Re-plan now")
        self.plan_button.on_click(lambda _: None if editor.plan_now() else None)
        self.auto_replan = gui.add_checkbox("Re-plan on every edit", True)
        self.status = gui.add_markdown("Status: starting")
        self.time = gui.add_slider("Time (s)", min=0.0, max=1.0, step=0.01, initial_value=0.0)
        self.time.on_update(lambda _: editor.show_time(self.time.value))  # playback too: never gated
        self.play_button = gui.add_button("Play", hint="Animate the robot along the trajectory")
        self.playback = Playback(self.time, self.play_button, lambda: editor.last_result is not None)
        self.play_button.on_click(lambda _: self.playback.toggle())
        tabs = gui.add_tab_group()
        with tabs.add_tab("Edit"):
            self._build_edit_tab(gui)
        with tabs.add_tab("Settings"):
            self._build_settings_tab(gui)
        with tabs.add_tab("Result"):
            self.metrics = gui.add_markdown("No plan yet.")
            self.force_plot = gui.add_uplot((np.zeros(2), np.zeros(2)), ({"label": "t (s)"}, {"label": "F (N)"}),
                                            title="Drive forces (N) over time (s)", aspect=1.6)
            self.length_plot = gui.add_uplot((np.zeros(2), np.zeros(2)), ({"label": "t (s)"}, {"label": "l (m)"}),
                                             title="Leg lengths (m) over time (s)", aspect=1.6)
        with tabs.add_tab("Files"):
            self._build_files_tab(gui, has_store)

    # ------------------------------------------------------------------ building
    def _on_input(self, widget, action: Callable[[], Any]) -> None:
        """Run ``action()`` when the user changes ``widget`` (not while the editor syncs)."""
        widget.on_update(lambda _: None if self._syncing else action())

    def _edit_on_input(self, widget, edit: Callable[[dict, Any], Any]) -> None:
        """Apply ``edit(request, widget.value)`` when the user changes ``widget``."""
        self._on_input(widget, lambda: self._editor.edit(lambda r: edit(r, widget.value)))

    def _build_edit_tab(self, gui) -> None:
        editor = self._editor
        self.start = gui.add_vector3("Start x, y (m), ψ (rad)", (0.0, 0.0, 0.0), step=0.001)
        self.end = gui.add_vector3("End x, y (m), ψ (rad)", (0.0, 0.0, 0.0), step=0.001)
        self._edit_on_input(self.start, lambda r, v: _state.set_pose(r, "start", v))
        self._edit_on_input(self.end, lambda r, v: _state.set_pose(r, "end", v))
        self.click_mode = gui.add_dropdown("Click on a cell", ("toggle obstacle", "nothing"),
                                           initial_value="toggle obstacle",
                                           hint="Shift + drag on the view adds a rectangle obstacle")
        with gui.add_folder("Rectangle obstacle"):
            self.rect_lower = gui.add_vector2("Lower x, y (m)", (0.02, -0.10), step=0.005)
            self.rect_upper = gui.add_vector2("Upper x, y (m)", (0.04, -0.02), step=0.005)
            gui.add_button("Add rectangle").on_click(
                lambda _: editor.add_rectangle(self.rect_lower.value, self.rect_upper.value))
        gui.add_button("Remove last obstacle").on_click(lambda _: editor.edit(_state.remove_last_obstacle))
        gui.add_button("Clear obstacles").on_click(lambda _: editor.edit(_state.clear_obstacles))
        self.cell_shape = gui.add_dropdown("Cell shape", ("square", "triangle"), initial_value="square")
        self._edit_on_input(self.cell_shape, lambda r, v: _state.set_layout_field(r, ("cell", "shape"), v))
        self.cell_size = gui.add_number("Cell size (m), 0 = auto", 0.02, min=0.0, max=1.0, step=0.001)
        self._edit_on_input(self.cell_size,
                            lambda r, v: _state.set_layout_field(r, ("cell", "size"), float(v) or None))
        self.clearance = gui.add_number("Clearance (m)", 0.0, min=0.0, max=1.0, step=0.001)
        self._edit_on_input(self.clearance, lambda r, v: _state.set_layout_field(r, ("clearance",), float(v)))
        self.bounds_lower = gui.add_vector2("Bounds lower x, y (m)", (-0.16, -0.16), step=0.01)
        self.bounds_upper = gui.add_vector2("Bounds upper x, y (m)", (0.16, 0.16), step=0.01)
        self._edit_on_input(self.bounds_lower, lambda r, v: _state.set_layout_field(r, ("bounds", "lower"), list(v)))
        self._edit_on_input(self.bounds_upper, lambda r, v: _state.set_layout_field(r, ("bounds", "upper"), list(v)))
        gui.add_button("New layout (default)").on_click(lambda _: editor.new_layout())

    def _build_settings_tab(self, gui) -> None:
        editor = self._editor
        self.robot = gui.add_dropdown("Robot", tuple(builtin_robot_names()), initial_value=DEFAULT_ROBOT)
        self._on_input(self.robot, lambda: editor.set_robot(self.robot.value))
        self.mode = gui.add_dropdown("Mode", ("paper", "constrained"), initial_value="paper",
                                     hint="paper: soft range criterion; constrained: hard corridor and drive limits")
        self._on_input(self.mode, lambda: editor.set_mode(self.mode.value))
        self.Ts = gui.add_number("Sample time Ts (s)", 0.01, min=0.001, max=0.1, step=0.001)
        self._edit_on_input(self.Ts, lambda r, v: _state.set_setting(r, "Ts", float(v)))
        paper = MODE_DEFAULTS["paper"]
        self.N = gui.add_number("Horizon N (samples)", paper["N"], min=1, max=200, step=1)
        self._edit_on_input(self.N, lambda r, v: _state.set_setting(r, "N", int(v)))
        self.k_r = gui.add_number("k_r, range penalty (1/m)", paper["k_r"], min=1e-9, max=1e12, step=0.1)
        self._edit_on_input(self.k_r, lambda r, v: _state.set_setting(r, "k_r", float(v)))
        self.k_u = gui.add_number("k_u, force penalty (1/N)", paper["k_u"], min=1e-12, max=1e12, step=1e-5)
        self._edit_on_input(self.k_u, lambda r, v: _state.set_setting(r, "k_u", float(v)))
        self.speed = None
        if HAS_SPEED_SETTING:
            self.speed = gui.add_number("Speed (m/s)", 0.1, min=0.0, max=10.0, step=0.01)
            self._edit_on_input(self.speed, lambda r, v: _state.set_setting(r, "speed_m_s", float(v) or None))

    def _build_files_tab(self, gui, has_store: bool) -> None:
        editor = self._editor
        self.name = gui.add_text("Corridor name", "editor example")
        # the name does not change the plan: stored in the request, no re-plan
        self._on_input(self.name, lambda: editor.state.apply(lambda r: _state.set_name(r, self.name.value)))
        self.stored = None
        if has_store:
            gui.add_button("Save as new corridor").on_click(lambda e: editor.files.save(new=True, client=e.client))
            gui.add_button("Save (overwrite loaded)").on_click(
                lambda e: editor.files.save(new=False, client=e.client))
            self.stored = gui.add_dropdown("Stored corridors", ("(none)",))
            gui.add_button("Load selected").on_click(lambda e: editor.files.load(client=e.client))
            gui.add_button("Refresh list").on_click(lambda _: editor.files.refresh_stored())
        else:
            gui.add_markdown("No corridor store configured: saving is off.")
        upload = gui.add_upload_button("Import request JSON", mime_type="application/json")
        upload.on_upload(lambda e: editor.files.import_upload(upload.value, client=e.client))
        gui.add_button("Export request JSON").on_click(lambda e: editor.files.export_request(e.client))
        gui.add_button("Download trajectory CSV").on_click(lambda e: editor.files.download_csv(e.client))
        self._build_cad_files(gui)

    def _build_cad_files(self, gui) -> None:
        """Files tab: a DXF/SVG drawing as the layout's obstacles; G-code, joints, DXF downloads."""
        editor = self._editor
        with gui.add_folder("CAD drawing and machine files"):
            self.drawing_scale = gui.add_number("Drawing scale", 1.0, min=1e-6, max=1e6, step=0.01,
                                                hint="Applied after the drawing's units (mm unless it says)")
            self.drawing_offset = gui.add_vector2("Drawing offset x, y (m)", (0.0, 0.0), step=0.001)
            drawing = gui.add_upload_button("Import drawing (DXF/SVG)", hint="Closed shapes become obstacles")
            drawing.on_upload(lambda e: editor.files.import_drawing(
                drawing.value, {"scale": float(self.drawing_scale.value),
                                "offset": [float(v) for v in self.drawing_offset.value]}, client=e.client))
            for fmt, label in (("gcode", "Download G-code (LinuxCNC)"), ("joints", "Download leg lengths "
                               "(halstreamer)"), ("dxf", "Download DXF (path, corridor, obstacles)")):
                gui.add_button(label).on_click(lambda e, f=fmt: editor.files.download_export(e.client, f))

    # ------------------------------------------------------------------ showing values
    @contextlib.contextmanager
    def syncing(self) -> Iterator[None]:
        """Within this block (nestable), setting widget values does not edit the request."""
        outer = self._syncing
        self._syncing = True
        try:
            yield
        finally:
            self._syncing = outer

    def show_request(self, request: dict) -> None:
        """Show the request's values in the widgets."""
        settings = request.get("settings", {})
        layout = request.get("layout")
        with self.syncing():
            if layout is not None:
                self.start.value = tuple(float(v) for v in layout["start"])
                self.end.value = tuple(float(v) for v in layout["end"])
                cell = layout.get("cell") or {}
                self.cell_shape.value = cell.get("shape", "square")
                self.cell_size.value = float(cell.get("size") or 0.0)
                self.clearance.value = float(layout.get("clearance", 0.0))
                self.bounds_lower.value = tuple(layout["bounds"]["lower"])
                self.bounds_upper.value = tuple(layout["bounds"]["upper"])
            robot = request.get("robot", DEFAULT_ROBOT)
            if isinstance(robot, str) and robot in builtin_robot_names():
                self.robot.value = robot
            self.mode.value = settings.get("mode", "paper")
            self.Ts.value = float(settings.get("Ts", 0.01))
            self.show_mode_settings(_state.mode_settings(request))
            if self.speed is not None and settings.get("speed_m_s") is not None:
                self.speed.value = float(settings["speed_m_s"])
            self.name.value = request.get("name") or ""

    def show_mode_settings(self, values: dict) -> None:
        """Show N [samples], k_r [1/m] and k_u [1/N] of ``values``."""
        with self.syncing():
            self.N.value = int(values["N"])
            self.k_r.value = float(values["k_r"])
            self.k_u.value = float(values["k_u"])

    def show_point(self, which: str, pose) -> None:
        """Show the ``which`` ("start" | "end") pose [x, y, psi] (m, m, rad)."""
        with self.syncing():
            getattr(self, which).value = tuple(float(v) for v in pose)

    def show_status(self, text: str) -> None:
        """Set the status line (markdown)."""
        self.status.content = f"Status: {text}"

    def show_result(self, result: dict | None, robot: Robot | None) -> None:
        """The result's time range on the slider (at its end) [s], its plots and metrics;
        or "no plan" (None)."""
        if result is None:
            self.metrics.content = "No plan: see the status line."
            return
        t = np.asarray(result["time"], float)
        with self.syncing():
            self.time.max = float(t[-1])
            self.time.step = float(result["settings"]["Ts"]) if t[-1] > 0 else 0.01
            self.time.value = float(t[-1])
        if robot is not None:
            self._show_plots(result, robot)
        self.metrics.content = metrics_markdown(result)

    def _show_plots(self, result: dict, robot: Robot) -> None:
        t = np.asarray(result["time"], float)
        force = np.asarray(result["drives"]["force"], float)
        length = np.asarray(result["drives"]["length"], float)
        n = force.shape[1]
        f_max = float(robot.force_max.min())
        limit = {"stroke": "#888", "dash": [4, 4]}

        def series(symbol: str, unit: str, lower: str, upper: str) -> tuple:
            return ({"label": "t (s)"},
                    *({"label": f"{symbol}{i + 1} ({unit})", "stroke": _PLOT_COLOURS[i % 6], "width": 1.5}
                      for i in range(n)),
                    {"label": f"{lower} ({unit})", **limit}, {"label": f"{upper} ({unit})", **limit})

        self.force_plot.series = series("F", "N", "+limit", "-limit")
        self.force_plot.data = (t, *(force[:, i] for i in range(n)), np.full_like(t, f_max), np.full_like(t, -f_max))
        self.length_plot.series = series("l", "m", "min", "max")
        self.length_plot.data = (t, *(length[:, i] for i in range(n)),
                                 np.full_like(t, float(robot.length_min.max())),
                                 np.full_like(t, float(robot.length_max.min())))


# ---------------------------------------------------------------------------- texts
_ERROR_TITLES = {"no_path": "No path", "unreachable": "Unreachable", "invalid_input": "Invalid input",
                 "too_large": "Too large", "singular": "Singular pose", "not_settled": "Not settled",
                 "diverged": "Diverged"}


def error_title(error: dict) -> str:
    """Notification title of a planner error ``{code, message, field}``."""
    code = str(error.get("code") or "Error")
    return _ERROR_TITLES.get(code, code)


def error_body(error: dict) -> str:
    """Notification text of a planner error: its message and the field to fix."""
    field = f" (field {error['field']})" if error.get("field") else ""
    return f"{error.get('message', '')}{field}"


def metrics_markdown(result: dict) -> str:
    """The result's metrics as a markdown table, with the limits it violates."""
    m = result["metrics"]
    lines = [
        "| metric | value |", "|---|---|",
        f"| duration | {m['duration_s']:.3f} s |",
        f"| end error | {m['end_error_m']:.2e} m, {m['end_error_rad']:.2e} rad |",
        (f"| max drive force | {m['max_drive_force_n']:.1f} N of {m['force_limit_n']:.0f} N "
         f"({100 * m['max_force_ratio']:.0f} %) |"),
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
