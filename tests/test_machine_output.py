"""Machine output of a plan: LinuxCNC G-code checked by LinuxCNC's own interpreter
(``rs274``, Debian's linuxcnc-uspace: ``make test`` installs it), the leg-length stream
checked against the kinematics and streamed through LinuxCNC's ``halstreamer`` into HAL,
and the DXF read back by ezdxf and re-imported."""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import ezdxf
import numpy as np
import pytest
import shapely

from planner import plan
from planner.exchange import export, import_drawing, read_gcode, to_dxf, to_gcode, to_joints, toolpath
from planner.exchange.gcode import DECIMALS
from planner.model import kinematics, load_robot
from tests.drawings import DRAWINGS, obstacle_region
from tests.linuxcnc import RS274, one_at_a_time, rs274
from tests.support import PSI_TURN, TABLE1, with_settings
from tests.test_gcode_in import compare_with_rs274

HALRUN = "/usr/bin/halrun"
PRINTED = 0.5 * 10 ** -DECIMALS  # half the last printed digit (mm, degree)


def _layout_request() -> dict:
    """A real drawing (LibreCAD's dining table, loose LINE/ARC, mm) at 1:20 between a start and an end."""
    res = import_drawing((DRAWINGS / "Table-dining-E.dxf").read_bytes(),
                         {"scale": 0.05, "offset": [0.0, 0.0225], "margin": 0.03,
                          "start": [-0.065, 0.0, 0.0], "end": [0.065, 0.0, 0.0]})
    return {"name": "around the table", **res.to_request()}


@pytest.fixture(scope="module")
def plans() -> dict:
    return {"table1": plan(TABLE1),
            "psi-turn constrained": plan(with_settings(PSI_TURN, mode="constrained")),
            "drawing layout": plan(_layout_request())}


_CANON = re.compile(r"^\s*\d+\s+N\.+\s+([A-Z_]+)\((.*)\)\s*$")


def canonical(lines: list[str]) -> list[tuple[str, list[str]]]:
    out = []
    for line in lines:
        m = _CANON.match(line)
        if m:
            out.append((m.group(1), [a.strip() for a in m.group(2).split(",")] if m.group(2) else []))
    return out


@pytest.mark.parametrize("name", ["table1", "psi-turn constrained", "drawing layout"])
def test_gcode_runs_in_rs274_and_reproduces_the_plan(plans, name):
    result = plans[name]
    program = to_gcode(result, source=name)
    assert program.splitlines()[5] == "G21 G90 G17" and program.rstrip().endswith("M2")
    canon = canonical(rs274(program))
    assert not any(c == "COMMENT" and "error" in " ".join(a).lower() for c, a in canon)
    assert ("USE_LENGTH_UNITS", ["CANON_UNITS_MM"]) in canon
    pose = np.column_stack((result.pose[:, :2] * 1e3, np.degrees(result.pose[:, 2])))  # mm, mm, degree
    ts = float(result.settings.Ts)
    # the rapid to the first pose, then one feed or dwell per sample, each taking Ts
    i = next(k for k, (c, _) in enumerate(canon) if c == "STRAIGHT_TRAVERSE")
    x, y, z, a, b, c = map(float, canon[i][1][:6])
    assert np.all(np.abs(np.array([x, y, c]) - pose[0]) <= PRINTED + 1e-9) and (z, a, b) == (0, 0, 0)
    current, rate, k = np.array([x, y, c]), None, 0
    feeds = dwells = 0
    for cmd, args in canon[i + 1:]:
        if cmd == "SET_FEED_RATE":
            rate = float(args[0])
        elif cmd == "STRAIGHT_FEED":
            k += 1
            nxt = np.array([float(args[0]), float(args[1]), float(args[5])])
            linear = math.hypot(*(nxt[:2] - current[:2]))
            length = linear if linear > 0 else abs(nxt[2] - current[2])  # LinuxCNC: XYZ length, else rotary
            assert rate is not None and length > 0
            seconds = length / rate * 60.0
            assert abs(seconds - ts) <= ts * (0.5e-4 / rate + 1e-9), (k, seconds)
            current = nxt
            feeds += 1
        elif cmd == "DWELL":
            k += 1
            assert float(args[0]) == pytest.approx(ts, abs=0.5e-4)
            dwells += 1
        elif cmd in ("STRAIGHT_TRAVERSE", "ARC_FEED"):
            pytest.fail(f"unexpected {cmd} in the program")
        else:
            continue
        if cmd in ("STRAIGHT_FEED", "DWELL"):
            assert np.all(np.abs(current - pose[k]) <= PRINTED + 1e-9), (k, current, pose[k])
    assert k == len(pose) - 1 and feeds > len(pose) // 2
    assert ("PROGRAM_END", []) in canon
    if name == "psi-turn constrained":  # the platform turns: C moves
        assert np.ptp(pose[:, 2]) > 5.0


@pytest.mark.parametrize("name", ["table1", "psi-turn constrained", "drawing layout"])
def test_gcode_reads_back_as_the_plan(plans, name):
    """The exported program read back (read_gcode(readback=True), the contour issue's reader):
    at each sample time the read-back path is at the plan's tool point and angle to the
    printed precision, its G93 durations add up to the plan's duration, every header line is
    read as a comment; and rs274 makes the same moves, angles and times of the program."""
    result = plans[name]
    header = ("design: round trip", "plan id: test", "request sha256: 0123abcd")
    program = to_gcode(result, source=name, header=header)
    p = read_gcode(program, readback=True)
    path = toolpath(p)
    ts, n = float(result.settings.Ts), len(result.pose)
    assert p.lines == len(program.splitlines()) and not p.warnings
    assert [c.text for c in p.comments][-3:] == list(header) and p.comments[0].text.startswith("rangeplan plan:")
    assert path.rapid[0] and not path.rapid[1:].any()  # the rapid to the first pose, then feed moves
    assert abs(path.duration_s - (n - 1) * ts) <= n * 1e-9
    # after the rapid the program's time is the plan's: sample k at k Ts (the path interpolated at that time)
    t = np.arange(n) * ts
    fed = slice(1, None)
    at = np.column_stack([np.interp(t, path.time[fed], v[fed]) for v in (*path.points.T, path.psi)])
    assert np.max(np.abs(at[:, :2] - result.pose[:, :2])) <= PRINTED * 1e-3 + 1e-12
    assert np.max(np.abs(np.degrees(at[:, 2] - result.pose[:, 2]))) <= PRINTED + 1e-9
    # every read-back point is a planned sample (the program's corners are the samples)
    k = np.rint(path.time[fed] / ts).astype(int)
    assert np.max(np.abs(path.time[fed] - k * ts)) <= n * 1e-9
    assert np.max(np.abs(path.points[fed] - result.pose[k, :2])) <= PRINTED * 1e-3 + 1e-12
    compare_with_rs274(program, readback=True)


def test_gcode_bad_program_fails_in_rs274(tmp_path):
    """The check above is real: rs274 rejects a G1 without F in inverse-time mode."""
    (tmp_path / "bad.ngc").write_text("G21 G93\nG1 X1 Y1\nM2\n")
    with one_at_a_time():
        r = subprocess.run([RS274, "-g", "bad.ngc", "bad.canon"], cwd=tmp_path, capture_output=True, text=True,
                           timeout=60, stdin=subprocess.DEVNULL)
    assert r.returncode != 0 and "F word missing" in r.stdout + r.stderr


def _stream_rows(text: str) -> np.ndarray:
    return np.array([[float(v) for v in line.split()] for line in text.splitlines()
                     if line.strip() and not line.startswith("#")])


@pytest.mark.parametrize("forces", [False, True])
def test_joint_stream_is_the_kinematics_leg_lengths(plans, forces):
    result = plans["drawing layout"]
    text = to_joints(result, forces=forces)
    header = [line for line in text.splitlines() if line.startswith("#")]
    assert any("leg lengths in mm" in h for h in header) and any(f"Ts = {result.settings.Ts:g} s" in h for h in header)
    rows = _stream_rows(text)
    robot = load_robot(result.robot)
    legs = kinematics.leg_lengths(robot, result.pose) * 1e3  # recomputed from the poses, mm
    assert rows.shape == (len(result.pose), 2 * robot.n_legs if forces else robot.n_legs)
    assert np.max(np.abs(rows[:, :robot.n_legs] - legs)) <= 0.5e-6 + 1e-9
    if forces:
        assert np.max(np.abs(rows[:, robot.n_legs:] - result.drives.force)) <= 0.5e-6 + 1e-9
    cfg = re.search(r"cfg=(f+)", text)
    assert cfg and len(cfg.group(1)) == rows.shape[1]


@pytest.mark.skipif(not Path(HALRUN).exists(), reason="linuxcnc-uspace is missing (make test installs it)")
def test_joint_stream_plays_through_halstreamer_into_hal(plans, tmp_path):
    """The stream file as LinuxCNC plays it: halstreamer -> streamer (one line per thread
    period onto float pins) -> sampler -> halsampler, in a simulated (non-realtime) HAL."""
    result = plans["table1"]
    text = to_joints(result)
    rows = _stream_rows(text)
    n, cols = rows.shape
    os.chmod(tmp_path, 0o777)
    (tmp_path / "plan.txt").write_text(text)
    (tmp_path / "sample.sh").write_text(f"#!/bin/sh\nhalsampler -n {n + 20} > {tmp_path}/sampled.txt\n")
    (tmp_path / "sample.sh").chmod(0o755)
    (tmp_path / "stream.hal").write_text("\n".join([
        "loadrt threads name1=stream period1=1000000",
        f"loadrt streamer depth={n + 16} cfg={'f' * cols}",
        f"loadrt sampler depth={n + 64} cfg={'f' * cols}",
        *(f"net leg{i + 1} streamer.0.pin.{i} => sampler.0.pin.{i}" for i in range(cols)),
        "addf streamer.0 stream", "addf sampler.0 stream",
        f"loadusr -w halstreamer {tmp_path}/plan.txt",  # the whole plan into the FIFO, then run
        "start", f"loadusr -w {tmp_path}/sample.sh", ""]))
    env = dict(os.environ)
    if os.geteuid() == 0:  # rtapi_app refuses root without a fallback user
        env["RTAPI_UID"] = "65534"
    fifo_dir = Path(tempfile.mkdtemp(prefix="rangeplan-rtapi-"))  # in /tmp: the fallback user must reach it
    fifo_dir.chmod(0o777)
    env["RTAPI_FIFO_PATH"] = str(fifo_dir / "rtapi_fifo")
    try:
        r = subprocess.run([HALRUN, "-f", str(tmp_path / "stream.hal")], env=env, capture_output=True, text=True,
                           timeout=120, cwd=tmp_path)
    finally:
        subprocess.run([HALRUN, "-U"], env=env, capture_output=True, timeout=60, cwd=tmp_path)
        shutil.rmtree(fifo_dir, ignore_errors=True)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    sampled = _stream_rows((tmp_path / "sampled.txt").read_text())
    start = int(np.argmin(np.abs(sampled[:, 0] - rows[0, 0])))  # before the first period the pins are 0
    got = sampled[start:start + n]
    assert got.shape == rows.shape and np.max(np.abs(got - rows)) <= 1e-6, "HAL did not play the stream in order"


def test_dxf_has_path_corridor_obstacles_in_mm(plans, tmp_path):
    request = _layout_request()
    result = plans["drawing layout"]
    from planner.schema import PlanRequest

    layout = PlanRequest.model_validate(request).layout
    text = to_dxf(result, layout)
    (tmp_path / "plan.dxf").write_text(text)
    doc = ezdxf.readfile(tmp_path / "plan.dxf")
    assert doc.header["$INSUNITS"] == 4
    msp = doc.modelspace()
    [path] = msp.query('LWPOLYLINE[layer=="PATH"]')
    assert np.allclose(np.array(path.get_points("xy")), result.pose[:, :2] * 1e3, rtol=0, atol=1e-9)
    cells = msp.query('LWPOLYLINE[layer=="CORRIDOR"]')
    segments = [s for s in result.corridor.segments if np.any(s.upper[:2] > s.lower[:2])]
    assert len(cells) == len(segments) > 0 and all(c.closed for c in cells)
    for c, s in zip(cells, segments):
        pts = np.array(c.get_points("xy")) / 1e3
        assert np.allclose(pts.min(axis=0), s.lower[:2]) and np.allclose(pts.max(axis=0), s.upper[:2])
    # the obstacles, read back by the importer, are the layout's obstacles
    back = import_drawing((tmp_path / "plan.dxf").read_bytes(), {"layers": ["OBSTACLES"], "bounds_layer": "BOUNDS"})
    assert obstacle_region(back.layout).symmetric_difference(obstacle_region(layout)).area < 1e-12
    assert np.allclose(back.layout.bounds.lower, layout.bounds.lower)
    assert np.allclose(back.layout.bounds.upper, layout.bounds.upper)


def test_dxf_keeps_triangle_cells_exact(tmp_path):
    request = _layout_request()
    request["layout"]["cell"] = {"shape": "triangle", "size": 0.012}
    result = plan(request)
    doc = ezdxf.read(__import__("io").StringIO(export(result, "dxf")))
    tris = [c for c in doc.modelspace().query('LWPOLYLINE[layer=="CORRIDOR"]') if len(c) == 3]
    assert tris and len(tris) == sum(1 for s in result.corridor.segments if s.polygon is not None)
    for t in tris:
        area = shapely.Polygon(np.array(t.get_points("xy")) / 1e3).area
        assert area == pytest.approx(math.sqrt(3) / 4 * 0.012 ** 2, rel=1e-9)


def test_rs274_is_installed_by_make_test():
    text = (Path(__file__).resolve().parent.parent / "Makefile").read_text()
    assert re.search(r"^test:.*\blinuxcnc\b", text, re.M) and "linuxcnc-uspace" in text
    assert shutil.which("rs274") or Path(RS274).exists()
