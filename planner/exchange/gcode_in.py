"""Reading a CAM program: RS274NGC (LinuxCNC's dialect) -> a :class:`~planner.schema.Program`
of lines and arcs in m (the program's own frame), split into cut passes, travel and dwells.

Supported (what CAM posts for a 2.5D contour emit): ``G0 G1 G2 G3`` (arcs by ``I J`` offsets,
incremental as LinuxCNC's default ``G91.1``, or by ``R``; full circles with ``I J``), ``G4 P``
(seconds), ``G17``, ``G20 G21``, ``G90 G91``, ``G61`` (exact stop), ``G64`` (``P``: the path
tolerance), ``F`` (units per minute, ``G94``), ``M3 M4 M5 M6 M7 M8 M9``, ``M0 M1`` (a pause: the tool stops
there), ``S``, ``T``, ``N`` line numbers, ``( )`` and ``;`` comments, ``%`` delimiters, ``M2``/``M30`` (what follows is
ignored, as LinuxCNC does). The no-op cancels CAM headers carry (``G40`` cutter compensation
off, ``G49`` tool length offset off, ``G80`` canned cycle off, ``G54`` the first work offset,
zero here, ``G94``) are accepted and listed. Anything else (``G41``/``G42`` cutter compensation,
canned cycles, ``O`` subroutines, parameters and expressions, ``G18``/``G19`` and other axes)
is a :class:`~planner.errors.PlannerError` naming the line and the word.

A feed move whose Z is below ``cut_below`` (somewhere along it) cuts; consecutive cutting
moves form a pass. Rapids and feed moves above it are travel; Z-only moves are plunges and
retracts (dwells of ``|dZ| / F``, or ``/ z_rapid`` for G0).
"""

from __future__ import annotations

import math
import re

import numpy as np

from ..errors import PlannerError
from ..schema.contour import (
    MAX_PROGRAM_BYTES,
    PathElement,
    Program,
    ProgramBlock,
    ProgramComment,
    ProgramWord,
)

__all__ = ["read_gcode"]

_UNIT = {"mm": 1e-3, "inch": 0.0254}
#: largest magnitude of a word's number (a length of 1 km in mm, a feed, a spindle speed)
MAX_WORD_VALUE = 1e6
#: largest difference between an arc's start and end radius (as LinuxCNC: 0.002 mm) [m]
ARC_RADIUS_TOL_M = 2e-6
_WORD = re.compile(r"([A-Z])\s*([-+]?\s*(?:\d+\.?\d*|\.\d+))")
_ACCEPTED_G = {0.0, 1.0, 2.0, 3.0, 4.0, 17.0, 20.0, 21.0, 90.0, 91.0, 61.0, 64.0, 40.0, 49.0, 80.0, 54.0, 94.0}
_ACCEPTED_M = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 30}
_WHY = {18.0: "the XZ plane (G18): only the XY plane (G17) is planar for this robot",
        19.0: "the YZ plane (G19): only the XY plane (G17) is planar for this robot",
        41.0: "cutter radius compensation (G41): post the program with compensation in the CAM (tool centre path)",
        42.0: "cutter radius compensation (G42): post the program with compensation in the CAM (tool centre path)",
        41.1: "cutter radius compensation (G41.1)", 42.1: "cutter radius compensation (G42.1)",
        93.0: "inverse-time feed (G93)", 95.0: "feed per revolution (G95)", 90.1: "absolute arc centres (G90.1)",
        92.0: "coordinate offsets (G92)", 28.0: "return to a stored position (G28)", 30.0: "G30"}


def _fail(line: int, message: str) -> PlannerError:
    return PlannerError("invalid_input", f"line {line}: {message}", "program")


def _strip_comments(text: str, line: int, comments: list[ProgramComment]) -> str:
    out = []
    i = 0
    while i < len(text):
        c = text[i]
        if c == "(":
            j = text.find(")", i)
            if j < 0:
                raise _fail(line, "unclosed comment '(' (RS274NGC comments end on the same line)")
            comments.append(ProgramComment(line=line, text=text[i + 1:j].strip()))
            i = j + 1
        elif c == ";":
            comments.append(ProgramComment(line=line, text=text[i + 1:].strip()))
            break
        else:
            out.append(c)
            i += 1
    return "".join(out)


def read_gcode(text: str, *, cut_below: float = 0.0, z_rapid_m_s: float = 0.05) -> Program:
    """Read ``text`` (a G-code program) into a :class:`~planner.schema.Program` in m, s and
    rad (module docstring). ``cut_below`` [m]: feed moves with Z below it cut.
    Raises :class:`~planner.errors.PlannerError` (field ``program``) naming the line and the
    word for anything it does not support."""
    if len(text.encode()) > MAX_PROGRAM_BYTES:
        raise PlannerError("too_large", f"the program has {len(text.encode())} bytes, more than the limit of "
                           f"{MAX_PROGRAM_BYTES}", "program")
    units = "mm"
    unit_set = False
    absolute = True
    motion: float | None = None
    feed = 0.0  # m/s
    exact = False
    tolerance: float | None = None
    pos = np.zeros(3)  # x, y, z [m]
    first_xy: np.ndarray | None = None
    words: list[ProgramWord] = []
    comments: list[ProgramComment] = []
    warnings: list[str] = []
    blocks: list[ProgramBlock] = []
    ended = False
    lines = text.splitlines()
    n_lines = 0

    def add_dwell(line: int, duration: float, reason: str) -> None:
        if duration <= 0 and reason != "pause":
            return
        if blocks and blocks[-1].kind == "dwell" and blocks[-1].reason == reason:
            blocks[-1].duration_s += duration
        else:
            blocks.append(ProgramBlock(kind="dwell", line=line, duration_s=duration, reason=reason))

    for ln, raw in enumerate(lines, start=1):
        n_lines = ln
        body = _strip_comments(raw, ln, comments).strip().upper()
        if not body or body == "%":
            continue
        if body.startswith("/"):
            raise _fail(ln, "block delete '/' is not supported")
        for bad in ("#", "[", "O"):
            if bad in body:
                what = {"#": "parameters ('#')", "[": "expressions ('[')",
                        "O": "O-word subroutines and control flow"}[bad]
                raise _fail(ln, f"{what} are not supported: '{body[:40]}'")
        rest = _WORD.sub("", body).replace(" ", "")
        if rest:
            raise _fail(ln, f"cannot read '{rest[:20]}' (not a word of a letter and a number)")
        found = [(m.group(1), float(m.group(2).replace(" ", ""))) for m in _WORD.finditer(body)]
        gs = [v for k, v in found if k == "G"]
        ms = [int(v) if v == int(v) else v for k, v in found if k == "M"]
        for k, v in found:
            if not abs(v) <= MAX_WORD_VALUE:
                raise _fail(ln, f"the word {k}{v:g} is out of range (|value| <= {MAX_WORD_VALUE:g})")
        vals: dict[str, float] = {}
        for k, v in found:
            if k in "GM":
                continue
            if k in vals:
                raise _fail(ln, f"the word {k} appears twice")
            vals[k] = v
        for g in gs:
            if g not in _ACCEPTED_G:
                why = _WHY.get(g) or ("a canned cycle" if 73 <= g <= 89 else "not supported")
                raise _fail(ln, f"the word G{g:g} is {why}")
        for k in vals:
            if k not in "XYZIJRFPSTN":
                why = "another axis: this robot moves in X and Y only" if k in "ABCUVW" else "not supported"
                raise _fail(ln, f"the word {k}{vals[k]:g} is {why}")
        for m in ms:
            if m not in _ACCEPTED_M:
                raise _fail(ln, f"the word M{m:g} is not supported")
        # modal settings in RS274NGC order: feed, spindle, tool, units, distance mode, path mode
        if 20.0 in gs or 21.0 in gs:
            units, unit_set = ("inch" if 20.0 in gs else "mm"), True
        u = _UNIT[units]
        if "F" in vals:
            if vals["F"] < 0:
                raise _fail(ln, f"F{vals['F']:g}: a feed must be positive")
            feed = vals["F"] * u / 60.0
        for k in ("S", "T"):
            if k in vals:
                words.append(ProgramWord(line=ln, word=f"{k}{vals[k]:g}"))
        for m in ms:
            if m not in (2, 30):
                words.append(ProgramWord(line=ln, word=f"M{m:g}"))
            if m in (0, 1):  # program pause / optional stop: the robot waits at rest
                add_dwell(ln, 0.0, "pause")
        for g in gs:
            if g in (40.0, 49.0, 80.0, 54.0, 94.0, 61.0, 64.0, 17.0):
                words.append(ProgramWord(line=ln, word=f"G{g:g}" + (f" P{vals['P']:g}" if g == 64.0 and "P" in vals
                                                                      else "")))
        if 90.0 in gs:
            absolute = True
        if 91.0 in gs:
            absolute = False
        if 61.0 in gs:
            exact = True
        if 64.0 in gs:
            exact = False
            if "P" in vals:
                if vals["P"] <= 0:
                    raise _fail(ln, f"G64 P{vals['P']:g}: the tolerance must be positive")
                tolerance = vals["P"] * u
        if 80.0 in gs:
            motion = None
        moving = [g for g in gs if g in (0.0, 1.0, 2.0, 3.0)]
        if len(moving) > 1:
            raise _fail(ln, f"two motion words on one line (G{moving[0]:g}, G{moving[1]:g})")
        if 4.0 in gs:
            if moving:
                raise _fail(ln, "G4 and a motion word on one line")
            if "P" not in vals or vals["P"] < 0:
                raise _fail(ln, "G4 needs P, the dwell in seconds (>= 0)")
            add_dwell(ln, vals["P"], "G4")
        elif "P" in vals and 64.0 not in gs:
            raise _fail(ln, f"the word P{vals['P']:g} without G4 or G64 is not supported")
        if moving:
            motion = moving[0]
        axes = {k: vals[k] for k in "XYZ" if k in vals}
        arcw = {k: vals[k] for k in "IJR" if k in vals}
        if (axes or arcw) and 4.0 not in gs:
            if motion is None:
                raise _fail(ln, f"axis words {' '.join(axes)} without a motion mode (G0, G1, G2, G3)")
            target = pos.copy()
            for i, k in enumerate("XYZ"):
                if k in axes:
                    target[i] = axes[k] * u if absolute else pos[i] + axes[k] * u
            if motion in (0.0, 1.0) and arcw:
                raise _fail(ln, f"{' '.join(arcw)} on a straight move G{motion:g}")
            if motion != 0.0 and feed <= 0:
                raise _fail(ln, f"G{motion:g} with no feed: give F first")
            if first_xy is None and (target[:2] != pos[:2]).any():
                first_xy = pos[:2].copy()
            _move(ln, motion, pos, target, arcw, u, feed, exact, cut_below, z_rapid_m_s, blocks, add_dwell)
            pos = target
        if 2 in ms or 30 in ms:
            ended = True
            break
        for k in ("S", "T", "N", "F"):
            vals.pop(k, None)
    if not unit_set:
        warnings.append("the program sets no units (G20/G21): read as millimetres (G21), LinuxCNC's default here")
    if not ended:
        warnings.append("the program has no M2/M30 end: read to its last line")
    if not any(b.kind == "cut" for b in blocks):
        raise PlannerError("invalid_input", f"the program has no cutting move (no feed move with Z below "
                           f"{cut_below * 1e3:g} mm): nothing to contour", "program")
    return Program(blocks=blocks, tolerance_m=tolerance, units=units, lines=n_lines, words=words, comments=comments,
                   warnings=warnings, start=first_xy if first_xy is not None else np.zeros(2))


def _move(ln: int, motion: float, pos: np.ndarray, target: np.ndarray, arcw: dict[str, float], u: float,
          feed: float, exact: bool, cut_below: float, z_rapid: float, blocks: list[ProgramBlock], add_dwell) -> None:
    """Append one move to ``blocks``: XY moves as lines/arcs (cut or travel), Z-only moves as dwells."""
    dz = target[2] - pos[2]
    xy_same = bool(np.all(np.abs(target[:2] - pos[:2]) < 1e-12))
    if motion in (0.0, 1.0) and xy_same:
        if dz != 0.0:
            speed = z_rapid if motion == 0.0 else feed
            add_dwell(ln, abs(dz) / speed, "plunge" if dz < 0 else "retract")
        return
    if motion in (2.0, 3.0):
        el = _arc(ln, motion, pos, target, arcw, u, feed, exact)
    else:
        d = target[:2] - pos[:2]
        el = PathElement(kind="line", line=ln, start=pos[:2].copy(), end=target[:2].copy(),
                         length_m=float(np.hypot(*d)), z_start_m=float(pos[2]), z_end_m=float(target[2]),
                         feed_m_s=feed if motion != 0.0 else 0.0, exact_stop=exact)
    cutting = motion != 0.0 and min(pos[2], target[2]) < cut_below
    if cutting:
        if blocks and blocks[-1].kind == "cut":
            blocks[-1].elements.append(el)
        else:
            blocks.append(ProgramBlock(kind="cut", line=ln, elements=[el]))
    else:
        blocks.append(ProgramBlock(kind="travel", line=ln, elements=[el], rapid=motion == 0.0))


def _arc(ln: int, motion: float, pos: np.ndarray, target: np.ndarray, arcw: dict[str, float], u: float,
         feed: float, exact: bool) -> PathElement:
    """G2 (clockwise) / G3 (counter-clockwise) in the XY plane, by I J or R."""
    p0, p1 = pos[:2], target[:2]
    ccw = motion == 3.0
    if "R" in arcw:
        if "I" in arcw or "J" in arcw:
            raise _fail(ln, "an arc with both R and I/J")
        r = abs(arcw["R"]) * u
        d = p1 - p0
        chord = float(np.hypot(*d))
        if chord < 1e-12:
            raise _fail(ln, f"G{motion:g} R: a full circle needs I and J (R gives no centre)")
        if chord > 2 * r * (1 + 1e-9) + 1e-9:
            raise _fail(ln, f"G{motion:g} R{arcw['R']:g}: the end point is {chord / u:g} away, farther than the "
                        "diameter")
        h = math.sqrt(max(r * r - chord * chord / 4, 0.0))
        mid = 0.5 * (p0 + p1)
        left = np.array([-d[1], d[0]]) / chord
        # the short arc (R > 0) turns the way of the motion with the centre on that side
        side = 1.0 if ccw else -1.0
        if arcw["R"] < 0:
            side = -side
        centre = mid + side * h * left
    else:
        if "I" not in arcw and "J" not in arcw:
            raise _fail(ln, f"G{motion:g} needs I and J (centre offsets) or R")
        centre = p0 + np.array([arcw.get("I", 0.0), arcw.get("J", 0.0)]) * u
    r0 = float(np.hypot(*(p0 - centre)))
    r1 = float(np.hypot(*(p1 - centre)))
    if r0 < 1e-9:
        raise _fail(ln, "an arc of zero radius")
    if abs(r1 - r0) > ARC_RADIUS_TOL_M:
        raise _fail(ln, f"the radius to the end of the arc ({r1 / u:.6g}) differs from the radius to its start "
                    f"({r0 / u:.6g})")
    a0 = math.atan2(p0[1] - centre[1], p0[0] - centre[0])
    a1 = math.atan2(p1[1] - centre[1], p1[0] - centre[0])
    sweep = a1 - a0
    if ccw:
        while sweep <= 1e-12:
            sweep += 2 * math.pi
    else:
        while sweep >= -1e-12:
            sweep -= 2 * math.pi
    z0, z1 = float(pos[2]), float(target[2])
    return PathElement(kind="arc", line=ln, start=p0.copy(), end=p1.copy(), centre=centre, radius_m=r0,
                       start_angle_rad=a0, sweep_rad=sweep, length_m=r0 * abs(sweep), z_start_m=z0, z_end_m=z1,
                       feed_m_s=feed, exact_stop=exact)
