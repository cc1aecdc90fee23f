"""Hostile numbers in drawings and programs (issue 33): NaN, infinities, 1e308, -0, deep
nests of groups and huge transforms are refused with a 4xx naming the element, entity or
line, never a 500; and a 500 (an unexpected error) is logged at error level with its
traceback and the request's id."""

from __future__ import annotations

import contextlib
import io
import logging
import math

import ezdxf
import pytest
from ezdxf.lldxf.const import DXFError
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app.api import create_app
from app.storage import Store
from tests.support import api_client

#: numbers as an SVG or G-code author could write them (and some no one should)
HOSTILE = ["nan", "NaN", "inf", "-inf", "Infinity", "1e308", "-1e308", "1e309", "1.7976931348623157e308", "-0",
           "0", "1", "-1", "3.5", "1e-320", "1e20", "-1e20", "1e6", "12"]
number = st.one_of(st.sampled_from(HOSTILE),
                   st.floats(allow_nan=True, allow_infinity=True).map(repr),
                   st.integers(-10 ** 30, 10 ** 30).map(str))
finite = st.one_of(st.sampled_from([1e308, -1e308, 1e300, -0.0, 0.0, 5.0, 1e20, -1e20, 5e-324]),
                   st.floats(allow_nan=False, allow_infinity=False))
EXAMPLES = settings(max_examples=60, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    app = create_app(Store(tmp_path_factory.mktemp("hostile")), workers=1, timeout_s=30, executor="thread")
    with api_client(app, raise_server_exceptions=False) as c:
        yield c


def _refused(r) -> None:
    """A 4xx (or a 200: some hostile values are harmless) with the one error shape, never a 5xx."""
    assert r.status_code < 500, r.text
    if r.status_code >= 400:
        assert r.json()["error"]["message"], r.text


# ---------------------------------------------------------------------------------------
# SVG

@st.composite
def svg_shape(draw) -> str:
    n = lambda: draw(number)  # noqa: E731
    kind = draw(st.sampled_from(["rect", "circle", "ellipse", "line", "polygon", "path", "path-curves"]))
    if kind == "rect":
        return f'<rect x="{n()}" y="{n()}" width="{n()}" height="{n()}"/>'
    if kind == "circle":
        return f'<circle cx="{n()}" cy="{n()}" r="{n()}"/>'
    if kind == "ellipse":
        return f'<ellipse cx="{n()}" cy="{n()}" rx="{n()}" ry="{n()}"/>'
    if kind == "line":
        return f'<line x1="{n()}" y1="{n()}" x2="{n()}" y2="{n()}"/>'
    if kind == "polygon":
        return f'<polygon points="{n()},{n()} {n()},{n()} {n()},{n()}"/>'
    if kind == "path":
        return f'<path d="M {n()} {n()} L {n()} {n()} L {n()} {n()} Z"/>'
    return (f'<path d="M 0 0 C {n()} {n()} {n()} {n()} 10 10 Q {n()} {n()} 20 0 '
            f'A {n()} {n()} {n()} 0 1 {n()} {n()} Z"/>')


@st.composite
def transform(draw) -> str:
    n = lambda: draw(number)  # noqa: E731
    return draw(st.sampled_from([f"scale({n()})", f"scale({n()} {n()})", f"translate({n()} {n()})",
                                 f"rotate({n()})", f"matrix({n()} {n()} {n()} {n()} {n()} {n()})",
                                 f"skewX({n()})", ""]))


@st.composite
def hostile_svg(draw) -> bytes:
    shapes = "".join(draw(st.lists(svg_shape(), min_size=1, max_size=4)))
    shapes += '<rect x="0" y="0" width="10" height="10"/>'  # a shape that is fine, so that the rest decides
    for _ in range(draw(st.integers(0, 4))):
        shapes = f'<g transform="{draw(transform())}">{shapes}</g>'
    if draw(st.booleans()):  # a deep nest of groups
        depth = draw(st.sampled_from([50, 500, 3000]))
        shapes = '<g transform="scale(10)">' * depth + shapes + "</g>" * depth
    size = draw(st.sampled_from(["", 'width="100" height="100"', f'width="{draw(number)}mm" height="100mm"',
                                 f'viewBox="0 0 {draw(number)} {draw(number)}" width="100mm" height="100mm"']))
    return f'<svg xmlns="http://www.w3.org/2000/svg" {size}>{shapes}</svg>'.encode()


@EXAMPLES
@given(svg=hostile_svg())
def test_hostile_svg_is_refused_never_a_5xx(client, svg):
    r = client.post("/v1/import", content=svg, headers={"Content-Type": "image/svg+xml"})
    _refused(r)


@pytest.mark.parametrize(("body", "names"), [
    ('<g transform="scale(1e300)"><g transform="scale(1e300)"><rect id="r7" x="0" y="0" width="10" height="10"/>'
     '</g></g>', ['<rect id=\'r7\'>', "not a finite number"]),
    ('<circle cx="1e308" cy="0" r="1e308"/>', ["<circle> number 1", "not a finite number"]),
    ('<polygon points="0,0 1e308,0 0,1e308"/>', ["<polygon> number 1", "beyond the limit of 1000 m"]),
    ('<path d="M 0 0 L 1e308 0 L 1e308 1e308 Z"/>', ["<path> number 1", "beyond the limit of 1000 m"]),
])
def test_svg_refusal_names_the_element_and_the_cause(client, body, names):
    svg = f'<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">{body}</svg>'.encode()
    r = client.post("/v1/import", content=svg, headers={"Content-Type": "image/svg+xml"})
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_drawing", r.text
    for name in names:
        assert name in r.json()["error"]["message"], r.text


# ---------------------------------------------------------------------------------------
# DXF

def _dxf(build) -> bytes:
    doc = ezdxf.new()
    doc.header["$INSUNITS"] = 4
    build(doc, doc.modelspace())
    out = io.StringIO()
    doc.write(out)
    return out.getvalue().encode()


@st.composite
def hostile_dxf(draw) -> bytes:
    entities = draw(st.lists(st.sampled_from(["line", "circle", "arc", "lwpolyline", "ellipse", "spline", "insert"]),
                             min_size=1, max_size=4))
    values = draw(st.lists(finite | st.sampled_from([math.nan, math.inf, -math.inf]), min_size=8, max_size=8))

    def add(doc, msp, kind: str) -> None:
        a, b, c, d, e, f, g, h = values
        if kind == "line":
            msp.add_line((a, b), (c, d))
        elif kind == "circle":
            msp.add_circle((a, b), e)
        elif kind == "arc":
            msp.add_arc((a, b), e, f, g)
        elif kind == "lwpolyline":
            msp.add_lwpolyline([(a, b, 0, 0, h), (c, d), (e, f)], close=True)
        elif kind == "ellipse":
            msp.add_ellipse((a, b), major_axis=(c, d, 0), ratio=0.5)
        elif kind == "spline":
            msp.add_spline([(a, b), (c, d), (e, f), (g, h)])
        else:  # nested blocks with huge scales
            inner = doc.blocks.new(name=f"IN{len(doc.blocks)}")
            inner.add_circle((a, 0), 5)
            outer = doc.blocks.new(name=f"OUT{len(doc.blocks)}")
            outer.add_blockref(inner.name, (b, c), dxfattribs={"xscale": e, "yscale": f, "rotation": g})
            msp.add_blockref(outer.name, (0, 0), dxfattribs={"xscale": h, "yscale": h})

    def build(doc, msp):
        msp.add_lwpolyline([(0, 0), (10, 0), (10, 10)], close=True)  # a shape that is fine
        for kind in entities:
            with contextlib.suppress(DXFError):  # values ezdxf refuses to write (a zero major axis)
                add(doc, msp, kind)

    return _dxf(build)


@EXAMPLES
@given(dxf=hostile_dxf())
def test_hostile_dxf_is_refused_never_a_5xx(client, dxf):
    r = client.post("/v1/import", content=dxf, headers={"Content-Type": "application/dxf"})
    _refused(r)


def test_dxf_refusal_names_the_entity_and_the_cause(client):
    def build(doc, msp):
        msp.add_lwpolyline([(0, 0), (10, 0), (10, 10)], close=True)
        msp.add_circle((math.nan, 0), 5)

    r = client.post("/v1/import", content=_dxf(build), headers={"Content-Type": "application/dxf"})
    assert r.status_code == 422, r.text
    message = r.json()["error"]["message"]
    assert "CIRCLE (handle " in message and "not a finite number" in message, message

    def far(doc, msp):
        msp.add_lwpolyline([(0, 0), (1e300, 0), (10, 1e300)], close=True)

    r = client.post("/v1/import", content=_dxf(far), headers={"Content-Type": "application/dxf"})
    assert r.status_code == 422 and "LWPOLYLINE (handle " in r.json()["error"]["message"], r.text
    assert "beyond the limit of 1000 m" in r.json()["error"]["message"]


def test_spline_of_many_fit_points_is_refused_before_ezdxf_builds_it(client):
    """Issue 33: a closed spline through 20 000 fit points (no control points) held a worker
    10-22 s until the 2 GiB cap, answered as "planning this request"; ezdxf interpolates fit
    points through a dense system (~n^2). Counted before, refused at once naming the entity."""
    import time

    import numpy as np

    a = np.linspace(0, 2 * math.pi, 20_000, endpoint=False)

    def build(doc, msp):
        msp.add_lwpolyline([(0, 0), (10, 0), (10, 10)], close=True)
        sp = msp.add_spline(np.c_[50 * np.cos(a), 50 * np.sin(a)].tolist())
        sp.closed = True

    data = _dxf(build)
    t0 = time.process_time()
    r = client.post("/v1/import", content=data, headers={"Content-Type": "application/dxf"})
    assert time.process_time() - t0 < 5.0
    assert r.status_code in (413, 422), r.text
    err = r.json()["error"]
    assert err["code"] == "too_large" and "SPLINE (handle " in err["message"] and "20000 fit points" in err["message"]
    assert "control points" in err["message"] and "planning this request" not in err["message"]

    def controls(doc, msp):  # the same count as control points flattens in linear time: refused over its bound
        msp.add_open_spline(np.c_[50 * np.cos(a), 50 * np.sin(a)].tolist())

    r = client.post("/v1/import", content=_dxf(controls), headers={"Content-Type": "application/dxf"})
    assert r.status_code in (413, 422) and "20000 control points" in r.json()["error"]["message"], r.text


def test_memory_error_of_an_import_does_not_say_planning():
    from app.failures import out_of_memory

    msg = out_of_memory(2048, "import")["message"]
    assert "reading this drawing" in msg and "planning" not in msg and "flatten_tolerance" in msg
    assert "contouring this program" in out_of_memory(2048, "contour")["message"]
    assert "planning this request" in out_of_memory(2048)["message"]


# ---------------------------------------------------------------------------------------
# G-code programs

@st.composite
def hostile_program(draw) -> str:
    word = st.builds(lambda letter, v: f"{letter}{v}", st.sampled_from("XYIJRF"), number)
    lines = ["G21 G90", "G1 X0 Y0 F100", "G1 Z-1"]
    for _ in range(draw(st.integers(1, 4))):
        g = draw(st.sampled_from(["G1", "G2", "G3", "G0", "G20 G1"]))
        lines.append(" ".join([g, *draw(st.lists(word, min_size=1, max_size=4))]))
    return "\n".join([*lines, "M2"]) + "\n"


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(program=hostile_program())
def test_hostile_program_is_refused_never_a_5xx(client, program):
    r = client.post("/v1/contour", json={"program": program, "settings": {"backend": "reference"}})
    _refused(r)


def test_program_beyond_the_workspace_limit_names_its_line(client):
    program = "G20 G90\nG1 X0 Y0 F999999\nG1 Z-1\nG1 X50000 Y0\nM2\n"  # 1.27 km in inches, at 420 m/s
    r = client.post("/v1/contour", json={"program": program})
    assert r.status_code == 422, r.text
    err = r.json()["error"]
    assert err["field"] == "program" and err["message"].startswith("line 4:") and "1000 m" in err["message"]


# ---------------------------------------------------------------------------------------
# the error log of a 500

def test_a_500_is_logged_at_error_level_with_its_traceback_and_request_id(client, caplog, monkeypatch):
    import planner.exchange as exchange

    def broken(*args, **kwargs):
        raise RuntimeError("a planner bug")

    monkeypatch.setattr(exchange, "import_drawing", broken)
    with caplog.at_level(logging.INFO, logger="rangeplan"):
        r = client.post("/v1/import", content=b'<svg xmlns="http://www.w3.org/2000/svg"/>',
                        headers={"Content-Type": "image/svg+xml", "X-Request-ID": "hostile-1"})
    assert r.status_code == 500 and r.headers["x-request-id"] == "hostile-1"
    errors = [rec for rec in caplog.records if rec.levelno >= logging.ERROR]
    assert errors, caplog.text
    rec = errors[0]
    assert rec.name == "rangeplan.error" and getattr(rec, "request_id", None) == "hostile-1"
    assert "RuntimeError: a planner bug" in rec.exc and "Traceback" in rec.exc  # type: ignore[attr-defined]


def test_an_exception_in_a_route_is_logged_at_error_level_with_the_request_id(tmp_path, caplog):
    app = create_app(Store(tmp_path), workers=1, executor="thread")

    @app.get("/v1/boom")
    async def boom():
        raise RuntimeError("route bug")

    with api_client(app, raise_server_exceptions=False) as c, caplog.at_level(logging.INFO, logger="rangeplan"):
        r = c.get("/v1/boom", headers={"X-Request-ID": "hostile-2"})
    assert r.status_code == 500
    errors = [rec for rec in caplog.records if rec.levelno >= logging.ERROR]
    assert errors and errors[0].exc_info and getattr(errors[0], "request_id", None) == "hostile-2", caplog.text
