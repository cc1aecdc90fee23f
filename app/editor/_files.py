"""The editor's files: corridors saved to / loaded from the store, the request JSON
imported and exported, DXF/SVG drawings imported as the layout's obstacles, G-code programs
opened to contour (the design becomes a contour request), and the planned trajectory as a
CSV, G-code, leg-length stream or DXF download.

A corridor is saved as its plan request (the one JSON shape); whatever is loaded or
imported is validated as a plan request first and replaces the design only when valid.
Failures become notifications naming the cause; they never change the design.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ._geometry import obstacle_shape
from ._placement import fit_drawing, free_point, reachable_region
from ._planning import (
    MACHINE_FORMATS,
    OUTPUT_FORMATS,
    ContourRequest,
    PlannerError,
    PlanRequest,
    PlanResult,
    RobotCache,
    drawing_request,
    editable,
    export_result,
    is_contour,
    reachable_points,
    to_csv,
    validate_request,
)
from ._state import EditorState

__all__ = ["EditorFiles", "FilesHost", "FilesPanel", "MachineFiles", "ProgramPlacement", "request_hash"]


def request_hash(request: dict) -> str:
    """SHA-256 (hex) of a plan request as canonical JSON (keys sorted, no spaces, UTF-8):
    the same design gives the same hash whatever the order it was typed in."""
    text = json.dumps(request, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def _design(request: dict | None) -> dict | None:
    """What decides a plan: the request without its name (renaming re-plans nothing)."""
    return None if request is None else {k: v for k, v in request.items() if k != "name"}


@dataclass(frozen=True)
class MachineFiles:
    """Whether the machine files (G-code, leg lengths, DXF, CSV) may be downloaded now:
    ``result`` is the plan of the design on screen (``plan`` its number, ``request`` the
    request it was planned for, ``model`` that request validated), or None and ``reason``
    says why not."""

    result: PlanResult | None
    request: dict | None
    plan: int
    reason: str
    model: PlanRequest | ContourRequest | None = None

    def header(self) -> tuple[str, ...]:
        """The provenance lines every downloaded file carries: design, plan id, request hash."""
        assert self.request is not None
        return (f"design: {self.request.get('name') or 'unnamed'}",
                f"plan id: editor plan #{self.plan}",
                f"request sha256: {request_hash(self.request)} (the request JSON, keys sorted, no spaces)")


class ProgramPlacement(Protocol):
    """The G-code program folder's fields (:class:`._gui_program.ProgramPanel`)."""

    @property
    def placement(self) -> dict[str, Any]: ...


class FilesPanel(Protocol):
    """What the files read of the session's panel (:class:`._gui.EditorGui`): the dropdown of
    stored corridors (None: no store) and the placement typed in the program folder."""

    @property
    def stored(self) -> Any: ...

    @property
    def program(self) -> ProgramPlacement: ...


class FilesHost(Protocol):
    """What the files take from their session (:class:`._session.Session`): its state,
    robots and panel, its notifications, and the edits that replace the design. Declared
    here so that this module never imports the session (the session imports it)."""

    @property
    def state(self) -> EditorState: ...

    @property
    def request(self) -> dict: ...

    @property
    def robots(self) -> RobotCache: ...

    @property
    def gui(self) -> FilesPanel: ...

    def notify(self, title: str, body: str, color: str = "red", client=None) -> None: ...

    def stored_changed(self) -> None: ...

    def open_design(self, request: dict) -> None: ...

    def set_request(self, request: dict, *, replan: bool = True, immediate: bool = False) -> None: ...

    def place_cameras(self, fit_layout: bool = False) -> None: ...


class EditorFiles:
    """Save / load / import / export for ``editor`` (the session, or any :class:`FilesHost`).
    ``store`` is an :class:`app.storage.Store` (its corridor methods), or None: saving is
    off. ``client`` arguments are the viser client that asked (its notifications and
    downloads go to it)."""

    def __init__(self, editor: FilesHost, store):
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
        if is_contour(req):  # the store keeps corridors (plan requests)
            self._editor.notify("Not saved", "a G-code program is not a corridor: keep its file (Export request "
                                "JSON keeps the program with its placement, Import request JSON opens it again)",
                                client=client)
            return
        valid, message = validate_request(req)
        if valid is None:  # saving validates exactly as planning does
            self._editor.notify("Not saved", message or "invalid request", client=client)
            return
        assert isinstance(valid, PlanRequest)
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
        if is_contour(req):  # a G-code program's design (exported with Export request JSON)
            self._editor.open_design(req)
            return True
        self._editor.set_request(req, immediate=True)
        self._editor.place_cameras()
        return True

    def open_program(self, upload, client=None, placement: dict | None = None) -> bool:
        """Open an uploaded G-code program (``upload.name``, ``upload.content`` bytes) as the
        design: a contour request (:class:`planner.schema.ContourRequest`) with the program,
        the placement (``placement``, default the panel's fields: ``origin`` [x, y] m or
        "fit", ``tolerance_m``, ``feed``) and the design's robot, planned at once. A file
        that is not text, or a request the schema refuses (too large, a bad origin), is refused
        with the cause and leaves the design as it is; a program the reader refuses is planned
        and fails naming its line (the status line and the notification say it)."""
        try:
            text = upload.content.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            self._editor.notify("Program not opened", f"{upload.name}: not a text file (UTF-8): {exc}", client=client)
            return False
        placement = placement if placement is not None else self._editor.gui.program.placement
        robot = self._editor.request.get("robot", "moving-slide")
        data: dict[str, Any] = {"name": upload.name, "program": text, "robot": robot, **placement}
        model, message = validate_request(data)
        if model is None:
            self._editor.notify("Program not opened", f"{upload.name}: {message}", client=client)
            return False
        self._editor.open_design(editable(model))
        self._editor.state.corridor_id = None
        origin = placement.get("origin", "fit")
        where = "placed in reach (origin fit)" if origin == "fit" else f"program zero at {list(origin)} m"
        self._editor.notify("Program opened", f"{upload.name}: {len(text.splitlines())} lines, {where}; planning…",
                            color="green", client=client)
        return True

    def export_request(self, client) -> None:
        """Send the design to ``client`` as ``corridor.json``."""
        self._download(client, "corridor.json", json.dumps(self._editor.request, indent=2).encode())

    def machine_files(self) -> MachineFiles:
        """The plan whose files may be downloaded: the newest plan, only when it succeeded and
        was planned for the design on screen (a failed plan, a pending re-plan or an edit since
        disable every download: a machine must never get the program of another design)."""
        state = self._editor.state
        with state.lock:
            result, planned, error = state.last_result, state.last_result_request, state.last_error
            gen, current, model = state.last_plan_generation, state.request, state.last_result_model
        if error is not None:
            message = error.message.split("; ")[0]
            return MachineFiles(None, None, gen, f"the newest plan failed ({error.code}: {message}); no file of "
                                "an earlier plan is offered — fix the design")
        if result is None or planned is None:
            return MachineFiles(None, None, gen, "no plan yet")
        if _design(planned) != _design(current):
            return MachineFiles(None, None, gen, f"the design has changed since plan #{gen} — wait for the re-plan "
                                "(or press Plan)")
        planned = {**planned, "name": current.get("name")} if current.get("name") else _design(planned) or {}
        return MachineFiles(result, planned, gen, f"files of plan #{gen}, the design on screen", model)

    def _current_plan(self, client) -> MachineFiles | None:
        files = self.machine_files()
        if files.result is None:
            self._editor.notify("No download", files.reason, color="yellow", client=client)
            return None
        return files

    def download_csv(self, client) -> None:
        """Send the plan of the design on screen to ``client`` as ``trajectory.csv``."""
        files = self._current_plan(client)
        if files is not None:
            assert files.result is not None
            self._download(client, "trajectory.csv", to_csv(files.result, files.header()).encode())

    # ------------------------------------------------------------------ CAD and machine files
    def import_drawing(self, upload, options: dict, client=None, *, place_margin: float | None = None) -> bool:
        """Replace the layout's bounds and obstacles by an uploaded DXF or SVG drawing's
        (``options``: :class:`planner.schema.ImportOptions`, e.g. scale and offset [m]); the
        start, end and cell settings stay. With ``place_margin`` [m] the drawing is placed
        (:meth:`place`): fitted into the reachable square less that margin, which becomes the
        bounds, with start and end kept if valid or moved next to the drawing. The view
        then fits the drawing. Returns whether the design changed."""
        request = self._editor.request
        try:
            if place_margin is None:
                req, summary = drawing_request(upload.content, upload.name, request, options)
            else:
                req, summary = self.place(upload, options, request, place_margin)
        except PlannerError as exc:
            self._editor.notify("Drawing not imported", f"{upload.name}: {exc}", client=client)
            return False
        self._editor.set_request(req, immediate=True)
        self._editor.place_cameras(fit_layout=True)
        self._editor.notify("Drawing imported", f"{upload.name}: {summary}", color="green", client=client)
        return True

    def place(self, upload, options: dict, request: dict, margin: float) -> tuple[dict, str]:
        """The request with the drawing placed where the robot reaches at the start's angle
        (see :mod:`._placement`) and a summary saying what was done (scale, offset, bounds,
        start / end kept or moved). Raises :class:`PlannerError` naming the field."""
        robot = self._editor.robots.of_request(request, fallback=True)
        assert robot is not None  # fallback: the default robot for a request whose robot is invalid
        layout = request.get("layout") or {}
        psi = float((layout.get("start") or [0.0, 0.0, 0.0])[2])
        try:
            lower, upper, centre = reachable_region(robot, psi)
        except ValueError as exc:
            raise PlannerError("invalid_input", str(exc), "layout.start") from None
        first, _ = drawing_request(upload.content, upload.name, request, {**options, "offset": [0.0, 0.0],
                                                                            "margin": 0.0})

        def reach(x, y, a):
            return reachable_points(robot, x, y, a)

        scale = float(options.get("scale", 1.0))
        cell_spec = (first["layout"].get("cell") or {})
        cell, shape = float(cell_spec.get("size") or 0.02), str(cell_spec.get("shape", "square"))
        room = margin + 1.5 * cell  # a lane of whole reachable cells around the drawing, beyond the margin
        try:
            p = fit_drawing([obstacle_shape(ob) for ob in first["layout"]["obstacles"]], centre, room, reach, psi)
        except ValueError as exc:
            raise PlannerError("invalid_input", str(exc), "margin") from None
        req, summary = drawing_request(upload.content, upload.name, request,
                                       {**options, "scale": scale * p.factor, "offset": list(p.offset), "margin": 0.0})
        out = req["layout"]
        placed = out["bounds"]
        # bounds: the reachable extent, grown to whole cells (cells beyond reach are "unreachable")
        n = np.ceil((upper - lower) / cell - 1e-9)
        lo = np.round(0.5 * (lower + upper) - 0.5 * n * cell, 6) + 0.0
        hi = np.round(lo + n * cell, 6) + 0.0
        out["bounds"] = {"lower": lo.tolist(), "upper": hi.tolist()}
        moved, taken = [], None
        for which, target in (("start", placed["lower"]), ("end", placed["upper"])):
            try:
                pose, was_moved = free_point(out[which], out["obstacles"], lo, hi, cell=cell, shape=shape,
                                             clearance=float(out.get("clearance", 0.0)), reach=reach, target=target,
                                             taken=taken)
            except ValueError:
                raise PlannerError("invalid_input", f"no free, reachable place for the {which} next to the drawing: "
                                   "give a smaller margin, scale or cell size", "margin") from None
            if was_moved:
                moved.append(f"{which} moved to ({pose[0]:.4f}, {pose[1]:.4f}) m (its cell was in or next to an "
                             "obstacle, or out of reach)")
            out[which] = pose
            taken = pose
        text = (f"{summary}; placed where the robot reaches at ψ {psi:g} rad (x {lower[0]:.3f}…{upper[0]:.3f} m, "
                f"y {lower[1]:.3f}…{upper[1]:.3f} m, the bounds) with a {margin:g} m margin and a "
                f"{1.5 * cell:g} m lane for the path around it: scale "
                f"{scale * p.factor:.4g}{' (shrunk to fit)' if p.shrunk else ''}, offset ({p.offset[0]:.4f}, "
                f"{p.offset[1]:.4f}) m; " + ("; ".join(moved) if moved else "start and end kept"))
        return req, text

    #: download file name of each machine format (the registry's)
    EXPORTS = {fmt: OUTPUT_FORMATS[fmt].filename for fmt in MACHINE_FORMATS}

    def download_export(self, client, fmt: str) -> None:
        """Send the plan of the design on screen to ``client`` as G-code, a leg-length stream
        or DXF (refused, with the reason, when there is none: see :meth:`machine_files`)."""
        files = self._current_plan(client)
        if files is not None:
            assert files.result is not None and files.request is not None
            text = export_result(files.result, fmt, files.model or files.request, files.header())
            self._download(client, self.EXPORTS[fmt], text.encode())

    @staticmethod
    def _download(client, filename: str, content: bytes) -> None:
        if client is not None:
            client.send_file_download(filename, content, save_immediately=True)
