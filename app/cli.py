"""Command line: ``rangeplan plan INPUT.json [-o OUT.json | .csv | .ngc | .txt | .dxf]``,
``rangeplan contour PROGRAM.ngc [--origin X,Y|fit] [--tolerance M] [--feed program|fastest] -o OUT``,
``rangeplan import DRAWING.dxf|.svg [options] -o request.json`` and ``rangeplan serve``.

Bad input exits with status 2 and one line naming the field and the cause.

``plan`` and ``contour`` submit the API's typed jobs (:class:`app.jobs.PlanJob`,
:class:`app.jobs.ContourJob`) to the in-process executor (:func:`run_here`): the same error
mapping and the same bytes per output format as ``POST /v1/plan`` answers (JSON indented
unless ``--compact``). Every command runs in its own process and ends with it: no resident
planner, nothing written after the command has ended (an output file is replaced whole).
"""

from __future__ import annotations

from planner._config import single_threaded_blas

single_threaded_blas()  # before numpy loads

import argparse  # noqa: E402
import contextlib  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import TYPE_CHECKING  # noqa: E402

if TYPE_CHECKING:
    from app.jobs import ContourJob, Done, Job, PlanJob


class InputError(Exception):
    """A user error: printed as one line, exit status 2."""


class PlannerBug(Exception):
    """A planner failure that is not the input's fault (``internal_error``): printed with its
    traceback, exit status 1."""

    def __init__(self, message: str, trace: str | None = None) -> None:
        super().__init__(message)
        self.trace = trace


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
    """``rangeplan plan REQUEST.json``: the API's :class:`app.jobs.PlanJob`, run in this process."""
    from app.jobs import PlanJob

    request = load_request(args.input)
    job = PlanJob(request, format=output_format(args), forces=args.forces, source=args.input)
    out = run_here(job, args.input, args.compile)
    s = out.summary or {}
    write_output(out.payload or b"", args, job.format,
                 f"{s['steps']} steps, {s['duration_s']:.2f} s, end error {s['end_error_m'] * 1e3:.3f} mm, "
                 f"max force {s['max_drive_force_n']:.1f} N, compute {s['compute_ms']:.0f} ms")
    return 0


def run_here(job: PlanJob | ContourJob, name: str, compile_first: bool) -> Done:
    """Run a planning ``job`` (:class:`app.jobs.PlanJob` / :class:`app.jobs.ContourJob`) on the
    in-process executor (:class:`app.executors.InProcessExecutor`: :func:`app.jobs.run_job`, as
    the service's workers run it, the same error mapping and serialisation; no time limit: the
    command is the user's to stop); its :class:`app.jobs.Done`, or an :class:`InputError` naming
    ``name`` and the cause (exit 2). A planner bug is an ``internal_error`` (exit 1, with its
    traceback). Unless ``compile_first``, a job whose kernels are not compiled yet plans on the
    numpy reference (:func:`reference_while_compiling`)."""
    from app.executors import InProcessExecutor
    from app.jobs import Failed
    from planner.orchestrator.compiling import compile_progress

    runs: Job = job if compile_first else reference_while_compiling(job)
    with compile_progress():  # the first plan after installing compiles the kernels: progress on stderr
        out = InProcessExecutor().run(runs)
    if isinstance(out, Failed):
        e = out.error
        why = f"{name}: {e.code}: {e.field + ': ' if e.field else ''}{e.message}"
        if out.status >= 500:
            raise PlannerBug(why, out.trace)
        raise InputError(why)
    return out


def reference_while_compiling(job: PlanJob | ContourJob) -> Job:
    """``job`` as it runs while the kernels are not compiled: the edges' one rule, as the
    service applies it (:func:`planner.orchestrator.background.while_compiling` decides and
    starts the background compile; :func:`app.executors.on_reference` moves the job to the numpy
    reference); one line on stderr says so, with the plan's work estimate on the reference
    where there is one (:func:`app.jobs.estimate`). Other jobs as they are."""
    from app.jobs import PlanJob
    from planner import PlannerError
    from planner.orchestrator.background import while_compiling

    try:  # a contour request's settings are filled by the program's (its plan_settings)
        st = job.request.settings if isinstance(job, PlanJob) else job.request.plan_settings()
    except PlannerError:
        return job  # the job names the fault
    running = while_compiling(st.backend, st.mode)
    if running is None:
        return job
    from app.executors import on_reference
    from app.jobs import estimate

    moved = on_reference(job)
    try:
        work = estimate(moved)
        plan_s = work.seconds if work is not None else None
    except PlannerError:
        plan_s = None  # the plan names the fault
    print(running.note(plan_s), file=sys.stderr, flush=True)
    return moved


def write_output(payload: bytes, args, fmt: str, summary: str, warnings: tuple[str, ...] = ()) -> None:
    """Write a job's ``payload`` (``fmt``, serialised by the job as the API serialises it:
    :data:`app.formats.OUTPUT_FORMATS`) to ``args.output`` (a one-line ``summary`` and any
    ``warnings`` on stderr) or to standard output (``args.output`` unset or ``-``). JSON is
    indented (one space) unless ``--compact``. A file is replaced whole (written beside it,
    then renamed): a command stopped while writing leaves the previous file as it was."""
    if fmt == "json" and not args.compact:
        payload = json.dumps(json.loads(payload), indent=1).encode()
    if not payload.endswith(b"\n"):
        payload += b"\n"
    if args.output and args.output != "-":
        _replace_file(Path(args.output), payload)
        print(f"wrote {args.output}: {summary}", file=sys.stderr)
        for w in warnings:
            print(f"  warning: {w}", file=sys.stderr)
    else:
        sys.stdout.flush()
        sys.stdout.buffer.write(payload)
        sys.stdout.flush()


def _replace_file(path: Path, data: bytes) -> None:
    """``path`` holding ``data``: a regular file (or a new one) is replaced at once by a renamed
    temporary file beside it (its mode kept); anything else (a device, a pipe, a symlink's
    target that is no regular file) is written in place."""
    import stat

    try:
        st = path.stat()
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise InputError(f"{path}: cannot write: {exc.strerror or exc}") from None
    if st is not None and not stat.S_ISREG(st.st_mode):
        try:
            path.write_bytes(data)
        except OSError as exc:
            raise InputError(f"{path}: cannot write: {exc.strerror or exc}") from None
        return
    target = path.resolve() if path.is_symlink() else path
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # the umask applies, as to a new file
        try:
            if st is not None:
                os.fchmod(fd, stat.S_IMODE(st.st_mode))
            with os.fdopen(fd, "wb", closefd=False) as f:
                f.write(data)
        finally:
            os.close(fd)
        os.replace(tmp, target)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise InputError(f"{path}: cannot write: {exc.strerror or exc}") from None
        raise


def parse_pair(text: str, option: str) -> list[float]:
    """``X,Y`` (m) -> [x, y]."""
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"{option}: expected X,Y in m (e.g. -0.04,-0.015), got {text!r}") from None
    return [x, y]


def cmd_contour(args) -> int:
    """``rangeplan contour PROGRAM.ngc``: plan a G-code program (issue 22)."""
    from planner import PlannerError
    from planner.contour import parse_contour_request
    from planner.schema import MAX_PROGRAM_BYTES

    try:
        path = Path(args.program)
        if args.program != "-" and path.stat().st_size > MAX_PROGRAM_BYTES:
            raise InputError(f"{args.program}: too_large: program: the program has {path.stat().st_size} bytes, "
                             f"more than the limit of {MAX_PROGRAM_BYTES}")
        text = sys.stdin.read() if args.program == "-" else path.read_text(errors="replace")
    except OSError as exc:
        raise InputError(f"{args.program}: cannot read: {exc.strerror or exc}") from None
    try:
        settings = json.loads(args.settings) if args.settings else {}
    except json.JSONDecodeError as exc:
        raise InputError(f"--settings: not valid JSON: {exc}") from None
    request = {"name": Path(args.program).name, "program": text, "feed": args.feed, "cut_below_m": args.cut_below,
               "settings": settings}
    if args.origin is not None:
        request["origin"] = "fit" if args.origin.strip().lower() == "fit" else parse_pair(args.origin, "--origin")
    if args.tolerance is not None:
        request["tolerance_m"] = args.tolerance
    if args.z_rapid is not None:
        request["z_rapid_m_s"] = args.z_rapid
    if args.z_accel is not None:
        request["z_accel_m_s2"] = args.z_accel
    from app.jobs import ContourJob

    try:
        job = ContourJob(parse_contour_request(request), format=output_format(args), forces=args.forces,
                         source=args.program)
    except PlannerError as exc:
        raise InputError(f"{args.program}: {exc.code}: {exc}") from None
    from app.job_progress import progress_here

    line = ProgressLine(sys.stderr, args.progress)
    try:
        with progress_here(line):
            out = run_here(job, args.program, args.compile)
    finally:
        line.close()
    s = out.summary or {}
    write_output(out.payload or b"", args, job.format, warnings=tuple(s["warnings"]),
                 summary=f"origin [{s['origin'][0]:g}, {s['origin'][1]:g}] m, {s['passes']} passes, cycle "
                 f"{s['cycle_time_s']:.2f} s (cutting {s['cut_time_s']:.2f} s), deviation "
                 f"{s['max_deviation_m'] * 1e3:.4f} mm of {s['tolerance_m'] * 1e3:.4f} mm, max force "
                 f"{s['max_drive_force_n']:.1f} N, compute {s['compute_ms']:.0f} ms")
    return 0


#: a contour shows its progress once it has run this long [s] (``--progress auto``)
PROGRESS_AFTER_S = 2.0


class ProgressLine:
    """The progress of a contour on stderr (issue 35): ``contour: 3/15 passes, 4 s, ~12 s
    left``, the time left as ``GET /v1/jobs/{id}`` states it (:func:`app.job_progress.time_left`).
    ``auto``: from :data:`PROGRESS_AFTER_S` on; ``always``: from the first pass; ``never``.
    On a terminal one line rewritten in place (at most 10 times a second); else a line at most
    every 5 s and at the last pass, so a log stays short."""

    def __init__(self, stream, mode: str = "auto"):
        import time

        self._clock = time.monotonic
        self.stream, self.mode = stream, mode
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self.t0 = self._clock()
        self.started: float | None = None
        self.shown_at: float | None = None

    def __call__(self, done: int, total: int, estimate_s: float | None) -> None:
        now = self._clock()
        if self.started is None:
            self.started = now  # the program is read and estimated: the passes start
        if self.mode == "never" or (self.mode == "auto" and now - self.t0 < PROGRESS_AFTER_S):
            return
        last = done >= total
        if self.shown_at is not None and not last and now - self.shown_at < (0.1 if self.tty else 5.0):
            return
        from app.job_progress import time_left

        left = time_left(done, total, self.started, now, now, estimate_s)
        text = f"contour: {done}/{total} passes, {now - self.t0:.0f} s"
        text += "" if left is None else f", ~{left:.0f} s left"
        self.stream.write(f"\r{text}\x1b[K" if self.tty else text + "\n")
        self.stream.flush()
        self.shown_at = now

    def close(self) -> None:
        """End the terminal's line (nothing was shown: nothing to end)."""
        if self.tty and self.shown_at is not None:
            self.stream.write("\n")
            self.stream.flush()


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


def add_import_parser(sub, full: bool = True) -> None:
    """The ``import`` sub-command; its options (help texts from :class:`planner.schema.ImportOptions`)
    only when ``full``: ``rangeplan --help`` and the other commands do not load the schema."""
    pi = sub.add_parser("import", help="turn a DXF or SVG drawing into a plan request with a layout",
                        description="Closed shapes of the drawing become obstacles (nested ones holes); loose LINE/ARC "
                        "pieces are joined. Lengths in m, angles in rad (in the robot's workspace).")
    pi.set_defaults(func=cmd_import)
    if not full:
        return
    from planner.schema import DRAWING_UNITS, ImportOptions, Layout
    from planner.schema.layout import Cell

    def helptext(field: str) -> str:
        return (ImportOptions.model_fields[field].description or "").replace("%", "%%")

    def cell_help(field: str) -> str:
        return (Cell.model_fields[field].description or "").replace("%", "%%")

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


def _format_name(text: str) -> str:
    """``--format``: one of :data:`app.formats.OUTPUT_FORMATS` (read when the flag is used:
    ``rangeplan --help`` does not import the planner)."""
    from app.formats import OUTPUT_FORMATS

    if text not in OUTPUT_FORMATS:
        raise argparse.ArgumentTypeError(f"invalid choice: {text!r} (choose from "
                                         f"{', '.join(repr(k) for k in OUTPUT_FORMATS)})")
    return text


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The whole parser; given the ``command`` about to run, the other commands' options that
    need heavy imports are left out (``rangeplan --help`` in well under a second)."""
    p = argparse.ArgumentParser(prog="rangeplan", description="Range-space predictive control trajectory planner "
                                "for planar parallel robots (SI units throughout).")
    from planner import __version__

    p.add_argument("--version", action="version", version=f"rangeplan {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    pp = sub.add_parser("plan", help="plan a trajectory for a request file")
    pp.add_argument("input", help="plan request JSON file ('-' for standard input)")
    pp.add_argument("-o", "--output", help="output file: .json (default), .csv, .ngc (G-code), .txt (leg lengths "
                    "for halstreamer) or .dxf; standard output if omitted")
    pp.add_argument("--format", type=_format_name, metavar="FORMAT", help="output format: json, csv or a machine "
                    "format as -o names them (default: from the output file's extension, else json)")
    pp.add_argument("--forces", action="store_true", help="joints format: add the drive forces (N)")
    pp.add_argument("--compact", action="store_true", help="JSON without indentation")
    pp.add_argument("--compile", action="store_true", help="compile the kernels first if they are not compiled yet "
                    "(minutes, once after installing) instead of planning on the numpy reference while they compile "
                    "in the background")
    pp.add_argument("--no-resident", action="store_true", help=argparse.SUPPRESS)  # no resident any more: accepted
    pp.set_defaults(func=cmd_plan)
    add_import_parser(sub, full=command in (None, "import"))
    pc = sub.add_parser("contour", help="plan a G-code program (CAM tool path) within its tolerance",
                        description="Every cut pass (feed moves below the cutting height) is planned within the "
                        "tolerance of the programmed path, each sample and the straight move to the next; rapids "
                        "are free moves; plunges, retracts and G4 at rest. One trajectory for the whole program.")
    pc.add_argument("program", help="G-code file (RS274NGC; '-' for standard input)")
    pc.add_argument("-o", "--output", help="output file: .json (default), .csv, .ngc, .txt or .dxf")
    pc.add_argument("--format", type=_format_name, metavar="FORMAT", help="output format (default: from the extension)")
    pc.add_argument("--origin", metavar="X,Y|fit", help="program zero in the robot frame, m (default 0,0); "
                    "negative: --origin=-0.04,-0.015; 'fit': where the program lies inside the robot's reach "
                    "(the summary says where)")
    pc.add_argument("--tolerance", type=float, metavar="M", help="largest distance from the programmed path, m "
                    "(default: the program's G64 P, else 5e-5)")
    pc.add_argument("--feed", choices=("program", "fastest"), default="program",
                    help="'program': never faster than F (default); 'fastest': as fast as the drives allow")
    pc.add_argument("--cut-below", type=float, default=0.0, metavar="Z",
                    help="feed moves with Z below this cut, m in the program frame (default 0)")
    pc.add_argument("--z-rapid", type=float, metavar="M_S", help="z_rapid_m_s: the Z axis speed, m/s (default 0.05)")
    pc.add_argument("--z-accel", type=float, metavar="M_S2",
                    help="z_accel_m_s2: the Z axis acceleration, m/s^2 (default 1)")
    pc.add_argument("--settings", metavar="JSON", help='plan settings as JSON, e.g. \'{"Ts": 0.005}\'')
    pc.add_argument("--forces", action="store_true", help="joints format: add the drive forces (N)")
    pc.add_argument("--compact", action="store_true", help="JSON without indentation")
    pc.add_argument("--compile", action="store_true", help="compile the kernels first if they are not compiled yet "
                    "(minutes, once after installing) instead of planning on the numpy reference while they compile "
                    "in the background")
    pc.add_argument("--progress", choices=("auto", "always", "never"), default="auto",
                    help="passes done and the time left on stderr: 'auto' once the contour has run "
                    f"{PROGRESS_AFTER_S:g} s (default), 'always', 'never'")
    pc.add_argument("--no-resident", action="store_true", help=argparse.SUPPRESS)
    pc.set_defaults(func=cmd_contour)
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
    """``rangeplan``: every command runs in this process and ends with it (no resident
    planner; the background compile after installing is the one process a command may start,
    README "the first plan"). Run as the program (``argv`` None: the console script,
    ``python -m app.cli``), ``plan`` and ``contour`` end the process themselves once done
    (:func:`_end_process`); given an ``argv`` (a caller in Python), it returns the status."""
    if argv is not None:
        return run(argv)
    code = run(sys.argv[1:])
    if _command(sys.argv[1:]) in ("plan", "contour"):
        _end_process(code)
    return code


def _end_process(code: int) -> None:
    """End this process with ``code`` after the exit handlers (:mod:`atexit`: a temporary
    kernel cache removed, weakref finalizers, logging) and the standard streams are flushed,
    without the interpreter's teardown: freeing the ~830 modules of a plan, numba's and
    LLVM's objects among them, takes ~0.26 CPU s (a quarter of a warm plan's; measured by
    benchmarks/bench_cli.py), for a process about to end. Returns (the normal exit follows)
    where the interpreter has no ``atexit._run_exitfuncs``."""
    import atexit

    run_exit_handlers = getattr(atexit, "_run_exitfuncs", None)
    if run_exit_handlers is None:
        return
    run_exit_handlers()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: the status Python gives a failed flush at exit
            code = 120
    os._exit(code)


def _command(argv: list[str]) -> str:
    """The first word that is no option names the command ("" for ``rangeplan --help``)."""
    return next((a for a in argv if not a.startswith("-")), "")


def seed_kernels() -> None:
    """The image's compiled kernels (its read-only seed) copied to the kernel cache before the
    planner is imported (:func:`app.kernel_cache.seed_kernel_cache`): ``docker run IMAGE rangeplan
    plan ...`` loads them instead of compiling them in the background."""
    from app.kernel_cache import seed_kernel_cache
    from app.settings import SettingsError

    with contextlib.suppress(SettingsError):  # a variable that does not parse is named where it is used
        seed_kernel_cache()


def run(argv: list[str]) -> int:
    """The CLI in this process (Ctrl-C: status 130, from the first import on)."""
    command = _command(argv)
    try:
        args = build_parser(command).parse_args(argv)
        if command in ("plan", "contour", "batch"):
            seed_kernels()
        return args.func(args)
    except InputError as exc:
        print(f"rangeplan: error: {exc}", file=sys.stderr)
        return 2
    except PlannerBug as exc:
        if exc.trace:
            print(exc.trace, end="", file=sys.stderr)
        print(f"rangeplan: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
