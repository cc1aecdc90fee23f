"""The HTTP API through FastAPI's TestClient (the real app, real worker processes, a
temporary SQLite store): Table I over HTTP equals the CLI, CSV with units, the bad-input
matrix with field paths and stable codes, saved corridors, stored plans, time limit,
concurrent requests, landing page, OpenAPI descriptions."""

from __future__ import annotations

import copy
import csv
import io
import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from app.api import create_app
from app.storage import Store
from planner.errors import PlannerError
from planner.schema import field_path
from tests.support import api_client, miscalibrate_slack, robot_description

ROOT = Path(__file__).resolve().parent.parent
TABLE1_PATH = ROOT / "app" / "static" / "examples" / "table1.json"
TABLE1 = json.loads(TABLE1_PATH.read_text())
P0 = {"lower": [0.0, 0.0, 0.0], "upper": [0.0, 0.0, 0.0]}


def seg(lo, hi):
    return {"lower": list(lo), "upper": list(hi)}


def shifted(req: dict, dx: float, dy: float) -> dict:
    out = copy.deepcopy(req)
    for s in out["segments"]:
        for k in ("lower", "upper"):
            s[k][0] += dx
            s[k][1] += dy
    return out


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    return Store(tmp_path_factory.mktemp("data"))


@pytest.fixture(scope="module")
def client(store):
    app = create_app(store, workers=2, timeout_s=60, max_body_bytes=256 * 1024)
    with api_client(app) as c:
        yield c


@pytest.fixture(scope="module")
def table1_http(client):
    r = client.post("/v1/plan", json=TABLE1)
    assert r.status_code == 200, r.text
    return r


def strip_volatile(result: dict) -> dict:
    out = copy.deepcopy(result)
    out["metrics"].pop("compute_ms", None)
    out["metrics"].pop("qp_time_ms", None)  # measured too (constrained mode, the default)
    out.pop("plan_id", None)
    return out


def assert_error(r, status: int, code: str, field: str | None | type(...) = ...):
    assert r.status_code == status, r.text
    err = r.json()["error"]
    assert err["code"] == code, err
    assert isinstance(err["message"], str) and err["message"]
    if field is not ...:
        assert err["field"] == field, err
    return err


# ---------------------------------------------------------------------------------------
# service

def test_health_and_robots(client):
    assert client.get("/health").json()["status"] == "ok"
    ready = client.get("/ready").json()
    assert ready["pool"]["workers"] == 2 and ready["pool"]["mode"] == "process"
    robots = client.get("/v1/robots").json()
    names = [r["name"] for r in robots]
    assert "moving-slide" in names
    ms = client.get("/v1/robots/moving-slide").json()
    assert len(ms["base_pivots"]) == next(r["legs"] for r in robots if r["name"] == "moving-slide")
    assert_error(client.get("/v1/robots/../../etc"), 404, "not_found")
    assert_error(client.get("/v1/robots/no-such-robot"), 404, "not_found")


# ---------------------------------------------------------------------------------------
# planning

def test_table1_over_http_equals_cli(table1_http, tmp_path):
    """Same request, same numbers: the HTTP result equals `rangeplan plan` bit for bit
    (apart from the measured compute time and the stored plan's id)."""
    out = tmp_path / "cli.json"
    p = subprocess.run([sys.executable, "-m", "app.cli", "plan", str(TABLE1_PATH), "-o", str(out)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    cli = json.loads(out.read_text())
    http = table1_http.json()
    assert strip_volatile(http) == strip_volatile(cli)
    # and it is a real plan: ends at the end point, inside the corridor, at rest
    pose = np.array(http["pose"])
    assert np.hypot(*(pose[-1, :2] - np.array(TABLE1["segments"][-1]["lower"][:2]))) < 1e-3
    assert np.allclose(pose[0], TABLE1["segments"][0]["lower"])
    assert http["metrics"]["settled"] is True
    assert len(http["time"]) == len(http["pose"]) == len(http["drives"]["force"])


def test_stored_plan_is_fetched_again(client, table1_http, store):
    plan_id = table1_http.json()["plan_id"]
    assert table1_http.headers["location"] == f"/v1/plans/{plan_id}"
    again = client.get(f"/v1/plans/{plan_id}")
    assert again.status_code == 200
    assert again.json() == table1_http.json()
    assert store.plan_info(plan_id)["request"]["segments"] == TABLE1["segments"]
    assert_error(client.get("/v1/plans/" + "f" * 32), 404, "not_found")


def _parse_csv(text: str):
    rows = list(csv.reader(io.StringIO(text)))
    return rows[0], np.array(rows[1:], dtype=float)


@pytest.mark.parametrize("how", ["accept", "query"])
def test_csv_has_units_and_same_numbers(client, table1_http, how):
    if how == "accept":
        r = client.post("/v1/plan", json=TABLE1, headers={"Accept": "text/csv"})
    else:
        r = client.post("/v1/plan?format=csv", json=TABLE1)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("text/csv")
    header, data = _parse_csv(r.text)
    units = ("_s", "_m", "_rad", "_m_s", "_rad_s", "_m_s2", "_rad_s2", "_n")
    assert all(h.endswith(units) for h in header), header
    res = table1_http.json()
    assert data.shape[0] == len(res["time"])
    assert np.array_equal(data[:, header.index("time_s")], res["time"])
    assert np.array_equal(data[:, [header.index(c) for c in ("x_m", "y_m", "psi_rad")]], res["pose"])
    forces = np.array(res["drives"]["force"])
    assert np.array_equal(data[:, header.index("leg4_force_n")], forces[:, 3])
    # the stored plan in CSV too
    r2 = client.get(f"/v1/plans/{res['plan_id']}", params={"format": "csv"})
    assert np.array_equal(_parse_csv(r2.text)[1], data)


# ---------------------------------------------------------------------------------------
# bad input: 422 (or 413) with the field path and a plain message, never 5xx

def _bad_cases():
    t = TABLE1
    lower_gt_upper = copy.deepcopy(t)
    lower_gt_upper["segments"][3]["lower"][0] = 0.5
    return [
        ("lower > upper", lower_gt_upper, "invalid_input", "segments[3].lower"),
        ("one segment", {"segments": [P0]}, "invalid_input", "segments"),
        ("no corridor", {"robot": "moving-slide"}, "invalid_input", "segments"),
        ("pose of 2", {"segments": [{"lower": [0, 0], "upper": [0, 0, 0]}, P0]}, "invalid_input",
         "segments[0].lower"),
        ("string number", {"segments": [{"lower": [0, 0, "a"], "upper": [0, 0, 0]}, P0]}, "invalid_input",
         "segments[0].lower[2]"),
        ("Ts = 0", {**t, "settings": {"Ts": 0}}, "invalid_input", "settings.Ts"),
        ("Ts < 0", {**t, "settings": {"Ts": -0.01}}, "invalid_input", "settings.Ts"),
        ("horizon too long", {**t, "settings": {"N": 10_000}}, "invalid_input", "settings.N"),
        ("samples too many", {**t, "settings": {"samples_per_segment": 10 ** 7}}, "invalid_input",
         "settings.samples_per_segment"),
        ("total steps", {"segments": [P0] * 150, "settings": {"samples_per_segment": 2000}}, "too_large",
         "settings.samples_per_segment"),
        ("unknown field", {**t, "colour": "red"}, "invalid_input", "colour"),
        ("unknown setting", {**t, "settings": {"speed": 1}}, "invalid_input", "settings.speed"),
        ("unknown robot", {**t, "robot": "no-such-robot"}, "invalid_input", "robot"),
        ("negative k_u", {**t, "settings": {"k_u": -1}}, "invalid_input", "settings.k_u"),
        ("unreachable", {"segments": [P0, seg([0.3, 0, 0], [0.3, 0, 0])]}, "unreachable", "segments[1]"),
        ("not settled", {**t, "settings": {"mode": "paper", "tail_max_s": 0.0, "samples_per_segment": 1}},
         "not_settled", "settings.tail_max_s"),
    ]


@pytest.mark.parametrize("name, body, code, field", _bad_cases(), ids=[c[0] for c in _bad_cases()])
def test_bad_input_matrix(client, name, body, code, field):
    assert_error(client.post("/v1/plan", json=body), 422, code, field)


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity", "1e999"])
def test_non_finite_numbers_rejected(client, literal):
    text = json.dumps(TABLE1).replace("-0.08", literal, 1)
    r = client.post("/v1/plan", content=text, headers={"Content-Type": "application/json"})
    assert_error(r, 422, "invalid_input", "segments[0].lower[0]")


def test_invalid_json_and_missing_body(client):
    r = client.post("/v1/plan", content=b'{"segments": [', headers={"Content-Type": "application/json"})
    err = assert_error(r, 422, "invalid_input")
    assert "JSON" in err["message"]
    assert_error(client.post("/v1/plan"), 422, "invalid_input")
    assert_error(client.post("/v1/plan", json=[1, 2]), 422, "invalid_input")


def test_body_size_limit_by_header_and_by_stream(client):
    big = {**TABLE1, "name": "x" * 100, "segments": TABLE1["segments"] * 400}  # > 256 KiB
    text = json.dumps(big).encode()
    assert len(text) > 256 * 1024
    err = assert_error(client.post("/v1/plan", content=text, headers={"Content-Type": "application/json"}),
                       413, "too_large", None)
    assert "262144" in err["message"]

    def chunks():  # chunked transfer: no Content-Length, the streamed size is counted
        for i in range(0, len(text), 16384):
            yield text[i:i + 16384]
    r = client.post("/v1/plan", content=chunks(), headers={"Content-Type": "application/json"})
    assert "content-length" not in {k.lower() for k in r.request.headers}
    assert_error(r, 413, "too_large", None)
    # the service is fine afterwards
    assert client.get("/health").status_code == 200


def test_field_path_strips_body_and_union_tags(client):
    assert field_path(("body", "segments", 3, "lower")) == "segments[3].lower"
    assert field_path(("body", "robot", "~description", "legs", "~each", 2, "rod")) == "robot.legs[2].rod"
    assert field_path(("body",)) is None
    # the union branch the client meant is named, not the first branch (a robot name)
    desc = robot_description("moving-slide")
    desc["platform"]["mass"] = 0
    assert_error(client.post("/v1/plan", json={**TABLE1, "robot": desc}), 422, "invalid_input", "robot.platform.mass")
    desc = robot_description("moving-slide")
    desc["legs"] = [copy.deepcopy(desc["legs"]) for _ in range(4)]
    desc["legs"][2]["rod"]["mass"] = -1.0
    r = client.post("/v1/plan", json={**TABLE1, "robot": desc})
    assert_error(r, 422, "invalid_input", "robot.legs[2].rod.mass")


# ---------------------------------------------------------------------------------------
# concurrency and the compute limit

def test_concurrent_plans_do_not_mix(client, store):
    """Six different corridors (Table I shifted) planned at once: each answer is the plan of
    its own request (starts and ends at its own points) and its stored copy matches."""
    shifts = [(dx, dy) for dx in (-0.02, 0.0, 0.02) for dy in (-0.02, 0.01)]
    results: dict[int, dict] = {}

    def go(i, dx, dy):
        r = client.post("/v1/plan", json=shifted(TABLE1, dx, dy))
        results[i] = r.json() if r.status_code == 200 else {"status": r.status_code, "body": r.text}

    threads = [threading.Thread(target=go, args=(i, dx, dy)) for i, (dx, dy) in enumerate(shifts)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    ids = set()
    for i, (dx, dy) in enumerate(shifts):
        res = results[i]
        assert "pose" in res, res
        pose = np.array(res["pose"])
        start = np.array(TABLE1["segments"][0]["lower"][:2]) + [dx, dy]
        end = np.array(TABLE1["segments"][-1]["lower"][:2]) + [dx, dy]
        assert np.allclose(pose[0, :2], start, atol=1e-12)
        assert np.hypot(*(pose[-1, :2] - end)) < 1e-3
        assert store.get_plan(res["plan_id"]) == res
        ids.add(res["plan_id"])
    assert len(ids) == len(shifts)


def long_corridor() -> dict:
    """Table I's cells back and forth: 100 segments x 2000 samples = 200 000 steps, the
    largest request the planner accepts (minutes of compute today, seconds if 50x faster)."""
    mid = TABLE1["segments"][1:-1]
    body = (mid + mid[::-1]) * 5
    return {"segments": [TABLE1["segments"][0], *body[:98], TABLE1["segments"][-1]],
            "settings": {"samples_per_segment": 2000}}


def test_pool_time_limit_replaces_worker():
    from app.jobs import Done, SleepJob
    from app.workers import JobTimeout, PlanPool
    pool = PlanPool(workers=1, timeout_s=0.5)
    try:
        with pytest.raises(JobTimeout):
            pool.run(SleepJob(60))
        assert pool.replaced == 1
        assert pool.run(SleepJob(0)) == Done(b"{}")
    finally:
        pool.close()


def slow_corridor(n: int = 40) -> dict:
    """A random walk of point segments in the constrained mode: the corridor cannot be kept
    within the limits, every step solves the slack problem (~10 ms instead of ~0.3 ms). Since
    issue 20 the estimate counts (and the plan keeps to) the slack work it allows: with the
    slack costs miscalibrated (:func:`tests.support.miscalibrate_slack`) the work estimate
    (~0.1 s) is far below the time it takes (seconds)."""
    pts = np.cumsum(np.random.default_rng(0).uniform(-0.001, 0.001, (n, 2)), axis=0)
    return {"segments": [{"lower": [float(x), float(y), 0.0], "upper": [float(x), float(y), 0.0]} for x, y in pts],
            "settings": {"mode": "constrained", "require_settled": False}}


@pytest.mark.serial  # then Table I within a 1 s compute limit
def test_compute_limit_stops_runaway_plan(store, monkeypatch, tmp_path):
    """A plan longer than the limit (its estimate miscalibrated) answers 422 `timeout`
    promptly; the killed worker is replaced and the next plan succeeds; /health answered
    meanwhile."""
    miscalibrate_slack(monkeypatch, tmp_path)
    monkeypatch.setenv("RANGEPLAN_WORKER_START", "exec")  # workers started now, with that environment
    app = create_app(store, workers=1, timeout_s=1.0)
    with api_client(app) as c:
        done = {}

        def slow():
            done["r"] = c.post("/v1/plan", json=slow_corridor())

        th = threading.Thread(target=slow)
        th.start()
        h = c.get("/health")
        assert h.status_code == 200
        th.join(60)
        assert not th.is_alive()
        err = assert_error(done["r"], 422, "timeout", None)
        assert "1 s" in err["message"]
        assert c.get("/ready").json()["pool"]["replaced_workers"] == 1
        assert c.post("/v1/plan", json=TABLE1).status_code == 200


@pytest.mark.serial  # a bound of 0.5 s
def test_too_much_work_is_refused_in_well_under_a_second(store, monkeypatch):
    """The largest corridor the schema accepts (200 000 steps) against a 1 s limit (the
    synchronous one and a job's): refused with too_much_work naming the estimate, the limit and
    the field, before any worker is busy (the pool stays idle and plans Table I at once), not
    turned into a job (issue 35: over the jobs' limit too)."""
    monkeypatch.setenv("RANGEPLAN_JOB_TIMEOUT_S", "1")
    app = create_app(store, workers=1, timeout_s=1.0)
    with api_client(app) as c:
        assert c.post("/v1/plan", json=TABLE1).status_code == 200
        t0 = time.perf_counter()
        r = c.post("/v1/plan", json=long_corridor())
        took = time.perf_counter() - t0
        err = assert_error(r, 422, "too_much_work", "settings.samples_per_segment")
        assert took < 0.5, took
        assert "limit of 1 s" in err["message"] and "100 segments x 2000 samples" in err["message"]
        est = float(err["message"].split("estimated ")[1].split(" s")[0])
        assert est > 1.0
        constrained = {**TABLE1, "settings": {"mode": "constrained", "N": 150, "backend": "reference"}}
        assert_error(c.post("/v1/plan", json=constrained), 422, "too_much_work", "settings.N")
        assert c.get("/ready").json()["pool"]["in_flight"] == 0
        assert c.post("/v1/plan", json=TABLE1).status_code == 200


# ---------------------------------------------------------------------------------------
# saved corridors

def all_corridors(client) -> list[dict]:
    """Every corridor's summary, page after page."""
    out, cursor = [], None
    while True:
        page = client.get("/v1/corridors", params={"limit": 200, **({"cursor": cursor} if cursor else {})}).json()
        out += page["items"]
        cursor = page["next_cursor"]
        if cursor is None:
            return out


def test_corridor_lifecycle(client):
    original = {**TABLE1, "name": "lifecycle"}
    r = client.post("/v1/corridors", json=original)
    assert r.status_code == 201, r.text
    rec = r.json()
    cid = rec["id"]
    assert r.headers["location"] == f"/v1/corridors/{cid}"
    assert rec["name"] == "lifecycle" and rec["request"]["segments"] == TABLE1["segments"]
    assert client.get(f"/v1/corridors/{cid}").json() == rec
    assert cid in [c["id"] for c in all_corridors(client)]

    moved = {**shifted(TABLE1, 0.01, 0.0), "name": "moved"}
    upd = client.put(f"/v1/corridors/{cid}", json=moved).json()
    assert upd["name"] == "moved" and upd["request"]["segments"] == moved["segments"]

    r = client.post(f"/v1/corridors/{cid}/plan")
    assert r.status_code == 200, r.text
    pose = np.array(r.json()["pose"])
    assert np.hypot(*(pose[-1, :2] - np.array(moved["segments"][-1]["lower"][:2]))) < 1e-3
    assert client.get(f"/v1/plans/{r.json()['plan_id']}").json() == r.json()
    csv_r = client.post(f"/v1/corridors/{cid}/plan", headers={"Accept": "text/csv"})
    assert csv_r.headers["content-type"].startswith("text/csv")

    assert client.delete(f"/v1/corridors/{cid}").status_code == 204
    for r in (client.get(f"/v1/corridors/{cid}"), client.delete(f"/v1/corridors/{cid}"),
              client.put(f"/v1/corridors/{cid}", json=TABLE1), client.post(f"/v1/corridors/{cid}/plan")):
        assert_error(r, 404, "not_found", None)


def test_corridor_validated_before_saving(client):
    n = len(all_corridors(client))
    bad = copy.deepcopy(TABLE1)
    bad["segments"][2]["upper"][1] = -1.0
    assert_error(client.post("/v1/corridors", json=bad), 422, "invalid_input", "segments[2].lower")
    assert_error(client.post("/v1/corridors", json={"segments": [P0]}), 422, "invalid_input", "segments")
    assert len(all_corridors(client)) == n


# ---------------------------------------------------------------------------------------
# segmentation

LAYOUT = {"robot": "moving-slide",
          "layout": {"bounds": {"lower": [-0.1, -0.05], "upper": [0.1, 0.08]},
                     "obstacles": [{"type": "rectangle", "lower": [-0.02, -0.05], "upper": [0.01, 0.03]}],
                     "clearance": 0.0, "cell": {"shape": "square", "size": 0.02},
                     "start": [-0.08, 0.0, 0.0], "end": [0.07, 0.0, 0.0]}}


def test_segment_layout(client):
    r = client.post("/v1/segment", json=LAYOUT)
    assert r.status_code == 200, r.text
    s = r.json()
    cells = {c["id"]: c for c in s["cells"]}
    assert s["path"] and all(cells[i]["state"] == "free" for i in s["path"])
    segs = s["segments"]
    assert segs[0]["lower"] == segs[0]["upper"] == LAYOUT["layout"]["start"]
    assert segs[-1]["lower"] == segs[-1]["upper"] == LAYOUT["layout"]["end"]
    # the corridor goes around the obstacle: no path cell's box overlaps its interior
    ob = LAYOUT["layout"]["obstacles"][0]
    for sg in segs[1:-1]:
        lo, hi = np.array(sg["lower"][:2]), np.array(sg["upper"][:2])
        overlap = np.minimum(hi, ob["upper"]) - np.maximum(lo, ob["lower"])
        assert not np.all(overlap > 1e-9), sg


def test_segment_errors(client):
    assert_error(client.post("/v1/segment", json=TABLE1), 422, "invalid_input", "layout")
    walled = copy.deepcopy(LAYOUT)
    walled["layout"]["obstacles"] = [{"type": "rectangle", "lower": [-0.01, -0.05], "upper": [0.01, 0.08]}]
    assert_error(client.post("/v1/segment", json=walled), 422, "no_path")
    tiny = copy.deepcopy(LAYOUT)
    tiny["layout"]["cell"]["size"] = 1e-5
    assert_error(client.post("/v1/segment", json=tiny), 422, "too_large")
    # a layout plans too (segmentation inside the plan)
    r = client.post("/v1/plan", json=LAYOUT)
    assert r.status_code == 200, r.text
    pose = np.array(r.json()["pose"])
    assert np.hypot(*(pose[-1, :2] - np.array(LAYOUT["layout"]["end"][:2]))) < 1e-3


# ---------------------------------------------------------------------------------------
# landing page and OpenAPI

def test_landing_page(client):
    r = client.get("/")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    html = r.text
    assert 'href="/docs"' in html and "app.js" in html and "8080" in html
    js = client.get("/app.js")
    assert js.status_code == 200 and "/v1/plan" in js.text
    assert client.get("/examples/table1.json").json() == TABLE1


def test_openapi_every_field_described_with_unit_models(client):
    spec = client.get("/openapi.json").json()
    schemas = spec["components"]["schemas"]
    undocumented = []
    names = [n for n in schemas if n not in ("HTTPValidationError", "ValidationError")]
    for want in ("PlanRequest", "Segment", "Settings", "PlanResult", "Metrics", "Drives", "CorridorSamples",
                 "CorridorRecord", "Layout", "RobotDescription", "SegmentationResult", "Timing"):
        assert any(n == want or n.startswith(f"{want}-") for n in names), (want, names)
    for name in names:
        for prop, sch in schemas[name].get("properties", {}).items():
            if "description" not in sch and "$ref" not in sch and not any("$ref" in a for a in sch.get("anyOf", [])):
                undocumented.append(f"{name}.{prop}")
    assert not undocumented, undocumented
    # the 422 responses document the one error shape, not FastAPI's default
    plan_422 = spec["paths"]["/v1/plan"]["post"]["responses"]["422"]["content"]["application/json"]["schema"]
    assert plan_422["$ref"].endswith("/ErrorResponse")
    assert "text/csv" in spec["paths"]["/v1/plan"]["post"]["responses"]["200"]["content"]


def test_non_utf8_body_is_invalid_input(client):
    r = client.post("/v1/plan", content=b"\xff\xfe\x00{", headers={"Content-Type": "application/json"})
    assert_error(r, 422, "invalid_input", None)


def test_degenerate_robot_is_422_singular_not_500(client):
    """Found by the schemathesis run: a custom robot whose pivots all coincide (zero-length
    legs) made the planner's linear algebra fail; the answer is a 422 naming the robot."""
    leg = {"cylinder": {"com": 0.0, "inertia": 0.0, "mass": 0.0}, "rod": {"com": 0.0, "inertia": 0.0, "mass": 0.0},
           "force_max": 5e-324, "length_max": 1.0, "length_min": 5e-324, "speed_max": 5e-324}
    robot = {"base_pivots": [[0.0, 0.0]] * 3, "platform_pivots": [[0.0, 0.0]] * 3, "legs": leg,
             "platform": {"inertia": 5e-324, "mass": 5e-324}}
    r = client.post("/v1/plan", json={"robot": robot, "segments": [P0, P0]})
    assert r.status_code == 422, r.text
    assert r.json()["error"]["code"] in ("singular", "invalid_input")
    assert r.json()["error"]["field"] is not None and r.json()["error"]["field"].startswith("robot")


# ---------------------------------------------------------------------------------------
# the workers' result encoding (orjson with a quick finiteness check; the stdlib otherwise)

def _same_json_values(a, b) -> bool:
    """Equal, float for float bit for bit (so -0.0 != 0.0), and int stays int."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        return a.hex() == b.hex()
    if isinstance(a, dict):
        return list(a) == list(b) and all(_same_json_values(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(_same_json_values(x, y) for x, y in zip(a, b))
    return a == b


def test_result_encoding_has_the_stdlib_numbers():
    from app.result_json import dumps as _dumps
    rng = np.random.default_rng(7)
    rows = (rng.normal(size=(50, 3)) * 10.0 ** rng.integers(-300, 300, size=(50, 3))).tolist()
    result = {"name": "coin\u00e7on \u2013 \u00b5m", "plan_id": None, "steps": 3, "settled": True,
              "time": [0.0, 0.01, 0.02, 1e-7, 1e16, 1e22, 5e-324, -0.0, 1.7976931348623157e308],
              "pose": rows, "pair": (1.5, -2.5), "np": np.float64(0.1) * 3,
              "huge": [1e308, 1e308], "nested": {"a": [[1, 2.5], [True, None]], "b": []}}
    out = _dumps(result)
    assert isinstance(out, bytes)
    stdlib = json.loads(json.dumps(result, allow_nan=False))
    assert _same_json_values(json.loads(out), stdlib)
    # what orjson would write differently (non-string keys) is the stdlib's to encode
    assert json.loads(_dumps({"a": {1: 2.0}})) == {"a": {"1": 2.0}}


@pytest.mark.parametrize("where, put", [
    ("result.pose[17][1]", lambda r: r["pose"][17].__setitem__(1, float("nan"))),
    ("result.time[3]", lambda r: r["time"].__setitem__(3, float("inf"))),
    ("result.metrics.energy", lambda r: r["metrics"].__setitem__("energy", -float("inf"))),
    ("result.pair[0]", lambda r: r.__setitem__("pair", (float("nan"), 1.0))),
    ("result.drives.force[0][2]", lambda r: r["drives"]["force"][0].__setitem__(2, float("nan"))),
])
def test_non_finite_result_is_diverged_naming_the_number(where, put):
    from app.result_json import dumps as _dumps
    from planner.errors import PlannerError
    result = {"time": [0.01 * k for k in range(20)], "pose": [[0.1, 0.2, 0.0]] * 20,
              "metrics": {"energy": 1.0, "steps": 19}, "pair": (1.0, 2.0),
              "drives": {"force": [[1.0, 2.0, 3.0, 4.0] for _ in range(20)]}}
    result["pose"] = [list(p) for p in result["pose"]]
    put(result)
    with pytest.raises(PlannerError) as exc:
        _dumps(result)
    assert exc.value.code == "diverged" and exc.value.field == "settings"
    assert f"at {where};" in exc.value.message


def test_worker_plans_builtin_robot_like_the_planner():
    """The worker keeps one model per built-in robot: its results are the planner's own,
    and an unknown robot name is still the planner's error naming the field."""
    from app.jobs import Done, PlanJob, run_job
    from planner import parse_request
    from tests.support import plan_json
    job = PlanJob(parse_request(TABLE1), "json")
    for _ in range(2):
        out = run_job(job)
        assert isinstance(out, Done) and out.plan_id is None and out.payload is not None
        assert strip_volatile(json.loads(out.payload)) == strip_volatile(plan_json(TABLE1))
    with pytest.raises(PlannerError) as exc:  # validated before it reaches a worker
        parse_request({**TABLE1, "robot": "no-such-robot"})
    assert exc.value.code == "invalid_input" and exc.value.field == "robot"


def _openapi_validator(client, name: str):
    """A JSON-schema validator for ``#/components/schemas/<name>`` of the served OpenAPI
    document (OpenAPI 3.1 schemas are JSON Schema 2020-12)."""
    from jsonschema import Draft202012Validator

    spec = client.get("/openapi.json").json()
    schemas = spec["components"]["schemas"]
    key = name if name in schemas else f"{name}-Output"
    return Draft202012Validator({"$ref": f"#/components/schemas/{key}", "components": spec["components"]})


def _assert_closed(schema: dict, schemas: dict, seen: set) -> None:
    """Every object schema reachable from ``schema`` forbids fields it does not list."""
    if isinstance(schema, dict):
        ref = schema.get("$ref")
        if ref:
            name = ref.rsplit("/", 1)[-1]
            if name not in seen:
                seen.add(name)
                _assert_closed(schemas[name], schemas, seen)
            return
        if schema.get("type") == "object" and "properties" in schema:
            assert schema.get("additionalProperties") is False, schema.get("title")
        for v in schema.values():
            _assert_closed(v, schemas, seen)
    elif isinstance(schema, list):
        for v in schema:
            _assert_closed(v, schemas, seen)


@pytest.mark.parametrize("case", ["paper", "constrained", "layout", "fastest"])
def test_real_results_validate_against_the_openapi_schema(client, case):
    """The OpenAPI result schema lists every field a real result carries (it forbids any
    other) in both modes, for a layout plan and for a fastest-timing plan."""
    body = {"paper": TABLE1, "constrained": {**TABLE1, "settings": {"mode": "constrained"}},
            "layout": LAYOUT, "fastest": {**TABLE1, "settings": {"mode": "constrained", "fastest": True}}}[case]
    r = client.post("/v1/plan", json=body)
    assert r.status_code == 200, r.text
    validator = _openapi_validator(client, "PlanResult")
    errors = sorted(validator.iter_errors(r.json()), key=lambda e: list(e.path))
    assert not errors, [f"{list(e.path)}: {e.message}" for e in errors[:5]]
    spec = client.get("/openapi.json").json()
    _assert_closed(validator.schema, spec["components"]["schemas"], set())
    res = r.json()
    if case in ("constrained", "fastest"):
        assert res["metrics"]["contained"] is True and res["metrics"]["qp_solver"] == "stagewise"
    assert res["timing"]["samples_per_segment"] == res["settings"]["samples_per_segment"]


def test_other_responses_validate_against_the_openapi_schema(client):
    r = client.post("/v1/segment", json=LAYOUT)
    assert r.status_code == 200, r.text
    assert not list(_openapi_validator(client, "SegmentationResult").iter_errors(r.json()))
    r = client.get("/v1/robots/moving-slide")
    assert r.status_code == 200 and not list(_openapi_validator(client, "RobotDescription").iter_errors(r.json()))
    assert r.json()["platform"]["mass"] > 0
    r = client.post("/v1/corridors", json={**TABLE1, "name": "schema check"})
    assert r.status_code == 201 and not list(_openapi_validator(client, "CorridorRecord").iter_errors(r.json()))
