"""The editor in a real browser: Debian's headless Chromium driven by Playwright
(``executable_path=/usr/bin/chromium``; Playwright's own browser download is never used).

Checks: the page renders (the WebGL canvas is not blank), the Plan button re-plans on the
server, dragging the end handle's gizmo with the mouse moves the end point and re-plans,
editing the end point in the panel re-plans, and the page makes no request outside
127.0.0.1. The browser is closed before the viser server stops.
"""

import base64
import math
import socket
import time
from pathlib import Path
from urllib.parse import urlparse

import numpy as np
import pytest

CHROMIUM = "/usr/bin/chromium"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]
W, H = 1400, 900



def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(cond, timeout=60.0):
    t = time.monotonic() + timeout
    while time.monotonic() < t:
        if cond():
            return True
        time.sleep(0.05)
    return False


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    from playwright.sync_api import sync_playwright

    from app.editor import start_editor
    from app.storage import Store

    assert Path(CHROMIUM).exists(), "Debian chromium is missing: `make test` installs it (apt-get install chromium)"
    store = Store(tmp_path_factory.mktemp("editor") / "rangeplan.sqlite3")
    editor = start_editor("127.0.0.1", free_port(), store, debounce=0.15)
    assert editor.wait_idle(60) and editor.last_result is not None
    urls: list[str] = []
    pw = sync_playwright().start()
    browser = pw.chromium.launch_persistent_context(  # a new, empty --user-data-dir
        str(tmp_path_factory.mktemp("chromium-profile")), executable_path=CHROMIUM, args=FLAGS,
        viewport={"width": W, "height": H})
    try:
        page = browser.pages[0] if browser.pages else browser.new_page()
        page.on("request", lambda r: urls.append(r.url))
        page.on("websocket", lambda ws: urls.append(ws.url))
        page.goto(editor.url)
        page.wait_for_selector("canvas", timeout=30_000)
        assert wait_for(lambda: len(editor.server.get_clients()) == 1, 30)
        time.sleep(2.0)  # first frames, camera placed by the server
        yield editor, page, urls
    finally:
        browser.close()  # before the viser server: its stop blocks while a client is connected
        pw.stop()
        editor.stop()


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


def test_page_renders_a_non_blank_scene(session):
    editor, page, _ = session
    px = canvas_pixels(page)
    assert px.std() > 10.0, "the WebGL canvas is blank"
    colours = {tuple(c) for c in (px // 16).reshape(-1, 3).astype(int)}
    assert len(colours) >= 8, "the scene should show cells, corridor, trajectory and robot in several colours"
    assert page.get_by_role("button", name="Plan", exact=True).count() == 1


def test_plan_button_replans_on_the_server(session):
    editor, page, _ = session
    done, gen = editor.plans_done, editor.last_plan_generation
    page.get_by_role("button", name="Plan", exact=True).click()
    assert wait_for(lambda: editor.plans_done > done and editor.last_plan_generation > gen)
    assert editor.wait_idle(60)
    res = editor.last_result
    end = editor.request["layout"]["end"]
    assert np.linalg.norm(np.array(res["pose"][-1][:2]) - end[:2]) < 1e-4


def test_dragging_the_end_handle_moves_the_end_and_replans(session):
    """A real mouse drag on the end handle's x-arrow, at its projected screen position."""
    editor, page, _ = session
    assert editor.wait_idle(60)
    cam = list(editor.server.get_clients().values())[0].camera
    box = page.locator("canvas").first.bounding_box()
    ppm = (box["height"] / 2) / ((cam.position[2]) * math.tan(cam.fov / 2))  # pixels per metre, top-down

    def screen(x, y):
        return (box["x"] + box["width"] / 2 + (x - cam.look_at[0]) * ppm,
                box["y"] + box["height"] / 2 - (y - cam.look_at[1]) * ppm)

    lay = editor.request["layout"]
    before = list(lay["end"])
    span = max(b - a for a, b in zip(lay["bounds"]["lower"], lay["bounds"]["upper"]))
    arrow = 0.55 * 0.12 * span  # along the x-arrow of the gizmo (its scale is 0.12 x the view span)
    sx, sy = screen(before[0] + arrow, before[1])
    done = editor.plans_done
    page.mouse.move(sx, sy)
    page.mouse.down()
    for i in range(1, 11):
        page.mouse.move(sx - 3 * i, sy)
        time.sleep(0.03)
    page.mouse.up()
    assert wait_for(lambda: editor.request["layout"]["end"][0] < before[0] - 0.005, 10), "the drag did not move the end"
    after = editor.request["layout"]["end"]
    assert after[1] == pytest.approx(before[1]) and after[2] == before[2]  # x-arrow: only x moves
    assert wait_for(lambda: editor.plans_done > done) and editor.wait_idle(60)
    assert editor.last_error is None
    assert np.linalg.norm(np.array(editor.last_result["pose"][-1][:2]) - np.array(after[:2])) < 1e-4


def test_editing_the_end_in_the_panel_replans(session):
    editor, page, _ = session
    row = page.get_by_text("End x, y", exact=False).first.locator("xpath=ancestor::div[.//input][1]")
    inputs = row.locator("input")
    assert inputs.count() == 3
    done = editor.plans_done
    inputs.nth(1).fill("0.02")
    inputs.nth(1).press("Enter")
    assert wait_for(lambda: editor.request["layout"]["end"][1] == pytest.approx(0.02), 10)
    assert wait_for(lambda: editor.plans_done > done) and editor.wait_idle(60)
    assert abs(editor.last_result["pose"][-1][1] - 0.02) < 1e-4


def test_the_page_makes_no_request_outside_loopback(session):
    _, page, urls = session
    page.reload()
    page.wait_for_selector("canvas", timeout=30_000)
    time.sleep(2.0)
    assert urls, "no request recorded"
    hosts = {urlparse(u).hostname for u in urls if not u.startswith(("data:", "blob:", "about:"))}
    assert hosts <= {"127.0.0.1", "localhost"}, hosts


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


def test_files_tab_imports_a_drawing_and_downloads_gcode(session, tmp_path):
    """Files tab: upload a DXF through the browser's file chooser (its closed shapes become
    the layout's obstacles and the design re-plans), then download the plan's G-code."""
    from planner.exchange import to_gcode
    from planner.schema import PlanResult

    editor, page, _ = session
    assert editor.wait_idle(60)
    page.get_by_role("tab", name="Files").click()
    done = editor.plans_done
    with page.expect_file_chooser() as chooser:
        page.get_by_role("button", name="Import drawing (DXF/SVG)").click()
    chooser.value.set_files(str(_wall_drawing(tmp_path / "wall.dxf")))
    assert wait_for(lambda: len(editor.request["layout"]["obstacles"]) == 3, 20), editor.request["layout"]
    kinds = sorted(o["type"] for o in editor.request["layout"]["obstacles"])
    assert kinds == ["circle", "circle", "polygon"]
    assert np.allclose(editor.request["layout"]["bounds"]["lower"], [-0.145, -0.145])
    assert wait_for(lambda: editor.plans_done > done) and editor.wait_idle(60)
    assert editor.last_error is None, editor.last_error
    with page.expect_download() as download:
        page.get_by_role("button", name="Download G-code (LinuxCNC)").click()
    assert download.value.suggested_filename == "trajectory.ngc"
    text = Path(download.value.path()).read_text()
    assert text == to_gcode(PlanResult.model_validate(editor.last_result), source="rangeplan editor")
    assert "G93" in text and text.rstrip().endswith("M2")
    from tests.linuxcnc import rs274
    rs274(text)
