"""The G-code preview, as LinuxCNC's AXIS previews a program: the program the G-code
download gives (the same function, header and plan) read back by the G-code reader
(:func:`planner.exchange.read_gcode` with ``readback=True``: G93 inverse time, the C axis)
and drawn over the planned trajectory, feed moves as a line, rapids dashed.

What the panel says is measured on the read-back program, not assumed: its line count, its
duration (the G93 times of its moves and its dwells) and how far its path is from the
planned trajectory (every program point from the trajectory and every planned sample from
the program's path, and the read-back pose at each sample time against the plan's).

The preview exists only for the plan of the design on screen (:meth:`EditorFiles.machine_files`,
the downloads' rule): an edit, a pending re-plan or a failed plan hides it and disables the
toggle with the reason. It is computed off the GUI's threads (a thread per new plan) and
shown only if the plan is still the current one when it is done.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from app.formats import GCODE_FORMAT

from . import _geometry as geo
from ._files import EditorFiles, MachineFiles, request_hash
from ._planning import PlannerError, export_result, read_gcode, toolpath

__all__ = ["GcodePreview", "PreviewHost", "PreviewPanel", "PreviewScene", "Previewer", "build_preview"]

log = logging.getLogger("rangeplan.editor")


@dataclass(frozen=True)
class GcodePreview:
    """The read-back program of one plan: ``points`` (n, 2) [m] of its path in order and
    ``rapid`` (n - 1,) whether each piece is a rapid; ``lines`` of text, ``duration_s`` [s]
    of its feed moves and dwells; ``path_deviation_m``: the largest distance of a program
    point from the planned trajectory or of a planned sample from the program's path [m];
    ``time_deviation_m`` / ``psi_deviation_rad``: the largest difference of the read-back
    tool point / angle at a sample time from the plan's sample [m, rad]."""

    key: tuple[int, str]
    points: np.ndarray
    rapid: np.ndarray
    lines: int
    duration_s: float
    plan_duration_s: float
    path_deviation_m: float
    time_deviation_m: float
    psi_deviation_rad: float
    text: str = ""  #: the program as the G-code download writes it


    def segments(self, rapid: bool) -> np.ndarray:
        """The feed (``rapid`` False) or rapid pieces of the path, (M, 2, 2) [m], without
        pieces of length 0 (a dwell, a move of the angle alone)."""
        a, b = self.points[:-1], self.points[1:]
        keep = (self.rapid == rapid) & np.any(a != b, axis=1)
        return np.stack((a[keep], b[keep]), axis=1)

    def summary(self) -> str:
        """One line for the panel (mm, µm, s, degrees)."""
        return (f"{self.lines} lines, duration {self.duration_s:.3f} s read back (plan {self.plan_duration_s:.3f} s); "
                f"path within {self.path_deviation_m * 1e6:.2f} µm of the planned trajectory, at the sample times "
                f"{self.time_deviation_m * 1e6:.2f} µm and ψ {np.degrees(self.psi_deviation_rad):.5f}°")


def build_preview(files: MachineFiles) -> GcodePreview:
    """The preview of the plan ``files`` offers (its result must be set): the G-code exactly
    as the download writes it, read back and measured against the plan."""
    assert files.result is not None and files.request is not None
    text = export_result(files.result, GCODE_FORMAT, files.model or files.request, files.header())
    path = toolpath(read_gcode(text, readback=True))
    res = files.result
    pose = np.asarray(res.pose, float)
    t = np.asarray(res.time, float) - float(res.time[0])
    fed = slice(1, None) if path.rapid.size and path.rapid[0] else slice(None)  # after the rapid to the start
    at = np.column_stack([np.interp(t, path.time[fed], v[fed]) for v in (*path.points.T, path.psi)])
    return GcodePreview(
        key=(files.plan, request_hash(files.request)), points=path.points, rapid=path.rapid,
        lines=len(text.splitlines()), duration_s=path.duration_s, plan_duration_s=float(t[-1]),
        path_deviation_m=geo.polyline_distance(path.points[fed], pose[:, :2]),
        time_deviation_m=float(np.max(np.hypot(*(at[:, :2] - pose[:, :2]).T))),
        psi_deviation_rad=float(np.max(np.abs(at[:, 2] - pose[:, 2]))), text=text)


class PreviewPanel(Protocol):
    """What the preview uses of the session's panel (:class:`._gui.EditorGui`): the toggle
    (its ``value``) and the line under it."""

    @property
    def preview(self) -> Any: ...

    def show_preview(self, enabled: bool, text: str | None) -> None: ...


class PreviewScene(Protocol):
    """Where the preview is drawn (:class:`._scene.EditorScene`)."""

    def show_preview(self, preview: GcodePreview | None) -> None: ...


class PreviewHost(Protocol):
    """What the preview takes from its session (:class:`._session.Session`): the files (which
    plan may be downloaded), the panel and the scene. Declared here so that this module
    never imports the session (the session imports it)."""

    @property
    def files(self) -> EditorFiles: ...

    @property
    def gui(self) -> PreviewPanel: ...

    @property
    def scene(self) -> PreviewScene: ...


class Previewer:
    """The preview of one session (any :class:`PreviewHost`): follows the newest plan of the
    design on screen while the toggle is on (:meth:`refresh` after every edit and every
    published plan)."""

    def __init__(self, session: PreviewHost):
        self._session = session
        self._lock = threading.Lock()
        self._shown: tuple[int, str] | None = None  # key of the preview on screen
        self._busy: tuple[int, str] | None = None  # key being computed
        self.preview: GcodePreview | None = None  #: the preview on screen (None: hidden)
        self.computed = 0  #: previews built (for tests)

    def refresh(self) -> None:
        """Show, hide or (re)compute the preview for the plan of the design on screen."""
        session = self._session
        files = session.files.machine_files()
        gui = session.gui
        key = (files.plan, request_hash(files.request)) if files.result is not None and files.request else None
        with self._lock:
            on = bool(gui.preview.value)
            if key is None or not on:
                self._shown, self.preview = None, None
                session.scene.show_preview(None)
                gui.show_preview(key is not None, "off" if key is not None else f"no preview: {files.reason}")
                return
            if key == self._shown or key == self._busy:
                gui.show_preview(True, None)
                return
            self._busy = key
            gui.show_preview(True, f"reading the G-code of plan #{files.plan} back…")
        threading.Thread(target=self._compute, args=(files, key), daemon=True, name="rangeplan-editor-preview").start()

    def _compute(self, files: MachineFiles, key: tuple[int, str]) -> None:
        session = self._session
        try:
            preview, error = build_preview(files), None
        except PlannerError as exc:  # the reader refused the program (e.g. too large): say so, show nothing
            log.warning("G-code preview failed: %s", exc)
            preview, error = None, str(exc)
        except Exception as exc:  # never leave the toggle waiting: the cause goes to the panel and the log
            log.exception("G-code preview failed")
            preview, error = None, f"{type(exc).__name__}: {exc}"
        with self._lock:
            if self._busy == key:
                self._busy = None
            now = session.files.machine_files()
            current = (now.plan, request_hash(now.request)) if now.result is not None and now.request else None
            if current != key or not session.gui.preview.value:  # a newer plan or edit, or switched off meanwhile
                return
            self._shown, self.preview = key, preview
            self.computed += 1
            session.scene.show_preview(preview)
            session.gui.show_preview(True, preview.summary() if preview is not None else
                                     f"the program could not be read back: {error}")
