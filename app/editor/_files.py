"""The editor's files: corridors saved to / loaded from the store, the request JSON
imported and exported, DXF/SVG drawings imported as the layout's obstacles, and the planned
trajectory as a CSV, G-code, leg-length stream or DXF download.

A corridor is saved as its plan request (the one JSON shape); whatever is loaded or
imported is validated as a plan request first and replaces the design only when valid.
Failures become notifications naming the cause; they never change the design.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

from ._planning import (
    MACHINE_FORMATS,
    OUTPUT_FORMATS,
    PlannerError,
    drawing_request,
    editable,
    export_result,
    to_csv,
    validate_request,
)

if TYPE_CHECKING:
    from ._session import Session

__all__ = ["EditorFiles"]


class EditorFiles:
    """Save / load / import / export for ``editor``. ``store`` is an
    :class:`app.storage.Store` (its corridor methods), or None: saving is off. ``client``
    arguments are the viser client that asked (its notifications and downloads go to it)."""

    def __init__(self, editor: Session, store):
        self._editor = editor
        self.store = store
        self.stored_ids: dict[str, str] = {}  #: stored corridor id by its label in the dropdown

    # ------------------------------------------------------------------ store
    def refresh_stored(self) -> None:
        """Re-read the list of stored corridors into the dropdown."""
        dropdown = self._editor.gui.stored
        if self.store is None or dropdown is None:
            return
        try:
            rows = self.store.list_corridors()
        except Exception as exc:
            self._editor.notify("Could not list corridors", str(exc))
            return
        self.stored_ids = {f"{r.get('name') or '(unnamed)'} · {r['id'][:8]}": r["id"] for r in rows}
        dropdown.options = tuple(self.stored_ids) or ("(none)",)

    def save(self, new: bool, client=None) -> None:
        """Save the design as a new corridor (``new``) or over the one it was loaded from /
        last saved as (a new one if there is none or it was deleted meanwhile)."""
        state = self._editor.state
        req = state.request
        valid, message = validate_request(req)
        if valid is None:  # saving validates exactly as planning does
            self._editor.notify("Not saved", message or "invalid request", client=client)
            return
        req = valid.to_json_dict()
        try:
            if new or state.corridor_id is None:
                rec = self.store.create_corridor(req, name=req.get("name"))
            else:
                rec = self.store.update_corridor(state.corridor_id, req, name=req.get("name"))
                if rec is None:
                    rec = self.store.create_corridor(req, name=req.get("name"))
        except Exception as exc:
            self._editor.notify("Not saved", f"{type(exc).__name__}: {exc}", client=client)
            return
        state.corridor_id = rec["id"]
        self._editor.stored_changed()  # every tab's list
        self._editor.notify("Saved", f"corridor '{rec.get('name') or ''}' id {rec['id']}", color="green",
                            client=client)

    def load(self, client=None) -> None:
        """Load the corridor chosen in the dropdown."""
        dropdown = self._editor.gui.stored
        cid = self.stored_ids.get(dropdown.value) if dropdown is not None else None
        if cid is None:
            self._editor.notify("Nothing to load", "choose a stored corridor first", color="yellow", client=client)
            return
        rec = self.store.get_corridor(cid)
        if rec is None:
            self._editor.notify("Not found", f"corridor {cid} no longer exists", client=client)
            self.refresh_stored()
            return
        if self.load_request(rec["request"], client, f"corridor {cid}"):
            self._editor.state.corridor_id = cid

    # ------------------------------------------------------------------ request JSON
    def import_upload(self, upload, client=None) -> None:
        """Import an uploaded request JSON file (``upload.name``, ``upload.content`` bytes)."""
        try:
            data = json.loads(upload.content.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            self._editor.notify("Import failed", f"{upload.name}: not valid JSON ({exc})", client=client)
            return
        if self.load_request(data, client, upload.name):
            self._editor.state.corridor_id = None

    def load_request(self, data: Any, client, origin: str) -> bool:
        """Replace the design with the plan request ``data`` (from ``origin``, for the
        messages) and plan it at once; returns False (design unchanged) when it is invalid."""
        model, message = validate_request(data) if isinstance(data, dict) else (None, "a plan request must be a "
                                                                               "JSON object")
        if model is None:
            self._editor.notify("Import failed", f"{origin}: {message}", client=client)
            return False
        req = editable(model)
        self._editor.set_request(req, immediate=True)
        self._editor.place_cameras()
        return True

    def export_request(self, client) -> None:
        """Send the design to ``client`` as ``corridor.json``."""
        self._download(client, "corridor.json", json.dumps(self._editor.request, indent=2).encode())

    def download_csv(self, client) -> None:
        """Send the newest trajectory to ``client`` as ``trajectory.csv``."""
        result = self._editor.last_result
        if result is None:
            self._editor.notify("No trajectory", "plan a corridor first", color="yellow", client=client)
            return
        self._download(client, "trajectory.csv", to_csv(result).encode())

    # ------------------------------------------------------------------ CAD and machine files
    def import_drawing(self, upload, options: dict, client=None) -> bool:
        """Replace the layout's bounds and obstacles by an uploaded DXF or SVG drawing's
        (``options``: :class:`planner.schema.ImportOptions`, e.g. scale and offset [m]); the
        start, end and cell settings stay. Returns whether the design changed."""
        try:
            req, summary = drawing_request(upload.content, upload.name, self._editor.request, options)
        except PlannerError as exc:
            self._editor.notify("Drawing not imported", f"{upload.name}: {exc}", client=client)
            return False
        self._editor.set_request(req, immediate=True)
        self._editor.place_cameras()
        self._editor.notify("Drawing imported", f"{upload.name}: {summary}", color="green", client=client)
        return True

    #: download file name of each machine format (the registry's)
    EXPORTS = {fmt: OUTPUT_FORMATS[fmt].filename for fmt in MACHINE_FORMATS}

    def download_export(self, client, fmt: str) -> None:
        """Send the newest trajectory to ``client`` as G-code, a leg-length stream or DXF."""
        result = self._editor.last_result
        if result is None:
            self._editor.notify("No trajectory", "plan a corridor first", color="yellow", client=client)
            return
        text = export_result(result, fmt, self._editor.request)
        self._download(client, self.EXPORTS[fmt], text.encode())

    @staticmethod
    def _download(client, filename: str, content: bytes) -> None:
        if client is not None:
            client.send_file_download(filename, content, save_immediately=True)
