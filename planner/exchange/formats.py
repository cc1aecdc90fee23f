"""The machine output formats of a plan: the one registry, by name, of each format's writer,
media type, file extension(s) and description. Everything that offers an export (the CLI,
the HTTP API's ``?format=``, the typed client, the editor's download buttons) reads this
table through :mod:`app.formats`; a new format is its writer module plus one entry here."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

from ..schema import Layout, PlanResult
from .dxf_export import to_dxf
from .gcode import to_gcode
from .joints import to_joints

__all__ = ["EXPORT_FORMATS", "ExportFormat", "export", "export_format_for"]

ExportFormat = Literal["gcode", "joints", "dxf"]


@dataclass(frozen=True)
class _Format:
    media_type: str
    extension: str
    what: str
    #: ``(result, layout, forces, source, header) -> text``
    write: Callable[[PlanResult, Layout | None, bool, str | None, Sequence[str]], str]
    #: file-name endings that name this format (the first is :attr:`extension`)
    suffixes: tuple[str, ...]
    #: a short title (the editor's download button) and the editor's download file name
    title: str
    filename: str


#: name -> writer, media type, file extension, description
EXPORT_FORMATS: dict[str, _Format] = {
    "gcode": _Format("text/plain; charset=utf-8", ".ngc", "LinuxCNC G-code: X Y in mm, C = psi in degrees, G93 "
                     "inverse-time feed, one G1 per sample time",
                     lambda r, layout, forces, source, header: to_gcode(r, source, header), (".ngc", ".nc", ".gcode"),
                     "G-code (LinuxCNC)", "trajectory.ngc"),
    "joints": _Format("text/plain; charset=utf-8", ".txt", "leg lengths per sample in mm (with forces in N), "
                      "whitespace-separated, for halstreamer",
                      lambda r, layout, forces, source, header: to_joints(r, forces, source, header), (".txt",),
                      "leg lengths (halstreamer)", "legs.txt"),
    "dxf": _Format("image/vnd.dxf", ".dxf", "DXF in mm: the path on layer PATH, corridor cells on CORRIDOR, "
                   "obstacles on OBSTACLES",
                   lambda r, layout, forces, source, header: to_dxf(r, layout, header), (".dxf",),
                   "DXF (path, corridor, obstacles)", "plan.dxf"),
}


def export_format_for(path: str) -> ExportFormat | None:
    """The export format a file name's extension names (``.ngc``/``.nc``/``.gcode``,
    ``.txt``, ``.dxf``), or None."""
    name = path.lower()
    for fmt, spec in EXPORT_FORMATS.items():
        if name.endswith(spec.suffixes):
            return fmt  # type: ignore[return-value]
    return None


def export(result: PlanResult, format: ExportFormat, *, layout: Layout | None = None, forces: bool = False,
           source: str | None = None, header: Sequence[str] = ()) -> str:
    """The plan in ``format`` as text. ``layout`` adds obstacles and bounds to a DXF,
    ``forces`` drive-force columns to the joint stream, ``source`` names the plan's origin
    in the G-code and joint headers, ``header`` adds provenance lines to every format's
    header (comments; DXF custom header properties)."""
    spec = EXPORT_FORMATS.get(format)
    if spec is None:
        raise ValueError(f"unknown export format {format!r}; one of {', '.join(EXPORT_FORMATS)}")
    return spec.write(result, layout, forces, source, header)
