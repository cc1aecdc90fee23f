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
    """rs274's canonical moves in m: ('line', x, y, z, rapid) / ('arc', x, y, cx, cy, turn, z) /
    ('dwell', s), and the unit it printed them in (per move)."""
    unit = 1e-3
    moves: list[tuple] = []
    for ln in rs274(program):
        m = re.search(r"(\w+)\((.*)\)", ln)
        if not m:
            continue
        name, args = m.group(1), m.group(2)
        if name == "USE_LENGTH_UNITS":
            unit = 0.0254 if "INCHES" in args else 1e-3
            continue
        if name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED"):
            v = [float(a) for a in args.split(",")]
            moves.append(("line", v[0] * unit, v[1] * unit, v[2] * unit, name == "STRAIGHT_TRAVERSE", unit))
        elif name == "ARC_FEED":
            v = [float(a) for a in args.split(",")]
            moves.append(("arc", v[0] * unit, v[1] * unit, v[2] * unit, v[3] * unit, int(v[4]), v[5] * unit, unit))
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


def compare_with_rs274(text: str) -> Program:
    """Parse ``text`` and check every XY move against rs274's canonical moves: end points,
    arc centres, directions and full turns (to the printed precision: 4 decimals of the unit)."""
    p = read_gcode(text)
    canon, _ = canonical_moves(text)
    xy_canon = []
    prev = np.zeros(3)
    for mv in canon:
        if mv[0] == "dwell":
            continue
        digits_m = 0.51e-4 * mv[-1]
        end = np.array([mv[1], mv[2], mv[5] if mv[0] == "line" else mv[6]]) if mv[0] == "arc" else \
            np.array(mv[1:4])
        if mv[0] == "line" and np.all(np.abs(end[:2] - prev[:2]) < digits_m) and mv[0] == "line":
            prev = end  # a Z-only move: a plunge or retract, not an XY element
            continue
        xy_canon.append((mv, prev.copy()))
        prev = end
    ours = parsed_moves(p)
    assert len(ours) == len(xy_canon), (len(ours), len(xy_canon))
    for (e, rapid), (mv, start) in zip(ours, xy_canon):
        digits_m = 1.02e-4 * mv[-1]  # both ends printed
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
    dwells = [mv[1] for mv in canon if mv[0] == "dwell"]
    g4 = [b.duration_s for b in p.blocks if b.kind == "dwell" and b.reason == "G4"]
    assert np.allclose(dwells, g4)
    return p


def test_every_word_matches_rs274():
    p = compare_with_rs274(EVERY_WORD)
    assert p.tolerance_m == pytest.approx(2e-5)
    assert [w.word for w in p.words if w.word[0] in "MST"] == ["T2", "M6", "S12000", "M3", "M5", "M0"]
    assert {c.text for c in p.comments} >= {"full circle", "tool change", "the long way round"}
    assert not p.warnings
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


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_linuxcnc_samples_match_rs274(name):
    path = SAMPLES[name]
    assert path.exists(), f"{path} is missing: `make test` installs linuxcnc-uspace"
    text = path.read_text()
    p = compare_with_rs274(text)
    assert p.passes


@pytest.mark.parametrize("line, word", [
    ("G41 X1", "G41"), ("G42 D1", "G42"), ("G81 X1 Y1 Z-1 R1", "G81"), ("G18", "G18"), ("G19", "G19"),
    ("O100 sub", "O-word"), ("#1 = 2", "parameters"), ("G1 A5", "A5"), ("G90.1", "G90.1"), ("M98", "M98"),
    ("G1 X[1+2]", "expressions"), ("G2 X1 Y0", "I and J"), ("G2 X10 Y0 R2", "diameter"), ("G1 Q2", "Q2"),
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
