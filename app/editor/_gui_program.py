"""The G-code program folder of the Files tab: open a CAM program and contour it (issue 32).

A program (RS274NGC, LinuxCNC's dialect: what ``POST /v1/contour`` and ``rangeplan contour``
take) is opened with its placement: program zero at a typed origin x, y in the robot frame
[m], or, with the field empty, ``origin: "fit"`` (placed inside the region the robot reaches,
with a margin; the plan says where). The tolerance (empty: the program's ``G64 P``, else
0.05 mm) and the feed (``program``: never faster than F; ``fastest``) are the contour
request's. Opening replaces the design by the contour request and plans it at once (undo,
or "Close program", brings a corridor back); changing a field of an opened program re-plans it like any edit.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from ._fields import Bounds, NumberField, VectorField, syncing
from ._files import EditorFiles
from ._planning import MAX_CONTOUR_TOLERANCE_M, MIN_CONTOUR_TOLERANCE_M, is_contour

__all__ = ["PROGRAM_MIME", "ProgramActions", "ProgramPanel", "set_contour_field"]

#: what the upload dialog offers: G-code files by their usual extensions (and any text)
PROGRAM_MIME = ".ngc,.nc,.gcode,.tap,.cnc,.txt,text/plain"


def set_contour_field(request: dict, key: str, value: Any) -> None:
    """Set a field of a contour request (``origin``: [x, y] m or None for "fit";
    ``tolerance_m``, None: the program's G64 P; ``feed``); nothing for a plan request."""
    if not is_contour(request):
        return
    if key == "origin":
        request["origin"] = "fit" if value is None else [float(v) for v in value]
    elif value is None:
        request.pop(key, None)
    else:
        request[key] = value


class ProgramActions(Protocol):
    """What the program folder asks of its session (:class:`._session.Session`): an edit of
    the request, the files (which open a program) and a new layout. Declared here so that
    this module never imports the session (the session imports it)."""

    @property
    def files(self) -> EditorFiles: ...

    def edit(self, fn: Callable[[dict], object], *, immediate: bool = False, key: str | None = None) -> bool: ...

    def new_layout(self) -> None: ...


class ProgramPanel:
    """The "G-code program" folder (``gui`` the tab's panel, ``session`` its session: any
    :class:`ProgramActions`)."""

    def __init__(self, gui, session: ProgramActions):
        self._session = session
        self.folder = gui.add_folder("G-code program (contour)")
        with self.folder:
            self.note = gui.add_markdown("Open a CAM program (LinuxCNC G-code) to plan its contour: the programmed "
                                         "path (black, rapids grey), the tolerance tube (orange) and the planned cut "
                                         "(blue) are drawn.")
            self.origin = VectorField(
                gui, "Program origin x, y (m), empty = fit", None, self._edit("origin"), names=("x", "y"),
                optional=True, hint="Where program zero (X0 Y0) sits in the robot frame; empty: placed where the "
                                    "robot reaches (the plan reports the origin used)")
            self.tolerance = NumberField(
                gui, "Tolerance (m), empty = G64 P", None, self._edit("tolerance_m"), optional=True,
                bounds=Bounds(ge=MIN_CONTOUR_TOLERANCE_M, le=MAX_CONTOUR_TOLERANCE_M),
                hint="Largest distance between the cut and the programmed path, both ways; empty: the program's "
                     "G64 P, else 0.05 mm")
            self.feed = gui.add_dropdown("Feed", ("program", "fastest"), initial_value="program",
                                         hint="program: never faster than F; fastest: as the drives allow")
            self.feed.on_update(lambda _: None if syncing.active() else self._edit("feed")(self.feed.value))
            self.upload = gui.add_upload_button("Open G-code program", mime_type=PROGRAM_MIME,
                                                hint="Replaces the design by the program, placed and planned")
            self.upload.on_upload(lambda e: session.files.open_program(self.upload.value, client=e.client))
            self.close_button = gui.add_button("Close program (new layout)", visible=False,
                                               hint="Back to a corridor: the default layout (Undo reopens the "
                                                    "program)")
            self.close_button.on_click(lambda _: session.new_layout())

    def _edit(self, key: str):
        def on_value(value) -> None:
            self._session.edit(lambda r: set_contour_field(r, key, value), key=f"field:program.{key}")
        return on_value

    @property
    def placement(self) -> dict[str, Any]:
        """The contour fields as typed: ``origin`` ([x, y] or "fit"), ``feed``, and
        ``tolerance_m`` when given (what :meth:`app.editor._files.EditorFiles.open_program` uses)."""
        origin = self.origin.value
        out: dict[str, Any] = {"origin": "fit" if origin is None else origin, "feed": self.feed.value}
        if self.tolerance.value is not None:
            out["tolerance_m"] = float(self.tolerance.value)
        return out

    def show(self, request: dict) -> None:
        """Show a contour request's placement fields (nothing for a plan request)."""
        self.close_button.visible = is_contour(request)
        if not is_contour(request):
            return
        origin = request.get("origin", [0.0, 0.0])
        self.origin.show(None if origin == "fit" else origin)
        self.tolerance.show(request.get("tolerance_m"))
        with syncing():
            self.feed.value = request.get("feed", "program")
