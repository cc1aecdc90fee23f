"""The editor in a real browser: Debian's headless Chromium driven by Playwright
(``executable_path=/usr/bin/chromium``; Playwright's own browser download is never used),
with real keystrokes and mouse events.

Each test opens its own tab (= its own editing session) on one editor server. Checked, as a
person would: the page renders; typed numbers keep their sign and exponent and a bad one is
shown on its field; two tabs are independent; a drag and an obstacle are undone and redone
with Ctrl+Z / Ctrl+Shift+Z; drags and drawn rectangles snap to the grid and the cursor
readout says where the mouse is; the plots' time axis reads seconds (the value uPlot renders
in its legend while the mouse is over the plot); a Table I segment corridor is edited in
the view and the panel and re-planned; the panel answers while a plan runs; no request
leaves 127.0.0.1; the G-code preview draws the downloaded program over the plan (checked in
the scene the page receives). Screenshots of each step go to ``$RANGEPLAN_SHOTS`` (default: the test's
tmp dir) to be looked at; ``RANGEPLAN_DOCS_SCREENSHOT=docs/editor.png`` also writes the
README's screenshot. The browser is closed before the viser server stops.
"""

import base64
import math
import os
import socket
import threading
import time
from pathlib import Path
from urllib.parse import urlparse

import numpy as np
import pytest

import app.editor._session as session_module
from tests.support import TABLE1_PATH
from tests.viser_client import SceneMirror

pytestmark = pytest.mark.browser

CHROMIUM = "/usr/bin/chromium"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]
#: the window: the README's screenshots at 1400 x 900; the tests at 880 x 860 (60 % of the
#: pixels, which the page's software WebGL draws in about that share of the time). Not lower: the
#: panel's controls above the tabs need ~620 px and the tabs' own box at least 220 px.
W, H = (1400, 900) if os.environ.get("RANGEPLAN_DOCS_SCREENSHOT") else (880, 860)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def settled(session, timeout=60.0) -> bool:
    """The session has planned its newest edit (past the debounce)."""
    time.sleep(0.3)
    return session.wait_idle(timeout)


def wait_for(cond, timeout=60.0):
    t = time.monotonic() + timeout
    while time.monotonic() < t:
        if cond():
            return True
        time.sleep(0.05)
    return False


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from playwright.sync_api import sync_playwright

    from app.editor import start_editor
    from app.storage import Store

    assert Path(CHROMIUM).exists(), "Debian chromium is missing: `make test` installs it (apt-get install chromium)"
    store = Store(tmp_path_factory.mktemp("editor") / "rangeplan.sqlite3")
    editor = start_editor("127.0.0.1", free_port(), store, debounce=0.15)
    urls: list[str] = []
    shots = Path(os.environ.get("RANGEPLAN_SHOTS") or tmp_path_factory.mktemp("shots"))
    shots.mkdir(parents=True, exist_ok=True)
    pw = sync_playwright().start()
    context = pw.chromium.launch_persistent_context(  # a new, empty --user-data-dir
        str(tmp_path_factory.mktemp("chromium-profile")), executable_path=CHROMIUM, args=FLAGS,
        viewport={"width": W, "height": H})
    context.on("request", lambda r: urls.append(r.url))
    try:
        yield editor, context, urls, shots
    finally:
        context.close()  # before the viser server: its stop blocks while a client is connected
        pw.stop()
        wait_for(lambda: not editor.sessions, 10)
        editor.stop()


def close_notifications(page) -> None:
    """Click every notification's close button that is there now, in one step in the page: a
    notification that closes itself meanwhile (or the first click closing more than one) leaves a
    locator taken before it with nothing to wait for. No wait for a still frame either: a loaded
    machine renders the software-WebGL page slowly."""
    page.evaluate("document.querySelectorAll('.mantine-Notification-closeButton').forEach(b => b.click())")


class Tab:
    """One browser tab of the editor and its session on the server."""

    def __init__(self, editor, context, shots: Path, *, mirror: bool = False):
        self.editor, self.shots = editor, shots
        known = {id(s) for s in editor.sessions}
        self.page = context.new_page()
        #: with ``mirror``: the scene as this page receives it (viser's websocket frames, decoded in
        #: the test's thread while Playwright runs a call: only for the tests that look at it)
        self.scene = SceneMirror()
        if mirror:
            self.page.on("websocket", lambda ws: ws.on(
                "framereceived", lambda payload: self.scene.feed(payload) if isinstance(payload, bytes) else None))
        # a loaded machine renders the software-WebGL page slowly: a click can wait many seconds
        # for a still frame; the tests wait on state, so a long limit costs nothing when all is well
        self.page.set_default_timeout(120_000)
        self.page.goto(editor.url)
        self.page.wait_for_selector("canvas", timeout=30_000)
        assert wait_for(lambda: any(id(s) not in known for s in editor.sessions), 30), "the tab got no session"
        self.session = next(s for s in editor.sessions if id(s) not in known)
        assert self.session.wait_idle(60) and self.session.last_result is not None
        time.sleep(1.5)  # first frames, camera placed by the server
        close_notifications(self.page)  # the "software WebGL" notice

    def lines(self, name: str):
        """The line-segment node ``name`` as this page received it (None: hidden). Playwright's
        sync API delivers the websocket frames while it runs a call: a short wait first."""
        self.page.wait_for_timeout(20)
        return self.scene.lines(name)

    def shot(self, name: str) -> Path:
        path = self.shots / f"{name}.png"
        self.page.screenshot(path=str(path))
        return path

    def field(self, label: str):
        """The text input of the field whose label contains ``label``."""
        return self.page.locator(
            f"xpath=//label[contains(normalize-space(), \"{label}\")]/ancestor::div[.//input][1]//input").first

    def type_into(self, label: str, text: str) -> None:
        """Select the field's text and type ``text`` key by key, as a person does."""
        box = self.field(label)
        box.click()
        box.press("Control+a")
        box.press_sequentially(text, delay=40)

    def tab(self, name: str) -> None:
        self.page.get_by_role("tab", name=name).click()
        time.sleep(0.3)

    def screen(self, x: float, y: float) -> tuple[float, float]:
        """Page pixel of the plane point (x, y) [m] in this tab's top-down view."""
        cam = self.session.client.camera
        box = self.page.locator("canvas").first.bounding_box()
        ppm = (box["height"] / 2) / (cam.position[2] * math.tan(cam.fov / 2))  # pixels per metre
        return (box["x"] + box["width"] / 2 + (x - cam.position[0]) * ppm,
                box["y"] + box["height"] / 2 - (y - cam.position[1]) * ppm)

    def drag(self, start, end, steps: int = 12) -> None:
        """A real mouse drag from page pixel ``start`` to ``end``."""
        m = self.page.mouse
        m.move(*start)
        m.down()
        for i in range(1, steps + 1):
            m.move(start[0] + (end[0] - start[0]) * i / steps, start[1] + (end[1] - start[1]) * i / steps)
            time.sleep(0.03)
        m.up()

    def focus_view(self) -> None:
        """Give the page the keyboard focus without touching a field (a click on the panel's title)."""
        self.page.get_by_text("rangeplan corridor editor").first.click()

    def close(self) -> None:
        self.page.close()


@pytest.fixture
def tab(server):
    editor, context, _, shots = server
    t = Tab(editor, context, shots)
    try:
        yield t
    finally:
        t.close()


def canvas_pixels(page) -> np.ndarray:
    """The WebGL canvas as the user sees it: an element screenshot decoded in the page's own
    2D canvas (no image library needed), as an (h, w, 3) array."""
    png = page.locator("canvas").first.screenshot()
    data = page.evaluate("""async (b64) => {
        const img = new Image(); img.src = 'data:image/png;base64,' + b64; await img.decode();
        const c = document.createElement('canvas'); c.width = 200; c.height = 130;
        const g = c.getContext('2d'); g.drawImage(img, 0, 0, 200, 130);
        return Array.from(g.getImageData(0, 0, 200, 130).data);
    }""", base64.b64encode(png).decode())
    return np.array(data, dtype=float).reshape(130, 200, 4)[..., :3]


# ---------------------------------------------------------------------------- the page
def test_page_renders_a_non_blank_scene(tab):
    px = canvas_pixels(tab.page)
    assert px.std() > 10.0, "the WebGL canvas is blank"
    colours = {tuple(c) for c in (px // 16).reshape(-1, 3).astype(int)}
    assert len(colours) >= 8, "the scene should show cells, corridor, trajectory and robot in several colours"
    assert tab.page.get_by_role("button", name="Plan", exact=True).count() == 1
    tab.shot("01-start")


def test_plan_button_replans_on_the_server(tab):
    s = tab.session
    done, gen = s.plans_done, s.last_plan_generation
    tab.page.get_by_role("button", name="Plan", exact=True).click()
    assert wait_for(lambda: s.plans_done > done and s.last_plan_generation > gen)
    assert s.wait_idle(60)
    end = s.request["layout"]["end"]
    assert np.linalg.norm(np.array(s.last_result.pose[-1][:2]) - end[:2]) < 1e-4
    assert wait_for(lambda: f"plan #{s.last_plan_generation}" in tab.page.locator("body").inner_text(), 10)


# ---------------------------------------------------------------------------- number entry
def test_negative_and_exponent_numbers_typed_with_real_keys(tab):
    s, page = tab.session, tab.page
    tab.type_into("Start x, y (m)", "-0.09, 0.02, 0")
    assert wait_for(lambda: s.request["layout"]["start"] == [-0.09, 0.02, 0.0], 10), s.request["layout"]["start"]
    assert tab.field("Start x, y (m)").input_value() == "-0.09, 0.02, 0", "the field keeps what was typed"
    tab.type_into("End x, y (m)", "6e-2, 4E-2, -0")
    assert wait_for(lambda: s.request["layout"]["end"] == [0.06, 0.04, 0.0], 10)
    assert s.wait_idle(60) and s.last_error is None
    assert np.allclose(s.last_result.pose[0][:2], [-0.09, 0.02], atol=1e-9)
    tab.tab("Settings")
    tab.type_into("k_u, force penalty", "2.5e-4")
    assert wait_for(lambda: s.request["settings"]["k_u"] == 2.5e-4, 10)
    assert tab.field("k_u, force penalty").input_value() == "2.5e-4"
    tab.type_into("Sample time Ts", "-0.01")  # out of range: shown on the field, nothing changes
    line = page.locator(".rangeplan-field-error", has_text="must be >= 0.0001, got -0.01")
    assert wait_for(lambda: line.count() == 1 and line.first.is_visible(), 10)
    assert s.request["settings"]["Ts"] == 0.01
    assert "\u26a0" in page.locator("xpath=//label[contains(normalize-space(), 'Sample time Ts')]").inner_text()
    border = tab.field("Sample time Ts").evaluate("e => getComputedStyle(e).borderTopColor")
    assert border == "rgb(224, 49, 49)", border
    tab.shot("02-field-error")
    tab.type_into("Sample time Ts", "0.01")
    assert wait_for(lambda: line.count() == 0 or not line.first.is_visible(), 10)
    assert s.wait_idle(60) and s.last_error is None and s.last_result.settings.k_u == 2.5e-4


def test_the_horizon_field_says_the_planners_default_and_empties_to_it(tab):
    """In the page: the empty N field's label says the horizon the planner uses for the
    current Ts ("auto (100)" at Ts 2 ms for the Moving Slide), a typed N is sent, and
    deleting it with the keyboard goes back to auto."""
    from planner.schema import builtin_description, default_horizon

    s, page = tab.session, tab.page
    robot = builtin_description(s.request["robot"])
    tab.tab("Settings")
    label = page.locator("xpath=//label[contains(normalize-space(), 'Horizon N')]")
    auto = default_horizon(0.01, robot, None)
    assert wait_for(lambda: f"empty = auto ({auto})" in label.inner_text(), 10), label.inner_text()
    assert tab.field("Horizon N").input_value() == "" and "N" not in s.request["settings"]
    tab.type_into("Sample time Ts", "0.002")
    auto = default_horizon(0.002, robot, None)
    assert wait_for(lambda: f"empty = auto ({auto})" in label.inner_text(), 10), label.inner_text()
    assert s.wait_idle(60) and s.last_error is None and s.last_result.settings.N == auto
    tab.type_into("Horizon N", "40")
    assert wait_for(lambda: s.request["settings"].get("N") == 40, 10)
    assert s.wait_idle(60) and s.last_error is None and s.last_result.settings.N == 40
    box = tab.field("Horizon N")
    box.click()
    box.press("Control+a")
    box.press("Backspace")
    assert wait_for(lambda: "N" not in s.request["settings"], 10)
    assert s.wait_idle(60) and s.last_error is None and s.last_result.settings.N == auto
    assert "\u26a0" not in label.inner_text(), "an empty N is valid"


# ---------------------------------------------------------------------------- tabs
def test_two_tabs_are_independent(server, tab):
    editor, context, _, shots = server
    other = Tab(editor, context, shots)
    try:
        a, b = tab.session, other.session
        assert a is not b
        before = b.request
        tab.type_into("End x, y (m)", "0.02, 0.06, 0")
        assert wait_for(lambda: a.request["layout"]["end"] == [0.02, 0.06, 0.0], 10) and a.wait_idle(60)
        other.page.bring_to_front()
        assert other.field("End x, y (m)").input_value() == "0.06, 0.04, 0"
        assert b.request == before and b.last_result.pose[-1][:2] == pytest.approx([0.06, 0.04], abs=1e-3)
        other.type_into("Start x, y (m)", "-0.1, 0, 0")
        assert wait_for(lambda: b.request["layout"]["start"] == [-0.1, 0.0, 0.0], 10)
        assert a.request["layout"]["start"] == [-0.08, 0.0, 0.0]
        other.shot("03-second-tab")
    finally:
        other.close()


# ---------------------------------------------------------------------------- undo, snapping, readout
def _drag_end_handle(tab, dx_px: float):
    lay = tab.session.request["layout"]
    span = max(b - a for a, b in zip(lay["bounds"]["lower"], lay["bounds"]["upper"]))
    arrow = 0.55 * 0.12 * span  # along the gizmo's x-arrow (its scale is 0.12 x the larger bounds side)
    sx, sy = tab.screen(lay["end"][0] + arrow, lay["end"][1])
    tab.drag((sx, sy), (sx + dx_px, sy))


def test_undo_and_redo_a_drag_and_an_obstacle_with_keys(tab):
    s = tab.session
    r0 = s.request
    _drag_end_handle(tab, -40)
    assert wait_for(lambda: s.request["layout"]["end"][0] < r0["layout"]["end"][0] - 0.01, 10), "the drag moved nothing"
    r1 = s.request
    x = r1["layout"]["end"][0]
    assert abs((x + 0.16) / 0.02 - round((x + 0.16) / 0.02)) < 1e-9, f"dragged end {x} is not on the 0.02 m grid"
    assert s.history.depth == (1, 0), "one drag is one undo step"
    # Shift + drag on the view draws a rectangle obstacle; its corners snap to the grid
    a, b = tab.screen(0.027, -0.094), tab.screen(0.071, -0.052)
    tab.page.keyboard.down("Shift")
    tab.drag(a, b)
    tab.page.keyboard.up("Shift")
    assert wait_for(lambda: len(s.request["layout"]["obstacles"]) == len(r0["layout"]["obstacles"]) + 1, 10)
    r2 = s.request
    assert r2["layout"]["obstacles"][-1] == {"type": "rectangle", "lower": [0.02, -0.1], "upper": [0.08, -0.06]}
    tab.shot("04-drag-and-obstacle")
    tab.focus_view()
    tab.page.keyboard.press("Control+z")
    assert wait_for(lambda: s.request == r1, 10), "Ctrl+Z undoes the obstacle"
    tab.page.keyboard.press("Control+z")
    assert wait_for(lambda: s.request == r0, 10), "Ctrl+Z undoes the drag"
    assert wait_for(lambda: tab.field("End x, y (m)").input_value() == "0.06, 0.04, 0", 10)
    tab.page.keyboard.press("Control+Shift+z")
    assert wait_for(lambda: s.request == r1, 10), "Ctrl+Shift+Z redoes the drag"
    tab.page.get_by_role("button", name="Redo", exact=True).click()
    assert wait_for(lambda: s.request == r2, 10), "the Redo button redoes the obstacle"
    assert settled(s) and s.last_error is None
    assert np.allclose(s.last_result.pose[-1][:2], r1["layout"]["end"][:2], atol=1e-4)


def test_snapping_and_the_cursor_readout(tab):
    s, page = tab.session, tab.page
    readout = page.locator("#rangeplan-cursor .xy")
    for x, y in ((0.0312, -0.0475), (-0.1033, 0.0871)):
        page.mouse.move(*tab.screen(x - 0.003, y))
        page.mouse.move(*tab.screen(x, y))
        assert wait_for(lambda: "m, y" in readout.inner_text(), 5)
        text = readout.inner_text().replace("\u2212", "-")
        got = [float(v) for v in text.split(" m")[0].split("x ")[1:]] + [float(text.split("y ")[1].split(" m")[0])]
        assert got == pytest.approx([x, y], abs=1e-3), text  # a pixel is ~0.9 mm here
        gx, gy = (-0.16 + 0.02 * round((v + 0.16) / 0.02) for v in (x, y))
        assert f"snaps to {gx:.4f}, {gy:.4f}".replace("-", "\u2212") in readout.inner_text()
    # snapping off: the drag lands where the mouse let go (to 0.1 mm)
    tab.tab("Edit")
    page.get_by_text("Snap drags to the grid").first.click()
    assert wait_for(lambda: s.gui.snap.value is False, 5)
    _drag_end_handle(tab, -31)
    assert wait_for(lambda: s.request["layout"]["end"][0] < 0.05, 10)
    x = s.request["layout"]["end"][0]
    assert abs(x * 1e4 - round(x * 1e4)) < 1e-6, "0.1 mm resolution"
    assert abs((x + 0.16) / 0.02 - round((x + 0.16) / 0.02)) > 1e-3, "not snapped to the cell grid"
    assert s.wait_idle(60)


# ---------------------------------------------------------------------------- plots
def test_plot_time_axis_reads_seconds(tab):
    s, page = tab.session, tab.page
    tab.tab("Result")
    duration = float(s.last_result.time[-1])
    over = page.locator(".u-over").first
    over.scroll_into_view_if_needed()
    bb = over.bounding_box()
    legend = page.locator(".u-legend").first
    for f in (0.25, 0.5, 0.9):
        page.mouse.move(bb["x"] + f * bb["width"], bb["y"] + 0.5 * bb["height"])
        time.sleep(0.3)
        text = legend.inner_text()
        assert text.startswith("t (s)"), text
        value = text.split("t (s)")[1].split("F1")[0].strip().strip(":").strip()
        assert float(value) == pytest.approx(f * duration, abs=0.03 * duration), text  # seconds, not a date
    titles = page.locator(".u-title").all_inner_texts()
    assert f"plan #{s.last_plan_generation}" in titles[0] and "limit ±150 N" in titles[0]
    tab.shot("05-plots")
    tab.tab("Edit")
    tab.type_into("End x, y (m)", "0.16, 0.16, 0")  # unreachable: the plan fails, the plots empty
    assert wait_for(lambda: s.last_error is not None and s.wait_idle(1), 30)
    tab.tab("Result")
    assert wait_for(lambda: "no plan" in page.locator(".u-title").first.inner_text(), 10)
    assert "failed" in page.locator("body").inner_text()


# ---------------------------------------------------------------------------- segment corridors
def test_table1_segment_corridor_is_edited_and_replanned(tab):
    s, page = tab.session, tab.page
    tab.tab("Files")
    page.locator("input[type=file]").first.set_input_files(str(TABLE1_PATH))
    assert wait_for(lambda: bool(s.request.get("segments")) and s.request.get("layout") is None, 20)
    assert s.wait_idle(60) and s.last_error is None
    tab.tab("Edit")
    assert page.get_by_text("12 boxes").first.is_visible()
    s.place_cameras()
    time.sleep(1.0)
    # a click on box 4 (x -0.04..-0.02, y 0..0.02) picks it
    page.mouse.click(*tab.screen(-0.03, 0.01))
    assert wait_for(lambda: s.selected_segment == 3, 10)
    assert wait_for(lambda: tab.field("Upper x, y (m)").input_value() == "-0.02, 0.02, 0", 10)
    time.sleep(0.5)
    # drag its top edge up by about one box: it lands on the grid
    tab.drag(tab.screen(-0.03, 0.02), tab.screen(-0.03, 0.043), steps=15)
    assert wait_for(lambda: s.request["segments"][3]["upper"][1] == 0.04, 10), s.request["segments"][3]
    assert settled(s) and s.last_error is None
    assert s.last_result.corridor.segments[3].upper[1] == pytest.approx(0.04)
    tab.shot("06-table1-edge-dragged")
    # type the lower corner with a psi range, insert a copy and remove it
    tab.type_into("Lower x, y (m)", "-0.04, 0, -0.1")
    tab.type_into("Upper x, y (m)", "-0.02, 0.04, 0.1")
    assert wait_for(lambda: s.request["segments"][3]["lower"] == [-0.04, 0.0, -0.1]
                    and s.request["segments"][3]["upper"] == [-0.02, 0.04, 0.1], 10)
    page.get_by_role("button", name="Insert a copy after it").click()
    assert wait_for(lambda: len(s.request["segments"]) == 13 and s.selected_segment == 4, 10)
    page.get_by_role("button", name="Remove this box").click()
    assert wait_for(lambda: len(s.request["segments"]) == 12, 10)
    assert settled(s) and s.last_error is None
    planned = s.last_result.corridor.segments
    assert np.allclose([p.lower for p in planned], [g["lower"] for g in s.request["segments"]])
    pose = np.asarray(s.last_result.pose)
    assert np.linalg.norm(pose[-1, :2] - [0.06, 0.04]) < 1e-3
    tab.shot("07-table1-replanned")


# ---------------------------------------------------------------------------- responsiveness
def test_the_panel_answers_while_a_plan_runs(tab, monkeypatch):
    """Plans run on the session's worker thread, so the panel answers meanwhile: each plan
    here is held on the worker until the value typed during it has reached the session (or
    30 s pass: a loaded machine types slowly into the software-rendered page), then computed
    for real (constrained mode, 5 mm cells). Were the
    plan run on the thread that handles the panel, the typed value could not arrive while the
    plan is held. The latency is measured by benchmarks/bench_editor.py, not asserted here."""
    s, page = tab.session, tab.page
    s.edit(lambda r: (r["settings"].update(mode="constrained"), r["layout"]["cell"].update(size=0.005)))
    assert settled(s, 120) and s.last_error is None
    arrived = threading.Event()
    real_compute = session_module.compute_plan

    def held_compute(request, robots):
        arrived.wait(30.0)
        return real_compute(request, robots)
    monkeypatch.setattr(session_module, "compute_plan", held_compute)
    received, expected = [], [None]
    field = s.gui.clearance
    on_value = field._on_value

    def spy(value):
        received.append((value, s.worker.started > s.worker.finished))
        on_value(value)
        if value == expected[0]:  # not a partial value such as "0.0" on the way
            arrived.set()
    field._on_value = spy
    for k in range(3):
        arrived.clear()
        expected[0] = None
        page.get_by_role("button", name="Plan", exact=True).click()
        assert wait_for(lambda: s.worker.started > s.worker.finished, 10), "no plan started"
        assert wait_for(lambda: "planning #" in page.locator("body").inner_text(), 2), "status shows no plan running"
        box = tab.field("Clearance (m)")
        box.click()
        box.press("Control+a")
        text = f"0.00{k + 1}"
        expected[0] = float(text)
        box.press_sequentially(text, delay=20)
        assert wait_for(lambda t=text: bool(received) and received[-1][0] == float(t), 5), "no typed value"
        assert received[-1][1], "the typed value arrived only after the plan ended"
        assert settled(s, 120)
    assert s.last_error is None and s.request["layout"]["clearance"] == 0.003


def test_the_page_makes_no_request_outside_loopback(server, tab):
    _, _, urls, _ = server
    tab.page.reload()
    tab.page.wait_for_selector("canvas", timeout=30_000)
    time.sleep(2.0)
    assert urls, "no request recorded"
    hosts = {urlparse(u).hostname for u in urls if not u.startswith(("data:", "blob:", "about:"))}
    assert hosts <= {"127.0.0.1", "localhost"}, hosts


def test_readme_screenshot_of_a_real_session(tab):
    """A layout with obstacles, a plan and the plots, as a person sees it (written to
    docs/editor.png when RANGEPLAN_DOCS_SCREENSHOT names that path)."""
    s, page = tab.session, tab.page
    s.add_rectangle([0.04, -0.12], [0.06, 0.0])
    s.move_handle("end", 0.1, -0.06, "end")
    assert s.wait_idle(60) and s.last_error is None, s.last_error
    tab.tab("Result")
    page.locator(".u-over").first.scroll_into_view_if_needed()
    s.gui.time.value = round(0.45 * float(s.last_result.time[-1]), 2)
    page.mouse.move(*tab.screen(-0.06, 0.1))
    time.sleep(1.0)
    path = tab.shot("08-readme")
    target = os.environ.get("RANGEPLAN_DOCS_SCREENSHOT")
    if target:
        Path(target).write_bytes(path.read_bytes())


def _wall_drawing(path: Path) -> Path:
    """A DXF (mm) of the editor's example wall drawn as loose lines, and two small discs
    that stretch the extents over the start and end."""
    import ezdxf

    doc = ezdxf.new("R2010", units=4)
    msp = doc.modelspace()
    corners = [(-20, -120), (0, -120), (0, 40), (-20, 40)]
    for a, b in zip(corners, corners[1:] + corners[:1]):
        msp.add_line(a, b)
    msp.add_circle((-130, -130), 5)
    msp.add_circle((130, 130), 5)
    doc.saveas(path)
    return path


def test_files_tab_imports_a_drawing_and_downloads_gcode(tab, tmp_path):
    """Files tab: upload a DXF through the browser's file chooser (its closed shapes become
    the layout's obstacles and the design re-plans), then download the plan's G-code."""
    from planner.exchange import to_gcode

    editor, page = tab.session, tab.page
    assert editor.wait_idle(60)
    tab.tab("Files")
    done = editor.plans_done
    with page.expect_file_chooser() as chooser:
        page.get_by_role("button", name="Import drawing (DXF/SVG)").click()
    chooser.value.set_files(str(_wall_drawing(tmp_path / "wall.dxf")))
    assert wait_for(lambda: len(editor.request["layout"]["obstacles"]) == 3, 20), editor.request["layout"]
    kinds = sorted(o["type"] for o in editor.request["layout"]["obstacles"])
    assert kinds == ["circle", "circle", "polygon"]
    lower = np.asarray(editor.request["layout"]["bounds"]["lower"])  # placed: the reachable square is the bounds
    assert np.allclose(lower, lower[0]) and -0.16 < lower[0] < -0.13
    assert wait_for(lambda: editor.plans_done > done) and editor.wait_idle(60)
    assert editor.last_error is None, editor.last_error
    gcode = page.get_by_role("button", name="Download G-code (LinuxCNC)")
    gcode.wait_for(state="visible")
    assert wait_for(gcode.is_enabled, 10)
    with page.expect_download() as download:
        gcode.click()
    assert download.value.suggested_filename == "trajectory.ngc"
    text = Path(download.value.path()).read_text()
    assert text == to_gcode(editor.last_result, source="rangeplan editor",
                            header=editor.files.machine_files().header())
    assert "G93" in text and text.rstrip().endswith("M2")
    from tests.linuxcnc import rs274
    rs274(text)


def test_after_a_failed_plan_no_download_of_an_earlier_plan_is_possible(tab):
    """Real clicks and keys: import a real drawing (placed, it plans at once), download its
    G-code, then type a start inside the obstacle: the plan fails, every download button is
    disabled with the reason shown, and clicking them downloads nothing."""
    import shapely

    from app.editor._geometry import obstacle_shape
    from tests.drawings import DRAWINGS

    s, page = tab.session, tab.page
    downloads = []
    page.on("download", lambda d: downloads.append(d.suggested_filename))
    tab.tab("Files")
    done = s.plans_done
    with page.expect_file_chooser() as chooser:
        page.get_by_role("button", name="Import drawing (DXF/SVG)").click()
    chooser.value.set_files(str(DRAWINGS / "Kitchen-cooker-V.dxf"))
    assert wait_for(lambda: s.plans_done > done and s.wait_idle(1), 60)
    assert s.last_error is None, s.last_error  # a real drawing, placed, plans at once
    gcode = page.get_by_role("button", name="Download G-code (LinuxCNC)")
    assert wait_for(gcode.is_enabled, 10)
    with page.expect_download() as download:
        gcode.click()
    first = Path(download.value.path()).read_text()
    gen = s.last_plan_generation
    assert f"(plan id: editor plan #{gen})" in first and "(request sha256: " in first
    # a start inside the obstacle, typed
    body = obstacle_shape(s.request["layout"]["obstacles"][0])
    inside = body.representative_point() if isinstance(body, shapely.Polygon) else body.centroid
    tab.tab("Edit")
    tab.type_into("Start x, y (m)", f"{inside.x:.4f}, {inside.y:.4f}, 0")
    assert wait_for(lambda: s.last_error is not None and s.wait_idle(1), 60), s.last_error
    tab.tab("Files")
    buttons = [page.get_by_role("button", name=n) for n in (
        "Download G-code (LinuxCNC)", "Download leg lengths (halstreamer)",
        "Download DXF (path, corridor, obstacles)", "Download trajectory CSV")]
    assert wait_for(lambda: all(b.is_disabled() for b in buttons), 10)
    assert wait_for(lambda: "the newest plan failed" in page.locator("body").inner_text(), 10)
    n = len(downloads)
    for b in buttons:
        b.click(force=True)  # a disabled button: the browser sends nothing
    time.sleep(1.0)
    assert len(downloads) == n == 1
    tab.shot("09-failed-plan-no-download")


def test_plan_undo_and_redo_stay_in_view_however_long_the_tab(tab):
    """The tabs' content scrolls in its own box: scrolled to its last control (Edit, Files),
    the Plan, Undo and Redo buttons are still on screen and clickable."""
    page = tab.page
    controls = [page.get_by_role("button", name=n, exact=True) for n in ("Plan", "Undo", "Redo")]
    for name, last in (("Edit", "Grid (m), empty = cell size"), ("Files", "Download trajectory CSV")):
        tab.tab(name)
        target = tab.field(last) if name == "Edit" else page.get_by_role("button", name=last)
        target.scroll_into_view_if_needed()
        assert wait_for(lambda t=target: (t.bounding_box() or {"y": -1})["y"] >= 0, 5)
        assert target.bounding_box()["y"] <= H
        for c in controls:
            box = c.bounding_box()
            assert box is not None and 0 <= box["y"] and box["y"] + box["height"] <= H, (name, box)
    s = tab.session
    done = s.plans_done
    controls[0].click()  # still clickable
    assert wait_for(lambda: s.plans_done > done, 60)


def test_readme_screenshot_of_an_imported_drawing_with_holes(tab):
    """LibreCAD's cooker (a body with four hob holes) imported in the Files tab, placed where the
    robot reaches, planned at once; the view fits it (written to docs/drawing.png when
    RANGEPLAN_DOCS_DRAWING_SCREENSHOT names that path)."""
    from tests.drawings import DRAWINGS

    s, page = tab.session, tab.page
    tab.tab("Files")
    done = s.plans_done
    with page.expect_file_chooser() as chooser:
        page.get_by_role("button", name="Import drawing (DXF/SVG)").click()
    chooser.value.set_files(str(DRAWINGS / "Kitchen-cooker-V.dxf"))
    assert wait_for(lambda: s.plans_done > done and s.wait_idle(1), 60)
    assert s.last_error is None, s.last_error
    assert sum(len(o.get("holes", [])) for o in s.request["layout"]["obstacles"]) >= 4
    s.gui.robot_style.value = "outline"
    s.gui.time.value = round(0.5 * float(s.last_result.time[-1]), 2)
    tab.tab("Result")
    close_notifications(page)
    time.sleep(1.5)
    path = tab.shot("10-drawing")
    target = os.environ.get("RANGEPLAN_DOCS_DRAWING_SCREENSHOT")
    if target:
        Path(target).write_bytes(path.read_bytes())


# ---------------------------------------------------------------------------- G-code preview
def _program_moves(text: str) -> tuple[np.ndarray, np.ndarray]:
    """The feed moves (M, 2, 2) and rapids (R, 2, 2) [m] in XY of a program as LinuxCNC's
    interpreter (rs274) runs it, without moves of C alone: independent of the editor's reader."""
    from tests.linuxcnc import rs274

    feed, rapid, prev = [], [], np.zeros(2)
    for line in rs274(text):
        for name, out in (("STRAIGHT_FEED(", feed), ("STRAIGHT_TRAVERSE(", rapid)):
            if name in line:
                v = [float(a) for a in line.split(name)[1].rstrip(")").split(",")]
                end = np.array(v[:2]) * 1e-3
                if np.any(end != prev):
                    out.append((prev, end))
                prev = end
    return np.array(feed).reshape(-1, 2, 2), np.array(rapid).reshape(-1, 2, 2)


def _on_segments(points: np.ndarray, segments: np.ndarray) -> float:
    """Largest distance [m] of ``points`` (n, 2) from the segments (M, 2, 2)."""
    a, b = segments[:, 0][None], segments[:, 1][None]
    d = b - a
    t = np.clip(np.sum((points[:, None] - a) * d, axis=2) / np.maximum(np.sum(d * d, axis=2), 1e-300), 0, 1)
    return float(np.max(np.min(np.linalg.norm(points[:, None] - (a + t[..., None] * d), axis=2), axis=1)))


@pytest.fixture
def mirrored_tab(server):
    """A tab whose received scene is decoded (:attr:`Tab.scene`)."""
    editor, context, _, shots = server
    t = Tab(editor, context, shots, mirror=True)
    try:
        yield t
    finally:
        t.close()


def test_gcode_preview_draws_the_downloaded_program_over_the_plan(mirrored_tab):
    """Real clicks and keys: switch the G-code preview on (Files tab); the line segments the
    page receives are the downloaded program's moves (read by rs274 in the test), on the
    planned trajectory; the panel states the program's lines and duration. A failed plan
    disables it and takes it off the view; the next plan brings it back, of that plan."""
    tab = mirrored_tab
    s, page = tab.session, tab.page
    tab.tab("Files")
    toggle = tab.field("G-code preview")
    assert wait_for(toggle.is_enabled, 10)
    toggle.click()
    assert wait_for(lambda: tab.lines("/preview/feed") is not None and s.preview.preview is not None, 30)
    gcode = page.get_by_role("button", name="Download G-code (LinuxCNC)")
    with page.expect_download() as download:
        gcode.click()
    text = Path(download.value.path()).read_text()
    feed, rapid = _program_moves(text)
    got = tab.lines("/preview/feed")
    assert got is not None and got.shape == (len(feed), 2, 3)
    f32 = 1e-8  # viser sends the points as float32: half a unit in the last place at 0.16 m is 7.5e-9 m
    assert np.max(np.abs(got[:, :, :2] - feed)) <= f32  # the program's points, in order
    dashes = tab.lines("/preview/rapid")
    assert dashes is not None and len(rapid) == 1 and _on_segments(dashes[:, :, :2].reshape(-1, 2), rapid) <= f32
    pose = np.asarray(s.last_result.pose, float)[:, :2]
    planned = np.stack((pose[:-1], pose[1:]), axis=1)
    assert _on_segments(got[:, :, :2].reshape(-1, 2), planned) <= 0.75e-7 + f32  # printed to 0.1 um
    body = page.locator("body")
    duration = (len(pose) - 1) * float(s.last_result.settings.Ts)
    assert wait_for(lambda: f"G-code preview: {len(text.splitlines())} lines, duration {duration:.3f} s"
                    in body.inner_text(), 10)
    tab.shot("11-gcode-preview")
    # a failed plan: the preview leaves the view and the toggle is disabled, with the reason
    tab.tab("Edit")
    tab.type_into("Start x, y (m)", "0.5, 0, 0")
    assert wait_for(lambda: s.last_error is not None and s.wait_idle(1), 60), s.last_error
    tab.tab("Files")
    assert wait_for(lambda: tab.lines("/preview/feed") is None and tab.lines("/preview/rapid") is None, 10)
    assert wait_for(toggle.is_disabled, 10)
    assert wait_for(lambda: "G-code preview: no preview: the newest plan failed" in body.inner_text(), 10)
    # fixed: the next plan's program is previewed (the toggle stayed on)
    tab.tab("Edit")
    tab.type_into("Start x, y (m)", "-0.08, -0.04, 0")
    assert wait_for(lambda: s.last_error is None and s.wait_idle(1), 60), s.last_error
    assert wait_for(lambda: (tab.lines("/preview/feed") is not None
                             and np.allclose(tab.lines("/preview/feed")[0, 0, :2], [-0.08, -0.04], atol=1e-8)), 30)
    assert toggle.is_enabled()


def test_files_tab_opens_a_gcode_program_and_shows_its_plan(mirrored_tab):
    """Files tab, real clicks: open FreeCAD's linuxcnc_post program through the file chooser
    of "Open G-code program" (the origin field empty: placed in reach). The design becomes the
    program, planned by the contour job; the page receives the programmed path at the origin
    the plan reports (the reader's path, within float32), the tolerance tube and the planned
    cut; the status names the passes, the deviation and the origin; the G-code download is the
    program the preview shows, with the post's tool change and spindle words."""
    from app.editor._planning import program_toolpath

    tab = mirrored_tab
    s, page = tab.session, tab.page
    program = Path(__file__).parent / "data" / "cam" / "freecad_linuxcnc.ngc"
    tab.tab("Files")
    done = s.plans_done
    with page.expect_file_chooser() as chooser:
        page.get_by_role("button", name="Open G-code program").click()
    chooser.value.set_files(str(program))
    assert wait_for(lambda: s.request.get("program") == program.read_text(), 30), s.request.keys()
    assert wait_for(lambda: s.plans_done > done, 120) and s.wait_idle(120)
    assert s.last_error is None, s.last_error
    c = s.last_result.contour
    assert c is not None and s.request["origin"] == "fit"
    path = program_toolpath(s.request)
    expect = path.points + np.asarray(c.origin)
    moves = np.any(expect[1:] != expect[:-1], axis=1) & ~path.rapid
    assert wait_for(lambda: tab.lines("/contour/program_feed") is not None, 30)
    got = tab.lines("/contour/program_feed")
    assert got.shape == (int(moves.sum()), 2, 3)
    assert np.max(np.abs(got[:, 0, :2] - expect[:-1][moves])) <= 1e-8
    assert np.max(np.abs(got[:, 1, :2] - expect[1:][moves])) <= 1e-8
    assert wait_for(lambda: tab.scene.mesh("/contour/tube") is not None, 10)
    traj = tab.lines("/result/trajectory")
    assert traj is not None and len(traj) == len(s.last_result.pose) - 1
    body = page.locator("body")
    assert wait_for(lambda: f"program zero at [{c.origin[0]:.4f}, {c.origin[1]:.4f}] m (fit)" in body.inner_text(), 10)
    toggle = tab.field("G-code preview")
    assert wait_for(toggle.is_enabled, 10)
    toggle.click()
    assert wait_for(lambda: s.preview.preview is not None and tab.lines("/preview/feed") is not None, 60)
    gcode = page.get_by_role("button", name="Download G-code (LinuxCNC)")
    with page.expect_download() as download:
        gcode.click()
    text = Path(download.value.path()).read_text()
    assert text == s.preview.preview.text
    assert "M6" in text and "S10000" in text
    tab.shot("12-gcode-program")
