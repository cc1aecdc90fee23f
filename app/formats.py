"""The one registry of a plan's output formats, as the CLI (``-o``/``--format``), the HTTP
API (``?format=``, media types, attachment names), the typed client and the editor's
download buttons offer them: the result JSON, the CSV table, and the machine formats of
:data:`planner.exchange.EXPORT_FORMATS` (G-code, leg lengths, DXF), each with its writer.

A new machine format is its writer in ``planner/exchange/`` and one entry in
``planner/exchange/formats.py``; every consumer here reads the names from
:data:`OUTPUT_FORMATS`. No web framework, storage or editor import (workers import it).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from planner.exchange import EXPORT_FORMATS
from planner.orchestrator import to_csv
from planner.schema import Layout, PlanResult

__all__ = ["GCODE_FORMAT", "MACHINE_FORMATS", "OUTPUT_FORMATS", "ExportFormatName", "OutputFormat", "PlanFormat",
           "format_for_path", "format_help", "write"]


@dataclass(frozen=True)
class OutputFormat:
    """One output format: ``name``, response ``media_type``, file ``extension`` (and the
    ``suffixes`` that name it), a description (``what``), whether it is a machine format
    (an export of a stored plan, offered by the editor as a download) and its writer
    ``(result, layout, forces, source, header) -> bytes`` (``header``: provenance lines,
    the editor's design, plan id and request hash; JSON has none)."""

    name: str
    media_type: str
    extension: str
    suffixes: tuple[str, ...]
    what: str
    machine: bool
    writer: Callable[[PlanResult, Layout | None, bool, str | None, Sequence[str]], bytes]
    title: str = ""
    filename: str = ""


def _machine(name: str) -> OutputFormat:
    spec = EXPORT_FORMATS[name]
    return OutputFormat(name, spec.media_type, spec.extension, spec.suffixes, spec.what, True,
                        lambda r, layout, forces, source, header: spec.write(r, layout, forces, source,
                                                                             header).encode(),
                        spec.title, spec.filename)


#: name -> format, in the order offered (``json`` first: the default)
OUTPUT_FORMATS: dict[str, OutputFormat] = {
    "json": OutputFormat("json", "application/json", ".json", (".json",), "the result JSON", False,
                         lambda r, layout, forces, source, header: r.to_json()),
    "csv": OutputFormat("csv", "text/csv; charset=utf-8", ".csv", (".csv",),
                        "one row per sample, units in the header", False,
                        lambda r, layout, forces, source, header: to_csv(r, header).encode()),
    **{name: _machine(name) for name in EXPORT_FORMATS},
}
#: the machine formats (exports of a stored plan; the editor's downloads)
MACHINE_FORMATS: tuple[str, ...] = tuple(k for k, v in OUTPUT_FORMATS.items() if v.machine)
#: the LinuxCNC program (``.ngc``), the machine format ``read_gcode`` reads back (the editor's preview)
GCODE_FORMAT: str = next(k for k, v in OUTPUT_FORMATS.items() if v.machine and v.extension == ".ngc")

if TYPE_CHECKING:
    PlanFormat = str
    ExportFormatName = str
else:
    #: the names as a type (FastAPI validates ``?format=`` against it: the OpenAPI enum)
    PlanFormat = Literal[tuple(OUTPUT_FORMATS)]
    #: the formats of a stored plan other than JSON (the typed client's ``export``)
    ExportFormatName = Literal[tuple(k for k in OUTPUT_FORMATS if k != "json")]


def format_help() -> str:
    """The ``?format=`` description: every format and what it is."""
    return ("Response format: 'json' (default), 'csv' (one row per sample, units in the header), "
            + ", ".join(f"'{k}' ({v.what})" for k, v in OUTPUT_FORMATS.items() if v.machine)
            + "; overrides the Accept header")


def format_for_path(path: str) -> str:
    """The output format a file name's extension names, else ``json``."""
    name = path.lower()
    for fmt, spec in OUTPUT_FORMATS.items():
        if name.endswith(spec.suffixes):
            return fmt
    return "json"


def write(result: PlanResult, fmt: str, *, layout: Layout | None = None, forces: bool = False,
          source: str | None = None, header: Sequence[str] = ()) -> bytes:
    """``result`` in the output format ``fmt`` (a ValueError names the formats for another);
    ``header`` lines go into the file's header (comments) where the format has one."""
    spec = OUTPUT_FORMATS.get(fmt)
    if spec is None:
        raise ValueError(f"unknown output format {fmt!r}; one of {', '.join(OUTPUT_FORMATS)}")
    return spec.writer(result, layout, forces, source, header)
