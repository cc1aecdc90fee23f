"""Reading CAM programs (issue 22): every program is also run through LinuxCNC's own
interpreter (``rs274 -g``, Debian linuxcnc-uspace) and the parsed path is compared with its
canonical moves (STRAIGHT_TRAVERSE, STRAIGHT_FEED, ARC_FEED, DWELL) one by one."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from planner.errors import PlannerError
from planner.exchange import read_gcode
from planner.schema import Program
from tests.linuxcnc import rs274

#: real CAM programs shipped by linuxcnc-uspace that are planar and use only supported words
SAMPLES = {
    "craftsman": Path("/usr/share/doc/linuxcnc/examples/sample-configs/sim/craftsman/screens/craftsmancnc.ngc"),
    "arcspiral": Path("/usr/share/linuxcnc/ncfiles/arcspiral.ngc"),
}

#: hand-written: every supported word
EVERY_WORD = """%
(header: a pocket outline, mm)
G21 G90 G17 G40 G49 G80 G54 G94
G64 P0.02
T2 M6 ; tool change
S12000 M3
F600
G0 X5 Y5 Z3
G1 Z-0.5 F120
G1 X25 F600
G2 X35 Y15 I0 J10
G3 X25 Y25 R10
G1 X15
G3 X5 Y15 R-10 (the long way round)
G91 G1 Y-10
G90 G2 X5 Y5 I5 J0
G4 P0.25
G61 G1 X10 Y10
G1 X12
G64 G0 Z3
G0 X20 Y20
G1 Z-1 F100
G3 X20 Y20 I4 J0 F300 (full circle)
G20 G1 X0.8 Y0.8
G21 G0 Z5
M5
M0
M2
G1 X1000 (after the end: ignored)
"""


def canonical_moves(program: str) -> tuple[list[tuple], float]:
    """rs274's canonical moves in m: ('line', x, y, z, rapid, c, rate) / ('arc', x, y, cx, cy, turn,
    z, c, rate) / ('dwell', s), each move followed by the unit it printed it in; c the C axis
    [degree], rate the feed rate in force [unit / minute] (0 for a rapid)."""
    unit = 1e-3
    moves: list[tuple] = []
    rate = 0.0
    for ln in rs274(program):
        m = re.search(r"(\w+)\((.*)\)", ln)
        if not m:
            continue
        name, args = m.group(1), m.group(2)
        if name == "USE_LENGTH_UNITS":
            unit = 0.0254 if "INCHES" in args else 1e-3
            continue
        if name == "SET_FEED_RATE":
            rate = float(args)
        elif name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED"):
            v = [float(a) for a in args.split(",")]
            rapid = name == "STRAIGHT_TRAVERSE"
            moves.append(("line", v[0] * unit, v[1] * unit, v[2] * unit, rapid, v[5], 0.0 if rapid else rate, unit))
        elif name == "ARC_FEED":
            v = [float(a) for a in args.split(",")]
            moves.append(("arc", v[0] * unit, v[1] * unit, v[2] * unit, v[3] * unit, int(v[4]), v[5] * unit, v[8], rate,
                          unit))
        elif name == "DWELL":
            moves.append(("dwell", float(args)))
    return moves, unit


def parsed_moves(p: Program) -> list:
    """The parsed program's XY elements, in order, with whether each is a rapid."""
    out = []
    for b in p.blocks:
        for e in b.elements:
            out.append((e, b.kind == "travel" and b.rapid))
    return out


def compare_with_rs274(text: str, readback: bool = False) -> Program:
    """Parse ``text`` and check every XY move against rs274's canonical moves: end points,
    arc centres, directions and full turns (to the printed precision: 4 decimals of the unit).
    ``readback``: read as the planner's own export (G93, the C axis): C and each move's
    inverse-time duration are checked too (the duration against the feed rate rs274 makes of
    F: its length / rate)."""
    p = read_gcode(text, readback=readback)
    canon, _ = canonical_moves(text)
    xy_canon = []
    prev, prev_c = np.zeros(3), 0.0
    for mv in canon:
        if mv[0] == "dwell":
            continue
        digits_m = 0.51e-4 * mv[-1]
        end = np.array([mv[1], mv[2], mv[6]]) if mv[0] == "arc" else np.array(mv[1:4])
        c = mv[7] if mv[0] == "arc" else mv[5]
        if mv[0] == "line" and np.all(np.abs(end[:2] - prev[:2]) < digits_m) and not (readback and c != prev_c):
            prev = end  # a Z-only move: a plunge or retract, not an XY element
            continue
        xy_canon.append((mv, prev.copy(), prev_c))
        prev, prev_c = end, c
    ours = parsed_moves(p)
    assert len(ours) == len(xy_canon), (len(ours), len(xy_canon))
    for (e, rapid), (mv, start, c0) in zip(ours, xy_canon):
        digits_m = 1.02e-4 * mv[-1]  # both ends printed
        if readback:
            c1 = mv[7] if mv[0] == "arc" else mv[5]
            assert e.c_start_rad is not None and e.c_end_rad is not None
            assert abs(math.degrees(e.c_start_rad) - c0) <= 1.02e-4 and abs(math.degrees(e.c_end_rad) - c1) <= 1.02e-4
            if rapid:
                assert e.duration_s is None
            else:
                rate = mv[-2]  # unit per minute; LinuxCNC: the XYZ length, else the rotary one
                length = e.length_m / mv[-1] if e.length_m > 0 else abs(c1 - c0)
                assert e.duration_s is not None and rate > 0
                assert abs(e.duration_s - 60.0 * length / rate) <= e.duration_s * (0.51e-4 / rate + 1e-9), e.line
        assert np.allclose(e.start, start[:2], atol=digits_m), (e.line, e.start, start)
        if mv[0] == "line":
            assert e.kind == "line" and rapid == mv[4], e.line
            assert np.allclose(e.end, mv[1:3], atol=digits_m), (e.line, e.end, mv)
            assert math.isclose(e.z_end_m, mv[3], abs_tol=digits_m)
        else:
            assert e.kind == "arc", e.line
            assert e.centre is not None and e.sweep_rad is not None and e.radius_m is not None
            assert np.allclose(e.centre, mv[3:5], atol=digits_m), (e.line, e.centre, mv)
            # rs274: +1 counter-clockwise, -1 clockwise (one turn at most here)
            assert np.sign(e.sweep_rad) == np.sign(mv[5]), e.line
            end = e.centre + e.radius_m * np.array([math.cos(e.start_angle_rad + e.sweep_rad),
                                                    math.sin(e.start_angle_rad + e.sweep_rad)])
            assert np.allclose(end, mv[1:3], atol=max(digits_m, 2.5e-6)), (e.line, end, mv)
            if np.allclose(mv[1:3], start[:2], atol=1e-12):
                assert math.isclose(abs(e.sweep_rad), 2 * math.pi), "a full circle"
            else:
                assert abs(e.sweep_rad) < 2 * math.pi
            assert math.isclose(e.length_m, e.radius_m * abs(e.sweep_rad))
    dwells: list[float] = []  # consecutive G4s (no move between) read as one dwell
    after_dwell = False
    for mv in canon:
        if mv[0] == "dwell" and after_dwell:
            dwells[-1] += mv[1]
        elif mv[0] == "dwell":
            dwells.append(mv[1])
        after_dwell = mv[0] == "dwell"
    g4 = [b.duration_s for b in p.blocks if b.kind == "dwell" and b.reason == "G4"]
    assert np.allclose(dwells, g4)
    return p


def test_every_word_matches_rs274():
    p = compare_with_rs274(EVERY_WORD)
    assert p.tolerance_m == pytest.approx(2e-5)
    assert [w.word for w in p.words if w.word[0] in "MST"] == ["T2", "M6", "S12000", "M3", "M5", "M0"]
    assert {c.text for c in p.comments} >= {"full circle", "tool change", "the long way round"}
    assert p.warnings == ["line 27: M0 (program pause) is planned as a stop at rest of 0 s: the operator's wait is "
                          "not in the cycle time"]
    kinds = [b.kind for b in p.blocks]
    # travel, plunge, cut ... G4 (dwell) ... retract, travel, plunge, cut (full circle, inch move), retract, pause
    assert kinds[:3] == ["travel", "dwell", "cut"] and kinds[-1] == "dwell" and p.blocks[-1].reason == "pause"
    g4 = [b for b in p.blocks if b.reason == "G4"]
    assert len(g4) == 1 and g4[0].duration_s == pytest.approx(0.25)
    plunge = p.blocks[1]
    assert plunge.reason == "plunge" and plunge.duration_s == pytest.approx(3.5e-3 / (120e-3 / 60))
    # the exact-stop moves stop at their ends
    assert [e.exact_stop for b in p.passes for e in b.elements if e.line in (18, 19)] == [True, True]
    # the long R arc (R < 0) sweeps more than half a turn; the short one less
    arcs = {e.line: e for b in p.passes for e in b.elements if e.kind == "arc"}
    assert abs(arcs[12].sweep_rad) < math.pi < abs(arcs[14].sweep_rad)
    assert arcs[23].sweep_rad == pytest.approx(2 * math.pi)
    # the inch move: X0.8 Y0.8 inch
    last = p.passes[-1].elements[-1]
    assert np.allclose(last.end, [0.8 * 0.0254, 0.8 * 0.0254])


def test_tabs_and_spaces_inside_words_read_as_rs274_reads_them():
    """Spaces and tabs mean nothing outside comments (LinuxCNC's 3dtest.ngc separates its words
    with tabs): the program with tabs between and inside words reads as rs274 reads it, and as
    the same program written plainly ('X- \t5' was a crash, a tab between words a refusal)."""
    tabbed = EVERY_WORD.replace(" ", "\t").replace("X", "X \t").replace("Y-", "Y- \t")
    p = compare_with_rs274(tabbed)
    plain = read_gcode(EVERY_WORD)
    assert [e.model_dump() for b in p.passes for e in b.elements] == \
        [e.model_dump() for b in plain.passes for e in b.elements]


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_linuxcnc_samples_match_rs274(name):
    path = SAMPLES[name]
    assert path.exists(), f"{path} is missing: `make test` installs linuxcnc-uspace"
    text = path.read_text()
    p = compare_with_rs274(text)
    assert p.passes


@pytest.mark.parametrize("line, word", [
    ("G41 X1", "G41"), ("G42 D1", "G42"), ("G81 X1 Y1 Z-1 R1", "G81"),
    ("O100 sub", "O-word"), ("#1 = 2", "parameters"), ("G1 A5", "A5"), ("G90.1", "G90.1"), ("M98", "M98"),
    ("G1 X[1+2]", "expressions"), ("G2 X1 Y0", "I and J"), ("G2 X10 Y0 R2", "diameter"), ("G1 Q2", "Q2"),
    ("G93", "G93: inverse-time feed (G93) is not supported"),  # the read-back's words: not for contour
    ("G1 X2 C5", "C5 is another axis"),
])
def test_unsupported_words_name_the_line_and_word(line, word):
    text = f"G21 G90\nF100\nG0 X0 Y0\n{line}\nG1 Z-1\nG1 X5\nM2\n"
    with pytest.raises(PlannerError) as err:
        read_gcode(text)
    assert err.value.field == "program"
    assert "line 4" in err.value.message and word in err.value.message


def test_missing_end_and_units_are_warnings():
    p = read_gcode("F100\nG1 Z-1\nG1 X5\n")
    assert any("M2/M30" in w for w in p.warnings) and any("G20/G21" in w for w in p.warnings)


def test_program_without_a_cut_and_too_large_program():
    with pytest.raises(PlannerError, match="no cutting move"):
        read_gcode("G21\nG0 X5\nM2\n")
    with pytest.raises(PlannerError) as err:
        read_gcode("G1 X1\n" * 400_000)
    assert err.value.code == "too_large"


def test_arc_radius_mismatch_is_refused():
    with pytest.raises(PlannerError, match="line 3: the radius to the end"):
        read_gcode("G21 F100\nG1 Z-1\nG2 X10 Y0 I5.1 J0\nM2\n")


@pytest.mark.parametrize("line", ["G1 X" + "9" * 400, "G1 X1e5", "S" + "1" * 40])
def test_numbers_out_of_range_or_not_numbers_are_refused(line):
    with pytest.raises(PlannerError) as err:
        read_gcode(f"G21 F100\nG1 Z-1\n{line}\nM2\n")
    assert "line 3" in err.value.message


#: hand-written in the export's dialect: inverse time, the C axis, an arc, a C-only move, dwells
READBACK = """(rangeplan plan: by hand)
G21 G90 G17
G0 X1.0000 Y2.0000 C10.0000
G93
G1 X3.0000 Y2.0000 C12.0000 F6000.000000
G4 P0.010000
G4 P0.010000
G1 X3.0000 Y2.0000 C13.5000 F6000.000000
G3 X1.0000 Y4.0000 R2 C15.0000 F3000.000000
G91 G1 X-1.0000 C-15.0000 F1500.000000
G90
G94
M2
"""


def test_readback_reads_inverse_time_and_the_c_axis_as_rs274():
    """The read-back mode against rs274: end points, C and each move's G93 time (checked
    against the feed rate rs274 makes of F) agree; the durations are 60 / F."""
    p = compare_with_rs274(READBACK, readback=True)
    moves = [e for b in p.blocks for e in b.elements]
    assert moves[0].duration_s is None  # the rapid: the machine's own speed
    assert [e.duration_s for e in moves[1:]] == pytest.approx([0.01, 0.01, 0.02, 0.04])
    assert math.degrees(moves[2].c_end_rad or 0.0) == pytest.approx(13.5) and moves[2].length_m == 0.0
    assert moves[-1].c_end_rad == pytest.approx(0.0, abs=1e-12)  # G91: C incremental
    assert [b.duration_s for b in p.blocks if b.kind == "dwell"] == pytest.approx([0.02])
    assert not p.passes and not p.warnings  # no cut: fine for a read-back
    assert p.comments[0].text == "rangeplan plan: by hand"


@pytest.mark.parametrize("text, message", [
    ("G21 G93\nG1 X1 Y1\nM2\n", "line 2: G1 in inverse-time feed (G93) needs a positive F"),
    ("G21 G93\nG1 X1 F100\nG1 X2\nM2\n", "line 3: G1 in inverse-time feed"),  # F is per line under G93
    ("G21 G93 G94\nM2\n", "line 1: G93 and G94 on one line"),
    ("G21 G93\nG1 X1 F100\nG94\nG1 X2\nM2\n", "line 4: G1 with no feed"),  # back in G94: a new F first
    ("G21\nG1 X1 B2 F100\nM2\n", "line 2: the word B2 is another axis"),
])
def test_readback_refusals_name_the_line(text, message):
    with pytest.raises(PlannerError) as err:
        read_gcode(text, readback=True)
    assert message in err.value.message, err.value.message


TAB = """G21 G90
G0 Z5
G0 X0 Y0
G1 Z0.5 F300
G1 X4 Z-1 F600
G1 X8
G1 X9 Z0.5
G1 X11
G1 X12 Z-1
G1 X16
G0 Z5
M2
"""


def test_a_tab_above_the_cut_height_stays_in_its_pass():
    """Feed moves above the cutting height between two cuts (ramp up, the tab's top, ramp down)
    are one pass with them (issue 32, goal 3): the path of the pass is the source's moves in
    order, Z as written; a rapid or a Z-only move between two cuts still ends the pass."""
    p = read_gcode(TAB)
    assert len(p.passes) == 1
    els = p.passes[0].elements
    assert [e.line for e in els] == [5, 6, 7, 8, 9, 10]
    assert all(np.allclose(a.end, b.start) for a, b in zip(els, els[1:]))
    assert max(e.z_end_m for e in els) == pytest.approx(0.5e-3) and els[3].z_start_m == pytest.approx(0.5e-3)
    rapid = TAB.replace("G1 X11\n", "G0 X11\n")
    assert len(read_gcode(rapid).passes) == 2
    vertical = TAB.replace("G1 X9 Z0.5\nG1 X11\nG1 X12 Z-1\n", "G1 Z0.5\nG1 X11\nG1 Z-1\n")
    assert len(read_gcode(vertical).passes) == 2


def test_a_moving_z_is_cut_within_the_z_axis_speed():
    """A move whose Z changes is cut at an XY feed at which its Z moves at most at the Z axis
    speed (z_rapid_m_s): F_xy |dZ| / L <= z_rapid; a move that keeps Z keeps its F."""
    steep = TAB.replace("G1 X9 Z0.5", "G1 X8.3 Z0.5")  # 0.3 mm for 1.5 mm of Z
    els = read_gcode(steep, z_rapid_m_s=0.004).passes[0].elements
    for e in els:
        dz = abs(e.z_end_m - e.z_start_m)
        assert e.feed_m_s * dz / e.length_m <= 0.004 + 1e-12
        if dz == 0:
            assert e.feed_m_s == pytest.approx(0.01)
    assert els[2].feed_m_s == pytest.approx(0.004 * 0.3 / 1.5)  # the bound itself, below F
