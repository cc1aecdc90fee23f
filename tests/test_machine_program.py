"""A contour plan as the machine's part program (issue 32, goal 3): the exported G-code, read
by LinuxCNC's own interpreter (``rs274``), issues the source program's spindle, tool, coolant,
offset and dwell commands in the source's order, moves Z as the source does (the pass's Z while
cutting, plunges and retracts with XY still, never a cut while XY travels) and takes the plan's
time; a corridor plan's G-code is unchanged."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from planner import plan
from planner.contour import plan_contour
from planner.exchange import read_gcode, to_gcode, to_joints, toolpath
from planner.exchange.gcode import DECIMALS
from planner.schema import PlanResult
from tests.linuxcnc import rs274

ROOT = Path(__file__).resolve().parent.parent
CAM = ROOT / "tests" / "data" / "cam"
#: words between moves, inside a joined plunge and between two joined G4s; M0, M1, M4, M7, G43.1, G49
WORDS_PROGRAM = """(words between moves and dwells)
G21 G90 G17
G64 P0.02
T2 M6
G43.1 Z1.5
S9000 M4
G0 Z5
G0 X2 Y2
M1
G0 Z1
M8
G1 Z-0.5 F200
G1 X12 F600
G1 Y8
G4 P0.25
M7
G4 P0.3
G1 X2
G1 Y2
G0 Z5
M9
M0
M5
G49
M2
"""
#: a ramp in, a tab above the cutting height and a helix in one pass (issue 32, goal 3)
TAB_PASS = """(a pass with a ramp in, a tab above the cut height and a helix)
G21 G90 G17
G64 P0.02
S9000 M3
G0 Z5
G0 X0 Y0
G1 Z0.5 F300
G1 X4 Y0 Z-1 F600
G1 X8
G1 X9 Z0.5
G1 X11
G1 X12 Z-1
G1 X16
G3 X16 Y6 Z-1.5 I0 J3
G1 X0 Y6
G1 Y0
G0 Z5
M5
M2
"""
#: TAB_PASS and a second pass after a rapid
TABS_PROGRAM = TAB_PASS.replace("G0 Z5\nM5", "G0 Z5\nG0 X20 Y0\nG1 Z-1 F300\nG1 X22 F600\nG0 Z5\nM5")
PROGRAMS = {"contour-part": ((ROOT / "app/static/examples/contour-part.ngc").read_text(), [-0.01, -0.01]),
            **{p.stem: (p.read_text(), [-0.005, -0.004]) for p in sorted(CAM.glob("*.n*c"))},
            "words": (WORDS_PROGRAM, [-0.01, -0.01]), "tabs": (TABS_PROGRAM, [-0.01, -0.01])}
PRINTED_MM = 0.5 * 10 ** -DECIMALS
#: the canonical commands that are not motion: what the machine does besides moving
WORDS = ("SELECT_TOOL", "START_CHANGE", "CHANGE_TOOL", "USE_TOOL_LENGTH_OFFSET", "SET_SPINDLE_SPEED",
         "START_SPINDLE_CLOCKWISE", "START_SPINDLE_COUNTERCLOCKWISE", "STOP_SPINDLE_TURNING", "FLOOD_ON", "FLOOD_OFF",
         "MIST_ON", "MIST_OFF", "PROGRAM_STOP", "OPTIONAL_PROGRAM_STOP", "SET_G5X_OFFSET", "DWELL")
_CANON = re.compile(r"^\s*\d+\s+N\.+\s+([A-Z_0-9]+)\((.*)\)\s*$")


#: rs274 prints a dwell's seconds with 4 decimals (``DWELL(0.0063)`` for the export's ``G4 P0.006250``):
#: a dwell read from it is within half a unit of the last digit
CANON_DWELL_S = 5e-5 + 1e-12


def _canon(program: str) -> list[tuple[str, str]]:
    return [(m.group(1), m.group(2)) for m in map(_CANON.match, rs274(program)) if m]


@pytest.fixture(scope="module")
def planned() -> dict[str, tuple[str, PlanResult, str]]:
    out = {}
    for name, (text, origin) in PROGRAMS.items():
        res = plan_contour({"program": text, "origin": origin})
        out[name] = (text, res, to_gcode(res, source=name))
    return out


def _samples(program: str, ts: float) -> tuple[np.ndarray, np.ndarray]:
    """The exported program as rs274 runs it, one row (x, y, z) [mm] per plan sample: the last
    rapid before inverse time (G93) is sample 0, each feed move in inverse time one sample, a
    dwell of P its P / Ts samples; and per sample, whether a move issued as written (a G28 or
    the first Z move after it or after the start: a rapid, or a feed move in units per minute)
    moved the tool since the sample before."""
    rows: list[list[float]] = []
    issued: list[bool] = []
    inverse, first, moved = False, None, False
    for name, args in _canon(program):
        if name == "COMMENT" and "feed mode set to inverse time" in args:
            if not rows:
                assert first is not None
                rows, issued, moved = [first], [False], False
            inverse = True
        elif name == "COMMENT" and "feed mode set to units per minute" in args:
            inverse = False
        elif name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED") and not (inverse and name == "STRAIGHT_FEED"):
            first, moved = [float(a) for a in args.split(",")[:3]], True
        elif name == "STRAIGHT_FEED":
            rows.append([float(a) for a in args.split(",")[:3]])
            issued.append(moved)
            moved = False
        elif name == "DWELL" and rows:
            n = round(float(args) / ts)
            assert abs(n * ts - float(args)) <= CANON_DWELL_S, f"a dwell of {args} s is not whole samples"
            rows += [first if moved and first is not None else rows[-1]] * n
            issued += [moved] + [False] * (n - 1)
            moved = False
    return np.array(rows), np.array(issued)


@pytest.mark.parametrize("name", list(PROGRAMS))
def test_machine_program_issues_the_source_words_in_order(planned, name):
    """The non-motion canonical commands (spindle, tool, tool length, coolant, stops, work
    offset, dwells of the source's G4) of the export equal the source's, in order; the export's
    dwells of one sample (the robot at rest) aside, a G4 within one sample time."""
    text, res, program = planned[name]
    ts = float(res.settings.Ts)
    src = [(n, a) for n, a in _canon(text) if n in WORDS]
    out = [(n, a) for n, a in _canon(program)
           if n in WORDS and not (n == "DWELL" and abs(float(a) - ts) <= CANON_DWELL_S)]
    assert [n for n, _ in out] == [n for n, _ in src]
    for (n, a), (_, b) in zip(out, src):
        if n == "DWELL":
            assert abs(float(a) - float(b)) < ts
        else:
            assert a == b
    assert any(n.startswith("START_SPINDLE") for n, _ in out)


@pytest.mark.parametrize("name", list(PROGRAMS))
def test_machine_program_moves_z_as_the_source(planned, name):
    """rs274's Z at each sample: at a cutting sample within the tolerance, with its XY distance,
    of the Z of the source's move being cut at that point (the read program's, whose XY is
    rs274's: tests/test_cam_posts.py; the 3-D tolerance, Z planned within the Z axis speed and
    acceleration); elsewhere,
    wherever XY moves, at or above the cutting height (no cut during a rapid); a plunge or
    retract moves Z alone to where the source ends it, never faster than the source's feed or
    Z rapid."""
    text, res, program = planned[name]
    c = res.contour
    assert c is not None
    p = read_gcode(text)
    xyz, issued = _samples(program, float(res.settings.Ts))
    assert len(xyz) == len(res.time)
    origin = np.asarray(c.origin)
    z = xyz[:, 2] * 1e-3  # m (the export is in mm), program frame (canonical Z is the program's: no work offset)
    elements = [e for b in p.blocks for e in b.elements]
    cutting = np.asarray(c.cutting)
    for k in np.nonzero(cutting)[0]:
        pt = res.pose[k, :2] - origin
        d, zp = min(_nearest(e, pt) for e in elements if e.line == c.program_line[k])
        assert d <= c.tolerance_m + 1e-9
        # the tool point within the tolerance of the source's 3-D move (Z planned within the Z axis limits)
        assert np.hypot(d, z[k] - zp) <= c.tolerance_m + PRINTED_MM * 1e-3 + 1e-9, k
    moved_xy = np.r_[False, np.any(np.abs(np.diff(xyz[:, :2], axis=0)) > 0, axis=1)]
    travel = moved_xy & ~cutting
    assert travel.any() and np.all(z[travel] >= -1e-9), "a cut while XY travels"
    # plunges and retracts: XY still, Z from the block's start to its end, at most the source's speed
    dz_steps = np.r_[False, np.abs(np.diff(xyz[:, 2])) > PRINTED_MM] & ~issued
    assert np.all(~moved_xy[dz_steps] | cutting[dz_steps]), "Z moves during an XY travel"
    assert c.dwell is not None
    holds = [b for b in p.blocks if b.kind == "dwell" and b.reason in ("plunge", "retract")]
    runs = _runs([d if d in ("plunge", "retract") else None for d in c.dwell])
    assert len(runs) == len(holds)
    for (a, b), blk in zip(runs, holds):
        assert abs(z[b - 1] - blk.z_moves[-1][1]) < 1e-6
        assert (b - a) * float(res.settings.Ts) >= blk.duration_s - 1e-9
        assert not moved_xy[a:b].any()


def _nearest(e, pt: np.ndarray) -> tuple[float, float]:
    """The distance of ``pt`` from the move ``e`` in XY [m] and the move's Z at the nearest point [m]."""
    if e.kind == "arc":
        c = np.asarray(e.centre)
        rel = (np.arctan2(*(pt - c)[::-1]) - e.start_angle_rad) * np.sign(e.sweep_rad) % (2 * np.pi)
        f = rel / abs(e.sweep_rad) if rel <= abs(e.sweep_rad) else float(rel - abs(e.sweep_rad) < 2 * np.pi - rel)
    else:
        a, d = np.asarray(e.start), np.asarray(e.end) - np.asarray(e.start)
        f = float(np.clip((pt - a) @ d / max(float(d @ d), 1e-24), 0, 1))
    q = e.point_at(np.array([f * e.length_m]))[0] if e.kind == "arc" else np.asarray(e.start) + f * d
    return float(np.hypot(*(pt - q))), e.z_start_m + f * (e.z_end_m - e.z_start_m)


def _runs(labels: list) -> list[tuple[int, int]]:
    """The maximal runs [a, b) of equal non-null labels."""
    out, k = [], 0
    while k < len(labels):
        if labels[k] is None:
            k += 1
            continue
        m = k
        while m < len(labels) and labels[m] == labels[k]:
            m += 1
        out.append((k, m))
        k = m
    return out


@pytest.mark.parametrize("name", list(PROGRAMS))
def test_machine_program_takes_the_plan_time(planned, name):
    """The exported program's time (its G93 moves, 1 / F minutes each, and its dwells) equals
    the plan's duration within one sample time, read back as the editor's preview reads it
    too, and it moves Z."""
    _, res, program = planned[name]
    total, inverse, zs = 0.0, False, set()
    for line in program.splitlines():
        if line.startswith("("):
            continue
        inverse = inverse or "G93" in line.split()
        inverse = inverse and "G94" not in line.split()
        m = re.match(r"G1 .* F([\d.]+)$", line)
        if m and inverse:
            total += 60.0 / float(m.group(1))
            zs.update(re.findall(r"Z(-?[\d.]+)", line))
        m = re.match(r"G4 P([\d.]+)$", line)
        if m:
            total += float(m.group(1))
    ts = float(res.settings.Ts)
    assert abs(total - res.metrics.duration_s) < ts
    assert len(zs) > 2
    # the editor's preview reads it back (read_gcode readback) with the same time
    assert abs(toolpath(read_gcode(program, readback=True)).duration_s - res.metrics.duration_s) < ts


#: a move the export issues as written, its start the machine's: the first Z move, a G28 Z
_STATEMENT = re.compile(r"^(G0 Z|G94 G1 Z|G28 Z|G91 G28 Z)")


@pytest.mark.parametrize("name", list(PROGRAMS))
def test_no_z_word_while_the_machine_s_z_is_unknown(planned, name):
    """The machine's Z is unknown before the source's first Z move and after a G28 Z until the
    next (a real machine starts where it was homed, not at Z 0): the export gives those
    samples no Z word and issues that next move as written, to the source's Z. Run from a
    machine at Z 50 mm (rs274 after ``G0 Z50``), the tool stays at 50 mm until the source's
    first Z move and then goes to its Z, as the source's own run does."""
    text, res, program = planned[name]
    body = [ln for ln in program.splitlines() if ln and not ln.startswith("(")]
    unknown, seen = True, []
    for ln in body:
        if _STATEMENT.match(ln):
            seen.append(ln)
            unknown = "G28" in ln
        elif unknown and not ln.startswith("G43.1"):  # a tool length offset's Z is not a move
            assert not re.search(r"\bZ-?[\d.]", ln), (name, ln)
    approach = [ln for ln in seen if not ln.startswith(("G28", "G91"))]
    assert approach
    first_z = float(re.search(r"Z(-?[\d.]+)", approach[0]).group(1))

    def levels(program_text: str) -> list[float]:
        """The Z levels [mm] the canonical moves go through, from a machine at Z 50 mm, to the
        first at ``first_z``."""
        out, scale = [50.0], 1.0
        head, rest = ("%\n", program_text.split("\n", 1)[1]) if program_text.startswith("%") else ("", program_text)
        for n, a in _canon(head + "G21 G90\nG0 Z50\n" + rest):
            scale = {"USE_LENGTH_UNITS(CANON_UNITS_INCHES)": 25.4, "USE_LENGTH_UNITS(CANON_UNITS_MM)": 1.0}.get(
                f"{n}({a})", scale)
            z = (float(a.split(",")[2]) if n in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED") else
                 float(a.split(",")[5]) if n == "ARC_FEED" else None)
            if z is not None and round(z * scale, 4) != out[-1]:
                out.append(round(z * scale, 4))
                if abs(out[-1] - first_z) <= 1e-4:
                    return out
        raise AssertionError(f"{name}: never at Z {first_z}: {out}")

    assert levels(program) == levels(text)  # the export's run and the source's alike


def test_joint_stream_states_the_words_at_their_samples(planned):
    """The leg-space stream's header names each issued word with its sample and source line."""
    _, res, _ = planned["fusion360"]
    head = [ln for ln in to_joints(res).splitlines() if ln.startswith("#")]
    assert any("M3" in ln and "line 12" in ln and "sample" in ln for ln in head)
    assert any("M9" in ln for ln in head)


def _old_to_gcode(result: PlanResult) -> str:
    """The export of a plan before issue 32 goal 3 (one G1 per sample, X Y C), for the corridor plan."""
    ts = float(result.settings.Ts)
    pose = np.asarray(result.pose, float)
    xy = np.round(pose[:, :2] * 1e3, DECIMALS) + 0.0
    c = np.round(np.degrees(pose[:, 2]), DECIMALS) + 0.0
    fmt = f"{{:.{DECIMALS}f}}"
    rows = [" ".join(f"{a}{fmt.format(v)}" for a, v in zip("XYC", (x, y, cc)))
            for (x, y), cc in zip(xy.tolist(), c.tolist())]
    feed = f"F{60.0 / ts:.6f}"
    lines = [
        f"(rangeplan plan: {result.name or 'unnamed'})",
        f"(robot: {result.robot}, mode {result.mode}, {len(pose)} samples, duration {(len(pose) - 1) * ts:g} s)",
        "(units: X Y tool point in mm, C platform angle psi in degrees; G93 inverse time: each G1 takes one sample "
        "time)",
        f"(sample time Ts = {ts:g} s, F = 60 / Ts = {60.0 / ts:g} per minute)",
        "(source: rangeplan)", "G21 G90 G17", f"G0 {rows[0]}", "G93"]
    lines += [f"G4 P{ts:.6f}" if rows[k] == rows[k - 1] else f"G1 {rows[k]} {feed}" for k in range(1, len(rows))]
    return "\n".join(lines + ["G94", "M2"]) + "\n"


def test_corridor_plan_gcode_is_unchanged():
    """Table I (app/static/examples/table1.json), a plan with no contour section: the same bytes
    as before."""
    res = plan(json.loads((ROOT / "app/static/examples/table1.json").read_text()))
    assert res.contour is None
    assert to_gcode(res) == _old_to_gcode(res)


@pytest.mark.parametrize("feed", ["program", "fastest"])
def test_z_in_the_material_is_one_pass_within_the_z_speed(feed):
    """The ramp, the tab and the helix of TAB_PASS are cut in one pass: its cutting samples
    run from the ramp to the end without a dwell (no retract; ``fastest`` comes to rest where the
    slope changes sharply, as the exact path must, ``zaxis.slope_stops``), the tool point of the
    exported program as rs274 runs it is within the tolerance of the source's 3-D moves at each
    of them, and Z moves at most at the Z axis speed between samples (the tab's flanks made
    steep, the axis slow: the bound binds)."""
    text = TAB_PASS.replace("G1 X9 Z0.5", "G1 X8.5 Z0.5").replace("G1 X12 Z-1", "G1 X11.5 Z-1")
    z_max = 0.01
    res = plan_contour({"program": text, "origin": [-0.01, -0.01], "feed": feed, "z_rapid_m_s": z_max})
    c = res.contour
    assert c is not None and len(c.passes) == 1
    cutting = np.asarray(c.cutting)
    first, last = np.nonzero(cutting)[0][[0, -1]]
    assert cutting[first:last + 1].all()
    assert c.dwell is not None and all(d is None for d in c.dwell[first + 1:last + 1])
    ts = float(res.settings.Ts)
    xyz, _ = _samples(to_gcode(res, source="tabs"), ts)
    assert _source_distance(text, _program_frame(xyz[first:last + 1], c.origin)).max() <= \
        c.tolerance_m + 2 * PRINTED_MM * 1e-3
    vz = np.abs(np.diff(xyz[first:last + 1, 2] * 1e-3)) / ts
    assert vz.max() <= z_max * 1.001 + 2 * PRINTED_MM * 1e-3 / ts, vz.max()
    assert vz.max() >= 0.5 * z_max  # the flanks run near the bound, not crawling


def _source_path(program: str, step_mm: float = 0.002) -> np.ndarray:
    """The source's feed moves as rs274 reads them (STRAIGHT_FEED, ARC_FEED in the XY plane:
    helices), as 3-D polyline segments (N, 2, 3) [mm] (arcs at points ``step_mm`` apart)."""
    pos = np.zeros(3)
    segs: list[np.ndarray] = []
    for name, args in _canon(program):
        v = [float(a) for a in args.split(",")] if name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "ARC_FEED") else []
        if name == "STRAIGHT_TRAVERSE":
            pos = np.array(v[:3])
        elif name == "STRAIGHT_FEED":
            segs.append(np.array([pos, v[:3]]))
            pos = np.array(v[:3])
        elif name == "ARC_FEED":
            end, centre, turn, z1 = np.array(v[:2]), np.array(v[2:4]), int(v[4]), v[5]
            a0 = np.arctan2(*(pos[:2] - centre)[::-1])
            a1 = np.arctan2(*(end - centre)[::-1])
            sweep = (a1 - a0) % (2 * np.pi) if turn > 0 else -((a0 - a1) % (2 * np.pi))
            if abs(sweep) < 1e-12:
                sweep = 2 * np.pi * np.sign(turn)
            sweep += 2 * np.pi * np.sign(turn) * (abs(turn) - 1)
            r = float(np.hypot(*(pos[:2] - centre)))
            n = max(int(np.ceil(abs(sweep) * r / step_mm)), 2)
            f = np.linspace(0.0, 1.0, n + 1)
            pts = np.column_stack((centre[0] + r * np.cos(a0 + f * sweep), centre[1] + r * np.sin(a0 + f * sweep),
                                   pos[2] + f * (z1 - pos[2])))
            segs += [pts[i:i + 2] for i in range(n)]
            pos = pts[-1]
    return np.array(segs)


def _program_frame(xyz_mm: np.ndarray, origin: list[float]) -> np.ndarray:
    """The exported samples (X, Y in the robot frame, Z the program's) in the program frame [mm]."""
    return xyz_mm - np.r_[np.asarray(origin) * 1e3, 0.0]


def _source_distance(program: str, xyz_mm: np.ndarray) -> np.ndarray:
    """Per point (mm, program frame) its 3-D distance [m] from the source's feed moves as rs274
    reads them (:func:`_source_path`)."""
    segs = _source_path(program)
    a, d = segs[:, 0], segs[:, 1] - segs[:, 0]
    dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-30)
    out = np.empty(len(xyz_mm))
    for k, p in enumerate(xyz_mm):
        f = np.clip(np.einsum("ij,ij->i", p - a, d) / dd, 0.0, 1.0)
        out[k] = float(np.sqrt(np.min(np.sum((a + f[:, None] * d - p) ** 2, axis=1)))) * 1e-3
    return out


def z_program(ramp_mm: float, depth_mm: float, tab_mm: float, flank_mm: float, pitch_mm: float, feed: float,
              tol_mm: float) -> str:
    """A generated pass: a straight ramp from Z +0.5 down to ``-depth`` over ``ramp_mm``, a
    line, a tab ``tab_mm`` high with flanks ``flank_mm`` long, a line, a helical circle of
    radius 3 mm going down ``pitch_mm``, back to the start at the last depth."""
    d, t, f = -depth_mm, -depth_mm + tab_mm, flank_mm
    x1 = ramp_mm
    x2 = x1 + 4
    x3 = x2 + f
    x4 = x3 + 2
    x5 = x4 + f
    x6 = x5 + 4
    return (f"G21 G90 G17\nG64 P{tol_mm}\nS9000 M3\nG0 Z5\nG0 X0 Y0\nG1 Z0.5 F300\n"
            f"G1 X{x1:g} Z{d:g} F{feed:g}\nG1 X{x2:g}\nG1 X{x3:g} Z{t:g}\nG1 X{x4:g}\nG1 X{x5:g} Z{d:g}\n"
            f"G1 X{x6:g}\nG3 X{x6:g} Y6 Z{d - pitch_mm / 2:g} I0 J3\nG3 X{x6:g} Y0 Z{d - pitch_mm:g} I0 J-3\n"
            f"G1 X0 Y0\nG0 Z5\nM5\nM2\n")


#: generated passes (ramp, depth, tab height, flank, helix pitch, F mm/min, G64 P), their feed,
#: and the Z axis (speed m/s, acceleration m/s^2)
Z_CASES = [((4, 1, 1.5, 1, 1, 600, 0.02), "program", 0.05, 1.0),
           ((2, 1.5, 1, 0.5, 2, 1200, 0.05), "fastest", 0.05, 0.5),
           ((1, 0.5, 0.8, 0.4, 0.5, 900, 0.02), "fastest", 0.02, 2.0),
           ((6, 2, 1, 2, 1.5, 1500, 0.05), "program", 0.03, 0.3)]


@pytest.mark.parametrize("case", Z_CASES, ids=[f"{c[1]}-{c[3]:g}" for c in Z_CASES])
def test_z_of_ramps_tabs_and_helices_within_the_z_axis_and_the_tolerance(case):
    """Generated passes with a ramp, a tab and a helix, planned at a Z axis speed and
    acceleration: the exported program's Z as rs274 runs it (one sample per feed move, a dwell
    its samples), differenced, moves at most at the axis speed and accelerates at most at the
    axis acceleration throughout the program (the cut, and the plunges and retracts, from rest
    to rest), the printed 0.0001 mm rounding aside; the tool point (X, Y, Z) at each cutting sample is within
    the tolerance of the source's 3-D path as rs274 reads it; the pass is one (no stop at the tab)."""
    (ramp, depth, tab, flank, pitch, f, tol), feed, v_z, a_z = case
    text = z_program(ramp, depth, tab, flank, pitch, f, tol)
    res = plan_contour({"program": text, "origin": [-0.01, -0.01], "feed": feed, "z_rapid_m_s": v_z,
                        "z_accel_m_s2": a_z})
    c = res.contour
    assert c is not None and len(c.passes) == 1
    ts = float(res.settings.Ts)
    xyz, _ = _samples(to_gcode(res, source="z"), ts)
    assert len(xyz) == len(res.time)
    cutting = np.asarray(c.cutting)
    first, last = np.nonzero(cutting)[0][[0, -1]]
    assert cutting[first:last + 1].all()
    z = xyz[:, 2] * 1e-3
    rounding = 2 * PRINTED_MM * 1e-3  # two printed Z values' rounding [m]
    vz = np.abs(np.diff(z)) / ts
    az = np.abs(np.diff(np.r_[z[0], z, z[-1]], 2)) / ts ** 2  # at rest in Z before and after the program
    assert vz.max() <= v_z * (1 + 1e-6) + rounding / ts, vz.max()
    assert az.max() <= a_z * (1 + 1e-6) + 2 * rounding / ts ** 2, (az.max(), int(np.argmax(az)))
    assert az.max() >= 0.3 * a_z  # Z does accelerate: the bound is met, not avoided by crawling
    dist = _source_distance(text, _program_frame(xyz[first:last + 1], c.origin))
    assert dist.max() <= tol * 1e-3 + rounding, dist.max()
    assert c.max_deviation_m <= tol * 1e-3 + 1e-12
