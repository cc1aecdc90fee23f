"""``POST /v1/contour``, ``rangeplan contour`` and ``Client.contour`` (issue 22): the same plan
as the library, the formats, the stored plan, the bad programs as 4xx / exit 2 naming the line."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from app.api import create_app
from app.storage import Store
from planner.contour import plan_contour
from tests.linuxcnc import rs274
from tests.support import api_client
from tests.test_contour import ORIGIN, SMALL


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    app = create_app(Store(tmp_path_factory.mktemp("data")), workers=1, timeout_s=120, max_body_bytes=256 * 1024)
    with api_client(app) as c:
        yield c


@pytest.fixture(scope="module")
def posted(client):
    r = client.post("/v1/contour", json={"program": SMALL, "origin": ORIGIN, "feed": "program"})
    assert r.status_code == 200, r.text
    return r


def test_http_equals_the_library_and_is_stored(client, posted):
    body = posted.json()
    lib = plan_contour({"program": SMALL, "origin": ORIGIN, "feed": "program"})
    assert np.allclose(body["pose"], lib.pose, atol=1e-12)
    assert body["contour"]["program_line"] == lib.contour.program_line
    assert body["contour"]["max_deviation_m"] <= body["contour"]["tolerance_m"]
    plan_id = posted.headers["X-Plan-Id"]
    again = client.get(f"/v1/plans/{plan_id}")
    assert again.status_code == 200 and again.json()["contour"]["cycle_time_s"] == body["contour"]["cycle_time_s"]
    ngc = client.get(f"/v1/plans/{plan_id}", params={"format": "gcode"})
    assert ngc.status_code == 200
    canon = rs274(ngc.text)  # LinuxCNC reads the exported program
    assert sum("STRAIGHT_FEED" in ln for ln in canon) > 100


@pytest.mark.parametrize("body, status, code, words", [
    ({"program": SMALL.replace("G1 X0", "G41 X0")}, 422, "invalid_input", ["line 11", "G41"]),
    ({"program": SMALL.replace("G2 X20", "G18 G2 X20")}, 422, "invalid_input", ["line 10", "G18"]),
    ({"origin": [0.3, 0.0]}, 422, "unreachable", ["line 7"]),
    ({"tolerance_m": 5e-6}, 422, "invalid_input", ["tolerance_m"]),
    ({"program": SMALL * 2000}, 413, "too_large", []),
    ({"program": "F100\nG1 Z-1\n" + "G1 X50\nG1 X-50\n" * 3000, "feed": "fastest"}, 422, "too_much_work",
     ["estimated"]),
])
def test_bad_programs_are_4xx_naming_the_cause(client, body, status, code, words):
    r = client.post("/v1/contour", json={"program": SMALL, "origin": ORIGIN, **body})
    assert r.status_code == status, r.text
    err = r.json()["error"]
    assert err["code"] == code
    for w in words:
        assert w in err["message"] + (err["field"] or ""), err


def test_cli_writes_the_same_plan_and_exits_2_on_a_bad_program(tmp_path):
    prog = tmp_path / "part.ngc"
    prog.write_text(SMALL)
    out = tmp_path / "part.json"
    r = subprocess.run([sys.executable, "-m", "app.cli", "contour", str(prog), f"--origin={ORIGIN[0]},{ORIGIN[1]}",
                        "-o", str(out)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())
    assert res["contour"]["max_deviation_m"] <= res["contour"]["tolerance_m"]
    bad = tmp_path / "bad.ngc"
    bad.write_text(SMALL.replace("G1 Y20", "G81 Y20"))
    r = subprocess.run([sys.executable, "-m", "app.cli", "contour", str(bad), "-o", str(out)], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 2 and "line 9" in r.stderr and "G81" in r.stderr and "Traceback" not in r.stderr
    big = tmp_path / "big.ngc"
    with big.open("w") as f:  # a 50 MB file: refused before reading it
        f.write("G1 X1\n" * (50_000_000 // 6))
    r = subprocess.run([sys.executable, "-m", "app.cli", "contour", str(big)], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2 and "too_large" in r.stderr


def test_typed_client_contour(client, posted, tmp_path):
    from app.client import Client, RangeplanError

    prog = tmp_path / "part.ngc"
    prog.write_text(SMALL)
    with Client(str(client.base_url), transport=client._transport) as rp:
        res = rp.contour(prog, origin=ORIGIN)
        assert res.contour is not None and res.plan_id
        assert np.allclose(res.pose, posted.json()["pose"], atol=1e-12)
        with pytest.raises(RangeplanError) as err:
            rp.contour(SMALL.replace("G1 Y20", "G83 Y20"), origin=ORIGIN)
        assert err.value.status == 422 and "G83" in err.value.message
        with pytest.raises(RangeplanError) as err:  # checked before sending
            rp.contour(SMALL, tolerance_m=1e-7)
        assert err.value.field == "tolerance_m" and err.value.status is None
