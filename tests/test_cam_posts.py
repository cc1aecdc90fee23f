"""Real CAM posts plan unedited (issue 32): small programs in the style of FreeCAD's
``linuxcnc_post``, Fusion 360's LinuxCNC post, Eagle's pcb-gcode (inch), Estlcam and
dxf2gcode (``tests/data/cam/``). Each is read by LinuxCNC's interpreter (``rs274 -g``), its
parsed XY path equals rs274's canonical XY moves (to 1e-9 m; arcs in the XZ/YZ planes as the
straight XY path they run along), and it plans at a reachable origin within its tolerance.
Refused words name the line, the word and what to change in the post."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from planner.contour import plan_contour
from planner.errors import PlannerError
from planner.exchange import read_gcode
from planner.schema import PathElement, Program
from tests.linuxcnc import rs274

CAM = Path(__file__).parent / "data" / "cam"
#: program zero in the robot frame: the programs span about -2..10 mm x 0..8 mm
ORIGIN = [-0.005, -0.004]
TOL = 1e-9  # m: the programs' numbers have at most 4 decimals, rs274 prints 4


def canonical_xy(program: str) -> list[tuple]:
    """rs274's canonical moves that change X or Y, in m: ('line', start, end, z_end, rapid) and
    ('arc', start, end, plane, centre (first, second), rotation, start xyz, end xyz)."""
    unit, plane = 1e-3, "XY"
    pos = np.zeros(3)
    out: list[tuple] = []
    for ln in rs274(program):
        m = re.search(r"(\w+)\((.*)\)", ln)
        if not m:
            continue
        name, args = m.group(1), m.group(2)
        if name == "USE_LENGTH_UNITS":
            unit = 0.0254 if "INCHES" in args else 1e-3
        elif name == "SELECT_PLANE":
            plane = args.removeprefix("CANON_PLANE_")
        elif name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED"):
            end = np.array([float(a) for a in args.split(",")[:3]]) * unit
            if np.any(end[:2] != pos[:2]):
                out.append(("line", pos[:2].copy(), end[:2], end[2], name == "STRAIGHT_TRAVERSE"))
            pos = end
        elif name == "ARC_FEED":
            v = [float(a) for a in args.split(",")]
            first, second, other = {"XY": (0, 1, 2), "XZ": (2, 0, 1), "YZ": (1, 2, 0)}[plane]
            end = np.zeros(3)
            end[first], end[second], end[other] = v[0] * unit, v[1] * unit, v[5] * unit
            centre = np.array([v[2], v[3]]) * unit
            out.append(("arc", pos[:2].copy(), end[:2].copy(), plane, centre, int(v[4]), pos.copy(), end.copy()))
            pos = end
    return out


def _plane_arc(mv: tuple) -> tuple[np.ndarray, float, float, float, tuple[int, int]]:
    """A canonical arc's centre, radius, start angle and signed sweep in its plane's axes."""
    first, second = {"XY": (0, 1), "XZ": (2, 0), "YZ": (1, 2)}[mv[3]]
    centre, turn, p0, p1 = mv[4], mv[5], mv[6], mv[7]
    a0 = math.atan2(p0[second] - centre[1], p0[first] - centre[0])
    a1 = math.atan2(p1[second] - centre[1], p1[first] - centre[0])
    sweep = a1 - a0
    while turn > 0 and sweep <= 1e-12:
        sweep += 2 * math.pi
    while turn < 0 and sweep >= -1e-12:
        sweep -= 2 * math.pi
    sweep += (abs(turn) - 1) * 2 * math.pi * np.sign(turn)
    return centre, float(np.hypot(*(p0[[first, second]] - centre))), a0, sweep, (first, second)


def _dist_to_polyline(p: np.ndarray, pieces: list[PathElement]) -> float:
    best = math.inf
    for e in pieces:
        a, b = np.asarray(e.start), np.asarray(e.end)
        d = b - a
        t = 0.0 if not d.any() else float(np.clip(np.dot(p - a, d) / np.dot(d, d), 0, 1))
        best = min(best, float(np.hypot(*(p - a - t * d))))
    return best


def z_unknown_lines(text: str) -> set[int]:
    """The source lines (1-based) run while the machine's Z is unknown: before the program's
    first Z word, and from a ``G28`` to the next line with a Z word (that line excluded)."""
    out, unknown = set(), True
    for ln, raw in enumerate(text.splitlines(), start=1):
        body = re.sub(r"\(.*?\)|;.*", "", raw).upper()
        if "G28" in body:
            unknown = True
        elif re.search(r"Z\s*[-+.\d]", body) and "G43.1" not in body:
            unknown = False
        if unknown:
            out.add(ln)
    return out


def assert_xy_path_equals_rs274(text: str, p: Program) -> None:
    """Every canonical XY move of rs274 against the parsed elements, in order, to ``TOL``: lines
    end to end; XY arcs (helices too) by centre, radius, ends, direction and Z; arcs in the XZ
    and YZ planes against the straight pieces parsed of them (the same line): the pieces run
    from its start to its end, every point of the arc (20001 samples) projects onto them, their
    ends lie on the arc (its circle, Z included) and their length is the arc's XY path length."""
    ours = [(e, b.kind == "travel" and b.rapid) for b in p.blocks for e in b.elements]
    canon = canonical_xy(text)
    unknown = z_unknown_lines(text)
    k = 0
    for mv in canon:
        e, rapid = ours[k]
        assert np.allclose(e.start, mv[1], atol=TOL, rtol=0), (e.line, e.start, mv[1])
        if mv[0] == "line":
            assert e.kind == "line" and rapid == mv[4], e.line
            assert np.allclose(e.end, mv[2], atol=TOL, rtol=0), (e.line, mv)
            # Z where the program has set it (rs274 starts at 0, the machine where it is)
            assert e.line in unknown or abs(e.z_end_m - mv[3]) <= TOL, (e.line, mv)
            k += 1
            continue
        centre, r, a0, sweep, (first, second) = _plane_arc(mv)
        if mv[3] == "XY":
            assert e.kind == "arc" and e.centre is not None and e.sweep_rad is not None and e.radius_m is not None
            assert np.allclose(e.centre, centre, atol=TOL, rtol=0) and abs(e.radius_m - r) <= TOL, e.line
            assert abs(e.sweep_rad - sweep) <= 1e-9 and np.allclose(e.end, mv[2], atol=TOL, rtol=0), e.line
            assert abs(e.z_start_m - mv[6][2]) <= TOL and abs(e.z_end_m - mv[7][2]) <= TOL, e.line
            k += 1
            continue
        pieces = []
        while k < len(ours) and ours[k][0].line == e.line:
            pieces.append(ours[k][0])
            k += 1
        assert all(q.kind == "line" for q in pieces), e.line
        assert np.allclose(pieces[-1].end, mv[2], atol=TOL, rtol=0), (e.line, pieces[-1].end, mv[2])
        for a, b in zip(pieces, pieces[1:]):
            assert np.array_equal(a.end, b.start) and a.z_end_m == b.z_start_m, e.line
        for q in pieces:  # the ends (with their Z) are points of the canonical arc
            for xy, z in ((q.start, q.z_start_m), (q.end, q.z_end_m)):
                pt = np.array([xy[0], xy[1], z])
                assert abs(math.hypot(pt[first] - centre[0], pt[second] - centre[1]) - r) <= TOL, e.line
                assert abs(pt[3 - first - second] - mv[6][3 - first - second]) <= TOL, e.line
        t = np.linspace(0.0, 1.0, 20001)
        samples = np.repeat(mv[6][None, :], t.size, axis=0)
        samples[:, first] = centre[0] + r * np.cos(a0 + t * sweep)
        samples[:, second] = centre[1] + r * np.sin(a0 + t * sweep)
        assert max(_dist_to_polyline(s[:2], pieces) for s in samples[::50]) <= TOL, e.line
        arc_xy_length = float(np.sum(np.hypot(*np.diff(samples[:, :2], axis=0).T)))
        assert abs(sum(q.length_m for q in pieces) - arc_xy_length) <= TOL, e.line
    assert k == len(ours), (k, len(ours))


def check_post(name: str, **expect) -> Program:
    """Read ``name`` from tests/data/cam, compare it with rs274 and plan it at ``ORIGIN``."""
    text = (CAM / name).read_text()
    p = read_gcode(text)
    assert_xy_path_equals_rs274(text, p)
    res = plan_contour({"program": text, "origin": ORIGIN})
    c = res.contour
    assert c is not None
    assert len(c.passes) == expect["passes"]
    assert c.max_deviation_m <= c.tolerance_m
    assert c.tolerance_m == pytest.approx(expect.get("tolerance", 5e-5))
    assert any(c.cutting) and c.cut_time_s > 0
    assert [w.word for w in c.words] == [w.word for w in p.words]
    return p


def test_freecad_linuxcnc_post():
    """FreeCAD 0.20 ``linuxcnc_post``: the preamble's cancels, ``M6 T1``, ``G43 H1`` (refused
    before), ``M3 S``, a profile and a helical entry (G2 with Z in G17), the postamble."""
    p = check_post("freecad_linuxcnc.ngc", passes=2)
    words = [w.word for w in p.words]
    assert words[:12] == ["G17", "G54", "G40", "G49", "G80", "G54", "M5", "T1", "M6", "G43 H1", "S10000", "M3"]
    assert words[-5:] == ["M5", "G17", "G54", "G80", "G40"]
    assert not p.warnings  # G54 alone: the default work offset, nothing to say
    helix = [e for b in p.passes for e in b.elements if e.kind == "arc" and e.z_start_m != e.z_end_m]
    assert len(helix) == 1 and helix[0].sweep_rad == pytest.approx(-2 * math.pi)
    assert helix[0].z_end_m - helix[0].z_start_m == pytest.approx(-0.4e-3)


def test_fusion360_post():
    """Fusion 360's LinuxCNC post: ``%``, ``O1001``, ``G91.1``, ``G28 G91 Z0.`` (a return to Z
    home, issued as written), ``G43 Z15. H1`` (issued as written, from Z home), coolant, a
    vertical lead-in (G18) and lead-out (G19) arc (refused before), ``G61``/``G64 P``, ``M30``."""
    p = check_post("fusion360.nc", passes=2, tolerance=2e-5)
    words = [w.word for w in p.words]
    assert words[:4] == ["O1001", "G94", "G17", "G91.1"]
    assert {"T1", "M6", "S5000", "M3", "G54", "M8", "G43 H1", "G18", "G19", "G61", "G64 P0.02", "M9",
            "M5"} <= set(words)
    assert [w for w in p.warnings if "G28" in w] == [
        f"line {n}: G28 Z (return to Z home) is issued as written; Z home is unknown here: its time is not counted, "
        "and the output gives no Z until the program's next Z move" for n in (8, 36)]
    # issued as written: each G28 and the Z move after the first (G43 Z15. H1: from Z home)
    assert [(w.line, w.word) for w in p.words if w.word[:2] in ("G0", "G9")] == [
        (4, "G94"), (4, "G91.1"), (8, "G91 G28 Z0.0000"), (16, "G0 Z15.0000"), (36, "G91 G28 Z0.0000")]
    first = p.passes[0].elements
    # the G18 lead-in: a quarter arc, XY along +X from (-2, 0) to (0, 0), down from Z 1 to -1 mm
    assert first[0].line == 19 and first[0].kind == "line"
    assert np.allclose(first[0].start, [-2e-3, 0]) and np.allclose(first[0].end, [0, 0])
    assert (first[0].z_start_m, first[0].z_end_m) == pytest.approx((1e-3, -1e-3))
    # the G19 lead-out: along +Y from (10, 6) to (10, 8), up to Z 1 mm
    assert first[-1].line == 23 and np.allclose([first[-1].start, first[-1].end], [[10e-3, 6e-3], [10e-3, 8e-3]])


def test_pcb_gcode_inch_program():
    """Eagle pcb-gcode: inch (G20), ``M03``, ``G04 P1`` spin-up, ``G00``/``G01``, ``F`` on its
    own line; the lengths are inch converted at the edge (0.2 in = 5.08 mm)."""
    p = check_post("pcb_gcode.ngc", passes=2)
    assert p.units == "inch"
    assert [b.duration_s for b in p.blocks if b.reason == "G4"] == [1.0]
    first = p.passes[0].elements[0]
    assert first.length_m == pytest.approx(0.2 * 0.0254, abs=1e-12)
    assert first.feed_m_s == pytest.approx(20 * 0.0254 / 60)


@pytest.mark.parametrize("name, passes", [("estlcam.nc", 2), ("dxf2gcode.ngc", 1)])
def test_estlcam_and_dxf2gcode_programs(name, passes):
    """Estlcam (``;`` comments, ``M03 S``, ``G00``/``G01``/``G03``) and dxf2gcode (comments after
    each header word, spaces inside words, ``T1 M6``, ``M3 M8``)."""
    check_post(name, passes=passes)


def test_cli_plans_the_fusion_post(tmp_path):
    out = tmp_path / "fusion.json"
    r = subprocess.run([sys.executable, "-m", "app.cli", "contour", str(CAM / "fusion360.nc"),
                        f"--origin={ORIGIN[0]},{ORIGIN[1]}", "-o", str(out)], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    c = json.loads(out.read_text())["contour"]
    assert len(c["passes"]) == 2 and c["max_deviation_m"] <= c["tolerance_m"]


#: a G18 arc of three quarters: its XY path runs out past both ends and back
VERTICAL = """G21 G90 G17
F300
G0 X1 Y2 Z1
G18 G3 X3 Z-1 I2 K0
G19 G2 Y4 Z1 J2 K0
G18 G2 X7 Z1 I2 K0
G18 G2 X7 Z1 I-2 K0 (a full circle: X back to 3 and out again)
G17 G0 Z5
M2
"""


def test_vertical_arcs_are_their_xy_lines():
    """Arcs in the XZ and YZ planes against rs274: cut where X (Y) or Z turns; the tool stops
    where the XY direction reverses (X at its extreme), not where only Z turns."""
    p = read_gcode(VERTICAL)
    assert_xy_path_equals_rs274(VERTICAL, p)
    by_line: dict[int, list[PathElement]] = {}
    for b in p.blocks:
        for e in b.elements:
            by_line.setdefault(e.line, []).append(e)
    assert [len(by_line[n]) for n in (4, 5, 6)] == [3, 1, 2]
    assert [e.exact_stop for e in by_line[4]] == [False, True, False]  # X turns at 5 mm
    assert np.allclose([e.end[0] for e in by_line[4]], [3e-3, 5e-3, 3e-3])
    assert not any(e.exact_stop for e in by_line[6])  # Z turns at -1 mm, X runs on
    assert np.allclose([e.end[0] for e in by_line[6]], [5e-3, 7e-3])
    assert np.allclose([e.end[0] for e in by_line[7]], [5e-3, 3e-3, 5e-3, 7e-3])
    assert [e.exact_stop for e in by_line[7]] == [False, True, False, False]


def test_the_first_z_move_starts_from_the_machine_s_height():
    """Before the first Z move the machine's Z is unknown: that move is kept as written (Z
    first, then its XY at that Z, travel); refused where its start would matter: incremental
    or a ramp into the cut."""
    p = read_gcode("G21 G90\nF100\nG0 X1 Y1 Z5\nG1 Z-1\nG1 X5\nG0 Z5\nM2\n")
    assert [(w.line, w.word) for w in p.words] == [(3, "G0 Z5.0000")]
    travel = p.blocks[0]
    assert travel.kind == "travel" and travel.rapid and travel.line == 3
    assert (travel.elements[0].z_start_m, travel.elements[0].z_end_m) == (5e-3, 5e-3)
    assert [b.reason for b in p.blocks if b.kind == "dwell"] == ["plunge", "retract"]
    with pytest.raises(PlannerError, match=r"line 3: an incremental Z move \(G91\) after the program's start"):
        read_gcode("G21 G90\nF100\nG91 G0 Z-5\nG90 G1 Z-1\nG1 X5\nM2\n")
    with pytest.raises(PlannerError, match=r"line 3: the first Z move after the program's start goes into the cut "
                       r"\(Z-1\) while moving in XY.*clearance height first"):
        read_gcode("G21 G90\nF100\nG1 X5 Z-1\nG1 X10\nM2\n")
    with pytest.raises(PlannerError, match=r"line 6: an incremental Z move \(G91\) after the G28 at line 5"):
        read_gcode("G21 G90\nF100\nG0 Z5\nG1 Z-1\nG28 G91 Z0\nG0 Z5\nM2\n")


@pytest.mark.parametrize("line, word, remedy", [
    ("G41 D1", "G41", "'Compensation type: In computer'"),
    ("G42", "G42", "compensation computed in the CAM"),
    ("G83 X1 Y1 Z-1 R1 Q0.5", "G83", "expand it into G0/G1 moves"),
    ("G81 X1 Y1 Z-1 R1", "G81", "a post without canned cycles"),
    ("G92 X0 Y0", "G92", "place the program with `origin`"),
    ("G10 L2 P1 X0", "G10", "place the program with `origin`"),
    ("G28 G91 X0. Y0.", "G28", "Safe retracts: Clearance height"),
    ("G28", "G28", "Z retract"),
    ("G53 G0 Z0", "G53", "Safe retracts"),
    ("G90.1", "G90.1", "G91.1"),
    ("G95", "G95", "units per minute (G94)"),
    ("G5.2 X1 Y1", "G5.2", "lines and arcs"),
    ("O100 sub", "O-word", "without subroutines"),
    ("#1 = 2", "'#'", "without subroutines, loops and macros"),
    ("M98 P100", "M98", "without subroutines"),
    ("M101", "M101", "post without it"),
    ("G1 X1 A5", "A5", "post for a 3-axis mill"),
    ("G18 G2 X2 Y1 Z1 I1 K0", "G2 in G18 with a Y move", "lead-in and lead-out arcs in the XY plane"),
    ("G2 X1 Y0 I0.5 K0", "the word K", "G17 XY: I J"),
    ("H1", "H1", "with G43"),
    ("/G1 X2", "'/'", "post without optional blocks"),
])
def test_refused_words_name_the_line_the_word_and_a_remedy(line, word, remedy):
    text = f"G21 G90\nF100\nG0 X0 Y0\n{line}\nG1 Z-1\nG1 X5\nM2\n"
    with pytest.raises(PlannerError) as err:
        read_gcode(text)
    msg = err.value.message
    assert err.value.field == "program" and msg.startswith("line 4: "), msg
    assert word in msg and remedy in msg, msg


def test_work_offsets_are_identity_with_a_warning():
    """G55..G59.3 are read as the identity, said once; the path equals rs274's (its offsets
    table is empty too)."""
    text = "G21 G90 G55\nF300\nG0 X1 Y1\nG1 Z-1\nG1 X3\nG59.3 G1 Y3\nG0 Z2\nM2\n"
    p = read_gcode(text)
    assert_xy_path_equals_rs274(text, p)
    # the first Z move (from the machine's height, unknown) as the export issues it
    assert [w.word for w in p.words] == ["G55", "G94 G1 Z-1.0000 F300.0000", "G59.3"]
    assert p.warnings == ["work offsets G55, G59.3: with no offsets table each is read as the identity (program X0 "
                          "Y0 is at `origin`): the program's parts in different work offsets overlap here"]


def test_optional_stop_and_tool_length_words_are_kept():
    """M1 is a stop at rest, warned; G43.1 Z is an offset, not a move; G49 and G61.1 are kept."""
    text = "G21 G90\nG43.1 Z0.5\nF300\nG0 X1 Y1\nG1 Z-1\nG61.1 G1 X3\nM1\nG1 Y3\nG49\nG0 Z2\nM2\n"
    p = read_gcode(text)
    assert_xy_path_equals_rs274(text, p)
    assert [w.word for w in p.words] == ["G43.1 Z0.5", "G94 G1 Z-1.0000 F300.0000", "G61.1", "M1", "G49"]
    assert [b.reason for b in p.blocks if b.kind == "dwell"] == ["pause", "retract"]  # the plunge: from unknown Z
    assert p.passes[0].elements[0].exact_stop and p.passes[-1].elements[-1].exact_stop
    assert p.warnings == ["line 7: M1 (optional stop) is planned as a stop at rest of 0 s: the operator's wait is "
                          "not in the cycle time"]
