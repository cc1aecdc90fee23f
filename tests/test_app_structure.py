"""The structure of app/ (issue 21): one registry of output formats that every consumer
reads, no function over 100 lines, one job model whose outcomes the API, the editor and
batches answer alike."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from app.formats import MACHINE_FORMATS, OUTPUT_FORMATS, format_for_path
from planner.exchange import EXPORT_FORMATS
from tests.support import api_client

ROOT = Path(__file__).resolve().parent.parent


def test_no_function_in_app_is_over_100_lines():
    long = []
    for path in (ROOT / "app").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                if lines > 100:
                    long.append(f"{path.relative_to(ROOT)}:{node.name} {lines}")
    assert not long, long


def test_format_names_are_spelled_only_in_the_registry():
    """No module of app/ spells a machine format's name in code (docstrings aside): each
    reads app.formats; a new format is its writer and one entry in planner/exchange/formats.py."""
    offenders = []
    for path in (ROOT / "app").rglob("*.py"):
        tree = ast.parse(path.read_text())
        docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                      if isinstance(n, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
                      and n.body and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
        literals = {id(c) for n in ast.walk(tree) if isinstance(n, ast.Subscript) and isinstance(n.value, ast.Name)
                    and n.value.id == "Literal" for c in ast.walk(n.slice)}  # e.g. a drawing's Literal["dxf", "svg"]
        for node in ast.walk(tree):
            if (isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings | literals
                    and node.value in EXPORT_FORMATS):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.value!r}")
    assert not offenders, offenders


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    from app.api import create_app
    from app.storage import Store

    app = create_app(Store(tmp_path_factory.mktemp("data")), workers=1, executor="thread")
    with api_client(app) as c:
        yield c


def test_every_consumer_offers_the_registry(client):
    """The HTTP ?format= enum, the CLI, the editor's downloads and the batch formats."""
    assert list(OUTPUT_FORMATS)[:2] == ["json", "csv"] and MACHINE_FORMATS == tuple(EXPORT_FORMATS)
    doc = client.get("/openapi.json").json()
    for path in ("/v1/plan", "/v1/plans/{plan_id}"):
        ops = doc["paths"][path]
        op = ops.get("post") or ops.get("get")
        (param,) = [p for p in op["parameters"] if p["name"] == "format"]
        schema = param["schema"].get("anyOf", [param["schema"]])[0]
        assert schema["enum"] == list(OUTPUT_FORMATS)
        for fmt in MACHINE_FORMATS:
            assert re.search(rf"'{fmt}' \(", param["description"])
    from app.batch.engine import FORMATS
    from app.editor._files import EditorFiles
    assert set(EditorFiles.EXPORTS) == set(MACHINE_FORMATS)
    assert set(FORMATS) - {"none"} <= set(OUTPUT_FORMATS)
    for fmt, spec in OUTPUT_FORMATS.items():
        for suffix in spec.suffixes:
            assert format_for_path(f"out/plan{suffix.upper()}") == fmt
