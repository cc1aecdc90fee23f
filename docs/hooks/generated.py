"""MkDocs hook: the HTTP API page (``http-api.md``) from the service's own OpenAPI document,
and the command reference of ``cli.md`` from the CLI's own parser.

At build time the app is composed as ``rangeplan serve`` composes it (:func:`app.api.create_app`,
on a throw-away store, with a token; no worker starts: the lifespan never runs) and its OpenAPI document is
written as Markdown in place of the page's ``<!-- openapi -->`` marker: every endpoint with its
parameters, request body and responses, then every model with its fields. Offline: no Swagger
or ReDoc script, nothing fetched. A route, parameter or model added to the service appears on
the next build.
"""

from __future__ import annotations

import json
import os
import re
import sys
import tempfile
from pathlib import Path
from typing import Any

MARKER = "<!-- openapi -->"
PAGE = "http-api.md"
CLI_MARKER = "<!-- cli-help -->"
CLI_PAGE = "cli.md"
METHODS = ("get", "post", "put", "patch", "delete")


def openapi_document(root: Path) -> dict[str, Any]:
    """The OpenAPI document of the app in the tree at ``root``."""
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))  # the tree's app, not another installed copy
    import secrets

    from app.api import create_app
    from app.security import AccessPolicy
    from app.storage import Store

    # as a server with a token documents itself (the bearer scheme and the 401 of /v1); the
    # token is a throw-away, never written anywhere
    access = AccessPolicy(token=secrets.token_urlsafe(32))
    with tempfile.TemporaryDirectory(prefix="rangeplan-docs-") as data:
        return create_app(Store(Path(data)), access=access).openapi()


def anchor(name: str) -> str:
    return "model-" + re.sub(r"[^A-Za-z0-9_-]+", "-", name).strip("-").lower()


def prose(text: Any) -> str:
    """A description as Markdown: ``<`` and ``>`` outside code spans escaped, so that
    ``Bearer <token>`` is text, not an HTML tag."""
    parts = re.split(r"(`+[^`]*`+)", str(text))
    return "".join(part if part.startswith("`") else part.replace("<", "&lt;").replace(">", "&gt;")
                   for part in parts)


def cell(text: Any) -> str:
    """One Markdown table cell: one line, pipes escaped."""
    return prose(" ".join(str(text).split())).replace("|", "\\|") if text not in (None, "") else ""


def type_of(schema: dict[str, Any]) -> str:
    """A schema's type in a few words, models linked to their section."""
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[-1]
        return f"[{name}](#{anchor(name)})"
    for key in ("anyOf", "oneOf", "allOf"):
        if key in schema:
            parts = [type_of(s) for s in schema[key]]
            return " \\| ".join(dict.fromkeys(parts))
    if "const" in schema:
        return f"`{schema['const']!r}`".replace("'", '"')
    if "enum" in schema:
        return " \\| ".join(f"`{v}`" for v in schema["enum"])
    kind = schema.get("type")
    if kind == "array":
        items = schema.get("items")
        if "prefixItems" in schema:
            return "[" + ", ".join(type_of(s) for s in schema["prefixItems"]) + "]"
        return f"array of {type_of(items)}" if items else "array"
    if kind == "object" and isinstance(schema.get("additionalProperties"), dict):
        return f"object of {type_of(schema['additionalProperties'])}"
    if isinstance(kind, list):
        return " \\| ".join(kind)
    return kind or "any"


def bounds(schema: dict[str, Any]) -> str:
    """The schema's constraints (bounds, lengths, pattern) and default, as text."""
    words = []
    for key, text in (("minimum", ">= {}"), ("exclusiveMinimum", "> {}"), ("maximum", "<= {}"),
                      ("exclusiveMaximum", "< {}"), ("minItems", "at least {} items"),
                      ("maxItems", "at most {} items"), ("minLength", "at least {} characters"),
                      ("maxLength", "at most {} characters"), ("pattern", "pattern `{}`")):
        if key in schema:
            words.append(text.format(schema[key]))
    for sub in schema.get("anyOf", []):
        inner = bounds({k: v for k, v in sub.items() if k != "default"})
        if inner:
            words.append(inner)
    if "default" in schema:
        words.append(f"default `{json.dumps(schema['default'])}`")
    return "; ".join(words)


def content_table(content: dict[str, Any]) -> list[str]:
    rows = []
    for media, body in content.items():
        schema = body.get("schema", {})
        rows.append(f"`{media}`: {type_of(schema) if schema else 'any'}")
    return rows


def endpoint(path: str, method: str, op: dict[str, Any]) -> list[str]:
    out = [f"### {method.upper()} `{path}` {{#{method}-{anchor(path)[6:] or 'root'}}}", ""]
    if op.get("summary"):
        out += [f"**{op['summary'].strip()}**", ""]
    if op.get("description"):
        out += [prose(op["description"].strip()), ""]
    if op.get("security") is not None:
        schemes = sorted({name for req in op["security"] for name in req})
        if schemes:
            out += [f"Authentication: {', '.join(schemes)} (when the server has a token).", ""]
    params = op.get("parameters", [])
    if params:
        out += ["| parameter | in | type | required | description |", "|---|---|---|---|---|"]
        for p in params:
            schema = p.get("schema", {})
            desc = "; ".join(x for x in (cell(p.get("description") or schema.get("description")),
                                         cell(bounds(schema))) if x)
            out.append(f"| `{p['name']}` | {p['in']} | {type_of(schema)} | {'yes' if p.get('required') else 'no'} "
                       f"| {desc} |")
        out.append("")
    body = op.get("requestBody")
    if body:
        req = "required" if body.get("required") else "optional"
        out += [f"Request body ({req}): " + "; ".join(content_table(body.get("content", {}))), ""]
    responses = op.get("responses", {})
    if responses:
        out += ["| status | description | content |", "|---|---|---|"]
        for status, resp in responses.items():
            out.append(f"| {status} | {cell(resp.get('description'))} "
                       f"| {cell('; '.join(content_table(resp.get('content', {}))))} |")
        out.append("")
    return out


def model(name: str, schema: dict[str, Any]) -> list[str]:
    out = [f"### {name} {{#{anchor(name)}}}", ""]
    if schema.get("description"):
        out += [prose(schema["description"].strip()), ""]
    props = schema.get("properties")
    if props:
        required = set(schema.get("required", []))
        out += ["| field | type | required | description |", "|---|---|---|---|"]
        for field, sub in props.items():
            desc = "; ".join(x for x in (cell(sub.get("description")), cell(bounds(sub))) if x)
            out.append(f"| `{field}` | {type_of(sub)} | {'yes' if field in required else 'no'} | {desc} |")
        out.append("")
    elif "enum" in schema or "anyOf" in schema or "oneOf" in schema or "type" in schema:
        out += [f"Type: {type_of(schema)}", ""]
    return out


def render(doc: dict[str, Any]) -> str:
    info = doc.get("info", {})
    out = [f"Generated from the OpenAPI {doc.get('openapi', '')} document of {info.get('title', '')} "
           f"{info.get('version', '')} (`app.api.create_app().openapi()`; the running service serves "
           "the same document at `/openapi.json`).", ""]
    if info.get("description"):
        out += [prose(info["description"].strip()), ""]
    schemes = doc.get("components", {}).get("securitySchemes", {})
    if schemes:
        out += ["## Authentication", ""]
        for name, s in schemes.items():
            kind = " ".join(str(s.get(k)) for k in ("type", "scheme", "in", "name") if s.get(k))
            out += [f"- `{name}` ({kind}): {cell(s.get('description'))}"]
        out.append("")
    out += ["## Endpoints", ""]
    for path, item in doc.get("paths", {}).items():
        for method in METHODS:
            if method in item:
                out += endpoint(path, method, item[method])
    out += ["## Models", ""]
    for name, schema in sorted(doc.get("components", {}).get("schemas", {}).items()):
        out += model(name, schema)
    return "\n".join(out)


def cli_help(root: Path) -> str:
    """``rangeplan --help`` and every command's ``--help``, from the CLI's own parser."""
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    import argparse

    from app.cli import build_parser

    columns = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "88"  # argparse wraps to the terminal's width
    try:
        parser = build_parser()
        out = ["```text", "$ rangeplan --help", parser.format_help().rstrip(), "```", ""]
        for action in parser._actions:  # the commands, in the order `rangeplan --help` lists them
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    out += [f"### rangeplan {name}", "", "```text", f"$ rangeplan {name} --help",
                            sub.format_help().rstrip(), "```", ""]
    finally:
        if columns is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = columns
    return "\n".join(out)


def on_page_markdown(markdown: str, page, config, files) -> str:  # mkdocs' hook signature
    """The generated parts of ``http-api.md`` and ``cli.md`` in place of their markers."""
    root = Path(config.config_file_path).resolve().parent
    for name, marker, make in ((PAGE, MARKER, lambda: render(openapi_document(root))),
                               (CLI_PAGE, CLI_MARKER, lambda: cli_help(root))):
        if page.file.src_uri == name:
            if marker not in markdown:
                raise ValueError(f"{name} has no {marker} marker for its generated part")
            return markdown.replace(marker, make())
    return markdown


#: a Sphinx cross-reference role in a docstring as mkdocstrings renders it (``:class:`~a.B```
#: -> ``:class:<code>~a.B</code>``)
ROLE = re.compile(r":(?:class|func|meth|attr|data|mod|exc|obj|const):<code>(~?)([^<]*)</code>")


def on_page_content(html: str, page, config, files) -> str:  # mkdocs' hook signature
    """The docstrings' Sphinx roles as plain code (``~`` keeps the last name, as Sphinx shows it)."""
    return ROLE.sub(lambda m: f"<code>{m.group(2).rsplit('.', 1)[-1] if m.group(1) else m.group(2)}</code>", html)

