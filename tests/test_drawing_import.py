"""Drawing import (planner.exchange.import_drawing): real LibreCAD drawings and generated
ones of every entity type against an independent shapely polygonize of the same entities
(tests/drawings.py) and against exact areas; units, placement, layers, open chains, holes,
SVG, and the errors bad drawings get."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import shapely
from shapely import affinity

from planner.errors import PlannerError
from planner.exchange import import_drawing
from planner.schema import MAX_POLYGON_POINTS, Layout
from planner.schema.drawing import MIN_TOLERANCE
from tests.drawings import (
    ENTITY_KINDS,
    LIBRECAD,
    dxf_bytes,
    entity_drawing,
    new_doc,
    obstacle_region,
    reference_region,
    rounded_rectangle,
)

AGREE_M2 = 1e-6  # the acceptance: area and outline agree with the reference to 1e-6 m^2
#: the reference's own error: ezdxf makes a hatch's arc edges cubic Bezier curves (2.7e-4 r off)
REFERENCE_ERROR_M2 = {"hatch": 1e-7}


def _agree(layout, ref) -> tuple[float, float]:
    mine = obstacle_region(layout)
    return abs(mine.area - ref.area), mine.symmetric_difference(ref).area


@pytest.mark.parametrize("path", LIBRECAD, ids=lambda p: p.name)
def test_librecad_drawings_agree_with_polygonize(path):
    """Real drawings (loose LINE/ARC, circles, ellipses; mm by $INSUNITS) at full size
    (up to 1.7 m across), flattened to 0.1 um."""
    data = path.read_bytes()
    res = import_drawing(data, {"flatten_tolerance": 1e-7})
    ref = reference_region(data, 1e-7)
    d_area, d_outline = _agree(res.layout, ref)
    assert d_area < AGREE_M2 and d_outline < AGREE_M2, (d_area, d_outline)
    rep = res.report
    assert (rep.units, rep.units_source, rep.metres_per_unit) == ("mm", "drawing", 1e-3)
    assert rep.open_chains == [] and rep.area_m2 == pytest.approx(ref.area, abs=AGREE_M2)


@pytest.mark.parametrize("path", LIBRECAD, ids=lambda p: p.name)
def test_librecad_at_workspace_scale_with_default_tolerance(path):
    """At the robot's scale (1:10) with the default 0.1 mm flattening: the outline is within
    the tolerance of the reference (symmetric difference <= tolerance x perimeter)."""
    data = path.read_bytes()
    res = import_drawing(data, {"scale": 0.1})
    ref = reference_region(data, 1e-7, scale=0.1)
    d_area, d_outline = _agree(res.layout, ref)
    assert d_area <= d_outline + 1e-15 and d_outline <= 1e-4 * ref.boundary.length


@pytest.mark.parametrize("kind", ENTITY_KINDS)
def test_each_entity_type_agrees_with_polygonize_and_exact_area(kind):
    data, exact, curved = entity_drawing(kind)
    for tol in (1e-4, 1e-6):
        res = import_drawing(data, {"flatten_tolerance": tol})
        ref = reference_region(data, tol / 10)
        d_area, d_outline = _agree(res.layout, ref)
        # chords within tol of every curve: the area differs by at most tol x curved length
        assert d_outline <= tol * curved + REFERENCE_ERROR_M2.get(kind, 1e-12), (tol, d_outline)
        if exact is not None:
            assert abs(obstacle_region(res.layout).area - exact) <= tol * curved + 1e-12
        if tol == 1e-6:
            assert d_area < AGREE_M2 and d_outline < AGREE_M2
        assert res.report.open_chains == []


def test_nested_shapes_are_holes_and_islands():
    data, exact, _ = entity_drawing("nested")
    res = import_drawing(data, {"flatten_tolerance": 1e-6})
    obs = res.layout.obstacles
    outer = [o for o in obs if o.type == "polygon" and len(o.holes) == 2]
    assert len(outer) == 1 and len(obs) == 2  # the plate with two holes, and the island
    island = [o for o in obs if o is not outer[0]][0]
    assert shapely.Polygon(island.points).area == pytest.approx(100e-6)
    assert res.report.holes == 2
    # a point in the circular hole is free, the island's centre is not
    region = obstacle_region(res.layout)
    assert not region.contains(shapely.Point(0.030, 0.015)) and region.contains(shapely.Point(0.030, 0.030))


@pytest.mark.parametrize("insunits, metres", [(1, 0.0254), (5, 0.01), (6, 1.0), (14, 0.1), (0, 1e-3)])
def test_units_from_insunits(insunits, metres):
    doc = new_doc(insunits)
    doc.modelspace().add_lwpolyline([(0, 0), (2, 0), (2, 1), (0, 1)], close=True)
    res = import_drawing(dxf_bytes(doc))
    assert res.report.metres_per_unit == metres
    assert res.report.units_source == ("default" if insunits == 0 else "drawing")
    assert res.report.area_m2 == pytest.approx(2 * metres ** 2, rel=1e-12)
    # the units option overrides the drawing
    res = import_drawing(dxf_bytes(doc), {"units": "cm"})
    assert res.report.units_source == "option" and res.report.area_m2 == pytest.approx(2e-4, rel=1e-12)


def test_unknown_units_name_the_cause():
    doc = new_doc(4)
    doc.header["$INSUNITS"] = 18  # astronomical units
    doc.modelspace().add_circle((0, 0), 1)
    with pytest.raises(PlannerError) as e:
        import_drawing(dxf_bytes(doc))
    assert e.value.code == "invalid_drawing" and e.value.field == "units" and "units unknown" in e.value.message
    assert import_drawing(dxf_bytes(doc), {"units": "mm"}).report.units == "mm"


def test_placement_is_scale_rotation_offset():
    data, _, _ = entity_drawing("lines_arcs")
    base = obstacle_region(import_drawing(data, {"flatten_tolerance": 1e-6}).layout)
    placed = import_drawing(data, {"flatten_tolerance": 2e-6, "scale": 2.0, "rotation": 0.7,
                                   "offset": [0.05, -0.02]})
    expect = affinity.translate(affinity.rotate(affinity.scale(base, 2, 2, origin=(0, 0)), 0.7, origin=(0, 0),
                                                use_radians=True), 0.05, -0.02)
    got = obstacle_region(placed.layout)
    assert got.area == pytest.approx(4 * base.area, rel=1e-9)
    assert got.symmetric_difference(expect).area < 1e-9
    # bounds: the extents plus the margin
    lo, hi = placed.layout.bounds.lower, placed.layout.bounds.upper
    x0, y0, x1, y1 = got.bounds
    assert np.allclose([lo[0], lo[1], hi[0], hi[1]], [x0 - 0.01, y0 - 0.01, x1 + 0.01, y1 + 0.01], atol=1e-12)


def test_layers_and_bounds_layer():
    doc = new_doc(4)
    msp = doc.modelspace()
    rounded_rectangle(msp, 0, 0, 40, 20, 4, layer="PARTS")
    msp.add_circle((70, 10), 5, dxfattribs={"layer": "HOLES"})
    msp.add_lwpolyline([(-50, -50), (150, -50), (150, 80), (-50, 80)], close=True, dxfattribs={"layer": "FRAME"})
    data = dxf_bytes(doc)
    res = import_drawing(data, {"layers": ["PARTS"], "bounds_layer": "FRAME"})
    assert [s.layer for s in res.report.shapes] == ["PARTS"] and res.report.bounds_source == "layer"
    assert np.allclose(res.layout.bounds.lower, [-0.05, -0.05]) and np.allclose(res.layout.bounds.upper, [0.15, 0.08])
    res = import_drawing(data, {"bounds_layer": "FRAME"})  # all other layers
    assert sorted(s.layer for s in res.report.shapes) == ["HOLES", "PARTS"]
    assert res.report.layers_in_drawing == ["FRAME", "HOLES", "PARTS"]
    with pytest.raises(PlannerError) as e:
        import_drawing(data, {"layers": ["NOPE"]})
    assert e.value.field == "layers" and "FRAME, HOLES, PARTS" in e.value.message


def test_open_chains_are_reported_with_their_location():
    doc = new_doc(4)
    msp = doc.modelspace()
    # a square with a 1 mm gap at its top-left corner, and a closed circle
    msp.add_line((0, 0), (20, 0))
    msp.add_line((20, 0), (20, 20))
    msp.add_line((20, 20), (1, 20))
    msp.add_line((0, 19), (0, 0))
    gap_only = dxf_bytes(doc)
    with pytest.raises(PlannerError) as e:
        import_drawing(gap_only)
    assert e.value.code == "invalid_drawing" and "no closed shape" in e.value.message
    assert "(0.0010 m, 0.0200 m)" in e.value.message or "(0.0000 m, 0.0190 m)" in e.value.message
    msp.add_circle((50, 10), 5)
    res = import_drawing(dxf_bytes(doc))
    [chain] = res.report.open_chains
    assert chain.pieces == 4 and chain.why == "open"
    assert chain.gap_m == pytest.approx(math.sqrt(2) * 1e-3)
    assert {tuple(np.round(chain.start, 6)), tuple(np.round(chain.end, 6))} == {(0.001, 0.02), (0.0, 0.019)}
    # a join tolerance above the gap closes it
    res = import_drawing(gap_only, {"join_tolerance": 2e-3})
    assert len(res.report.shapes) == 1 and res.report.open_chains == []


def test_hatch_over_its_own_border_counts_once():
    doc = new_doc(4)
    msp = doc.modelspace()
    msp.add_lwpolyline([(0, 0), (30, 0), (30, 30), (0, 30)], close=True)
    msp.add_hatch().paths.add_polyline_path([(0, 0), (30, 0), (30, 30), (0, 30)], is_closed=True)
    res = import_drawing(dxf_bytes(doc))
    assert len(res.layout.obstacles) == 1 and res.report.shapes[0].source == "LWPOLYLINE"
    assert res.report.area_m2 == pytest.approx(9e-4)


@pytest.mark.parametrize("data, needle", [
    (b"hello world", "not a DXF"),
    (b"0\nSECTION\n2\nENTITIES\n0\nENDSEC\n0\nEOF\n", "no closed shape"),
    (b"<svg xmlns='http://www.w3.org/2000/svg'><text>hi</text></svg>", "no closed shape"),
    (b"<svg xmlns='http://www.w3.org/2000/svg'><rect", "not an SVG"),
    (b"<html><svg/></html>", "not an SVG"),
])
def test_bad_drawings_name_the_cause(data, needle):
    fmt = "svg" if b"<" in data else "dxf"
    with pytest.raises(PlannerError) as e:
        import_drawing(data, format=fmt)
    assert e.value.code == "invalid_drawing" and needle in e.value.message


def test_bad_options_name_the_field():
    data, _, _ = entity_drawing("circle")
    for options, field in [({"scale": 0}, "scale"), ({"offset": [1]}, "offset"), ({"units": "furlong"}, "units"),
                           ({"flatten_tolerance": -1}, "flatten_tolerance"), ({"colour": 1}, "colour")]:
        with pytest.raises(PlannerError) as e:
            import_drawing(data, options)
        assert e.value.code == "invalid_input" and e.value.field == field
    for options, field in [({"scale": 5e-324}, "scale"), ({"scale": 1e300}, "scale"),
                           ({"flatten_tolerance": 5e-324}, "flatten_tolerance"),
                           ({"join_tolerance": 5e-324}, "join_tolerance"), ({"offset": [1e6, 0]}, "offset[0]"),
                           ({"start": [0, 0, 1e308]}, "start[2]"), ({"margin": 1e300}, "margin")]:
        with pytest.raises(PlannerError) as e:  # every number bounded up front
            import_drawing(data, options)
        assert e.value.code == "invalid_input" and e.value.field == field, (options, e.value)


@pytest.mark.parametrize("kind", ENTITY_KINDS)
@pytest.mark.serial  # a bound of 1 s
def test_a_curve_finer_than_a_shape_may_be_is_refused_before_it_is_flattened(kind):
    """Chords within 1 nm of a curve of ~1 m radius would be ~35 000 per curve, more than a
    shape may have (MAX_POLYGON_POINTS): too_large naming flatten_tolerance, in well under a
    second, for every curve type (arcs, bulges, ellipses, splines, hatch edges)."""
    data, _, _ = entity_drawing(kind)
    t0 = time.perf_counter()
    with pytest.raises(PlannerError) as e:
        import_drawing(data, {"flatten_tolerance": MIN_TOLERANCE, "scale": 100.0})
    assert time.perf_counter() - t0 < 1.0
    assert (e.value.code, e.value.field) == ("too_large", "flatten_tolerance")
    assert str(MAX_POLYGON_POINTS) in e.value.message
    ok = import_drawing(data, {"flatten_tolerance": 1e-4, "scale": 100.0})  # a coarser tolerance: the same shape
    assert ok.layout.obstacles


SVG = """<svg xmlns="http://www.w3.org/2000/svg" xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape"
     width="100mm" height="50mm" viewBox="0 0 100 50">
 <g inkscape:groupmode="layer" inkscape:label="Parts">
  <rect x="10" y="10" width="20" height="10"/>
  <circle cx="50" cy="25" r="5"/>
  <path fill-rule="evenodd" d="M 60 5 H 90 V 45 H 60 Z M 65 10 H 85 V 20 H 65 Z"/>
  <ellipse cx="20" cy="38" rx="8" ry="4" transform="rotate(30 20 38)"/>
 </g>
 <g id="frame"><rect x="0" y="0" width="100" height="50" fill="none"/></g>
 <path d="M 5 45 C 5 40 15 40 15 45 A 5 5 0 0 1 5 45 Z"/>
</svg>"""


def test_svg_shapes_units_layers_and_y_up():
    res = import_drawing(SVG.encode(), {"layers": ["Parts"], "bounds_layer": "frame", "flatten_tolerance": 1e-6})
    rep = res.report
    # the document is sized in mm (width="100mm"): the report says the unit the geometry was scaled as
    assert rep.format == "svg" and rep.units == "mm" and rep.units_source == "drawing"
    assert rep.metres_per_unit == 1e-3
    kinds = sorted(s.kind for s in rep.shapes)
    assert kinds == ["circle", "polygon", "polygon", "polygon"] and rep.holes == 1
    exact = (20 * 10 + math.pi * 25 + (30 * 40 - 20 * 10) + math.pi * 8 * 4) * 1e-6
    assert rep.area_m2 == pytest.approx(exact, abs=1e-6 * 0.2)
    # the frame is the bounds (100 x 50 mm); y turned up: the rect at y = 10..20 from the top is at 30..40 mm
    assert np.allclose(res.layout.bounds.lower, [0, 0], atol=1e-9)
    assert np.allclose(res.layout.bounds.upper, [0.1, 0.05], atol=1e-9)
    rect = [o for o in res.layout.obstacles if o.type == "polygon" and len(o.points) == 4 and not o.holes][0]
    assert np.allclose(np.sort(np.unique(np.round(rect.points[:, 1], 9))), [0.03, 0.04])
    circle = [o for o in res.layout.obstacles if o.type == "circle"][0]
    assert np.allclose(circle.center, [0.05, 0.025]) and circle.radius == pytest.approx(0.005)
    # units option: one user unit is a cm; the path outside any group is on "(no layer)"
    res = import_drawing(SVG.encode(), {"units": "cm", "layers": ["(no layer)"]})
    assert res.report.units_source == "option"
    r = 0.05  # the closed cubic + arc blob, 10 x 5 cm across
    assert 0.5 * math.pi * r * r < res.report.area_m2 < 0.1 * 0.1


def test_imported_layout_with_holes_segments_and_plans():
    """A plate with a hole: the hole's cells are free, the plate's blocked; a plan around it."""
    from planner import plan, segment

    doc = new_doc(4)
    msp = doc.modelspace()
    msp.add_lwpolyline([(-20, -30), (20, -30), (20, 30), (-20, 30)], close=True)
    msp.add_circle((0, 0), 12)  # a hole
    res = import_drawing(dxf_bytes(doc), {"margin": 0.03, "start": [-0.045, 0, 0], "end": [0.045, 0, 0]})
    layout = res.layout
    assert layout.obstacles[0].type == "polygon" and len(layout.obstacles[0].holes) == 1
    request = {"layout": {**layout.model_dump(mode="json", exclude_unset=True), "cell": {"size": 0.005}},
               "settings": {"Ts": 0.01}}
    seg = segment(request)
    cells = {c["id"]: c for c in seg.to_dict()["cells"]}
    inside_hole = [c for c in cells.values() if np.all(np.hypot(*np.asarray(c["polygon"]).T) < 0.011)]
    assert inside_hole and all(c["state"] == "free" for c in inside_hole)
    result = plan(request)
    region = obstacle_region(layout)
    assert not any(region.contains(shapely.Point(p)) for p in result.pose[:, :2])
    assert result.metrics.end_error_m < 1e-3


def test_polygon_holes_are_validated():
    base = {"bounds": {"lower": [-1, -1], "upper": [1, 1]}, "start": [0.9, 0.9, 0], "end": [-0.9, 0.9, 0]}
    square = [[0, 0], [0.5, 0], [0.5, 0.5], [0, 0.5]]
    ok = Layout.model_validate({**base, "obstacles": [{"type": "polygon", "points": square,
                                                       "holes": [[[0.1, 0.1], [0.2, 0.1], [0.2, 0.2]]]}]})
    assert len(ok.obstacles[0].holes) == 1
    from pydantic import ValidationError

    from planner.schema import planner_error
    with pytest.raises(ValidationError) as e:
        Layout.model_validate({**base, "obstacles": [{"type": "polygon", "points": square,
                                                      "holes": [[[0.4, 0.4], [0.9, 0.4], [0.9, 0.9]]]}]})
    err = planner_error(e.value)
    assert err.field == "obstacles[0].holes" and "inside the outline" in err.message
