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

Read back (``readback=True``): the planner's own export (:func:`planner.exchange.to_gcode`)
read as LinuxCNC runs it, for the editor's preview and the round-trip tests. Two words more
are accepted: ``G93`` inverse-time feed (``F`` on every feed move's line is 1 / the minutes
the move takes: its ``duration_s`` is 60 / F, as LinuxCNC times it) and the ``C`` axis (the
platform angle psi, degrees in the program, rad in ``c_start_rad`` / ``c_end_rad``; a move
of C alone is a line of length 0). A program without a cutting move is read (the export's
moves are at Z = 0: travel). Everything else is refused as without it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

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

__all__ = ["Toolpath", "read_gcode", "toolpath"]

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


@dataclass(frozen=True)
class Toolpath:
    """A program's tool path as one polyline, as LinuxCNC's AXIS previews it: ``points`` (n, 2)
    [m] in order (arcs sampled), ``psi`` (n,) the C axis [rad] (0 for a program read without
    ``readback``), ``time`` (n,) [s] when the tool is at each point (feed moves take their G93
    duration, else length / F; dwells hold a point; rapids take no time here, they run at the
    machine's own speed) and ``rapid`` (n - 1,): whether the piece from point k to k + 1 is a
    rapid (G0)."""

    points: np.ndarray
    psi: np.ndarray
    time: np.ndarray
    rapid: np.ndarray

    @property
    def duration_s(self) -> float:
        """The program's time without its rapids [s]: feed moves and dwells."""
        return float(self.time[-1])


def toolpath(program: Program, arc_step_m: float = 5e-4) -> Toolpath:
    """The path of ``program`` (:func:`read_gcode`) as a :class:`Toolpath`; arcs sampled at
    most ``arc_step_m`` [m] apart."""
    start = program.blocks[0].elements[0] if program.blocks and program.blocks[0].elements else None
    pts = [np.asarray(start.start if start is not None else program.start, float)]
    psi = [(start.c_start_rad or 0.0) if start is not None else 0.0]
    times, rapid, t = [0.0], [], 0.0
    for b in program.blocks:
        if b.kind == "dwell":
            if b.duration_s > 0:
                t += b.duration_s
                pts.append(pts[-1])
                psi.append(psi[-1])
                times.append(t)
                rapid.append(False)
            continue
        is_rapid = b.kind == "travel" and b.rapid
        for e in b.elements:
            n = max(1, math.ceil(e.length_m / arc_step_m)) if e.kind == "arc" else 1
            f = np.arange(1, n + 1) / n
            seconds = e.duration_s if e.duration_s is not None else (
                0.0 if is_rapid or e.feed_m_s <= 0 else e.length_m / e.feed_m_s)
            pts.extend(e.point_at(f * e.length_m) if e.kind == "arc" else [np.asarray(e.end, float)])
            c0 = e.c_start_rad or 0.0
            psi.extend((c0 + f * ((e.c_end_rad or 0.0) - c0)).tolist())
            times.extend((t + f * seconds).tolist())
            rapid.extend([is_rapid] * n)
            t += seconds
    return Toolpath(points=np.array(pts, float).reshape(-1, 2), psi=np.array(psi, float), time=np.array(times, float),
                    rapid=np.array(rapid, bool))


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


def read_gcode(text: str, *, cut_below: float = 0.0, z_rapid_m_s: float = 0.05, readback: bool = False) -> Program:
    """Read ``text`` (a G-code program) into a :class:`~planner.schema.Program` in m, s and
    rad (module docstring). ``cut_below`` [m]: feed moves with Z below it cut. ``readback``:
    read the planner's own export back (G93 inverse time and the C axis accepted, no cut
    needed; module docstring). Raises :class:`~planner.errors.PlannerError` (field
    ``program``) naming the line and the word for anything it does not support."""
    if len(text.encode()) > MAX_PROGRAM_BYTES:
        raise PlannerError("too_large", f"the program has {len(text.encode())} bytes, more than the limit of "
                           f"{MAX_PROGRAM_BYTES}", "program")
    units = "mm"
    unit_set = False
    absolute = True
    motion: float | None = None
    feed = 0.0  # m/s
    inverse = False  # G93: F is 1 / minutes per move, given on each feed move's line
    c_pos = 0.0  # the C axis [rad] (readback)
    accepted_g = _ACCEPTED_G | {93.0} if readback else _ACCEPTED_G
    axis_letters = "XYZC" if readback else "XYZ"
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
        rest = "".join(_WORD.sub("", body).split())  # spaces and tabs mean nothing outside comments
        if rest:
            raise _fail(ln, f"cannot read '{rest[:20]}' (not a word of a letter and a number)")
        found = [(m.group(1), float("".join(m.group(2).split()))) for m in _WORD.finditer(body)]
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
            if g not in accepted_g:
                why = _WHY.get(g) or ("a canned cycle" if 73 <= g <= 89 else "not supported")
                raise _fail(ln, f"the word G{g:g} is {why}")
        for k in vals:
            if k not in "XYZIJRFPSTN" and not (readback and k == "C"):
                why = "another axis: this robot moves in X and Y only" if k in "ABCUVW" else "not supported"
                raise _fail(ln, f"the word {k}{vals[k]:g} is {why}")
        for m in ms:
            if m not in _ACCEPTED_M:
                raise _fail(ln, f"the word M{m:g} is not supported")
        # modal settings in RS274NGC order: feed, spindle, tool, units, distance mode, path mode
        if 20.0 in gs or 21.0 in gs:
            units, unit_set = ("inch" if 20.0 in gs else "mm"), True
        u = _UNIT[units]
        if 93.0 in gs and 94.0 in gs:
            raise _fail(ln, "G93 and G94 on one line")
        if 93.0 in gs:
            inverse = True
        elif 94.0 in gs and inverse:  # back to units per minute: LinuxCNC needs a new F
            inverse, feed = False, 0.0
        if "F" in vals:
            if vals["F"] < 0:
                raise _fail(ln, f"F{vals['F']:g}: a feed must be positive")
            if not inverse:
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
            if g in (40.0, 49.0, 80.0, 54.0, 93.0, 94.0, 61.0, 64.0, 17.0):
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
        axes = {k: vals[k] for k in axis_letters if k in vals}
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
            duration: float | None = None
            if motion != 0.0 and inverse:
                if vals.get("F", 0.0) <= 0:
                    raise _fail(ln, f"G{motion:g} in inverse-time feed (G93) needs a positive F on its line "
                                "(1 / the minutes the move takes)")
                duration = 60.0 / vals["F"]
            elif motion != 0.0 and feed <= 0:
                raise _fail(ln, f"G{motion:g} with no feed: give F first")
            c_target = c_pos
            if "C" in axes:
                c_target = math.radians(axes["C"]) + (0.0 if absolute else c_pos)
            if first_xy is None and (target[:2] != pos[:2]).any():
                first_xy = pos[:2].copy()
            _move(ln, motion, pos, target, arcw, u, feed, exact, cut_below, z_rapid_m_s, blocks, add_dwell,
                  (c_pos, c_target) if readback else None, duration)
            pos, c_pos = target, c_target
        if 2 in ms or 30 in ms:
            ended = True
            break
        for k in ("S", "T", "N", "F"):
            vals.pop(k, None)
    if not unit_set:
        warnings.append("the program sets no units (G20/G21): read as millimetres (G21), LinuxCNC's default here")
    if not ended:
        warnings.append("the program has no M2/M30 end: read to its last line")
    if not readback and not any(b.kind == "cut" for b in blocks):
        raise PlannerError("invalid_input", f"the program has no cutting move (no feed move with Z below "
                           f"{cut_below * 1e3:g} mm): nothing to contour", "program")
    return Program(blocks=blocks, tolerance_m=tolerance, units=units, lines=n_lines, words=words, comments=comments,
                   warnings=warnings, start=first_xy if first_xy is not None else np.zeros(2))


def _move(ln: int, motion: float, pos: np.ndarray, target: np.ndarray, arcw: dict[str, float], u: float,
          feed: float, exact: bool, cut_below: float, z_rapid: float, blocks: list[ProgramBlock], add_dwell,
          c: tuple[float, float] | None = None, duration: float | None = None) -> None:
    """Append one move to ``blocks``: XY moves as lines/arcs (cut or travel), Z-only moves as
    dwells. ``c``: the C axis at the start and end [rad] (readback; a C-only move is a line of
    length 0); ``duration`` [s]: the move's inverse-time (G93) duration."""
    dz = target[2] - pos[2]
    xy_same = bool(np.all(np.abs(target[:2] - pos[:2]) < 1e-12))
    c_moves = c is not None and c[1] != c[0]
    if motion in (0.0, 1.0) and xy_same and not c_moves:
        if dz != 0.0:
            speed = z_rapid if motion == 0.0 else feed
            add_dwell(ln, duration if duration is not None else abs(dz) / speed, "plunge" if dz < 0 else "retract")
        return
    if motion in (2.0, 3.0):
        el = _arc(ln, motion, pos, target, arcw, u, feed, exact)
    else:
        d = target[:2] - pos[:2]
        el = PathElement(kind="line", line=ln, start=pos[:2].copy(), end=target[:2].copy(),
                         length_m=float(np.hypot(*d)), z_start_m=float(pos[2]), z_end_m=float(target[2]),
                         feed_m_s=feed if motion != 0.0 else 0.0, exact_stop=exact)
    if c is not None:
        el.c_start_rad, el.c_end_rad = float(c[0]), float(c[1])
    if duration is not None:
        el.duration_s = duration
        el.feed_m_s = el.length_m / duration  # the feed the move's time gives
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
