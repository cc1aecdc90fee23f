"""pydantic validation errors as :class:`~planner.errors.PlannerError`: the first failing
field as a path (``segments[3].lower``, ``robot.platform.mass``) and one plain message.

Validators of this package raise ``PydanticCustomError(code, message, {"field": ...})``:
``code`` is the error code (``invalid_input`` or ``too_large``) and ``field`` a path below
the failing model's location, so a check on a whole segment can still name ``lower``.
Union members are tagged ``~name`` and dropped from paths.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from pydantic import ValidationError

from ..errors import PlannerError

__all__ = ["field_path", "error_details", "planner_error", "format_validation_error"]

#: pydantic's numeric bound errors, said as the planner says them ("must be > 0, got -1")
_BOUNDS = {"greater_than": ("gt", ">"), "greater_than_equal": ("ge", ">="), "less_than": ("lt", "<"),
           "less_than_equal": ("le", "<=")}
#: pydantic error types that mean "more than a bound on work" (list lengths, cell counts)
_TOO_LARGE = {"too_long", "too_large"}


def field_path(loc: Sequence[Any], extra: str | None = None) -> str | None:
    """A pydantic ``loc`` (plus a validator's relative ``extra`` path) as ``a.b[3].c``;
    a leading ``body`` or ``query`` (FastAPI) and union tags (``~...``) are left out."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in ("body", "query") and not out:  # FastAPI's location of the field
            continue
        elif isinstance(part, str) and part.startswith("~"):
            continue
        else:
            out += f".{part}" if out else str(part)
    if extra:
        out = f"{out}.{extra}" if out else extra
    return out or None


def error_details(errors: Sequence[Any]) -> list[dict[str, Any]]:
    """``{code, field, message}`` for each pydantic error (``exc.errors()``)."""
    out = []
    for e in errors:
        ctx = e.get("ctx") or {}
        kind = e.get("type", "")
        msg = e.get("msg", "invalid value")
        if kind == "json_invalid":
            out.append({"code": "invalid_input", "field": None, "message": f"body is not valid JSON: "
                        f"{ctx.get('error', msg)}"})
            continue
        if kind == "missing" and tuple(e.get("loc", ())) == ("body",):
            msg = "a JSON body is required"
        if kind == "extra_forbidden":
            msg = "unknown field: not a field of this object"
        elif kind in _BOUNDS and _BOUNDS[kind][0] in ctx:
            key, op = _BOUNDS[kind]
            msg = f"must be {op} {ctx[key]}, got {e.get('input')!r}"
        code = "too_large" if kind in _TOO_LARGE else "invalid_input"
        out.append({"code": code, "field": field_path(e.get("loc", ()), ctx.get("field")), "message": msg})
    return out


def planner_error(exc: ValidationError, prefix: str | None = None) -> PlannerError:
    """The first error of ``exc`` as a PlannerError (``prefix`` is put before its field)."""
    details = error_details(exc.errors())
    first = details[0] if details else {"code": "invalid_input", "field": None, "message": "invalid input"}
    fld = first["field"]
    if prefix:
        fld = f"{prefix}.{fld}" if fld and not fld.startswith("[") else f"{prefix}{fld or ''}"
    return PlannerError(first["code"], first["message"], fld)


def format_validation_error(exc: ValidationError) -> str:
    """One line naming the first failing fields and the causes (for the CLI)."""
    details = error_details(exc.errors())
    parts = [f"{d['field'] or 'body'}: {d['message']}" for d in details[:3]]
    more = f" (+{len(details) - 3} more)" if len(details) > 3 else ""
    return "; ".join(parts) + more
