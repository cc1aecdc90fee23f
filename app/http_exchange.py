"""HTTP edges of :mod:`planner.exchange`: the drawing upload of ``POST /v1/import`` (raw
body or multipart), its options as query parameters (documented from
:class:`planner.schema.ImportOptions`), and the plan output formats (``?format=``).
"""

from __future__ import annotations

from typing import Any

from fastapi import Request
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.formats import OUTPUT_FORMATS
from planner.errors import PlannerError
from planner.exchange import DRAWING_FORMATS
from planner.schema import ImportOptions

__all__ = ["LIST_OPTIONS", "import_openapi", "import_options", "plan_content", "read_drawing"]

#: options that take several values: repeat the parameter or separate the values by commas
LIST_OPTIONS = ("layers", "offset", "start", "end")
_MULTIPART = "multipart/form-data"


def plan_content() -> dict[str, Any]:
    """The OpenAPI content types of a plan response besides JSON (one per media type of
    :data:`app.formats.OUTPUT_FORMATS`, without parameters)."""
    types = dict.fromkeys(f.media_type.split(";")[0] for f in OUTPUT_FORMATS.values())
    return {t: {"schema": {"type": "string"}} for t in types if t != "application/json"}


def import_openapi() -> dict[str, Any]:
    """``openapi_extra`` of ``POST /v1/import``: the body's content types and one query
    parameter per :class:`ImportOptions` field, with its description."""
    props = ImportOptions.model_json_schema()["properties"]
    params = []
    for name, prop in props.items():
        desc = prop.get("description", "")
        if name in LIST_OPTIONS:
            desc += " (repeat the parameter or separate the values by commas)"
            schema: dict[str, Any] = {"type": "array", "items": {"type": "string" if name == "layers" else "number"}}
        else:
            schema = {k: v for k, v in prop.items() if k not in ("description", "title", "default")}
        params.append({"name": name, "in": "query", "required": False, "description": desc, "schema": schema,
                       "style": "form", "explode": True})
    binary = {"schema": {"type": "string", "format": "binary"}}
    return {"parameters": params, "requestBody": {"required": True, "content": {
        **{ct: binary for ct in DRAWING_FORMATS},
        _MULTIPART: {"schema": {"type": "object", "properties": {"file": {"type": "string", "format": "binary"}},
                                "required": ["file"]}}}}}


def _numeric_options() -> frozenset[str]:
    """The :class:`ImportOptions` fields that hold numbers (or lists of numbers)."""

    def numeric(schema: dict[str, Any]) -> bool:
        if schema.get("type") == "number" or schema.get("type") == "integer":
            return True
        if schema.get("type") == "array":
            return numeric(schema.get("items", {}))
        return any(numeric(s) for s in schema.get("anyOf", ()))

    return frozenset(k for k, v in ImportOptions.model_json_schema()["properties"].items() if numeric(v))


_NUMERIC_OPTIONS = _numeric_options()


def _number(text: str) -> Any:
    """A query parameter's text as the number it spells (``"0.05"``, ``"-1e-3"``), else the
    text itself, which validation then refuses naming the field (the request models take
    JSON numbers only; a query string has none)."""
    try:
        return float(text)
    except ValueError:
        return text


def import_options(request: Request) -> dict[str, Any]:
    """The query parameters as :class:`ImportOptions` input (validated by the caller):
    list options split at commas, numbers read from their text."""
    out: dict[str, Any] = {}
    for key, value in request.query_params.multi_items():
        if key in LIST_OPTIONS:
            out.setdefault(key, []).extend(v.strip() for v in value.split(",") if v.strip())
        else:
            out[key] = value
    for key in _NUMERIC_OPTIONS & out.keys():
        value = out[key]
        out[key] = [_number(v) for v in value] if isinstance(value, list) else _number(value)
    return out


async def read_drawing(request: Request) -> tuple[bytes, str | None, str | None]:
    """The uploaded drawing: ``(bytes, file name, content type)``; 415 for a content type
    that is not a drawing or multipart, a PlannerError (422) for an empty or missing file."""
    ct = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if ct == _MULTIPART:
        try:
            form = await request.form()
        except StarletteHTTPException:  # the body limit (413, app.middleware) while the form was read
            raise
        except Exception as exc:  # a malformed multipart body
            raise PlannerError("invalid_input", f"malformed multipart body: {exc}", "file") from None
        upload = next((v for v in form.values() if not isinstance(v, str)), None)
        if upload is None:
            raise PlannerError("invalid_input", "the multipart body has no file: upload the drawing as a file "
                               "field (e.g. -F file=@drawing.dxf)", "file")
        data = await upload.read()
        filename, part_type = upload.filename, upload.content_type
    elif ct in DRAWING_FORMATS:
        data, filename, part_type = await request.body(), None, ct
    else:
        raise StarletteHTTPException(415, f"content type {ct or '(none)'!r} is not a drawing: send the DXF or SVG "
                                     f"as the body with Content-Type {', '.join(DRAWING_FORMATS)}, or as "
                                     f"{_MULTIPART}")
    if not data:
        raise PlannerError("invalid_drawing", "the drawing is empty", "drawing")
    return data, filename, part_type
