"""Command line: ``rangeplan plan INPUT.json [-o OUT.json | OUT.csv]`` and ``rangeplan serve``.

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


def cmd_plan(args) -> int:
    from planner import PlannerError, plan, to_csv

    request = load_request(args.input)
    try:
        result = plan(request)
    except PlannerError as exc:
        raise InputError(f"{args.input}: {exc.code}: {exc}") from None
    if args.output and args.output.lower().endswith(".csv"):
        text = to_csv(result)
    else:
        text = json.dumps(result.to_json_dict(), indent=None if args.compact else 1)
    if args.output and args.output != "-":
        Path(args.output).write_text(text + ("" if text.endswith("\n") else "\n"))
        m = result.metrics
        print(f"wrote {args.output}: {m.steps} steps, {m.duration_s:.2f} s, end error "
              f"{m.end_error_m * 1e3:.3f} mm, max force {m.max_drive_force_n:.1f} N, "
              f"compute {m.compute_ms:.0f} ms", file=sys.stderr)
    else:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
    return 0


def cmd_serve(args) -> int:
    from app.server import serve

    return serve(host=args.host, port=args.port, editor_port=args.editor_port, editor=not args.no_editor,
                 allow_unauthenticated=args.allow_unauthenticated)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="rangeplan", description="Range-space predictive control trajectory planner "
                                "for planar parallel robots (SI units throughout).")
    sub = p.add_subparsers(dest="command", required=True)
    pp = sub.add_parser("plan", help="plan a trajectory for a request file")
    pp.add_argument("input", help="plan request JSON file ('-' for standard input)")
    pp.add_argument("-o", "--output", help="output file: .json (default) or .csv; standard output if omitted")
    pp.add_argument("--compact", action="store_true", help="JSON without indentation")
    pp.set_defaults(func=cmd_plan)
    ps = sub.add_parser("serve", help="serve the HTTP API and the browser editor")
    ps.add_argument("--host", default=os.environ.get("RANGEPLAN_HOST", "127.0.0.1"),
                    help="API host (env RANGEPLAN_HOST, default 127.0.0.1)")
    ps.add_argument("--port", type=int, default=int(os.environ.get("RANGEPLAN_PORT", "8000")),
                    help="API port (env RANGEPLAN_PORT, default 8000)")
    ps.add_argument("--editor-port", type=int, default=int(os.environ.get("RANGEPLAN_EDITOR_PORT", "8080")),
                    help="editor (viser) port (env RANGEPLAN_EDITOR_PORT, default 8080)")
    ps.add_argument("--no-editor", action="store_true", help="serve the API only")
    ps.add_argument("--allow-unauthenticated", action="store_true",
                    help="serve on a non-loopback address without a token (RANGEPLAN_API_TOKEN); refused otherwise")
    ps.set_defaults(func=cmd_serve)
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
