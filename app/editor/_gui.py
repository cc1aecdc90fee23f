"""The control panel of one editing session (viser GUI, ``client.gui`` of one tab):
widgets, their callbacks, and the playback of the planned motion.

Widget callbacks return at once: each one turns the user's input into an edit of the
request (:mod:`app.editor._state`) through the session, which records it for undo and
schedules a debounced re-plan. Numbers are typed into text fields (:mod:`._fields`: the
sign, decimals and exponents are kept; a bad value is shown on its field). While the
session shows values in the widgets (``with syncing():``, per thread) their callbacks do
nothing, so showing a request never edits it.

Undo and redo: the buttons, and Ctrl+Z / Ctrl+Shift+Z (Cmd on a Mac), registered as
viser commands with hotkeys (the browser delivers them while the focus is not in a text
field; inside a field the browser's own text undo applies).

Labels state units: m, rad, s, N.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

from . import _state
from ._cursor import CursorReadout
from ._fields import Bounds, NumberField, VectorField, syncing
from ._gui_program import ProgramActions, ProgramPanel
from ._gui_segments import SegmentActions, SegmentsPanel
from ._planning import (
    DEFAULT_LAYOUT_SPEED_M_S,
    DEFAULT_MODE,
    DEFAULT_ROBOT,
    HAS_SPEED_SETTING,
    MACHINE_FORMATS,
    MODE_DEFAULTS,
    OUTPUT_FORMATS,
    auto_horizon,
    builtin_robot_names,
    field_bounds,
)
from ._result import ResultPanel, leg_legend_html

if TYPE_CHECKING:
    from ._planning import ErrorDetail, PlanResult
    from ._preview import Previewer
    from ._scene import EditorScene
    from ._state import EditorState

__all__ = ["PLAY_FPS", "EditorGui", "PanelActions", "Playback", "error_body", "error_title", "horizon_label"]

PLAY_FPS = 30.0  #: playback frame rate [1/s]
#: the tab group's content (viser puts it in a Mantine ScrollArea nested in the panel's own) scrolls
#: in a box of its own: the controls above the tabs (Plan, Undo, Redo, status, time) stay visible
PANEL_CSS = (".mantine-ScrollArea-root .mantine-ScrollArea-root{max-height:max(220px,calc(100vh - 620px))}"
             ".mantine-ScrollArea-root .mantine-ScrollArea-root>.mantine-ScrollArea-viewport"
             "{max-height:max(220px,calc(100vh - 620px));overscroll-behavior:contain}")
_XY, _XY_PSI = ("x", "y"), ("x", "y", "ψ")


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
        """Stop for good (the session ends)."""
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


def _bounds(model: str, field: str) -> Bounds:
    return Bounds(**field_bounds(model, field))


class PanelActions(SegmentActions, ProgramActions, Protocol):
    """What the panel's callbacks ask of their session (:class:`._session.Session`): its
    edits, undo, planning and playback, the files, the preview and the scene (the folders'
    own needs included). Declared here so that this module never imports the session (the
    session imports it and hands itself to :class:`EditorGui`)."""

    @property
    def state(self) -> EditorState: ...

    @property
    def scene(self) -> EditorScene: ...

    @property
    def preview(self) -> Previewer: ...

    @property
    def last_result(self) -> PlanResult | None: ...

    @property
    def last_error(self) -> ErrorDetail | None: ...

    def plan_now(self) -> int: ...

    def undo(self) -> bool: ...

    def redo(self) -> bool: ...

    def show_time(self, t: float) -> None: ...

    def grid_changed(self) -> None: ...

    def notify(self, title: str, body: str, color: str = "red", client=None) -> None: ...

    def add_rectangle(self, lower, upper) -> None: ...

    def set_robot(self, name: str) -> None: ...

    def set_mode(self, mode: str) -> None: ...


class EditorGui:
    """The panel of one session: the widgets (public attributes, for the session and
    tests) and their callbacks into ``session`` (any :class:`PanelActions`)."""

    def __init__(self, gui, session: PanelActions, *, has_store: bool):
        self._session = session
        gui.configure_theme(control_width="large", dark_mode=False, show_logo=False, show_share_button=False)
        gui.add_markdown("**rangeplan corridor editor** — x right, y up; m, rad, s, N")
        self.plan_button = gui.add_button("Plan", color="blue", hint="Re-plan now")
        self.plan_button.on_click(lambda _: None if session.plan_now() else None)
        self.undo_button = gui.add_button("Undo", disabled=True, hint="Ctrl+Z (not while typing in a field)")
        self.undo_button.on_click(lambda _: session.undo())
        self.redo_button = gui.add_button("Redo", disabled=True, hint="Ctrl+Shift+Z")
        self.redo_button.on_click(lambda _: session.redo())
        gui.add_command("Undo", description="Undo the last edit", hotkey="Z",
                        modifier="cmd/ctrl").on_trigger(lambda _: session.undo())
        gui.add_command("Redo", description="Redo the last undone edit", hotkey="Z",
                        modifier="cmd/ctrl+shift").on_trigger(lambda _: session.redo())
        self.auto_replan = gui.add_checkbox("Re-plan on every edit", True)
        self.status = gui.add_markdown("Status: starting")
        self.cursor = CursorReadout(gui)
        self.time = gui.add_slider("Time (s)", min=0.0, max=1.0, step=0.01, initial_value=0.0)
        self.time.on_update(lambda _: session.show_time(self.time.value))  # playback too: never gated
        self.play_button = gui.add_button("Play", hint="Animate the robot along the trajectory")
        self.playback = Playback(self.time, self.play_button,
                                 lambda: session.last_result is not None and session.last_error is None)
        self.play_button.on_click(lambda _: self.playback.toggle())
        self.robot_style = gui.add_dropdown("Robot drawn", ("solid", "outline", "hidden"), initial_value="solid",
                                            hint="outline: thin legs, no platform fill, so a narrow corridor under "
                                                 "the robot stays readable")
        self.robot_style.on_update(lambda _: session.scene.set_robot_style(self.robot_style.value))
        self.leg_legend = gui.add_html(leg_legend_html(4, None))
        # The tabs' content scrolls in its own box, so the controls above it (Plan, Undo, Redo,
        # status, time, Play) stay in view however long the Edit or Files tab is.
        gui.add_html(f"<style>{PANEL_CSS}</style>")
        tabs = gui.add_tab_group()
        with tabs.add_tab("Edit"):
            self._build_edit_tab(gui)
        with tabs.add_tab("Settings"):
            self._build_settings_tab(gui)
        with tabs.add_tab("Result"):
            self.result = ResultPanel(gui)
        with tabs.add_tab("Files"):
            self._build_files_tab(gui, has_store)
        #: error field paths of the request (as the planner names them) -> the field that edits it
        self.fields_by_path: dict[str, Any] = {
            "layout.start": self.start, "layout.end": self.end, "layout.cell.size": self.cell_size,
            "layout.cell": self.cell_size, "layout.clearance": self.clearance, "layout.psi_range": self.psi_range,
            "layout.bounds.lower": self.bounds_lower, "layout.bounds.upper": self.bounds_upper,
            "layout.bounds": self.bounds_upper, "settings.Ts": self.Ts, "settings.N": self.N,
            "settings.k_r": self.k_r, "settings.k_u": self.k_u,
        }
        if self.speed is not None:
            self.fields_by_path["settings.speed_m_s"] = self.speed
        self.fields_by_path.update({"origin": self.program.origin, "tolerance_m": self.program.tolerance})

    # ------------------------------------------------------------------ building
    def _on_input(self, widget, action: Callable[[], Any]) -> None:
        """Run ``action()`` when the user changes ``widget`` (not while the session syncs)."""
        widget.on_update(lambda _: None if syncing.active() else action())

    def _edit(self, key: str, edit: Callable[[dict, Any], Any]) -> Callable[[Any], None]:
        """A field callback: ``edit(request, value)`` as one undo step per field being typed."""
        def on_value(value) -> None:
            self._session.edit(lambda r: edit(r, value), key=f"field:{key}")
        return on_value

    def _build_edit_tab(self, gui) -> None:
        session = self._session
        self.layout_folder = gui.add_folder("Layout")
        with self.layout_folder:
            self.reach_note = gui.add_markdown("")
            self.start = VectorField(gui, "Start x, y (m), ψ (rad)", (0.0, 0.0, 0.0),
                                     self._edit("start", lambda r, v: _state.set_pose(r, "start", v)), names=_XY_PSI)
            self.end = VectorField(gui, "End x, y (m), ψ (rad)", (0.0, 0.0, 0.0),
                                   self._edit("end", lambda r, v: _state.set_pose(r, "end", v)), names=_XY_PSI)
            self.click_mode = gui.add_dropdown("Click on a cell", ("toggle obstacle", "nothing"),
                                               initial_value="toggle obstacle",
                                               hint="Shift + drag on the view adds a rectangle obstacle")
            with gui.add_folder("Rectangle obstacle", expand_by_default=False):
                self.rect_lower = VectorField(gui, "Lower x, y (m)", (0.02, -0.10), lambda v: None, names=_XY)
                self.rect_upper = VectorField(gui, "Upper x, y (m)", (0.04, -0.02), lambda v: None, names=_XY)
                gui.add_button("Add rectangle").on_click(lambda _: self._add_rectangle())
            gui.add_button("Remove last obstacle").on_click(
                lambda _: session.edit(_state.remove_last_obstacle, key=None))
            gui.add_button("Clear obstacles").on_click(lambda _: session.edit(_state.clear_obstacles, key=None))
            self.cell_shape = gui.add_dropdown("Cell shape", ("square", "triangle"), initial_value="square")
            self._on_input(self.cell_shape, lambda: session.edit(
                lambda r: _state.set_layout_field(r, ("cell", "shape"), self.cell_shape.value)))
            self.cell_size = NumberField(gui, "Cell size (m), empty = auto", 0.02, self._edit(
                "cell", lambda r, v: _state.set_layout_field(r, ("cell", "size"), v)),
                bounds=_bounds("Cell", "size"), optional=True)
            self.clearance = NumberField(gui, "Clearance (m)", 0.0,
                                         self._edit("clearance",
                                                    lambda r, v: _state.set_layout_field(r, ("clearance",), v)),
                                         bounds=_bounds("Layout", "clearance"))
            self.bounds_lower = VectorField(gui, "Bounds lower x, y (m)", (-0.16, -0.16), self._edit(
                "bounds_lower", lambda r, v: _state.set_layout_field(r, ("bounds", "lower"), list(v))), names=_XY)
            self.bounds_upper = VectorField(gui, "Bounds upper x, y (m)", (0.16, 0.16), self._edit(
                "bounds_upper", lambda r, v: _state.set_layout_field(r, ("bounds", "upper"), list(v))), names=_XY)
            self.psi_range = VectorField(gui, "ψ range min, max (rad), empty = start…end", None, self._edit(
                "psi_range", lambda r, v: _state.set_layout_field(r, ("psi_range",), v)), names=("min", "max"),
                optional=True)
            gui.add_button("New layout (default)").on_click(lambda _: session.new_layout())
        self.segments = SegmentsPanel(gui, session)
        with gui.add_folder("Snapping"):
            self.snap = gui.add_checkbox("Snap drags to the grid", True,
                                         hint="Dragged handles, box edges and drawn rectangles land on the grid")
            self._on_input(self.snap, session.grid_changed)
            self.grid = NumberField(gui, "Grid (m), empty = cell size", None, lambda v: session.grid_changed(),
                                    bounds=Bounds(gt=0.0), optional=True)

    def _add_rectangle(self) -> None:
        lo, hi = self.rect_lower.value, self.rect_upper.value
        if lo is None or hi is None:
            self._session.notify("Rectangle not added", "fix its corners first (see the fields)", color="yellow")
            return
        self._session.add_rectangle(lo, hi)

    def _build_settings_tab(self, gui) -> None:
        session = self._session
        self.robot = gui.add_dropdown("Robot", tuple(builtin_robot_names()), initial_value=DEFAULT_ROBOT)
        self._on_input(self.robot, lambda: session.set_robot(self.robot.value))
        self.mode = gui.add_dropdown("Mode", ("constrained", "paper"), initial_value=DEFAULT_MODE,
                                     hint="constrained: hard corridor and drive limits; paper: the seed's soft range "
                                     "criterion")
        self._on_input(self.mode, lambda: session.set_mode(self.mode.value))
        defaults = MODE_DEFAULTS[DEFAULT_MODE]

        def setting(key: str, label: str, value, **kw) -> NumberField:
            return NumberField(gui, label, value, self._edit(key, lambda r, v: _state.set_setting(r, key, v)),
                               bounds=_bounds("Settings", key), **kw)

        self.Ts = setting("Ts", "Sample time Ts (s)", 0.01)
        # empty (auto): the planner's default for the current Ts, robot and mode, shown in the label
        self.N = setting("N", horizon_label(auto_horizon(_state.DEFAULT_REQUEST)), None, integer=True, optional=True,
                         hint="Empty: the planner's default, which follows the sample time and the robot "
                         "(constrained mode); a typed value is sent as settings.N")
        self.k_r = setting("k_r", "k_r, range penalty (1/m)", defaults["k_r"])
        self.k_u = setting("k_u", "k_u, force penalty (1/N)", defaults["k_u"])
        speed_label = f"Speed (m/s), empty: {DEFAULT_LAYOUT_SPEED_M_S:g} on a layout"
        self.speed = setting("speed_m_s", speed_label, None, optional=True) if HAS_SPEED_SETTING else None

    def _build_files_tab(self, gui, has_store: bool) -> None:
        editor = self._session
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
        self.program = ProgramPanel(gui, editor)
        self._build_cad_files(gui)

    def _build_cad_files(self, gui) -> None:
        """Files tab: a DXF/SVG drawing as the layout's obstacles; G-code, joints, DXF downloads."""
        editor = self._session
        with gui.add_folder("CAD drawing and machine files"):
            self.drawing_scale = NumberField(gui, "Drawing scale", 1.0, lambda v: None, bounds=Bounds(gt=0.0),
                                             hint="Applied after the drawing's units (mm unless it says)")
            self.drawing_offset = VectorField(gui, "Drawing offset x, y (m)", (0.0, 0.0), lambda v: None, names=_XY)
            self.place_drawing = gui.add_checkbox(
                "Place drawing in the reachable region", True,
                hint="Fit the drawing (shrunk if it does not fit, never enlarged) into the square the robot reaches, "
                     "less the margin; start and end kept if free, else moved next to the drawing")
            self.place_margin = NumberField(gui, "Placement margin (m)", 0.03, lambda v: None,
                                            bounds=Bounds(ge=0.0, le=0.1))
            drawing = gui.add_upload_button("Import drawing (DXF/SVG)", hint="Closed shapes become obstacles")
            drawing.on_upload(lambda e: editor.files.import_drawing(
                drawing.value, {"scale": float(self.drawing_scale.value or 1.0),
                                "offset": [float(v) for v in (self.drawing_offset.value or (0.0, 0.0))]},
                client=e.client, place_margin=(float(self.place_margin.value if self.place_margin.value is not None
                                                      else 0.03) if self.place_drawing.value else None)))
        with gui.add_folder("Machine files (of the plan on screen)"):
            self.downloads_note = gui.add_markdown("Downloads: no plan yet")
            self.preview = gui.add_checkbox(
                "G-code preview", False, disabled=True,
                hint="Draw the program the G-code download gives, read back, over the plan (as LinuxCNC's AXIS "
                     "previews a program): feed moves in teal, rapids dashed red")
            self._on_input(self.preview, editor.preview.refresh)
            self.preview_note = gui.add_markdown("")
            self.download_buttons = {}
            for fmt in (*MACHINE_FORMATS, "csv"):
                title = OUTPUT_FORMATS[fmt].title or "trajectory CSV"
                button = gui.add_button(f"Download {title}", disabled=True)
                if fmt == "csv":
                    button.on_click(lambda e: editor.files.download_csv(e.client))
                else:
                    button.on_click(lambda e, f=fmt: editor.files.download_export(e.client, f))
                self.download_buttons[fmt] = button

    # ------------------------------------------------------------------ showing values
    def show_request(self, request: dict, selected_segment: int = 0) -> None:
        """Show the request's values in the widgets; the layout or the segments folder."""
        settings = request.get("settings", {})
        layout = request.get("layout")
        segments = request.get("segments") or []
        self.program.show(request)
        with syncing():
            self.layout_folder.visible = layout is not None
            self.segments.folder.visible = layout is None and bool(segments)
            self.click_mode.visible = layout is not None
            if layout is not None:
                self.start.show(layout["start"])
                self.end.show(layout["end"])
                cell = layout.get("cell") or {}
                self.cell_shape.value = cell.get("shape", "square")
                self.cell_size.show(cell.get("size"))
                self.clearance.show(float(layout.get("clearance", 0.0)))
                self.bounds_lower.show(layout["bounds"]["lower"])
                self.bounds_upper.show(layout["bounds"]["upper"])
                self.psi_range.show(layout.get("psi_range"))
            elif segments:
                self.segments.show(segments, selected_segment)
            robot = request.get("robot", DEFAULT_ROBOT)
            if isinstance(robot, str) and robot in builtin_robot_names():
                self.robot.value = robot
            self.mode.value = settings.get("mode", DEFAULT_MODE)
            self.Ts.show(float(settings.get("Ts", 0.01)))
            self.show_mode_settings(_state.mode_settings(request))
            self.show_auto_horizon(request)
            if self.speed is not None:
                self.speed.show(settings.get("speed_m_s"))
            self.name.value = request.get("name") or ""

    def show_mode_settings(self, values: dict) -> None:
        """Show N [samples] (None: empty, auto), k_r [1/m] and k_u [1/N] of ``values``."""
        self.N.show(None if values["N"] is None else int(values["N"]))
        self.k_r.show(float(values["k_r"]))
        self.k_u.show(float(values["k_u"]))

    def show_auto_horizon(self, request: dict) -> None:
        """Say in the N field's label which horizon the planner uses when the field is empty
        (it follows Ts, the robot and the mode)."""
        self.N.set_label(horizon_label(auto_horizon(request)))

    def show_point(self, which: str, pose) -> None:
        """Show the ``which`` ("start" | "end") pose [x, y, psi] (m, m, rad)."""
        getattr(self, which).show([float(v) for v in pose])

    def show_downloads(self, enabled: bool, reason: str) -> None:
        """Enable the machine-file downloads (G-code, leg lengths, DXF, CSV) or disable them,
        with the ``reason`` shown above them."""
        for button in self.download_buttons.values():
            if button.disabled == enabled:
                button.disabled = not enabled
        text = f"{'✅' if enabled else '⛔'} Downloads: {reason}"
        if self.downloads_note.content != text:
            self.downloads_note.content = text

    def show_preview(self, enabled: bool, text: str | None) -> None:
        """Enable the G-code preview toggle (a plan of the design on screen) or disable it;
        ``text`` (markdown, None: unchanged) under it: what the preview measured, or why none."""
        if self.preview.disabled == enabled:
            self.preview.disabled = not enabled
        if text is not None:
            content = f"G-code preview: {text}"
            if self.preview_note.content != content:
                self.preview_note.content = content

    def show_status(self, text: str) -> None:
        """Set the status line (markdown)."""
        self.status.content = f"Status: {text}"

    def show_history(self, can_undo: bool, can_redo: bool) -> None:
        """Enable the Undo / Redo buttons as there is something to undo / redo."""
        self.undo_button.disabled = not can_undo
        self.redo_button.disabled = not can_redo

    def show_field_error(self, path: str | None, message: str) -> bool:
        """Show a planner error on the field that edits ``path`` (the longest known prefix);
        returns whether there was one."""
        while path:
            field = self.fields_by_path.get(path)
            if field is not None:
                field.show_error(message, source="plan")
                return True
            path = path.rpartition(".")[0]
        return False

    def clear_plan_errors(self) -> None:
        """Remove the planner's errors from the fields (the newest plan worked)."""
        for field in {id(f): f for f in self.fields_by_path.values()}.values():
            field.clear_error(source="plan")

    def show_time_range(self, t_end: float, Ts: float) -> None:
        """The slider spans the plan [0, t_end] [s] in steps of ``Ts`` and sits at its end."""
        with syncing():
            self.time.max = float(t_end)
            self.time.step = float(Ts) if t_end > 0 else 0.01
            self.time.value = float(t_end)


# ---------------------------------------------------------------------------- texts
def horizon_label(auto: int | None) -> str:
    """The N field's label: what an empty field stands for (``auto``: the planner's default
    horizon [samples] for the current settings; None: not known, the settings are invalid)."""
    return f"Horizon N (samples), empty = auto ({auto})" if auto is not None else \
        "Horizon N (samples), empty = auto"


_ERROR_TITLES = {"no_path": "No path", "unreachable": "Unreachable", "invalid_input": "Invalid input",
                 "too_large": "Too large", "singular": "Singular pose", "not_settled": "Not settled",
                 "diverged": "Diverged"}


def error_title(error: ErrorDetail) -> str:
    """Notification title of a planner error."""
    code = error.code or "Error"
    return _ERROR_TITLES.get(code, code)


def error_body(error: ErrorDetail) -> str:
    """Notification text of a planner error: its message and the field to fix."""
    field = f" (field {error.field})" if error.field else ""
    return f"{error.message}{field}"
