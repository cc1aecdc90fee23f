"""Editor tests without a browser: the geometry it draws, and one editing session's
server-side behaviour (debounced re-plan on a worker thread, stale results dropped, errors
reported, cell toggling, save/load through the store, request round trip). A session
belongs to a tab: the tests connect a headless viser client (tests/viser_client.py).
Undo, number entry, snapping, segment lists and two tabs: tests/test_editor_session.py."""

from __future__ import annotations

import copy
import json
import math
import socket
import time

import numpy as np
import pytest

from app import editor as editor_mod
from app import jobs
from app.editor import _geometry as geo
from app.editor import _planning
from planner.model import SINGULAR_TOL, kinematics, load_robot
from tests.viser_client import HeadlessClient


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# ---------------------------------------------------------------------------- geometry
def test_polygon_mesh_area_matches_polygons():
    polys = [geo.rectangle([0, 0], [0.02, 0.01]), [[0, 0], [0.03, 0], [0, 0.04]],
             [[0, 0], [0, 0.04], [0.03, 0]]]  # clockwise triangle is flipped
    v, f = geo.polygon_mesh(polys, z=0.5)
    tri = v[f]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(cross[:, 2] > 0), "every face must face the top-down camera (+z)"
    assert np.isclose(0.5 * cross[:, 2].sum(), 0.02 * 0.01 + 2 * 0.5 * 0.03 * 0.04)
    assert np.all(v[:, 2] == 0.5)


def test_point_in_convex_and_shrink():
    sq = geo.rectangle([0, 0], [1, 1])
    assert geo.point_in_convex((0.5, 0.5), sq) and geo.point_in_convex((1.0, 0.3), sq)
    assert not geo.point_in_convex((1.01, 0.5), sq)
    assert geo.point_in_convex((0.5, 0.5), sq[::-1])
    small = geo.shrink(sq, 0.5)
    assert np.allclose(np.min(small, axis=0), [0.25, 0.25]) and np.allclose(np.max(small, axis=0), [0.75, 0.75])


def test_reachable_boundary_separates_reachable_from_unreachable():
    robot = load_robot("moving-slide")
    xs, ys, mask = _planning.reachable_mask(robot, [-0.3, -0.3], [0.3, 0.3], 0.0, n=61)
    assert mask.any() and not mask.all()
    # the mask agrees with the model at sample points
    for iy, ix in [(30, 30), (0, 0), (30, 45), (45, 30)]:
        pose = np.array([[xs[ix], ys[iy], 0.0]])
        L = kinematics.leg_lengths(robot, pose)[0]
        ok = bool(np.all((L >= robot.length_min) & (L <= robot.length_max))
                  and kinematics.singularity_measure(robot, pose)[0] >= SINGULAR_TOL)
        assert mask[iy, ix] == ok
    b = geo.mask_boundary(xs, ys, mask)
    assert b.shape[1:] == (2, 3) and len(b) > 0
    # every boundary edge's midpoint lies half a grid step between a reachable and an unreachable sample
    h = xs[1] - xs[0]
    mid = b.mean(axis=1)[:, :2]
    for m in mid[:: max(1, len(mid) // 25)]:
        n = np.array([[1, 0], [-1, 0], [0, 1], [0, -1]]) * h / 2
        states = []
        for d in n:
            p = m + d
            ix, iy = np.argmin(abs(xs - p[0])), np.argmin(abs(ys - p[1]))
            if abs(xs[ix] - p[0]) < 1e-9 and abs(ys[iy] - p[1]) < 1e-9:
                states.append(mask[iy, ix])
        assert len(states) == 2 and states[0] != states[1]


def test_robot_geometry_leg_lengths_match_model():
    robot = load_robot("moving-slide")
    pose = np.array([0.03, -0.02, 0.1])
    g = _planning.robot_geometry(robot, pose)
    assert np.allclose(g["lengths"], kinematics.leg_lengths(robot, pose[None])[0])
    # platform keeps its shape: pivot distances are those of the description
    d = np.linalg.norm(g["pivots"][:, None] - g["pivots"][None], axis=-1)
    d0 = np.linalg.norm(robot.platform[:, None] - robot.platform[None], axis=-1)
    assert np.allclose(d, d0)


def test_time_ticks_every_tenth_second():
    t = np.arange(0, 1.2501, 0.01)
    poses = np.column_stack((t * 2.0, -t, np.zeros_like(t)))
    ticks = geo.time_ticks(t, poses, 0.1)
    assert len(ticks) == 13
    assert np.allclose(ticks[:, 0], np.arange(13) * 0.2) and np.allclose(ticks[:, 1], -np.arange(13) * 0.1)


def test_screen_plane_maps_are_inverse_for_a_top_down_camera():
    # camera 1 m above (0.1, -0.05), looking down, image up = +y: OpenCV camera frame
    # x_cam = +x world, y_cam = -y world, z_cam = -z world -> 180 deg about x
    wxyz = (0.0, 1.0, 0.0, 0.0)
    pos = (0.1, -0.05, 1.0)
    fov, aspect = math.radians(60), 1.5
    centre = geo.screen_to_plane((0.5, 0.5), pos, wxyz, fov, aspect)
    assert np.allclose(centre, [0.1, -0.05])
    top = geo.screen_to_plane((0.5, 0.0), pos, wxyz, fov, aspect)
    assert np.isclose(top[1] - (-0.05), math.tan(fov / 2)), "upper screen edge is +y"
    right = geo.screen_to_plane((1.0, 0.5), pos, wxyz, fov, aspect)
    assert np.isclose(right[0] - 0.1, math.tan(fov / 2) * aspect), "right screen edge is +x"
    for uv in [(0.2, 0.7), (0.9, 0.1)]:
        p = geo.screen_to_plane(uv, pos, wxyz, fov, aspect)
        assert np.allclose(geo.plane_to_screen(p, pos, wxyz, fov, aspect), uv)


# ---------------------------------------------------------------------------- a stand-in segmentation
class _FakeSeg:
    def __init__(self, cells, path, segments, to_dict):
        self.segments, self._d = segments, to_dict

    def to_dict(self):
        return self._d


class FakeSegmentation:
    """Square cells, blocked when an obstacle's bounding box meets the cell's middle,
    unreachable when a corner is outside the legs' stroke; breadth-first path. Used only
    when a test needs to control the segmentation's timing."""

    def __init__(self, delay: float = 0.0):
        self.delay = delay
        self.calls = 0

    def segment(self, layout, robot, settings, field_path="layout"):
        from planner.errors import PlannerError
        from planner.schema import Segment

        if not isinstance(layout, dict):  # a validated planner.schema.Layout
            layout = layout.model_dump(mode="json")
        self.calls += 1
        time.sleep(self.delay)
        lo, hi = np.array(layout["bounds"]["lower"]), np.array(layout["bounds"]["upper"])
        h = (layout.get("cell") or {}).get("size") or 0.02
        nx, ny = int(round((hi[0] - lo[0]) / h)), int(round((hi[1] - lo[1]) / h))
        boxes = []
        for ob in layout.get("obstacles", []):
            p = np.array(geo.obstacle_polygon(ob))
            boxes.append((p.min(axis=0), p.max(axis=0)))
        cells, state = [], {}
        for j in range(ny):
            for i in range(nx):
                a = lo + h * np.array([i, j])
                b = a + h
                cid = j * nx + i
                corners = np.array([[a[0], a[1], 0], [b[0], a[1], 0], [b[0], b[1], 0], [a[0], b[1], 0]])
                L = kinematics.leg_lengths(robot, corners)
                if not np.all((L >= robot.length_min) & (L <= robot.length_max)):
                    st = "unreachable"
                elif any(np.all(np.maximum(a, blo) < np.minimum(b, bhi)) for blo, bhi in boxes):
                    st = "blocked"
                else:
                    st = "free"
                state[(i, j)] = st
                cells.append({"id": cid, "polygon": geo.rectangle(a, b), "state": st})

        def cell_of(p):
            return (min(int((p[0] - lo[0]) // h), nx - 1), min(int((p[1] - lo[1]) // h), ny - 1))

        s, e = cell_of(layout["start"]), cell_of(layout["end"])
        if state.get(e) == "unreachable":
            raise PlannerError("unreachable", "end point lies in an unreachable cell", f"{field_path}.end")
        prev, queue = {s: None}, [s]
        while queue:
            c = queue.pop(0)
            if c == e:
                break
            for d in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                n = (c[0] + d[0], c[1] + d[1])
                if n in state and n not in prev and state[n] == "free":
                    prev[n] = c
                    queue.append(n)
        if e not in prev:
            raise PlannerError("no_path", "no free path of cells from the start to the end", field_path)
        path = [e]
        while prev[path[-1]] is not None:
            path.append(prev[path[-1]])
        path.reverse()
        start, end = np.array(layout["start"], float), np.array(layout["end"], float)
        segs = [Segment(lower=start.copy(), upper=start.copy())]
        for (i, j) in path:
            a = lo + h * np.array([i, j])
            segs.append(Segment(lower=np.array([a[0], a[1], 0.0]), upper=np.array([a[0] + h, a[1] + h, 0.0])))
        segs.append(Segment(lower=end.copy(), upper=end.copy()))
        d = {"cell": {"shape": "square", "size": h}, "bounds": layout["bounds"], "cells": cells,
             "path": [j * nx + i for (i, j) in path],
             "segments": [{"lower": sg.lower.tolist(), "upper": sg.upper.tolist()} for sg in segs],
             "start": start.tolist(), "end": end.tolist(),
             # the rest of planner.schema.SegmentationResult (the editor reads it typed)
             "clearance": 0.0, "psi_range": [0.0, 0.0], "turns": 0, "grown_obstacles": [], "compute_ms": 0.0,
             "counts": {st: sum(c["state"] == st for c in cells) for st in ("free", "blocked", "unreachable")},
             "halfplanes": [None] * len(segs)}
        return _FakeSeg(cells, path, segs, d)


def real_segmentation_available() -> bool:
    try:
        from planner import corridor
        return hasattr(corridor, "segment")
    except ImportError:
        return False


@pytest.fixture
def seg_impl():
    """The editor runs on the real segmentation (planner.corridor); the slow fake
    above is used only where a test needs to control timing."""
    assert real_segmentation_available()
    yield None


class MemStore:
    """The agreed ``app.storage.Store`` corridor interface, in memory."""

    def __init__(self):
        self.rows, self.n = {}, 0

    def create_corridor(self, request, name=None):
        self.n += 1
        rid = f"c{self.n:08d}"
        self.rows[rid] = {"id": rid, "name": name, "created": "t", "updated": "t", "request": copy.deepcopy(request)}
        return copy.deepcopy(self.rows[rid])

    def get_corridor(self, rid):
        return copy.deepcopy(self.rows.get(rid))

    def update_corridor(self, rid, request, name=None):
        if rid not in self.rows:
            return None
        self.rows[rid].update(request=copy.deepcopy(request), name=name)
        return copy.deepcopy(self.rows[rid])

    def delete_corridor(self, rid):
        return self.rows.pop(rid, None) is not None

    def list_corridors(self):
        return [copy.deepcopy(r) for r in self.rows.values()]


class Tab:
    """An editor server with one headless tab connected: ``session`` is that tab's."""

    def __init__(self, store=None, **kwargs):
        self.editor = editor_mod.start_editor("127.0.0.1", free_port(), store, **kwargs)
        self.clients = []
        self.session = self.connect()

    def connect(self):
        n = len(self.editor.sessions)
        self.clients.append(HeadlessClient(self.editor.port))
        sessions = self.editor.wait_for_sessions(n + 1, 30)
        assert len(sessions) == n + 1, "the tab got no session"
        return sessions[-1]

    def stop(self):
        for c in self.clients:
            c.close()
        deadline = time.monotonic() + 10  # the server ends the sessions as the tabs go
        while self.editor.sessions and time.monotonic() < deadline:
            time.sleep(0.05)
        self.editor.stop()


@pytest.fixture
def tab(seg_impl):
    t = Tab(MemStore(), debounce=0.15)
    try:
        assert t.session.wait_idle(60)
        yield t
    finally:
        t.stop()


@pytest.fixture
def editor(tab):
    """The session of one tab (the editing API the tests drive)."""
    return tab.session


# ---------------------------------------------------------------------------- editor behaviour
def test_initial_plan_reaches_the_end_inside_the_corridor(editor):
    assert editor.last_error is None, editor.last_error
    assert editor.plans_done == 1
    res, seg = editor.last_result, editor.last_segmentation
    end = np.array(editor.request["layout"]["end"])
    pose = np.array(res.pose)
    assert np.linalg.norm(pose[-1, :2] - end[:2]) < 1e-3
    assert res.metrics.max_corridor_violation_m < 5e-3
    # the planned path runs through the segmentation's path cells, none blocked
    states = {c.id: c.state for c in seg.cells}
    assert seg.path and all(states[i] == "free" for i in seg.path)
    # the metrics panel and the slider show this result
    assert f"{res.metrics.duration_s:.3f} s" in editor.gui.result.metrics.content
    assert math.isclose(editor.gui.time.max, res.time[-1])


def test_edits_are_debounced_into_one_plan(editor):
    n0 = editor.plans_done
    for x in np.linspace(0.02, 0.06, 8):  # a drag: many moves in quick succession
        editor.move_handle("end", float(x), 0.06)
    assert editor.plans_done == n0, "no plan may start while the edits keep coming"
    assert editor.wait_idle(60)
    assert editor.plans_done == n0 + 1
    assert editor.request["layout"]["end"][:2] == [0.06, 0.06]
    assert np.linalg.norm(np.array(editor.last_result.pose[-1][:2]) - [0.06, 0.06]) < 1e-3
    assert list(editor.gui.end.value[:2]) == [0.06, 0.06]


@pytest.mark.serial  # a bound of 0.2 s
def test_stale_result_never_overwrites_a_newer_one(seg_impl, monkeypatch):
    fake = FakeSegmentation(delay=0.8)
    monkeypatch.setattr(jobs, "segmentation_module", lambda: fake)
    t = Tab(None, debounce=0.05)
    h = t.session
    try:
        time.sleep(0.3)  # the first (slow) plan is running now
        t0 = time.monotonic()
        h.move_handle("end", 0.02, 0.10)
        assert time.monotonic() - t0 < 0.2, "an edit must return at once while a plan runs"
        assert h.wait_idle(60)
        assert h.stale_discarded >= 1
        assert np.linalg.norm(np.array(h.last_result.pose[-1][:2]) - [0.02, 0.10]) < 1e-3
    finally:
        t.stop()


def test_errors_become_notifications_and_the_editor_recovers(editor):
    good = editor.last_result
    editor.move_handle("end", 0.15, 0.15)  # outside the reachable workspace
    assert editor.wait_idle(60)
    assert editor.last_error is not None and editor.last_error.code in ("unreachable", "no_path")
    assert editor.notifications and editor.notifications[-1][1]
    assert editor.last_result is good, "a failed plan keeps the last good trajectory"
    # a wall across the whole workspace between start and end: no path
    editor.move_handle("end", 0.06, 0.04)
    editor.edit(lambda r: r["layout"]["obstacles"].append({"type": "rectangle", "lower": [-0.04, -0.16],
                                                            "upper": [-0.03, 0.16]}))
    assert editor.wait_idle(60)
    assert editor.last_error.code == "no_path"
    # an obstacle over the start: the error names the start
    editor.edit(lambda r: r["layout"]["obstacles"].__setitem__(-1, {"type": "rectangle", "lower": [-0.1, -0.02],
                                                                     "upper": [-0.06, 0.02]}))
    assert editor.wait_idle(60)
    assert editor.last_error.code == "invalid_input" and editor.last_error.field == "layout.start"
    assert "obstacle" in editor.notifications[-1][1]
    # bad input names the field
    editor.edit(lambda r: r["settings"].__setitem__("Ts", -1.0))
    assert editor.wait_idle(60)
    assert editor.last_error.code == "invalid_input" and editor.last_error.field == "settings.Ts"
    assert "must be >= 0.0001, got -1" in editor.last_error.message and "settings.Ts" in editor.notifications[-1][1]
    # fix everything: planning works again
    editor.edit(lambda r: (r["settings"].__setitem__("Ts", 0.01), r["layout"]["obstacles"].pop()))
    assert editor.wait_idle(60)
    assert editor.last_error is None and editor.last_result is not good


def test_toggling_a_cell_blocks_it_and_toggling_again_frees_it(editor):
    seg = editor.last_segmentation
    free = [c for c in seg.cells if c.state == "free" and c.id in seg.path[2:-2]]
    cell = free[0]
    cx, cy = np.mean(cell.polygon, axis=0)
    n_obs = len(editor.request["layout"]["obstacles"])
    assert editor.toggle_cell_at(float(cx), float(cy))
    assert editor.wait_idle(60)
    states = {c.id: c.state for c in editor.last_segmentation.cells}
    assert states[cell.id] == "blocked"
    # only that cell: its neighbours keep their state
    assert sum(states[i] == "blocked" for i in states) == sum(c.state == "blocked" for c in seg.cells) + 1
    assert cell.id not in editor.last_segmentation.path
    assert editor.toggle_cell_at(float(cx), float(cy))
    assert editor.wait_idle(60)
    assert len(editor.request["layout"]["obstacles"]) == n_obs
    assert {c.id: c.state for c in editor.last_segmentation.cells}[cell.id] == "free"


def test_settings_controls_change_the_request(editor):
    editor.gui.mode.value = "paper"  # first: a mode switch moves N, k_r, k_u still at the old mode's defaults
    editor.gui.N.text.value = "30"
    editor.gui.k_u.text.value = "1e-4"
    editor.gui.cell_size.text.value = ""  # auto
    assert editor.wait_idle(60)
    r = editor.request
    assert r["settings"]["N"] == 30 and r["settings"]["k_u"] == 1e-4
    assert "size" not in r["layout"]["cell"]
    assert editor.last_result.settings.N == 30


def test_an_unset_horizon_stays_unset_and_its_auto_value_is_the_planners():
    """N left out of the editor's request stays out through mode switches (the planner
    chooses it); the value the N field announces for an empty field is the one the planner
    fills in: per mode, Ts and robot (a description's own masses and limits count)."""
    from app.editor import _state
    from planner import PlanRequest
    from planner.schema import MODE_DEFAULTS, builtin_description

    r = copy.deepcopy(_state.DEFAULT_REQUEST)
    assert "N" not in r["settings"] and _state.mode_settings(r)["N"] is None
    for mode in ("paper", "constrained"):
        _state.switch_mode(r, mode)
        assert "N" not in r["settings"] and _state.mode_settings(r)["N"] is None
    heavy = builtin_description("moving-slide").model_dump(mode="json")
    heavy["platform"]["mass"] *= 20  # longer braking: a longer default horizon
    for mode, Ts, robot in (("paper", 0.002, "moving-slide"), ("constrained", 0.01, "moving-slide"),
                            ("constrained", 0.002, "moving-slide"), ("constrained", 0.005, "moving-slide"),
                            ("constrained", 0.01, heavy)):
        r["settings"].update(mode=mode, Ts=Ts)
        r["robot"] = robot
        used = PlanRequest.model_validate(r).settings.N
        assert _planning.auto_horizon(r) == used, (mode, Ts)
    heavy_N = _planning.auto_horizon(r)
    assert heavy_N is not None and heavy_N > MODE_DEFAULTS["constrained"]["N"], "the heavy robot's is longer"
    r["settings"]["Ts"] = -1.0
    assert _planning.auto_horizon(r) is None  # invalid settings: nothing announced, the planner names Ts


def test_mode_switch_moves_untouched_penalties_to_the_mode_defaults(editor):
    """N, k_r, k_u still at the paper defaults follow the mode to the constrained defaults;
    a value the user changed stays; the plan uses what the request says."""
    from planner.schema import MODE_DEFAULTS

    paper, con = MODE_DEFAULTS["paper"], MODE_DEFAULTS["constrained"]
    editor.gui.mode.value = "paper"
    for field, value in ((editor.gui.N, paper["N"]), (editor.gui.k_r, paper["k_r"]), (editor.gui.k_u, 3e-4)):
        field.text.value = str(value)
    editor.gui.mode.value = "constrained"
    st = editor.request["settings"]
    assert (st["mode"], st["N"], st["k_r"], st["k_u"]) == ("constrained", con["N"], con["k_r"], 3e-4)
    assert (editor.gui.N.value, editor.gui.k_r.value, editor.gui.k_u.value) == (con["N"], con["k_r"], 3e-4)
    assert editor.wait_idle(60)
    used = editor.last_result.settings
    assert (used.mode, used.N, used.k_r, used.k_u) == ("constrained", con["N"], con["k_r"], 3e-4)
    editor.gui.mode.value = "paper"
    st = editor.request["settings"]
    assert (st["N"], st["k_r"], st["k_u"]) == (paper["N"], paper["k_r"], 3e-4)
    assert editor.wait_idle(60)


def test_save_load_and_import_round_trip(editor):
    editor.files.save(new=True)
    store = editor.store
    (rec,) = store.list_corridors()
    assert rec["request"] == editor.request
    editor.move_handle("end", 0.04, 0.08)
    editor.files.save(new=False)
    assert store.get_corridor(rec["id"])["request"]["layout"]["end"][:2] == [0.04, 0.08]
    editor.move_handle("end", 0.0, 0.10)
    assert editor.wait_idle(60)
    editor.files.refresh_stored()
    editor.gui.stored.value = editor.gui.stored.options[0]
    editor.files.load()
    assert editor.request["layout"]["end"][:2] == [0.04, 0.08]
    assert editor.wait_idle(60)
    # import: the exported JSON loads back unchanged; broken JSON is a notification
    exported = json.dumps(editor.request).encode()
    upload = type("U", (), {"name": "x.json", "content": exported})()
    editor.files.import_upload(upload)
    assert editor.request == json.loads(exported)
    editor.files.import_upload(type("U", (), {"name": "bad.json", "content": b"{nope"})())
    assert editor.notifications[-1][0] == "Import failed"
    editor.files.import_upload(type("U", (), {"name": "bad.json", "content": b'{"layout": {"bounds": 3}}'})())
    assert "layout.bounds" in editor.notifications[-1][1]
    assert editor.request == json.loads(exported), "a bad import must not change the design"


def test_segments_only_request_is_planned(editor):
    with _table1() as f:
        data = json.load(f)
    editor.files.load_request(data, None, "table1")
    assert editor.wait_idle(60)
    assert editor.last_error is None
    assert editor.last_segmentation is None
    end = np.array(data["segments"][-1]["lower"][:2])
    assert np.linalg.norm(np.array(editor.last_result.pose[-1][:2]) - end) < 1e-3


def _table1():
    from tests.support import TABLE1_PATH

    return open(TABLE1_PATH)


def test_playback_moves_the_robot_along_the_trajectory(editor):
    drawn = []
    orig = editor.scene.show_robot
    editor.scene.show_robot = lambda robot, pose, force=None: (drawn.append(np.array(pose)), orig(robot, pose, force))
    editor.gui.time.value = 0.0
    editor.gui.playback.toggle()
    deadline = time.monotonic() + editor.gui.time.max + 5
    while editor.gui.playback.playing and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not editor.gui.playback.playing
    assert len(drawn) > 10
    start, end = np.array(editor.request["layout"]["start"]), np.array(editor.request["layout"]["end"])
    assert np.linalg.norm(drawn[0][:2] - start[:2]) < 0.01
    assert np.linalg.norm(drawn[-1][:2] - end[:2]) < 1e-3
    assert math.isclose(editor.gui.time.value, editor.gui.time.max)


def test_scene_nodes_are_created_once_and_updated_in_place(seg_impl, monkeypatch):
    """Every scene node of a tab is added once, when its session opens (in that tab's own
    scene); a re-plan, playback frames, hiding (a failed plan, a request without a layout),
    segment drags and showing again only update the kept viser handles: no node is added or
    removed after that. A second tab adds its own copy of each node, once."""
    import viser
    from viser._scene_handles import SceneNodeHandle

    added, removed = [], []

    def spy_add(method_name):
        method = getattr(viser.SceneApi, method_name)

        def add(self, name, *args, **kwargs):
            added.append((id(self), name))
            return method(self, name, *args, **kwargs)
        return add

    for method_name in dir(viser.SceneApi):
        if method_name.startswith("add_"):
            monkeypatch.setattr(viser.SceneApi, method_name, spy_add(method_name))
    remove_by_name, remove = viser.SceneApi.remove_by_name, SceneNodeHandle.remove
    monkeypatch.setattr(viser.SceneApi, "remove_by_name",
                        lambda self, name: (removed.append(name), remove_by_name(self, name))[1])
    monkeypatch.setattr(SceneNodeHandle, "remove", lambda self: (removed.append(self.name), remove(self))[1])

    t = Tab(MemStore(), debounce=0.05)
    h = t.session
    try:
        assert h.wait_idle(60) and h.last_error is None
        scene = h.scene
        server_nodes = [name for scope, name in added if scope == id(t.editor.server.scene)]
        assert set(server_nodes) <= {"/WorldAxes"}, "the editor draws nothing every tab would share"
        added[:] = [(scope, name) for scope, name in added if scope != id(t.editor.server.scene)]
        assert len(added) == len(set(added)), "a node was added twice while the session opened"
        assert {id(h.client.scene)} == {scope for scope, _ in added}, "nodes must be the tab's own"
        names = {name for _, name in added}
        assert {"/robot/legs", "/robot/platform", "/result/trajectory", "/seg/cells_free", "/handles/end",
                "/segments/handle_left"} <= names
        at_start = len(added)

        # a re-plan updates the trajectory, cells and robot on the same handles
        trajectory, legs = scene.trajectory, scene.legs
        before = trajectory.points.copy()
        h.move_handle("end", 0.02, 0.06)
        assert h.wait_idle(60) and h.last_error is None
        assert scene.trajectory is trajectory and scene.legs is legs
        assert trajectory.visible and not np.array_equal(trajectory.points, before)
        h.move_handle("end", 0.02, 0.06, phase="end")
        assert np.allclose(scene.gizmos["end"].position[:2], [0.02, 0.06])

        # N playback frames move the platform frame and the legs: nothing added per frame
        t_end = h.gui.time.max
        poses, leg_points = [], []
        for tk in np.linspace(0.0, t_end, 40):
            h.gui.time.value = round(float(tk), 2)
            poses.append(scene.platform.position.copy())
            leg_points.append(scene.legs.points.copy())
        assert len(added) == at_start, f"playback added nodes: {added[at_start:]}"
        assert len({tuple(np.round(p, 6)) for p in poses}) > 30, "the platform must move frame by frame"
        assert not np.array_equal(leg_points[0], leg_points[-1])
        end = h.request["layout"]["end"]
        assert np.allclose(poses[-1][:2], end[:2], atol=1e-3)
        h.gui.playback.toggle()  # the real playback thread: the same, at PLAY_FPS
        deadline = time.monotonic() + t_end + 5
        while h.gui.playback.playing and time.monotonic() < deadline:
            time.sleep(0.05)
        assert len(added) == at_start

        # a failed plan hides the result and the robot (visible = False), nothing re-added
        h.move_handle("end", 0.15, 0.15)
        assert h.wait_idle(60) and h.last_error is not None
        assert not scene.trajectory.visible and not scene.ticks.visible and not scene.robot.visible
        assert not any(node.visible for node in scene.cells.values())
        h.move_handle("end", 0.06, 0.04)
        assert h.wait_idle(60) and h.last_error is None
        assert scene.trajectory.visible and scene.robot.visible and scene.cells["free"].visible

        # a request without a layout hides the layout, its gizmos and cells and shows the boxes;
        # dragging a box edge moves the kept handle meshes; a new layout shows the layout again
        with _table1() as f:
            h.files.load_request(json.load(f), None, "table1")
        assert not scene.gizmos["start"].visible and not scene.obstacles.visible and not scene.bounds.visible
        assert not any(node.visible for node in scene.cells.values()), "no leftovers of the layout"
        assert h.wait_idle(60) and h.last_error is None
        assert scene.seg_boxes.visible and scene.trajectory.visible
        h.select_segment(3)
        for phase, x in (("start", -0.02), ("update", -0.01), ("end", 0.0)):
            h.drag_segment("right", phase, x, 0.01)
        assert h.request["segments"][3]["upper"][0] == 0.0
        assert h.wait_idle(60)
        h.new_layout()
        assert h.wait_idle(60) and h.last_error is None
        assert scene.gizmos["start"].visible and scene.obstacles.visible and not scene.seg_boxes.visible

        assert added[at_start:] == [], "scene nodes were added after the session opened"
        assert removed == [], "scene nodes were removed"

        # a second tab: its own nodes, each once, in its own scene; the first tab's are untouched
        h2 = t.connect()
        assert h2.wait_idle(60)
        second = added[at_start:]
        assert {scope for scope, _ in second} == {id(h2.client.scene)}
        assert sorted(name for _, name in second) == sorted(name for _, name in added[:at_start])
    finally:
        t.stop()
