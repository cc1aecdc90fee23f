"""The editor opens a G-code program (issue 32, goal 5), without a browser: a real CAM post's
program (FreeCAD's linuxcnc_post, tests/data/cam) opened from the Files tab is placed in reach
(origin fit) or at a typed origin, planned by the contour job, and drawn: the programmed path
(as the G-code reader reads the program), the tolerance tube (the cells the passes were
planned through) and the planned cut, with the preview of the machine program the download
gives. A program the reader refuses names its line in the status line. Tabs are headless
viser clients (tests/viser_client.py)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import shapely

from app.editor import _geometry as geo
from app.editor import _state
from app.editor._planning import reachable_points
from planner.exchange import read_gcode
from planner.schema import PathElement
from tests.test_editor import MemStore, Tab
from tests.test_editor_session import wait_for

CAM = Path(__file__).parent / "data" / "cam"


@pytest.fixture
def tab():
    t = Tab(MemStore(), debounce=0.1)
    try:
        assert t.session.wait_idle(60)
        yield t
    finally:
        t.stop()


def _on_element(p: np.ndarray, el: PathElement) -> float:
    """Distance [m] of the point ``p`` (program frame) from the programmed move ``el``."""
    a, b = np.asarray(el.start, float), np.asarray(el.end, float)
    if el.kind == "line":
        d = b - a
        t = 0.0 if not d.any() else float(np.clip((p - a) @ d / (d @ d), 0.0, 1.0))
        return float(np.hypot(*(p - a - t * d)))
    assert el.centre is not None and el.radius_m is not None
    return abs(float(np.hypot(*(p - np.asarray(el.centre, float)))) - el.radius_m)


def _drawn(client, name: str) -> np.ndarray:
    segs = client.scene.lines(name)
    return np.zeros((0, 2, 3)) if segs is None else segs


def _open(s, name: str, placement: dict | None = None, content: bytes | None = None) -> bool:
    data = content if content is not None else (CAM / name).read_bytes()
    return s.files.open_program(SimpleNamespace(name=name, content=data), placement=placement)


def test_an_opened_program_is_placed_planned_and_drawn(tab):
    """freecad_linuxcnc.ngc (G54, G43 H1, M6 T1, M3 S10000, a profile with arcs and a helix)
    opened with the panel's placement (origin empty: fit) replaces the corridor and plans at
    once through the contour job. The plan lies where the robot reaches; the tab receives the
    programmed path exactly as the reader reads the program (every vertex on one of its moves,
    every move's end a vertex, the feed and rapid lengths the program's), placed at the origin
    the plan reports; the tube of the plan's cells, holding every cutting sample; the cut as
    the result's samples. The preview is the program the G-code download returns, read back
    within 1 um of the cut, and it is a machine program (the tool change and spindle words are
    in it). A typed origin then moves the plan and the drawing by exactly the difference, and
    until it is planned no file of the old placement is offered."""
    s, client = tab.session, tab.clients[0]
    sent: list[str] = []
    s.client.send_file_download = lambda name, content, **kw: sent.append(content.decode())
    text = (CAM / "freecad_linuxcnc.ngc").read_text()
    done = s.plans_done
    assert s.gui.program.origin.value is None  # the panel's default: fit
    assert _open(s, "freecad_linuxcnc.ngc")
    assert s.request["program"] == text and s.request["origin"] == "fit"
    assert wait_for(lambda: s.plans_done > done, 120) and s.wait_idle(120)
    assert s.last_error is None, s.last_error
    res = s.last_result
    c = res.contour
    assert c is not None and len(c.passes) >= 1
    origin = np.asarray(c.origin, float)
    robot = s.robots.of_request(s.request)
    pose = np.asarray(res.pose, float)
    assert np.max(np.abs(pose[:, 2])) < 1e-3  # contours plan at psi 0
    assert reachable_points(robot, pose[:, 0], pose[:, 1], 0.0).all()
    assert f"[{origin[0]:.4f}, {origin[1]:.4f}] m (fit)" in s.gui.status.content
    assert c.max_deviation_m <= c.tolerance_m

    # the programmed path as the reader reads the program (independently here), placed at the origin
    program = read_gcode(text)
    elements = [(e, b.kind == "travel" and b.rapid) for b in program.blocks for e in b.elements]
    assert wait_for(lambda: len(_drawn(client, "/contour/program_feed")) > 0, 30)
    feed, rapid = _drawn(client, "/contour/program_feed"), _drawn(client, "/contour/program_rapid")
    assert np.all(feed[:, :, 2] == np.float32(geo.Z["program"]))
    for segs, is_rapid in ((feed, False), (rapid, True)):
        mine = [e for e, r in elements if r == is_rapid and e.length_m > 0]
        pts = segs[:, :, :2].reshape(-1, 2) - origin
        worst = max(min(_on_element(p, e) for e in mine) for p in pts)
        kind = "rapid" if is_rapid else "feed"
        assert worst < 1e-6, f"a drawn vertex is {worst * 1e6:.2f} um off the program's {kind} moves"
        for e in mine:  # every move's end is a drawn vertex
            assert np.min(np.hypot(*(pts - np.asarray(e.end)).T)) < 1e-6, f"line {e.line}: its end is not drawn"
        drawn_len = float(np.sum(np.hypot(*(segs[:, 1, :2] - segs[:, 0, :2]).T)))
        assert drawn_len == pytest.approx(sum(e.length_m for e in mine), rel=2e-3)  # arcs as chords

    # the tube: the plan's cells, filled; every cutting sample inside one of them
    cells = [shapely.Polygon(sg.polygon) for sg in res.corridor.segments if sg.polygon is not None]
    assert cells
    assert wait_for(lambda: client.scene.mesh("/contour/tube") is not None, 30)
    v, f = client.scene.mesh("/contour/tube")
    tri = v[f][:, :, :2]
    a, b = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    assert 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum() == pytest.approx(sum(p.area for p in cells),
                                                                                       rel=1e-3)
    tube = shapely.union_all([p.buffer(2e-6) for p in cells])
    cutting = pose[np.asarray(c.cutting, bool), :2]
    assert shapely.contains_xy(tube, cutting[:, 0], cutting[:, 1]).all()

    # drawn nearly in the plane (no parallax between the program, the tube and the cut), in order
    for name in ("/contour/program_feed", "/contour/tube", "/result/trajectory", "/preview/feed"):
        sx, sy, sz = np.broadcast_to(np.asarray(client.scene.node(name).get("scale", 1.0), float), 3)
        assert sx == sy == 1.0 and 0 < sz * geo.Z["preview"] <= 1e-5, (name, sz)
    # the Result tab states G64 P both ways as the plan measured it
    for stated in (f"{c.max_deviation_m * 1e3:.4f} mm / {c.max_path_deviation_m * 1e3:.4f} mm",
                   f"{c.tolerance_m * 1e3:g} mm", f"[{origin[0]:.4f}, {origin[1]:.4f}] m"):
        assert stated in s.gui.result.metrics.content, stated
    # the planned cut: the result's samples, in order
    traj = client.scene.lines("/result/trajectory")
    assert traj is not None and len(traj) == len(pose) - 1
    assert np.allclose(traj[:, 0, :2], pose[:-1, :2], atol=1e-6) and np.allclose(traj[-1, 1, :2], pose[-1, :2],
                                                                                   atol=1e-6)

    # the preview: the machine program the download returns, read back along the cut
    assert wait_for(lambda: not s.gui.preview.disabled, 30)
    client.type(s.gui.preview, True)
    assert wait_for(lambda: s.preview.preview is not None, 60)
    s.files.download_export(s.client, "gcode")
    assert sent and s.preview.preview.text == sent[-1]
    assert s.preview.preview.path_deviation_m <= 1e-6
    words = set(re.findall(r"\b([MST]\d+)", sent[-1]))
    assert {"M3", "S10000", "T1", "M6"} <= words, words
    assert wait_for(lambda: f"{s.preview.preview.lines} lines" in s.gui.preview_note.content, 10)
    client.type(s.gui.preview, False)
    assert wait_for(lambda: s.preview.preview is None and client.scene.lines("/preview/feed") is None)
    # every machine file of the plan, each naming the program and the plan
    n = len(sent)
    for fmt in ("joints", "dxf"):
        s.files.download_export(s.client, fmt)
    s.files.download_csv(s.client)
    assert len(sent) == n + 3
    for body in sent[n - 1:]:
        assert f"editor plan #{s.last_plan_generation}" in body and "design: freecad_linuxcnc.ngc" in body
    assert len([ln for ln in sent[-1].splitlines() if ln and not ln.startswith("#")]) == len(pose) + 1  # + header

    # a typed origin (the panel's field): not planned yet, nothing of the fit plan is offered
    s.gui.auto_replan.value = False
    typed = (origin + [0.004, -0.003]).round(4)
    client.type(s.gui.program.origin.text, f"{typed[0]:g}, {typed[1]:g}")
    assert wait_for(lambda: s.request["origin"] == typed.tolist(), 10)
    assert wait_for(lambda: all(btn.disabled for btn in s.gui.download_buttons.values()) and s.gui.preview.disabled,
                    10)
    assert "changed since" in s.gui.downloads_note.content
    gen = s.last_plan_generation
    s.plan_now()
    assert wait_for(lambda: s.last_plan_generation > gen, 120) and s.wait_idle(120)
    assert s.last_error is None, s.last_error
    assert s.last_result.contour.origin == pytest.approx(typed.tolist(), abs=1e-12)
    moved = _drawn(client, "/contour/program_feed")
    assert moved.shape == feed.shape
    assert np.allclose(moved[:, :, :2] - feed[:, :, :2], typed - origin, atol=1e-6)
    s.gui.auto_replan.value = True
    # not a corridor: not saved to the store; the request JSON keeps it and opens it again
    s.files.save(new=True)
    assert s.notifications[-1][0] == "Not saved" and not s.store.list_corridors()
    exported: list[bytes] = []
    s.client.send_file_download = lambda name, content, **kw: exported.append(content)
    s.files.export_request(s.client)
    assert json.loads(exported[-1])["program"] == text
    assert s.files.load_request(json.loads(exported[-1]), None, "corridor.json")
    assert s.request["program"] == text and s.request["origin"] == typed.tolist() and s.wait_idle(120)
    assert s.last_error is None and s.undo()
    # undo the origin, undo the opening: the corridor is back, the program's drawing gone
    assert s.undo() and s.request["origin"] == "fit"
    assert s.undo() and "layout" in s.request and "program" not in s.request
    assert wait_for(lambda: client.scene.lines("/contour/program_feed") is None
                    and client.scene.mesh("/contour/tube") is None, 30)
    assert wait_for(lambda: np.all(np.asarray(client.scene.node("/result/trajectory").get("scale"), float) == 1.0),
                    10)
    # "Close program" (shown only for a program) starts a new layout with the program's robot
    assert not s.gui.program.close_button.visible
    assert s.redo() and s.redo() and s.gui.program.close_button.visible
    client.click(s.gui.program.close_button)
    assert wait_for(lambda: "program" not in s.request, 10)
    assert s.request["layout"] == _state.DEFAULT_REQUEST["layout"]
    assert s.wait_idle(120) and s.last_error is None and s.last_result.contour is None


def test_a_bad_program_names_its_line_in_the_status(tab):
    """A program with a canned cycle (G81, refused by the reader) opens, and its plan fails
    with the reader's message naming line 4 in the status line and the notification (no
    traceback); no file is offered. A file that is not text is not opened at all: the design
    stays."""
    s = tab.session
    bad = b"G21 G90\nG0 X0 Y0 Z5\nG1 Z-1 F100\nG81 X5 Y5 Z-2 R1 F100\nG1 X10 Y0\nM2\n"
    done = s.plans_done
    gen = s.last_plan_generation
    assert _open(s, "drill.ngc", {"origin": [0.0, 0.0]}, bad)
    assert wait_for(lambda: s.worker.started > gen and s.wait_idle(60) and s.last_error is not None, 60)
    assert s.plans_done == done  # nothing planned
    status = s.gui.status.content
    assert "failed" in status and "line 4" in status and "G81" in status, status
    assert "Traceback" not in status and all("Traceback" not in b for _, b in s.notifications)
    assert any("line 4" in b for _, b in s.notifications)
    assert s.last_error.field == "program"
    assert all(btn.disabled for btn in s.gui.download_buttons.values())
    assert "failed" in s.gui.downloads_note.content
    before = s.request
    assert not _open(s, "binary.ngc", {"origin": "fit"}, b"\xff\xfe\x00G1 X1\x9c")
    assert s.request == before and s.notifications[-1][0] == "Program not opened"


def test_an_origin_out_of_reach_is_shown_on_its_field_with_one_that_fits(tab):
    """Program zero typed 0.3 m out: the plan fails, the origin field says which move leaves
    the reach and proposes an origin that fits; typed into the field, that origin plans, the
    program lies where the robot reaches and the field's error is gone."""
    s, client = tab.session, tab.clients[0]
    gen = s.last_plan_generation
    assert _open(s, "freecad_linuxcnc.ngc", {"origin": [0.3, 0.3]})
    assert wait_for(lambda: s.worker.started > gen and s.wait_idle(60) and s.last_error is not None, 120)
    field = s.gui.program.origin
    assert s.last_error.field == "origin" and field.error is not None
    found = re.search(r"an origin that fits: \[(\S+), (\S+)\] m", field.error)
    assert found and "line " in field.error, field.error
    proposal = [float(found[1]), float(found[2])]
    done = s.plans_done
    client.type(field.text, f"{proposal[0]:g}, {proposal[1]:g}")
    assert wait_for(lambda: s.plans_done > done, 120) and s.wait_idle(120)
    assert s.last_error is None and field.error is None
    assert s.last_result.contour.origin == pytest.approx(proposal, abs=1e-12)
    pose = np.asarray(s.last_result.pose, float)
    assert reachable_points(s.robots.of_request(s.request), pose[:, 0], pose[:, 1], 0.0).all()
