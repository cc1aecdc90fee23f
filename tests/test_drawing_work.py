"""A drawing import's work counted before it is done (issue 33, goal 2): nested block
references, MINSERT grids, hatch edges, bulges, SVG ``<use>`` copies and overlapping outlines
are counted from the parsed file (:func:`planner.exchange.estimate_import`); the counts are
checked against independent arithmetic on the generated drawing; a drawing over a work limit
is refused before any curve is flattened, naming what to change; and the estimate holds
(measured CPU within 1.5x of it, and not below a third of it)."""

from __future__ import annotations

import math
import time

import pytest

from planner.errors import PlannerError
from planner.exchange import estimate_import, import_drawing
from tests.drawings import dxf_bytes, new_doc

MM = {"units": "mm"}


def nested(fan: int, depth: int, copies: int = 1) -> bytes:
    """Blocks ``depth`` deep, each inserting the one below ``fan`` times; the bottom block a
    square of four LINEs and a circle; one reference at the top (a MINSERT grid of ``copies``)."""
    doc = new_doc(4)
    blk = doc.blocks.new("B0")
    for a, b in (((0, 0), (1, 0)), ((1, 0), (1, 1)), ((1, 1), (0, 1)), ((0, 1), (0, 0))):
        blk.add_line(a, b)
    blk.add_circle((0.5, 0.5), 0.3)
    for d in range(1, depth + 1):
        blk = doc.blocks.new(f"B{d}")
        for k in range(fan):
            blk.add_blockref(f"B{d - 1}", ((k % 5) * 2.0 * 5 ** (d - 1), (k // 5) * 2.0 * 5 ** (d - 1)))
    ref = doc.modelspace().add_blockref(f"B{depth}", (0, 0))
    if copies > 1:
        ref.grid(size=(copies, 1), spacing=(1000.0, 1000.0))
    return dxf_bytes(doc)


def hatches(n: int, edges: int) -> bytes:
    doc = new_doc(4)
    msp = doc.modelspace()
    for k in range(n):
        cx = k * 5.0
        h = msp.add_hatch()
        path = h.paths.add_edge_path()
        for j in range(edges):
            a0, a1 = 2 * math.pi * j / edges, 2 * math.pi * (j + 1) / edges
            path.add_line((cx + 2 * math.cos(a0), 2 * math.sin(a0)), (cx + 2 * math.cos(a1), 2 * math.sin(a1)))
    return dxf_bytes(doc)


def circles(n: int, r: float, pitch: float) -> bytes:
    doc = new_doc(4)
    msp = doc.modelspace()
    for k in range(n):
        msp.add_circle(((k % 20) * pitch, (k // 20) * pitch), r)
    return dxf_bytes(doc)


def svg_uses(n: int, per: int) -> bytes:
    group = "".join(f'<rect x="{j * 1.5:.1f}" y="0" width="1" height="1"/>' for j in range(per))
    uses = "".join(f'<use xlink:href="#g" x="0" y="{k * 2.0:.1f}"/>' for k in range(n))
    return (f'<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" width="400mm" '
            f'height="400mm" viewBox="0 0 400 400"><defs><g id="g">{group}</g></defs>{uses}</svg>').encode()


@pytest.mark.parametrize("fan, depth, copies", [(4, 3, 1), (10, 2, 1), (3, 2, 7)])
def test_nested_block_references_are_counted_exploded(fan, depth, copies):
    """Entities with every INSERT exploded: ``copies`` x (fan^depth bottom blocks of 5
    entities + the references at each level), counted without exploding one."""
    work = estimate_import(nested(fan, depth, copies), MM, format="dxf")
    references = sum(fan ** d for d in range(1, depth + 1))  # the INSERTs inside the blocks
    expected = 1 + copies * (fan ** depth * 5 + references)
    assert work.counts["entity"] == expected, (work.counts, expected)
    # each bottom block's circle: one curve per copy, the square's lines and circle pieces
    assert work.counts["curve"] == copies * fan ** depth
    assert work.counts["piece"] == copies * fan ** depth * 5


def test_hatch_edges_are_counted_one_by_one():
    work = estimate_import(hatches(30, 12), MM, format="dxf")
    assert work.counts["piece"] == 30 * 12 and work.counts["vertex"] == 30 * 12 * 2


def test_circle_vertices_follow_the_flattening_rule():
    """A circle of radius r at tolerance t flattens into ceil(sqrt(r (2 pi)^2 / (8 t))) chords
    (planner.exchange._flatten); the count is the rule's, so it grows as 1 / sqrt(t)."""
    data = circles(10, 5.0, 20.0)
    coarse = estimate_import(data, {**MM, "flatten_tolerance": 1e-4}, format="dxf").counts["vertex"]
    fine = estimate_import(data, {**MM, "flatten_tolerance": 1e-6}, format="dxf").counts["vertex"]
    n = math.ceil(math.sqrt(5.0 * (2 * math.pi) ** 2 / (8 * 1e-3)))  # 1e-6 m = 1e-3 mm
    assert fine == 10 * (n + 1)
    assert 8 < fine / coarse < 11  # ~sqrt(100)


def test_overlapping_outlines_are_counted_pair_by_pair():
    """Circles whose boxes overlap: every pair of the n is one (r 50 mm on a 1 mm grid); the
    same circles apart: none."""
    n = 40
    assert estimate_import(circles(n, 50.0, 1.0), MM, format="dxf").counts["pair"] == n * (n - 1) // 2
    assert estimate_import(circles(n, 1.0, 5.0), MM, format="dxf").counts["pair"] == 0


def test_svg_use_copies_are_counted():
    """A group of 20 rects used 30 times: 20 + 30 x 20 shape elements."""
    work = estimate_import(svg_uses(30, 20), {}, format="svg")
    assert work.counts["svg_element"] == 20 + 30 * 20


def test_the_estimate_follows_the_counts():
    """Four times the nested copies: about four times the estimate (the fixed cost aside)."""
    small = estimate_import(nested(5, 2, 2), MM, format="dxf").seconds
    big = estimate_import(nested(5, 2, 8), MM, format="dxf").seconds
    assert 3.0 < (big - 0.09) / (small - 0.09) < 4.5


def test_a_drawing_over_the_limit_is_refused_before_its_curves(monkeypatch):
    """With ``work_limit_s`` below its estimate a drawing is refused ``too_much_work`` with
    the estimate and what to change, and no curve is flattened (the flattening is patched to
    fail: it is never reached)."""
    from planner.exchange import _flatten

    data = circles(200, 50.0, 1.0)
    est = estimate_import(data, MM, format="dxf")

    def boom(*args, **kwargs):
        raise AssertionError("flattened before the work was checked")

    monkeypatch.setattr(_flatten, "chords", boom)
    with pytest.raises(PlannerError) as err:
        import_drawing(data, MM, format="dxf", work_limit_s=est.seconds / 2)
    e = err.value
    assert e.code == "too_much_work" and e.field == "drawing", e.to_dict()
    assert f"{est.seconds:.3g} s" in e.message and "overlapping" in e.message and "remove the outlines" in e.message


def test_fine_tolerance_is_named_when_vertices_cost_most():
    data = circles(20, 50.0, 200.0)
    with pytest.raises(PlannerError) as err:
        import_drawing(data, {**MM, "flatten_tolerance": 1e-7}, format="dxf", work_limit_s=1e-3)
    assert err.value.code == "too_much_work" and err.value.field == "flatten_tolerance", err.value.to_dict()


def test_within_the_limit_the_import_is_unchanged():
    data = nested(4, 2)
    assert import_drawing(data, MM, format="dxf", work_limit_s=60.0).report == import_drawing(
        data, MM, format="dxf").report


@pytest.mark.serial  # compares CPU seconds with the estimate
@pytest.mark.parametrize("name, data, fmt", [
    ("nested", nested(4, 4), "dxf"), ("minsert", nested(5, 2, 40), "dxf"), ("hatches", hatches(200, 30), "dxf"),
    ("overlapping circles", circles(150, 30.0, 1.0), "dxf"), ("svg uses", svg_uses(100, 20), "svg")])
def test_the_estimate_holds(name, data, fmt):
    """Measured CPU seconds of the import within [1/3, 1.5] x its estimate (benchmarks/README:
    0.6-1.2 on the benchmark's drawings)."""
    options = MM if fmt == "dxf" else {}
    import_drawing(data, options, format=fmt)  # warm (imports, first-use loads)
    est = estimate_import(data, options, format=fmt).seconds
    t0 = time.process_time()
    import_drawing(data, options, format=fmt)
    cpu = time.process_time() - t0
    assert est / 3 <= cpu <= 1.5 * est, (name, cpu, est)


def test_the_service_refuses_a_drawing_over_its_time_limit(tmp_path):
    """``POST /v1/import`` passes the server's time limit to the import (app.jobs.bounded):
    a drawing estimated over it is refused 422 ``too_much_work`` on the field ``drawing``,
    naming the estimate, at once; a drawing estimated under the same limit imports."""
    from app.api import create_app
    from app.storage import Store
    from tests.support import api_client

    big, small = circles(800, 50.0, 1.0), circles(200, 50.0, 1.0)  # ~13 s and ~1 s estimated
    est = estimate_import(big, MM, format="dxf").seconds
    assert est > 4 * estimate_import(small, MM, format="dxf").seconds
    for data, limit, status in ((big, est / 2, 422), (small, est / 2, 200)):
        app = create_app(Store(tmp_path / f"data{status}"), workers=1, timeout_s=limit)
        with api_client(app) as client:
            r = client.post("/v1/import", params=MM, content=data, headers={"Content-Type": "application/dxf"})
        assert r.status_code == status, r.text
        if status == 422:
            err = r.json()["error"]
            assert err["code"] == "too_much_work" and err["field"] == "drawing", err
            assert f"{est:.3g} s" in err["message"]


def _arc_svg(body: str) -> bytes:
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="400mm" height="400mm" viewBox="0 0 400 400">{body}'
            '</svg>').encode()


def _arc_circle(x: float, y: float, r: float) -> str:
    """A circle as a path of two arcs (flattened by the import, unlike a <circle>)."""
    return f'<path d="M{x},{y + r} A{r},{r} 0 1,0 {x + 2 * r},{y + r} A{r},{r} 0 1,0 {x},{y + r} Z"/>'


@pytest.mark.parametrize("transform", ["scale(10)", "matrix(10,0,0,10,4,5)", "rotate(30) scale(2) scale(5)",
                                       "scale(10, 4)"])
def test_svg_transforms_scale_the_chords_counted(transform):
    """A curve scaled up by its element's and ancestors' transforms flattens into more chords
    (issue 33 goal 2): the estimate counts them as the same curve drawn at that size, and
    at least as many as the import makes (its own count of the shape's vertices)."""
    def within(shape: str, transform: str = "") -> bytes:  # the same element tree each time
        return _arc_svg(f'<g transform="{transform}"><g>{shape}</g></g>')

    small, large = _arc_circle(1, 1, 3), _arc_circle(10, 10, 30)
    scaled = estimate_import(within(small, transform), {}, format="svg").counts["vertex"]
    plain = estimate_import(within(small), {}, format="svg").counts["vertex"]
    big = estimate_import(within(large), {}, format="svg").counts["vertex"]
    assert scaled > plain
    assert abs(scaled - big) <= 2, (scaled, big)
    made = sum(s.vertices for s in import_drawing(within(small, transform), {}, format="svg").report.shapes)
    made_plain = sum(s.vertices for s in import_drawing(within(small), {}, format="svg").report.shapes)
    assert made > made_plain and scaled >= made
    # a rotation alone changes nothing
    turned = within(small, "rotate(45)")
    assert estimate_import(turned, {}, format="svg").counts["vertex"] == plain
