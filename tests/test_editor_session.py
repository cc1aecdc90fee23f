"""The editor's editing sessions without a browser: number entry (parsing and checks against
the request schema's own messages), undo / redo, snapping, clipping to the bounds, one
session per tab, one notification per error state, segment-list corridors, the plots.
Tabs are headless viser clients (tests/viser_client.py) that send what a browser sends."""

from __future__ import annotations

import copy
import json
import threading
import time

import numpy as np
import pytest
import shapely
from pydantic import ValidationError

from app import jobs
from app.editor import _geometry as geo
from app.editor import _planning
from app.editor._fields import Bounds, parse_number, parse_vector
from app.editor._history import COALESCE_S, History
from planner.schema import Settings, format_validation_error
from tests.support import TABLE1
from tests.test_editor import FakeSegmentation, MemStore, Tab


def wait_for(cond, timeout=10.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.02)
    return False


# ---------------------------------------------------------------------------- number entry
@pytest.mark.parametrize("text, value", [("-0.09", -0.09), ("\u22120.09", -0.09), ("1e-5", 1e-5), ("-2.5E+3", -2500.0),
                                         (".5", 0.5), ("5.", 5.0), ("+3", 3.0), ("-0", 0.0), ("  0.02 ", 0.02)])
def test_numbers_keep_sign_decimals_and_exponents(text, value):
    v, err = parse_number(text)
    assert err is None and v == value and str(v) != "-0.0"


@pytest.mark.parametrize("text, message", [("abc", "not a number: 'abc'"), ("-", "not a number: '-'"),
                                           ("1e", "not a number: '1e'"), ("inf", "not a number: 'inf'"),
                                           ("0,02", "use a point as the decimal separator"), ("", "required")])
def test_bad_numbers_are_named(text, message):
    v, err = parse_number(text)
    assert v is None and err is not None and message in err


@pytest.mark.parametrize("field, value", [("Ts", -1.0), ("Ts", 2.0), ("Ts", 5e-5), ("k_r", 0.0), ("N", 0), ("N", 500)])
def test_field_bounds_say_what_the_request_schema_says(field, value):
    """The editor's check of a typed setting gives the very message validation gives (an
    independent source: pydantic with the planner's error wording)."""
    bounds = Bounds(**_planning.field_bounds("Settings", field))
    v, err = parse_number(str(value), integer=field == "N", bounds=bounds)
    with pytest.raises(ValidationError) as exc:
        Settings.model_validate({field: value})
    assert v is None and err == format_validation_error(exc.value).removeprefix(f"{field}: ")


def test_whole_numbers_and_vectors():
    assert parse_number("20", integer=True) == (20, None)
    assert parse_number("20.5", integer=True)[1] == "must be a whole number, got 20.5"
    assert parse_number("", optional=True) == (None, None)
    assert parse_vector("-0.08, 0.04, 0", ("x", "y", "ψ")) == ([-0.08, 0.04, 0.0], None)
    assert parse_vector("-0.08, 0.04", ("x", "y", "ψ"))[1] == "needs 3 numbers separated by commas (x, y, ψ), got 2"
    assert parse_vector("-0.08, zero", ("x", "y"))[1] == "y: not a number: 'zero'"
    assert parse_vector("", ("min", "max"), optional=True) == (None, None)


# ---------------------------------------------------------------------------- undo history
def test_history_steps_coalesce_by_key_and_time():
    now = [0.0]
    h = History(clock=lambda: now[0])
    states = [{"v": i} for i in range(6)]
    assert h.record(states[0], "field:a")  # typing in a: one step
    now[0] += 0.3
    assert not h.record(states[1], "field:a")
    now[0] += COALESCE_S + 0.1  # a pause: a new step
    assert h.record(states[2], "field:a")
    assert h.record(states[3], "field:b")  # another field: a new step
    h.seal()
    assert h.record(states[4], "field:b")  # sealed (a drag ended): a new step
    assert h.depth == (4, 0)
    assert h.undo(states[5]) == states[4] and h.undo(states[4]) == states[3]
    assert h.undo(states[3]) == states[2] and h.undo(states[2]) == states[0]
    assert h.undo(states[0]) is None and h.depth == (0, 4)
    # a drag: one step from begin() to seal(), however long it takes
    h2 = History(clock=lambda: now[0])
    h2.begin("drag:end")
    for i in range(5):
        now[0] += 2 * COALESCE_S
        assert h2.record(states[i], "drag:end") == (i == 0)
    h2.seal()
    assert h2.record(states[5], "drag:end") and h2.depth == (2, 0)
    assert h.redo(states[0]) == states[2]
    h.record(states[2], None)  # a new edit after undo drops the redo branch
    assert not h.can_redo and h.redo(states[3]) is None


# ---------------------------------------------------------------------------- snapping and clipping
def test_snap_lands_on_the_grid_from_the_origin():
    assert geo.snap(0.08742640253814118, 0.02, -0.16) == 0.08
    assert geo.snap(-0.0874, 0.02, -0.15) == -0.09  # the grid runs from the origin
    assert geo.snap(0.08742640253814118, None) == 0.0874  # no grid: 0.1 mm
    assert geo.snap(-1e-9, 0.02) == 0.0 and str(geo.snap(-1e-9, 0.02)) == "0.0"
    pts = np.random.default_rng(1).uniform(-0.2, 0.2, (200, 2))
    for p in pts:
        q = geo.snap_point(p, 0.005, (-0.16, -0.16))
        k = (np.array(q) + 0.16) / 0.005
        assert np.allclose(k, np.round(k), atol=1e-9) and np.all(np.abs(np.array(q) - p) <= 0.0025 + 1e-12)


def test_triangle_cells_clipped_to_the_bounds_tile_exactly_the_bounds():
    """The triangle grid overhangs the bounds; clipped, its cells lie inside and their areas
    add up to the bounds' area (shapely's union as the independent check)."""
    from planner.corridor import segment
    from planner.schema import Layout, Settings

    layout = Layout.model_validate({"bounds": {"lower": [-0.16, -0.16], "upper": [0.16, 0.16]},
                                    "cell": {"shape": "triangle", "size": 0.02},
                                    "start": [-0.08, 0, 0], "end": [0.06, 0.04, 0]})
    seg = segment(layout, _planning.RobotCache().get("moving-slide"), Settings()).to_dict()
    raw = [c["polygon"] for c in seg["cells"]]
    assert np.max(np.abs(np.concatenate(raw))) > 0.16 + 1e-3, "the grid overhangs (else this test shows nothing)"
    clipped = geo.clip_polygons(raw, [-0.16, -0.16], [0.16, 0.16])
    pts = np.concatenate([np.asarray(p) for p in clipped])
    assert np.all(np.abs(pts) <= 0.16 + 1e-12)
    area = sum(shapely.Polygon(p).area for p in clipped)
    assert area == pytest.approx(0.32 * 0.32, rel=1e-9)
    assert shapely.union_all([shapely.Polygon(p) for p in clipped]).area == pytest.approx(0.32 * 0.32, rel=1e-9)


def test_clip_segments_keeps_the_inside_part():
    rng = np.random.default_rng(2)
    segs = np.concatenate((rng.uniform(-1, 1, (300, 2, 2)), np.zeros((300, 2, 1))), axis=2)
    out = geo.clip_segments(segs, [-0.5, -0.3], [0.4, 0.6])
    assert np.all(out[..., 0] >= -0.5 - 1e-12) and np.all(out[..., 0] <= 0.4 + 1e-12)
    assert np.all(out[..., 1] >= -0.3 - 1e-12) and np.all(out[..., 1] <= 0.6 + 1e-12)
    box = shapely.box(-0.5, -0.3, 0.4, 0.6)
    expected = sum(shapely.LineString(s[:, :2]).intersection(box).length for s in segs)
    assert np.linalg.norm(out[:, 1, :2] - out[:, 0, :2], axis=1).sum() == pytest.approx(expected, rel=1e-9)


# ---------------------------------------------------------------------------- sessions
@pytest.fixture
def tab():
    t = Tab(MemStore(), debounce=0.1)
    try:
        assert t.session.wait_idle(60)
        yield t
    finally:
        t.stop()


def test_typed_numbers_reach_the_request_and_bad_ones_stay_on_the_field(tab):
    s, client = tab.session, tab.clients[0]
    client.type(s.gui.start.text, "-0.09, 0.02, 0")
    assert wait_for(lambda: s.request["layout"]["start"] == [-0.09, 0.02, 0.0])
    client.type(s.gui.Ts.text, "5e-3")
    assert wait_for(lambda: s.request["settings"]["Ts"] == 0.005)
    assert s.wait_idle(60) and s.last_error is None and s.last_result.settings.Ts == 0.005
    done = s.plans_done
    client.type(s.gui.cell_size.text, "-0.02")
    # the field checks the schema's own bound on the cell size, and says it as validation does
    (op, bound), = ((k, v) for k, v in _planning.field_bounds("Cell", "size").items() if k in ("gt", "ge"))
    assert bound > -0.02
    expected = f"must be {'>' if op == 'gt' else '>='} {float(bound)}, got -0.02"
    assert wait_for(lambda: s.gui.cell_size.error == expected), (s.gui.cell_size.error, expected)
    assert s.gui.cell_size.text.label.startswith("\u26a0") and s.gui.cell_size.text.value == "-0.02"
    assert s.request["layout"]["cell"]["size"] == 0.02, "an invalid entry edits nothing"
    time.sleep(0.4)
    assert s.plans_done == done and s.wait_idle(10)
    client.type(s.gui.cell_size.text, "0.0005")  # valid for the field; the planner: too many cells
    assert wait_for(lambda: s.request["layout"]["cell"]["size"] == 0.0005) and s.wait_idle(60)
    assert s.last_error.code == "too_large" and s.last_error.field == "layout.cell.size"
    assert s.gui.cell_size.error and "409600 square cells" in s.gui.cell_size.error
    client.type(s.gui.cell_size.text, "0.01")
    assert wait_for(lambda: s.request["layout"]["cell"]["size"] == 0.01) and s.wait_idle(60)
    assert s.last_error is None and s.gui.cell_size.error is None


def test_two_tabs_never_change_each_other(tab):
    a = tab.session
    b = tab.connect()
    assert b is not a and b.wait_idle(60) and b.last_error is None
    before_b, plans_b = b.request, b.plans_done
    tab.clients[0].type(a.gui.end.text, "0.02, 0.06, 0")
    a.add_rectangle([0.04, -0.1], [0.06, -0.04])
    assert wait_for(lambda: a.request["layout"]["end"] == [0.02, 0.06, 0.0]) and a.wait_idle(60)
    assert b.request == before_b and b.plans_done == plans_b and b.gui.end.text.value == "0.06, 0.04, 0"
    assert b.last_result.pose[-1][:2] == pytest.approx([0.06, 0.04], abs=1e-3)
    # sharing is explicit: save in one tab, load by name in the other
    a.files.save(new=True)
    assert wait_for(lambda: b.gui.stored.options[0] != "(none)"), "the other tab's list is refreshed"
    b.gui.stored.value = b.gui.stored.options[0]
    b.files.load()
    assert b.request == a.request and b.wait_idle(60)


def test_undo_and_redo_every_kind_of_edit(tab):
    s = tab.session
    r0 = s.request
    # a drag is one step, however many moves it has
    s.move_handle("end", 0.03, 0.05, "start")
    for x in (0.035, 0.04, 0.045):
        s.move_handle("end", x, 0.05)
    s.move_handle("end", 0.045, 0.055, "end")
    r1 = s.request
    assert r1["layout"]["end"][:2] == [0.04, 0.06]  # snapped to the 0.02 m cell grid from -0.16
    s.add_rectangle([0.02, -0.1], [0.04, -0.02])  # an obstacle
    r2 = s.request
    tab.clients[0].type(s.gui.k_u.text, "2e-3")  # a setting, typed
    assert wait_for(lambda: s.request["settings"]["k_u"] == 2e-3)
    r3 = s.request
    table1 = copy.deepcopy(TABLE1)
    s.files.load_request(table1, None, "table1")  # a load
    r4 = s.request
    assert r4["segments"] == table1["segments"]
    assert s.history.depth == (4, 0) and not s.gui.undo_button.disabled and s.gui.redo_button.disabled
    for expected in (r3, r2, r1, r0):
        assert s.undo() and s.request == expected
    assert not s.undo() and s.gui.undo_button.disabled
    assert s.gui.end.text.value == "0.06, 0.04, 0" and float(s.gui.k_u.text.value) == r0["settings"]["k_u"] != 2e-3
    for expected in (r1, r2, r3, r4):
        assert s.redo() and s.request == expected
    assert not s.redo()
    assert s.wait_idle(60) and s.last_error is None
    assert s.last_result.corridor.segments[3].upper[:2].tolist() == table1["segments"][3]["upper"][:2]


def test_snapping_toggle_and_grid(tab):
    s = tab.session
    s.move_handle("end", 0.0517, 0.0391)
    assert s.request["layout"]["end"][:2] == [0.06, 0.04]
    s.gui.grid.text.value = "0.005"
    s.move_handle("end", 0.0517, 0.0391)
    assert s.request["layout"]["end"][:2] == [0.05, 0.04]
    s.gui.snap.value = False
    s.move_handle("end", 0.05172345, 0.03914567)
    assert s.request["layout"]["end"][:2] == [0.0517, 0.0391]
    assert s.wait_idle(60)


def test_one_notification_per_error_state_updated_while_typing(tab, monkeypatch):
    s, client = tab.session, tab.clients[0]
    shown, updates, removed = [], [], []
    orig = s.client.add_notification

    def add(title, body, **kw):
        note = orig(title, body, **kw)
        shown.append(note)
        return note
    monkeypatch.setattr(s.client, "add_notification", add)
    for text in ("0.5", "0.45", "0.4"):  # typed one after another: each too large for the 0.32 m bounds
        client.type(s.gui.cell_size.text, text)
        assert wait_for(lambda t=text: s.request["layout"]["cell"]["size"] == float(t)) and s.wait_idle(60)
        assert s.last_error is not None and s.last_error.field == "layout.cell.size"
        updates.append((s._error_note.title, s._error_note.body))
    assert len(shown) == 1, "one notification for the one error state, its text updated"
    assert len({b for _, b in updates}) == 3 and "0.4 m" in updates[-1][1]
    note = shown[0]
    monkeypatch.setattr(type(note), "remove", lambda self: removed.append(self))
    client.type(s.gui.cell_size.text, "0.02")
    assert wait_for(lambda: s.request["layout"]["cell"]["size"] == 0.02) and s.wait_idle(60)
    assert s.last_error is None and removed == [note] and s._error_note is None


def test_a_segment_list_corridor_is_edited_box_by_box(tab):
    s = tab.session
    # the paper mode: the moves below open a gap between boxes 3 and 4, which only the paper's
    # soft criterion plans (the constrained mode answers infeasible, naming the box)
    s.files.load_request({**copy.deepcopy(TABLE1), "settings": {"mode": "paper"}}, None, "table1")
    assert s.wait_idle(60) and s.last_error is None
    assert s.gui.segments.folder.visible and not s.gui.layout_folder.visible
    assert "12 boxes" in s.gui.status.content
    # a click in the view picks the box under it: (-0.03, 0.01) lies in box 4 (index 3)
    assert s.segment_at(-0.03, 0.01) == 3
    s.select_segment(3)
    assert s.gui.segments.lower.text.value == "-0.04, 0, 0" and s.gui.segments.upper.text.value == "-0.02, 0.02, 0"
    # drag its top edge up: snapped to the grid (the smallest box side, 0.02 m), one undo step
    for phase, y in (("start", 0.021), ("update", 0.03), ("end", 0.0372)):
        s.drag_segment("top", phase, -0.03, y)
    assert s.request["segments"][3]["upper"][1] == 0.04 and s.history.depth[0] == 2
    assert s.wait_idle(60) and s.last_error is None
    assert s.last_result.corridor.segments[3].upper[1] == pytest.approx(0.04)
    # the centre moves the whole box; typed corners and the psi range of every box
    s.drag_segment("centre", "start", -0.03, 0.02)
    s.drag_segment("centre", "end", -0.01, 0.02)
    moved = s.request["segments"][3]
    assert moved["lower"][:2] == [-0.02, 0.0] and moved["upper"][:2] == [0.0, 0.04]
    tab.clients[0].type(s.gui.segments.upper.text, "-0.02, 0.03, 0.1")
    assert wait_for(lambda: s.request["segments"][3]["upper"] == [-0.02, 0.03, 0.1])
    s.set_psi_range_all(-0.05, 0.05)
    segs = s.request["segments"]
    assert all(g["lower"][2] == -0.05 and g["upper"][2] == 0.05 for g in segs[1:-1])
    assert segs[0]["lower"][2] == segs[0]["upper"][2] == 0.0, "start and end keep their angles"
    n = len(segs)
    s.insert_segment()
    assert len(s.request["segments"]) == n + 1 and s.selected_segment == 4
    s.remove_segment()
    assert len(s.request["segments"]) == n
    assert s.wait_idle(60)
    # every edit re-planned: the plan is the request's corridor
    assert s.last_error is None
    planned = s.last_result.corridor.segments
    assert np.allclose([p.upper for p in planned], [g["upper"] for g in s.request["segments"]])
    assert np.allclose([p.lower for p in planned], [g["lower"] for g in s.request["segments"]])
    # a box turned inside out by typing: the planner's message on that box's field
    s.select_segment(3)
    tab.clients[0].type(s.gui.segments.lower.text, "0.05, 0, 0")
    assert wait_for(lambda: s.request["segments"][3]["lower"][0] == 0.05) and s.wait_idle(60)
    assert s.last_error.field.startswith("segments[3]")
    assert "must be <= upper" in (s.gui.segments.lower.error or "")


def test_plots_read_in_seconds_scaled_to_the_data_and_cleared_after_a_failure(tab):
    s = tab.session
    res, robot = s.last_result, s.robots.get("moving-slide")
    panel = s.gui.result
    force = np.asarray(res.drives.force)
    f_max = float(np.min(robot.force_max))
    assert panel.force_plot.scales["x"]["time"] is False and panel.length_plot.scales["x"]["time"] is False
    lo, hi = panel.force_plot.scales["y"]["range"]
    assert lo <= force.min() and hi >= force.max()
    assert hi - lo < 0.5 * f_max, "scaled to the forces (~10 N), not to the +-150 N limits"
    assert np.array_equal(panel.force_plot.data[0], np.asarray(res.time))
    assert f"plan #{s.last_plan_generation}" in panel.force_plot.title
    panel.include_limits.value = True
    lo, hi = panel.force_plot.scales["y"]["range"]
    assert lo <= -f_max and hi >= f_max
    s.move_handle("end", 0.16, 0.16)  # unreachable: the plan fails
    assert s.wait_idle(60) and s.last_error is not None
    assert all(len(d) == 0 for d in panel.force_plot.data) and panel.plan is None
    assert "failed" in panel.header.content and "no plan" in panel.force_plot.title


@pytest.mark.serial  # a bound of 0.5 s
def test_the_panel_answers_while_a_plan_runs(monkeypatch):
    """A slow segmentation (1 s) on the worker: typed values, undo and the status line are
    handled at once meanwhile, and the status names the plan being computed."""
    fake = FakeSegmentation(delay=1.0)
    monkeypatch.setattr(jobs, "segmentation_module", lambda: fake)
    t = Tab(None, debounce=0.05)
    s, client = t.session, t.clients[0]
    try:
        assert wait_for(lambda: fake.calls >= 1 and "planning #" in s.gui.status.content)
        t0 = time.monotonic()
        client.type(s.gui.end.text, "0.02, 0.06, 0")
        assert wait_for(lambda: s.request["layout"]["end"] == [0.02, 0.06, 0.0], 0.5), "no answer while planning"
        assert time.monotonic() - t0 < 0.5
        assert "re-planning" in s.gui.status.content or "planning #" in s.gui.status.content
        assert s.undo() and s.request["layout"]["end"] == [0.06, 0.04, 0.0]
        assert s.wait_idle(60)
    finally:
        t.stop()


def test_export_is_the_edited_request(tab):
    s = tab.session
    sent = []
    s.client.send_file_download = lambda name, content, **kw: sent.append((name, content))
    s.move_handle("end", 0.02, 0.06)
    s.files.export_request(s.client)
    assert json.loads(sent[-1][1]) == s.request


# ---------------------------------------------------------------------------- exact obstacles, machine files
def _drawing_with_a_triangular_hole(path):
    """A concave (L-shaped) outline in mm with a triangular hole: drawn as a fan from one
    vertex it would cover free space, drawn without holes it would fill the triangle."""
    import ezdxf

    doc = ezdxf.new("R2010", units=4)
    msp = doc.modelspace()
    msp.add_lwpolyline([(-60, -60), (60, -60), (60, -20), (-20, -20), (-20, 60), (-60, 60)], close=True)
    msp.add_lwpolyline([(-52, -52), (-28, -52), (-52, -28)], close=True)
    doc.saveas(path)
    return path


def _received_obstacles(client, expected_faces_min: int = 1):
    """Triangles (F, 3, 2) of the obstacle mesh and its outline segments, as the tab received them."""
    mesh = client.scene.mesh("/layout/obstacles")
    edges = client.scene.lines("/layout/obstacle_edges")
    if mesh is None or edges is None or len(mesh[1]) < expected_faces_min:
        return None
    v, f = mesh
    return v[f][:, :, :2], v[f][0, 0, 2], edges


@pytest.mark.parametrize("name, scale", [("Kitchen-cooker-V.dxf", 0.3), ("Bathroom-bath-E.dxf", 0.15),
                                         ("l-with-triangular-hole", 1.0)])
def test_imported_obstacles_are_drawn_exactly_in_the_scene_the_tab_receives(tab, tmp_path, name, scale):
    """The obstacle triangles the browser gets cover the obstacle exactly: their area is the
    drawing's (an independent even-odd reference, tests/drawings.py) within 1 %, no
    triangle lies in a hole or outside the outline, and the outlines (holes too) are drawn
    above the fill."""
    from types import SimpleNamespace

    from tests.drawings import DRAWINGS, reference_region

    s, client = tab.session, tab.clients[0]
    path = DRAWINGS / name if name.endswith(".dxf") else _drawing_with_a_triangular_hole(tmp_path / "l.dxf")
    data = path.read_bytes()
    before = client.scene.messages
    assert s.files.import_drawing(SimpleNamespace(name=path.name, content=data), {"scale": scale})
    layout = s.request["layout"]
    assert any(ob.get("holes") for ob in layout["obstacles"]), "the drawing has holes"
    region = reference_region(data, 1e-4, scale=scale)
    lo, hi = layout["bounds"]["lower"], layout["bounds"]["upper"]
    region = region.intersection(shapely.box(*lo, *hi))
    assert wait_for(lambda: client.scene.messages > before and _received_obstacles(client) is not None, 20)

    def exact():
        got = _received_obstacles(client)
        if got is None:
            return False
        tris = got[0]
        a, b = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
        area = 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum()
        return abs(area - region.area) <= 0.01 * region.area
    assert wait_for(exact, 20), "the obstacle triangles' area differs from the drawing's by more than 1 %"
    tris, z_fill, edges = _received_obstacles(client)
    centroids = tris.mean(axis=1)
    inside = shapely.contains_xy(region.buffer(2e-4), centroids[:, 0], centroids[:, 1])
    assert inside.all(), f"{int((~inside).sum())} triangle(s) with the centroid outside the obstacle or in a hole"
    holes = [shapely.Polygon(h) for g in getattr(region, "geoms", [region]) for h in g.interiors]
    assert holes
    covered = shapely.union_all(shapely.polygons(tris))
    for hole in holes:  # a hole is open: what the triangles cover of it is its rim at most
        assert covered.intersection(hole).area <= 0.01 * hole.area
    # every outline and hole outline is drawn, above the fill
    assert np.all(edges[:, :, 2] > z_fill)
    drawn = shapely.union_all([shapely.LineString(e[:, :2]) for e in edges])
    for ring in [g.exterior for g in getattr(region, "geoms", [region])] + [h.exterior for h in holes]:
        assert ring.difference(drawn.buffer(3e-4)).length <= 0.01 * ring.length


def test_machine_files_only_for_the_plan_of_the_design_on_screen(tab):
    """The downloads (G-code, leg lengths, DXF, CSV) are on only while the newest plan
    succeeded for the design on screen; each file names the design, the plan and its request's
    hash. A failed plan (start inside an obstacle) or an edit not yet planned switches every
    download off with the reason shown, and a click then sends nothing."""
    import hashlib

    s, client = tab.session, tab.clients[0]
    sent = []
    s.client.send_file_download = lambda name, content, **kw: sent.append((name, content.decode()))
    buttons = s.gui.download_buttons
    assert set(buttons) == {"gcode", "joints", "dxf", "csv"}
    assert wait_for(lambda: not any(b.disabled for b in buttons.values()))
    gen = s.last_plan_generation
    canonical = json.dumps(s.request, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    digest = hashlib.sha256(canonical.encode()).hexdigest()
    for fmt in ("gcode", "joints", "dxf"):
        s.files.download_export(s.client, fmt)
    s.files.download_csv(s.client)
    assert [n for n, _ in sent] == ["trajectory.ngc", "legs.txt", "plan.dxf", "trajectory.csv"]
    for _, text in sent:
        assert f"editor plan #{gen}" in text and digest in text and "design: editor example" in text
    assert "-0.000000" not in sent[1][1]
    # an edit not planned yet: off at once, with the reason
    s.gui.auto_replan.value = False
    s.edit(lambda r: r["layout"]["end"].__setitem__(0, r["layout"]["end"][0] - 0.01))
    assert all(b.disabled for b in buttons.values())
    assert f"changed since plan #{gen}" in s.gui.downloads_note.content
    s.gui.auto_replan.value = True
    # a start inside the obstacle: the plan fails, nothing of the earlier plan can be downloaded
    n = len(sent)
    client.type(s.gui.start.text, "-0.01, -0.05, 0")
    assert wait_for(lambda: s.last_error is not None and s.wait_idle(30), 30), s.last_error
    assert s.last_result is not None  # the earlier plan is still kept (its plots are cleared) ...
    assert all(b.disabled for b in buttons.values())  # ... but no file of it is offered
    assert "failed" in s.gui.downloads_note.content
    for button in buttons.values():
        client.click(button)
    s.files.download_export(s.client, "gcode")  # even a click the browser sent before the button went grey
    time.sleep(0.5)
    assert len(sent) == n
    assert s.notifications[-1][0] == "No download"


def test_gcode_preview_follows_the_plan_of_the_design_on_screen(tab):
    """The G-code preview: on, it is the download's program read back (its path's vertices
    are the exported program's G0/G1 points, parsed here by a regular expression), its
    duration the plan's; an edit not yet planned hides it and disables the toggle with the
    reason; the next plan brings it back (a new program); off, it leaves the view."""
    import re

    s, client = tab.session, tab.clients[0]
    sent = []
    s.client.send_file_download = lambda name, content, **kw: sent.append(content.decode())
    assert wait_for(lambda: not s.gui.preview.disabled)
    client.type(s.gui.preview, True)
    assert wait_for(lambda: s.preview.preview is not None and client.scene.lines("/preview/feed") is not None, 30)
    s.files.download_export(s.client, "gcode")
    moves = [(float(m[1]), float(m[2])) for m in re.finditer(r"^G[01] X(\S+) Y(\S+)", sent[0], re.M)]
    pts = np.vstack(([0.0, 0.0], np.array(moves) * 1e-3))  # from X0 Y0, where a program starts

    def corners(p):  # without repeats (dwells, moves of C alone)
        return p[np.r_[True, np.any(p[1:] != p[:-1], axis=1)]]

    shown = s.preview.preview
    assert np.array_equal(corners(shown.points), corners(pts))
    assert shown.lines == len(sent[0].splitlines())
    ts = float(s.last_result.settings.Ts)
    assert shown.duration_s == pytest.approx((len(s.last_result.pose) - 1) * ts, abs=1e-9)
    assert shown.path_deviation_m <= 0.75e-7 and shown.time_deviation_m <= 0.75e-7
    assert f"{shown.lines} lines" in s.gui.preview_note.content
    gen = s.last_plan_generation
    s.gui.auto_replan.value = False
    s.edit(lambda r: r["layout"]["end"].__setitem__(1, r["layout"]["end"][1] - 0.02))
    assert s.gui.preview.disabled and s.preview.preview is None
    assert f"changed since plan #{gen}" in s.gui.preview_note.content
    assert wait_for(lambda: client.scene.lines("/preview/feed") is None)
    s.plan_now()
    assert wait_for(lambda: s.preview.preview is not None and s.preview.preview.key[0] > gen, 30)
    assert np.allclose(s.preview.preview.points[-1], np.asarray(s.request["layout"]["end"][:2]), atol=1e-3)
    client.type(s.gui.preview, False)
    assert wait_for(lambda: client.scene.lines("/preview/feed") is None and s.preview.preview is None)
    s.gui.auto_replan.value = True


def test_every_received_frame_has_the_legs_on_the_platform_pivots(tab):
    """Playback from two threads at once (the slider's and the Play thread's): in every window
    of messages the tab receives, each leg ends on its platform pivot as computed from the
    platform frame's pose (position and quaternion) and the pivots drawn in that frame."""
    from app.editor._geometry import quat_to_matrix

    s, client = tab.session, tab.clients[0]
    assert s.last_result is not None and s.last_error is None
    worst: list[float] = []

    def check(mirror) -> None:
        frame, pivots, legs = (mirror.props.get(n) for n in ("/robot/platform", "/robot/platform/pivots",
                                                             "/robot/legs"))
        if not frame or not pivots or not legs or "position" not in frame:
            return
        local = np.asarray(pivots["points"], float).reshape(-1, 3)
        ends = np.asarray(legs["points"], float).reshape(-1, 2, 3)[:, 1, :2]
        if len(ends) != len(local):
            return
        wxyz = frame.get("wxyz", (1.0, 0.0, 0.0, 0.0))  # viser's default orientation is not sent
        world = frame["position"] + local @ quat_to_matrix(wxyz).T
        worst.append(float(np.max(np.hypot(*(world[:, :2] - ends).T))))

    client.scene.watchers.append(check)
    t_end = float(s.last_result.time[-1])
    ts = np.linspace(0.0, t_end, 40)
    def play(times) -> None:
        for t in times:
            s.show_time(float(t))
            time.sleep(0.01)  # frames spread over many message windows

    other = threading.Thread(target=play, args=(ts[::-1],))
    other.start()
    play(ts)
    other.join()
    s.show_time(0.5 * t_end)
    assert wait_for(lambda: len(worst) >= 3, 10), len(worst)
    time.sleep(0.5)
    assert max(worst) < 5e-4, f"a frame showed a leg {max(worst) * 1e3:.1f} mm off its platform pivot"
    # and the last frame is the pose at 0.5 t_end, as the planner computed it
    from app.editor._geometry import sample_at
    pose = sample_at(np.asarray(s.last_result.time), np.asarray(s.last_result.pose), 0.5 * t_end)
    assert np.allclose(client.scene.node("/robot/platform")["position"][:2], pose[:2], atol=1e-6)
    # the outline style keeps the robot but drops the platform fill and thins the legs
    s.scene.set_robot_style("outline")
    assert wait_for(lambda: client.scene.visible.get("/robot/platform/fill") is False)
    assert wait_for(lambda: (client.scene.node("/robot/legs") or {}).get("thickness") == 1.5)


def test_a_placed_real_drawing_plans_at_once(tab):
    """A real drawing (LibreCAD's cooker, 0.5 m wide in mm) imported with "place drawing"
    while the start and end sit where the drawing lands: it is shrunk until it and its margin
    lie where the robot reaches, the reachable extent (about +-0.146 m) becomes the bounds (it
    is stated), start and end move to free space next to it (said so) and the design plans at
    once, with the view on the drawing."""
    from types import SimpleNamespace

    from app.editor._planning import reachable_points
    from tests.drawings import DRAWINGS

    s = tab.session
    s.edit(lambda r: (r["layout"]["start"].__setitem__(slice(0, 2), [0.0, 0.0]),
                      r["layout"]["end"].__setitem__(slice(0, 2), [0.01, 0.01])))
    data = (DRAWINGS / "Kitchen-cooker-V.dxf").read_bytes()
    done = s.plans_done
    assert s.files.import_drawing(SimpleNamespace(name="Kitchen-cooker-V.dxf", content=data), {"scale": 1.0},
                                  place_margin=0.03)
    layout = s.request["layout"]
    robot = s.robots.of_request(s.request)
    lo, hi = np.asarray(layout["bounds"]["lower"]), np.asarray(layout["bounds"]["upper"])
    assert np.all(np.abs(lo + 0.146) < 0.012) and np.all(np.abs(hi - 0.146) < 0.012), (lo, hi)
    shapes = shapely.union_all([geo.obstacle_shape(ob) for ob in layout["obstacles"]])
    x0, y0, x1, y1 = shapes.bounds
    assert 0.08 < x1 - x0 < 0.3  # shrunk from 0.5 m
    ring = np.asarray(shapely.get_coordinates(shapely.segmentize(shapes.buffer(0.03).boundary, 0.002)))
    assert reachable_points(robot, ring[:, 0], ring[:, 1], 0.0).all(), "the margin around the drawing is out of reach"
    note = s.notifications[-1][1]
    assert "shrunk to fit" in note and "start moved" in note and "end moved" in note, note
    assert "x -0.14" in note and "0.14" in note  # the reachable extent, stated
    cell = float(layout["cell"]["size"])
    for which in ("start", "end"):  # the square cell holding the point is clear of the drawing
        i, j = np.floor((np.asarray(layout[which][:2]) - lo) / cell)
        assert not shapely.box(*(lo + cell * np.array([i, j])), *(lo + cell * np.array([i + 1, j + 1]))).intersects(
            shapes), which
    assert wait_for(lambda: s.plans_done > done, 60) and s.wait_idle(60)
    assert s.last_error is None, s.last_error
    assert np.allclose(s.last_result.pose[-1][:2], layout["end"][:2], atol=1e-3)
    assert "Reachable at ψ 0 rad" in s.gui.reach_note.content


def test_the_horizon_is_the_planners_default_unless_typed(tab):
    """The editor sends no N unless the person typed one: at Ts 2 ms the plan uses the
    planner's default horizon for the robot (not the 30 samples of Ts 10 ms), the field's
    label says which; a typed N is sent, an emptied field goes back to auto. Exports carry
    N only when it was typed; a loaded request's own N is kept."""
    from app.editor._gui import horizon_label
    from planner.schema import MODE_DEFAULTS, builtin_description, default_horizon

    s, client = tab.session, tab.clients[0]
    sent = []
    s.client.send_file_download = lambda name, content, **kw: sent.append(json.loads(content))
    robot = builtin_description(s.request["robot"])
    assert "N" not in s.request["settings"] and "samples_per_segment" not in s.request["settings"]
    assert s.gui.N.text.value == "" and s.gui.N.text.label == horizon_label(default_horizon(0.01, robot, None))
    client.type(s.gui.Ts.text, "0.002")
    assert wait_for(lambda: s.request["settings"]["Ts"] == 0.002) and s.wait_idle(180)
    auto = default_horizon(0.002, robot, None)
    assert auto > MODE_DEFAULTS["constrained"]["N"], "at a fine Ts the default horizon is longer than Ts 10 ms's"
    assert s.gui.N.text.label == horizon_label(auto) and f"auto ({auto})" in s.gui.N.text.label
    assert "N" not in s.request["settings"], "the editor leaves the horizon to the planner"
    assert s.last_error is None and s.last_result.settings.Ts == 0.002
    assert s.last_result.settings.N == auto  # the planner's default was used (100 for the Moving Slide)
    s.files.export_request(s.client)
    assert "N" not in sent[-1]["settings"] and "samples_per_segment" not in sent[-1]["settings"]
    done = s.plans_done
    client.type(s.gui.N.text, "40")
    assert wait_for(lambda: s.request["settings"].get("N") == 40) and s.wait_idle(180)
    assert s.plans_done > done and s.last_error is None and s.last_result.settings.N == 40
    s.files.export_request(s.client)
    assert sent[-1]["settings"]["N"] == 40
    done = s.plans_done
    client.type(s.gui.N.text, "")
    assert wait_for(lambda: "N" not in s.request["settings"]) and s.wait_idle(180)
    assert s.plans_done > done and s.last_error is None and s.last_result.settings.N == auto
    assert s.gui.N.error is None and s.gui.N.text.label == horizon_label(auto)
    # an older save that says N 30 keeps it (shown, sent as it is) where the default is longer
    old = s.request
    old["settings"].update(N=30, Ts=0.005)
    assert default_horizon(0.005, robot, None) > 30
    done = s.plans_done
    s.set_request(old)
    assert s.gui.N.text.value == "30" and s.request["settings"]["N"] == 30 and s.wait_idle(180)
    assert s.plans_done > done and s.last_error is None and s.last_result.settings.N == 30
