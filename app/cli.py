"""Command line: ``rangeplan plan INPUT.json [-o OUT.json | .csv | .ngc | .txt | .dxf]``,
``rangeplan import DRAWING.dxf|.svg [options] -o request.json`` and ``rangeplan serve``.

Bad input exits with status 2 and one line naming the field and the cause.
"""

from __future__ import annotations

import os

# small dense matrices: single-threaded BLAS is much faster (must be set before numpy loads)
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402


class InputError(Exception):
    """A user error: printed as one line, exit status 2."""


def load_request(path: str):
    """Read a plan request file and validate it (:class:`planner.schema.PlanRequest`)."""
    from pydantic import ValidationError

    from planner.schema import PlanRequest, format_validation_error

    try:
        text = sys.stdin.read() if path == "-" else Path(path).read_text()
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        raw = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    if not isinstance(raw, dict):
        raise InputError(f"{path}: a plan request must be a JSON object")
    try:
        return PlanRequest.model_validate(raw)
    except ValidationError as exc:
        raise InputError(f"{path}: {format_validation_error(exc)}") from None


def output_format(args) -> str:
    """``--format``, else the output file's extension (.csv, .ngc/.nc/.gcode, .txt, .dxf), else JSON."""
    from app.formats import format_for_path

    return args.format or format_for_path(args.output or "")


def cmd_plan(args) -> int:
    from app.formats import write
    from planner import PlannerError, plan

    request = load_request(args.input)
    fmt = output_format(args)
    try:
        result = plan(request)
    except PlannerError as exc:
        raise InputError(f"{args.input}: {exc.code}: {exc}") from None
    if fmt == "json":
        text = json.dumps(result.to_json_dict(), indent=None if args.compact else 1)
    else:
        text = write(result, fmt, layout=request.layout, forces=args.forces, source=args.input).decode()
    if args.output and args.output != "-":
        Path(args.output).write_text(text + ("" if text.endswith("\n") else "\n"))
        m = result.metrics
        print(f"wrote {args.output}: {m.steps} steps, {m.duration_s:.2f} s, end error "
              f"{m.end_error_m * 1e3:.3f} mm, max force {m.max_drive_force_n:.1f} N, "
              f"compute {m.compute_ms:.0f} ms", file=sys.stderr)
    else:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
    return 0


def cmd_import(args) -> int:
    from planner import PlannerError
    from planner.exchange import import_drawing

    try:
        data = sys.stdin.buffer.read() if args.drawing == "-" else Path(args.drawing).read_bytes()
    except OSError as exc:
        raise InputError(f"{args.drawing}: cannot read: {exc.strerror or exc}") from None
    options = {"units": args.units, "layers": args.layer, "offset": args.offset, "rotation": args.rotation,
               "scale": args.scale, "join_tolerance": args.join_tolerance, "flatten_tolerance": args.flatten_tolerance,
               "margin": args.margin, "bounds_layer": args.bounds_layer, "start": args.start, "end": args.end}
    try:
        result = import_drawing(data, {k: v for k, v in options.items() if v is not None},
                                filename=None if args.drawing == "-" else args.drawing)
    except PlannerError as exc:
        raise InputError(f"{args.drawing}: {exc.code}: {exc}") from None
    request = result.to_request()
    request["layout"] = _with_cells(request["layout"], args)
    text = json.dumps(request, indent=1)
    if args.report:
        Path(args.report).write_text(json.dumps(result.report.model_dump(mode="json"), indent=1) + "\n")
    rep = result.report
    if args.output and args.output != "-":
        Path(args.output).write_text(text + "\n")
        print(f"wrote {args.output}: {len(rep.shapes)} obstacle(s), {rep.holes} hole(s), {len(rep.open_chains)} open "
              f"chain(s), units {rep.units} ({rep.units_source}), area {rep.area_m2:.6g} m^2", file=sys.stderr)
        for c in rep.open_chains[:5]:
            print(f"  open: layer {c.layer!r} from ({c.start[0]:.4f}, {c.start[1]:.4f}) m to ({c.end[0]:.4f}, "
                  f"{c.end[1]:.4f}) m ({c.why})", file=sys.stderr)
        if result.layout.start is None or result.layout.end is None:
            print("  add the start and end poses (--start X Y PSI --end X Y PSI, or in the file) before planning",
                  file=sys.stderr)
    else:
        sys.stdout.write(text + "\n")
    return 0


def _with_cells(layout: dict, args) -> dict:
    """The imported layout with the segmentation options given on the command line
    (``--cell-size`` m, ``--cell-shape``, ``--clearance`` m), checked by the layout's own
    schema (a bad value exits 2 naming ``layout.cell.size`` etc.)."""
    from pydantic import ValidationError

    from planner.schema import PARTIAL_LAYOUT, Layout, error_details

    cell = dict(layout.get("cell") or {})
    if args.cell_size is not None:
        cell["size"] = args.cell_size
    if args.cell_shape is not None:
        cell["shape"] = args.cell_shape
    out = {**layout, **({"cell": cell} if cell else {})}
    if args.clearance is not None:
        out["clearance"] = args.clearance
    try:
        Layout.model_validate(out, context=PARTIAL_LAYOUT)
    except ValidationError as exc:
        why = "; ".join(f"layout.{d['field']}: {d['message']}" for d in error_details(exc.errors())[:3])
        raise InputError(f"{args.drawing}: invalid_input: {why}") from None
    return out


def cmd_serve(args) -> int:
    from app.server import serve
    from app.settings import SettingsError, settings

    try:
        cfg = settings()  # the flags' defaults: RANGEPLAN_HOST, _PORT, _EDITOR_PORT
    except SettingsError as exc:
        raise InputError(str(exc)) from None
    return serve(host=args.host or cfg.host, port=cfg.port if args.port is None else args.port,
                 editor_port=cfg.editor_port if args.editor_port is None else args.editor_port,
                 editor=not args.no_editor, allow_unauthenticated=args.allow_unauthenticated)


def add_import_parser(sub) -> None:
    from planner.schema import DRAWING_UNITS, ImportOptions, Layout
    from planner.schema.layout import Cell

    def helptext(field: str) -> str:
        return (ImportOptions.model_fields[field].description or "").replace("%", "%%")

    def cell_help(field: str) -> str:
        return (Cell.model_fields[field].description or "").replace("%", "%%")

    pi = sub.add_parser("import", help="turn a DXF or SVG drawing into a plan request with a layout",
                        description="Closed shapes of the drawing become obstacles (nested ones holes); loose LINE/ARC "
                        "pieces are joined. Lengths in m, angles in rad (in the robot's workspace).")
    pi.add_argument("drawing", help="DXF or SVG file ('-' for standard input)")
    pi.add_argument("-o", "--output", help="plan request JSON to write; standard output if omitted")
    pi.add_argument("--layer", action="append", help=helptext("layers") + " (repeat for several)")
    pi.add_argument("--units", choices=sorted(DRAWING_UNITS), help=helptext("units"))
    pi.add_argument("--offset", nargs=2, type=float, metavar=("X", "Y"), help=helptext("offset"))
    pi.add_argument("--rotation", type=float, metavar="R", help=helptext("rotation"))
    pi.add_argument("--scale", type=float, metavar="S", help=helptext("scale"))
    pi.add_argument("--start", nargs=3, type=float, metavar=("X", "Y", "PSI"), help=helptext("start"))
    pi.add_argument("--end", nargs=3, type=float, metavar=("X", "Y", "PSI"), help=helptext("end"))
    pi.add_argument("--join-tolerance", type=float, metavar="M", help=helptext("join_tolerance"))
    pi.add_argument("--flatten-tolerance", type=float, metavar="M", help=helptext("flatten_tolerance"))
    pi.add_argument("--margin", type=float, metavar="M", help=helptext("margin"))
    pi.add_argument("--bounds-layer", metavar="NAME", help=helptext("bounds_layer"))
    pi.add_argument("--cell-size", type=float, metavar="M", help="layout.cell.size: " + cell_help("size")
                    + " (a drawing with narrow gaps needs small cells, e.g. 0.01)")
    pi.add_argument("--cell-shape", choices=("square", "triangle"), help="layout.cell.shape: " + cell_help("shape"))
    pi.add_argument("--clearance", type=float, metavar="M", help="layout.clearance: "
                    + (Layout.model_fields["clearance"].description or "").replace("%", "%%"))
    pi.add_argument("--report", metavar="FILE", help="write the import report (shapes, holes, open chains, "
                    "units) as JSON to FILE")
    pi.set_defaults(func=cmd_import)


def _format_name(text: str) -> str:
    """``--format``: one of :data:`app.formats.OUTPUT_FORMATS` (read when the flag is used:
    ``rangeplan --help`` does not import the planner)."""
    from app.formats import OUTPUT_FORMATS

    if text not in OUTPUT_FORMATS:
        raise argparse.ArgumentTypeError(f"invalid choice: {text!r} (choose from "
                                         f"{', '.join(repr(k) for k in OUTPUT_FORMATS)})")
    return text


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="rangeplan", description="Range-space predictive control trajectory planner "
                                "for planar parallel robots (SI units throughout).")
    sub = p.add_subparsers(dest="command", required=True)
    pp = sub.add_parser("plan", help="plan a trajectory for a request file")
    pp.add_argument("input", help="plan request JSON file ('-' for standard input)")
    pp.add_argument("-o", "--output", help="output file: .json (default), .csv, .ngc (G-code), .txt (leg lengths "
                    "for halstreamer) or .dxf; standard output if omitted")
    pp.add_argument("--format", type=_format_name, metavar="FORMAT", help="output format: json, csv or a machine "
                    "format as -o names them (default: from the output file's extension, else json)")
    pp.add_argument("--forces", action="store_true", help="joints format: add the drive forces (N)")
    pp.add_argument("--compact", action="store_true", help="JSON without indentation")
    pp.set_defaults(func=cmd_plan)
    add_import_parser(sub)
    ps = sub.add_parser("serve", help="serve the HTTP API and the browser editor")
    ps.add_argument("--host", help="API host (env RANGEPLAN_HOST, default 127.0.0.1)")
    ps.add_argument("--port", type=int, help="API port (env RANGEPLAN_PORT, default 8000)")
    ps.add_argument("--editor-port", type=int, help="editor (viser) port (env RANGEPLAN_EDITOR_PORT, default 8080)")
    ps.add_argument("--no-editor", action="store_true", help="serve the API only")
    ps.add_argument("--allow-unauthenticated", action="store_true",
                    help="serve on a non-loopback address without a token (RANGEPLAN_API_TOKEN); refused otherwise")
    ps.set_defaults(func=cmd_serve)
    from app.batch.cli import add_parser as add_batch_parser  # `rangeplan batch` (app/batch/)
    add_batch_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except InputError as exc:
        print(f"rangeplan: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
