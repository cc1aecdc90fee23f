"""The exchange formats over HTTP and on the command line: POST /v1/import (raw body and
multipart, options as query parameters, errors naming the cause), ?format=gcode|joints|dxf
on every plan endpoint, `rangeplan import` and `rangeplan plan -o x.ngc|.txt|.dxf`."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from app.api import create_app
from app.storage import Store
from planner.exchange import to_gcode
from planner.schema import PARTIAL_LAYOUT, ImportResult, PlanResult
from planner.schema.drawing import MIN_SCALE
from tests.drawings import DRAWINGS, obstacle_region
from tests.linuxcnc import rs274
from tests.support import TABLE1, TABLE1_PATH, api_client

TABLE = DRAWINGS / "Table-dining-E.dxf"
CLI = [sys.executable, "-m", "app.cli"]
PLACE = {"scale": "0.05", "offset": "0,0.0225", "margin": "0.03", "start": "-0.065,0,0", "end": "0.065,0,0"}


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    app = create_app(Store(tmp_path_factory.mktemp("exchange")), workers=1, timeout_s=60, executor="thread")
    with api_client(app) as c:
        yield c


def test_import_raw_and_multipart_agree(client):
    data = TABLE.read_bytes()
    raw = client.post("/v1/import", params=PLACE, content=data, headers={"Content-Type": "application/dxf"})
    assert raw.status_code == 200, raw.text
    multi = client.post("/v1/import", params=list(PLACE.items()), files={"file": ("table.dxf", data)})
    assert multi.status_code == 200 and multi.json() == raw.json()
    res = ImportResult.model_validate(raw.json(), context=PARTIAL_LAYOUT)
    rep = res.report
    assert rep.units == "mm" and rep.scale == 0.05 and len(rep.shapes) == 1 and rep.shapes[0].source == \
        "chain of 4 ARC + 4 LINE"
    assert np.allclose(res.layout.start, [-0.065, 0, 0]) and np.allclose(res.layout.end, [0.065, 0, 0])
    assert obstacle_region(res.layout).area == pytest.approx(rep.area_m2, rel=1e-9)  # coordinates rounded to 1e-12 m
    # the layout plans as it is
    r = client.post("/v1/plan", json={"layout": raw.json()["layout"]})
    assert r.status_code == 200, r.text


@pytest.mark.parametrize("params, body, ctype, status, code, field", [
    ({}, b"x", "text/plain", 415, "unsupported_media_type", None),
    ({}, b"", "application/dxf", 422, "invalid_drawing", "drawing"),
    ({}, b"not a drawing at all", "application/dxf", 422, "invalid_drawing", "drawing"),
    ({}, b"<svg xmlns='http://www.w3.org/2000/svg'/>", "image/svg+xml", 422, "invalid_drawing", "drawing"),
    ({"scale": "-1"}, None, "application/dxf", 422, "invalid_input", "scale"),
    ({"offset": "1,2,3"}, None, "application/dxf", 422, "too_large", "offset"),  # a list too long: too_large
    ({"units": "furlong"}, None, "application/dxf", 422, "invalid_input", "units"),
    ({"layers": "NOPE"}, None, "application/dxf", 422, "invalid_drawing", "layers"),
    ({"colour": "red"}, None, "application/dxf", 422, "invalid_input", "colour"),
])
def test_import_errors_name_the_cause(client, params, body, ctype, status, code, field):
    r = client.post("/v1/import", params=params, content=TABLE.read_bytes() if body is None else body,
                    headers={"Content-Type": ctype})
    assert r.status_code == status, r.text
    err = r.json()["error"]
    assert err["code"] == code and err["field"] == field and err["message"]


def test_import_multipart_without_a_file(client):
    r = client.post("/v1/import", data={"note": "no file"}, files={"x": ("", b"")}, params={})
    assert r.status_code == 422 and r.json()["error"]["field"] in ("file", "drawing")


def test_plan_formats_on_every_endpoint(client):
    r = client.post("/v1/plan", params={"format": "gcode"}, json=TABLE1)
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/plain")
    plan_id = r.headers["x-plan-id"]
    assert r.headers["content-disposition"] == f'attachment; filename="plan-{plan_id}.ngc"'
    stored = PlanResult.model_validate_json(client.get(f"/v1/plans/{plan_id}").content)
    gcode = client.get(f"/v1/plans/{plan_id}", params={"format": "gcode"}).text
    # the same program from the stored result (the source line names where it came from)
    strip = [line for line in gcode.splitlines() if not line.startswith("(source")]
    assert [line for line in r.text.splitlines() if not line.startswith("(source")] == strip
    assert [line for line in to_gcode(stored).splitlines() if not line.startswith("(source")] == strip
    rs274(r.text)
    rs274(gcode)
    joints = client.get(f"/v1/plans/{plan_id}", params={"format": "joints", "forces": "true"})
    rows = np.array([list(map(float, line.split())) for line in joints.text.splitlines() if line[0] != "#"])
    assert np.allclose(rows[:, :4], stored.drives.length * 1e3, atol=5e-7)
    assert np.allclose(rows[:, 4:], stored.drives.force, atol=5e-7)
    dxf = client.get(f"/v1/plans/{plan_id}", params={"format": "dxf"})
    assert dxf.headers["content-type"] == "image/vnd.dxf" and "$INSUNITS" in dxf.text
    csv = client.get(f"/v1/plans/{plan_id}", params={"format": "csv"})
    assert csv.headers["content-type"].startswith("text/csv")
    # a saved corridor planned straight to the joint stream
    cid = client.post("/v1/corridors", json=TABLE1).json()["id"]
    j = client.post(f"/v1/corridors/{cid}/plan", params={"format": "joints"})
    assert j.status_code == 200 and f"corridor {cid}" in j.text.splitlines()[0]
    bad = client.post("/v1/plan", params={"format": "pdf"}, json=TABLE1)
    assert bad.status_code == 422 and bad.json()["error"]["field"] == "format"


def test_dxf_of_a_layout_plan_has_its_obstacles(client):
    imported = client.post("/v1/import", params=PLACE, content=TABLE.read_bytes(),
                           headers={"Content-Type": "image/vnd.dxf"}).json()
    r = client.post("/v1/plan", json={"layout": imported["layout"]})
    dxf = client.get(f"/v1/plans/{r.json()['plan_id']}", params={"format": "dxf"}).text
    back = client.post("/v1/import", params={"layers": "OBSTACLES"}, content=dxf.encode(),
                       headers={"Content-Type": "application/dxf"}).json()
    assert back["report"]["area_m2"] == pytest.approx(imported["report"]["area_m2"], abs=1e-12)


def test_openapi_documents_import_options_and_formats(client):
    spec = client.get("/openapi.json").json()
    op = spec["paths"]["/v1/import"]["post"]
    names = {p["name"] for p in op["parameters"]}
    assert {"units", "layers", "offset", "rotation", "scale", "join_tolerance", "flatten_tolerance", "margin",
            "bounds_layer", "start", "end"} <= names
    assert {"application/dxf", "image/vnd.dxf", "image/svg+xml", "multipart/form-data"} <= set(
        op["requestBody"]["content"])
    fmt = [p for p in spec["paths"]["/v1/plan"]["post"]["parameters"] if p["name"] == "format"][0]
    assert "gcode" in json.dumps(fmt) and "joints" in json.dumps(fmt) and "dxf" in json.dumps(fmt)


def run(*args):
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=300)


def test_cli_import_then_plan_to_each_machine_format(tmp_path):
    req = tmp_path / "table.json"
    r = run("import", str(TABLE), "--scale", "0.05", "--offset", "0", "0.0225", "--margin", "0.03",
            "--start", "-0.065", "0", "0", "--end", "0.065", "0", "0", "-o", str(req), "--report",
            str(tmp_path / "report.json"))
    assert r.returncode == 0, r.stderr
    assert "1 obstacle(s)" in r.stderr and "units mm (drawing)" in r.stderr
    request = json.loads(req.read_text())
    assert set(request) == {"layout"} and request["layout"]["start"] == [-0.065, 0.0, 0.0]
    assert json.loads((tmp_path / "report.json").read_text())["units"] == "mm"
    for suffix, needle in ((".ngc", "G93"), (".txt", "# leg1_length_mm"), (".dxf", "PATH")):
        out = tmp_path / f"plan{suffix}"
        r = run("plan", str(req), "-o", str(out))
        assert r.returncode == 0, r.stderr
        assert needle in out.read_text()
    rs274((tmp_path / "plan.ngc").read_text())
    r = run("plan", str(TABLE1_PATH), "--format", "joints", "--forces")
    assert r.returncode == 0 and "leg4_force_n" in r.stdout
    assert len([line for line in r.stdout.splitlines() if not line.startswith("#")]) == len(
        json.loads(run("plan", str(TABLE1_PATH), "--compact").stdout)["time"])


@pytest.mark.parametrize("args, needle", [
    (["/nonexistent.dxf"], "cannot read"),
    ([str(TABLE1_PATH)], "not a DXF or SVG"),
    ([str(TABLE), "--layer", "NOPE"], "layers: no geometry on layer(s) 'NOPE'"),
    ([str(TABLE), "--scale", "0"], f"scale: must be >= {MIN_SCALE:g}, got 0"),  # the schema's bound
    ([str(TABLE), "--scale", "0.05", "--cell-size", "-0.01"], "layout.cell.size: must be >= "),
    ([str(TABLE), "--scale", "0.05", "--clearance", "-1"], "layout.clearance: must be >= 0"),
])
def test_cli_import_errors_exit_2_with_one_line(args, needle):
    r = run("import", *args)
    assert r.returncode == 2 and needle in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert "Traceback" not in r.stderr


def test_cli_import_sets_the_cells_and_an_svg_in_mm_says_mm(tmp_path):
    """--cell-size, --cell-shape and --clearance land in the request's layout, and a plan of a
    drawing that needs 1 cm cells then works; an SVG sized width="200mm" reports units mm."""
    req = tmp_path / "table.json"
    r = run("import", str(TABLE), "--scale", "0.05", "--offset", "0", "0.0225", "--margin", "0.03",
            "--start", "-0.065", "0", "0", "--end", "0.065", "0", "0", "--cell-size", "0.01", "--cell-shape",
            "triangle", "--clearance", "0.002", "-o", str(req))
    assert r.returncode == 0, r.stderr
    layout = json.loads(req.read_text())["layout"]
    assert layout["cell"] == {"shape": "triangle", "size": 0.01} and layout["clearance"] == 0.002
    svg = tmp_path / "plate.svg"
    svg.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="200mm" height="100mm" viewBox="0 0 200 100">'
                   '<rect x="80" y="30" width="40" height="40"/></svg>')
    r = run("import", str(svg), "--scale", "0.5", "-o", str(tmp_path / "plate.json"), "--report",
            str(tmp_path / "rep.json"))
    assert r.returncode == 0, r.stderr
    assert "units mm (drawing)" in r.stderr
    rep = json.loads((tmp_path / "rep.json").read_text())
    assert rep["units"] == "mm" and rep["metres_per_unit"] == 1e-3
    assert abs(rep["area_m2"] - (0.04 * 0.5) ** 2) < 1e-9  # 40 mm square at scale 0.5
