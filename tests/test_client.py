"""The typed client (app.client) against a real `rangeplan serve` process with a token, as
deployed: the manual's example (docs/client.md) runs as written, every method returns the planner's own
models, and every error (server answer, client-side validation, transport, a missing or
wrong token) is one exception type with code, message and field."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest

from app.client import Client, RangeplanError
from tests.drawings import DRAWINGS
from tests.linuxcnc import rs274
from tests.support import ROOT, TABLE1
from tests.test_server_process import Server, free_port

TOKEN = "client-test-token-0123456789"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    srv = Server(tmp_path_factory.mktemp("client"), free_port(), {"RANGEPLAN_API_TOKEN": TOKEN})
    yield srv
    srv.stop()


def manual_example() -> str:
    """The client example of the manual's Python client page."""
    text = (ROOT / "docs" / "client.md").read_text()
    section = text[text.index("# Python client"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_manual_example_runs_against_a_real_server(server, tmp_path):
    code = manual_example()
    assert 8 <= len(code.strip().splitlines()) <= 16
    code = code.replace("http://127.0.0.1:8000", server.url)
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300,
                       env={**os.environ, "PYTHONPATH": str(ROOT), "RANGEPLAN_API_TOKEN": TOKEN})
    assert r.returncode == 0, r.stderr
    out = r.stdout.strip().splitlines()
    assert out[-1].startswith("invalid_input segments")  # the error example: one exception type
    program = ROOT / "table.ngc"
    try:
        assert program.read_text().startswith("(rangeplan plan: around the table")
        rs274(program.read_text())
    finally:
        program.unlink(missing_ok=True)


def test_every_method_returns_the_planner_models(server):
    with Client(server.url, token=TOKEN) as rp:
        result = rp.plan(TABLE1)
        assert result.plan_id and result.pose.shape[1] == 3
        again = rp.fetch_plan(result.plan_id)
        assert np.array_equal(again.pose, result.pose)
        rec = rp.save(TABLE1)
        assert rec.request.segments is not None and rec.id in [r["id"] for r in rp.list()]
        renamed = rp.save({**TABLE1, "name": "renamed"}, rec.id)
        assert renamed.id == rec.id and rp.fetch(rec.id).name == "renamed"
        planned = rp.plan_corridor(rec.id)
        assert np.array_equal(planned.pose, result.pose)
        joints = rp.export(result.plan_id, "joints", forces=True)
        assert "leg4_force_n" in joints
        assert rp.export(result.plan_id, "csv").startswith("time_s,")
        drawing = rp.import_drawing(DRAWINGS / "Kitchen-cooker-V.dxf", scale=0.1, layers=["Contour"])
        assert drawing.report.holes == 4 and drawing.layout.start is None
        svg = b"<svg xmlns='http://www.w3.org/2000/svg' width='10mm' height='10mm'><circle cx='5' cy='5' r='2'/></svg>"
        assert rp.import_drawing(svg, format="svg").layout.obstacles[0].type == "circle"
        rp.delete(rec.id)
        assert rec.id not in [r["id"] for r in rp.list()]


def test_errors_are_one_exception_type(server):
    with Client(server.url, token=TOKEN) as rp:
        with pytest.raises(RangeplanError) as e:  # the server's 404
            rp.fetch("nope")
        assert (e.value.code, e.value.status) == ("not_found", 404)
        with pytest.raises(RangeplanError) as e:  # the planner's 422, naming the field
            rp.plan({"segments": [{"lower": [0, 0, 0], "upper": [0, 0, 0]},
                                  {"lower": [0.3, 0, 0], "upper": [0.3, 0, 0]}]})
        assert e.value.code == "unreachable" and e.value.status == 422 and e.value.field
        with pytest.raises(RangeplanError) as e:  # validated before sending
            rp.plan({"segments": [{"lower": [0, 0, 0], "upper": [-1, 0, 0]}]})
        assert e.value.code == "invalid_input" and e.value.field.startswith("segments") and e.value.status is None
        with pytest.raises(RangeplanError) as e:
            rp.import_drawing(b"not a drawing", format="dxf")
        assert (e.value.code, e.value.field) == ("invalid_drawing", "drawing")
        with pytest.raises(RangeplanError) as e:
            rp.import_drawing(ROOT / "README.md")
        assert e.value.field == "format"
    with Client(f"http://127.0.0.1:{free_port()}", timeout=2) as down, pytest.raises(RangeplanError) as e:
        down.list()
    assert e.value.code == "unavailable"


def test_the_token_is_sent_and_a_missing_or_wrong_one_is_a_clear_error(server, monkeypatch):
    monkeypatch.delenv("RANGEPLAN_API_TOKEN", raising=False)
    for token in (None, "wrong-token-0123456789"):
        with Client(server.url, token=token) as rp, pytest.raises(RangeplanError) as e:
            rp.list()
        assert (e.value.code, e.value.status) == ("unauthorized", 401) and "token" in e.value.message
    monkeypatch.setenv("RANGEPLAN_API_TOKEN", TOKEN)  # the default: the token of the environment
    with Client(server.url) as rp:
        assert isinstance(rp.list(), list)
