"""The machine output formats of a plan, by name, with their media type and file extension."""

from __future__ import annotations

from collections.abc import Sequence
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


#: name -> media type, file extension, description
EXPORT_FORMATS: dict[str, _Format] = {
    "gcode": _Format("text/plain; charset=utf-8", ".ngc", "LinuxCNC G-code: X Y in mm, C = psi in degrees, G93 "
                     "inverse-time feed, one G1 per sample time"),
    "joints": _Format("text/plain; charset=utf-8", ".txt", "leg lengths per sample in mm (with forces in N), "
                      "whitespace-separated, for halstreamer"),
    "dxf": _Format("image/vnd.dxf", ".dxf", "DXF in mm: the path on layer PATH, corridor cells on CORRIDOR, "
                   "obstacles on OBSTACLES"),
}


def export_format_for(path: str) -> ExportFormat | None:
    """The export format a file name's extension names (``.ngc``/``.nc``/``.gcode``,
    ``.txt``, ``.dxf``), or None."""
    name = path.lower()
    if name.endswith((".ngc", ".nc", ".gcode")):
        return "gcode"
    if name.endswith(".txt"):
        return "joints"
    if name.endswith(".dxf"):
        return "dxf"
    return None


def export(result: PlanResult, format: ExportFormat, *, layout: Layout | None = None, forces: bool = False,
           source: str | None = None, header: Sequence[str] = ()) -> str:
    """The plan in ``format`` as text. ``layout`` adds obstacles and bounds to a DXF,
    ``forces`` drive-force columns to the joint stream, ``source`` names the plan's origin
    in the G-code and joint headers, ``header`` adds provenance lines to every format's
    header (comments; DXF custom header properties)."""
    if format == "gcode":
        return to_gcode(result, source, header)
    if format == "joints":
        return to_joints(result, forces, source, header)
    if format == "dxf":
        return to_dxf(result, layout, header)
    raise ValueError(f"unknown export format {format!r}; one of {', '.join(EXPORT_FORMATS)}")
