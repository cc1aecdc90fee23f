"""Reading a CAM program: RS274NGC (LinuxCNC's dialect) -> a :class:`~planner.schema.Program`
of lines and arcs in m (the program's own frame), split into cut passes, travel and dwells.

Supported (what CAM posts for a 2.5D contour emit: FreeCAD's ``linuxcnc_post``, Fusion 360,
pcb-gcode, Estlcam, dxf2gcode): ``G0 G1 G2 G3`` (arcs by centre offsets, incremental as
LinuxCNC's default ``G91.1``, or by ``R``; full circles by offsets; a Z move in ``G17`` is a
helix, its XY path the arc), ``G17 G18 G19`` (an arc in the XZ or YZ plane, e.g. a vertical
lead-in, runs along a straight line in XY: it is read as the lines between the quarter points
of its circle where X, Y or Z turns, a stop where the XY direction reverses; a helix along the
other axis is refused), ``G4 P`` (seconds), ``G20 G21`` (converted to m here), ``G90 G91``,
``G61 G61.1`` (exact stop), ``G64`` (``P``: the path tolerance), ``F`` (units per minute,
``G94``), ``M3 M4 M5 M6 M7 M8 M9`` with ``S`` and ``T``, ``M0 M1`` (a stop at rest, warned),
``G43``/``G43 H`` (the tool table is unknown: the Z words after it are the program's),
``G43.1 Z``, ``G49`` (the current Z shifts by the change of offset, as LinuxCNC's), ``G54``
to ``G59.3`` (no offsets table: the identity, warned for any but ``G54``; ``origin`` places
the program), ``G28`` with Z alone (``G28 G91 Z0.``: the machine goes to its Z home, issued as
written by the export, warned),
``G40 G80`` cancels, ``O`` program numbers alone on a line, ``N``, ``( )`` and ``;``
comments, ``%``, ``M2``/``M30`` (what follows is ignored, as LinuxCNC does). The spindle,
tool and mode words are kept in ``Program.words``. Anything else (cutter compensation,
canned cycles, ``G92``/``G10``/``G53``, ``G28`` in X or Y, ``O`` subroutines, parameters
and expressions, other axes) is a :class:`~planner.errors.PlannerError` naming the line, the
word and what to change in the CAM post.

A feed move whose Z is below ``cut_below`` (somewhere along it) cuts; consecutive cutting
moves form a pass, and feed moves above it between two cutting moves (a tab) join it
(:mod:`planner.exchange._tabs`: a move whose Z changes is cut at most at the Z speed
``z_rapid``). Rapids and other feed moves above it are travel; Z-only moves are plunges and
retracts (dwells of ``|dZ| / F``, or ``/ z_rapid`` for G0).

The machine's Z is unknown before the program's first Z move and after a ``G28 Z`` until the
next Z move: the moves there are travel, read at the Z of that next move (or ``cut_below`` if
lower), and that move is kept in ``Program.words`` as the export issues it (``G0 Z..`` or
``G94 G1 Z.. F..`` in mm; its time is not counted); it may not be incremental, nor a ramp
into the cut.

Read back (``readback=True``): the planner's own export (:func:`planner.exchange.to_gcode`)
read as LinuxCNC runs it, for the editor's preview and the round-trip tests. Two words more
are accepted: ``G93`` inverse-time feed (``F`` on every feed move's line is 1 / the minutes
the move takes: its ``duration_s`` is 60 / F, as LinuxCNC times it) and the ``C`` axis (the
platform angle psi, degrees in the program, rad in ``c_start_rad`` / ``c_end_rad``; a move
of C alone is a line of length 0). A program without a cutting move is read (the export's
moves are at Z = 0: travel; a Z move not in inverse time and a ``G28 Z`` are moves it issues as
written, their time not counted). Everything else is refused as without it.
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
from ._tabs import cap_z_speed, join_tabs

__all__ = ["Toolpath", "read_gcode", "toolpath"]

_UNIT = {"mm": 1e-3, "inch": 0.0254}
#: largest magnitude of a word's number (a length of 1 km in mm, a feed, a spindle speed)
MAX_WORD_VALUE = 1e6
#: largest difference between an arc's start and end radius (as LinuxCNC: 0.002 mm) [m]
ARC_RADIUS_TOL_M = 2e-6
_WORD = re.compile(r"([A-Z])\s*([-+]?\s*(?:\d+\.?\d*|\.\d+))")
#: work offsets: with no offsets table each is the identity (``origin`` places the program)
_WORK_OFFSETS = {54.0, 55.0, 56.0, 57.0, 58.0, 59.0, 59.1, 59.2, 59.3}
#: mode words kept in the program's word list (for re-emitting them): planes, cancels, offsets, path modes
_MODE_G = {17.0, 18.0, 19.0, 40.0, 43.0, 43.1, 49.0, 80.0, 93.0, 94.0, 61.0, 61.1, 64.0, 91.1} | _WORK_OFFSETS
_ACCEPTED_G = {0.0, 1.0, 2.0, 3.0, 4.0, 20.0, 21.0, 28.0, 90.0, 91.0} | _MODE_G - {93.0}
_ACCEPTED_M = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 30}
#: the plane's axes (first, second) and its other axis, as LinuxCNC's ARC_FEED orders them
_PLANE_AXES = {17.0: (0, 1, 2), 18.0: (2, 0, 1), 19.0: (1, 2, 0)}
#: the centre offset words of the plane's first and second axis
_PLANE_OFFSETS = {17.0: ("I", "J"), 18.0: ("K", "I"), 19.0: ("J", "K")}
_NO_COMP = ("post the tool centre path with the compensation computed in the CAM (FreeCAD: the Profile "
            "operation's 'Use Compensation' on; Fusion 360: 'Compensation type: In computer')")
_PLACE = "remove it and place the program with `origin` (program X0 Y0 in the robot frame)"
_RETRACT = ("end the operation with a Z retract in work coordinates (Fusion 360: post property 'Safe retracts: "
            "Clearance height'; G28 with Z alone, e.g. 'G28 G91 Z0.', is read as a Z retract)")
#: refused G words: what they are, and what to change in the CAM post
_WHY_G: dict[float, tuple[str, str]] = {
    41.0: ("cutter radius compensation", _NO_COMP), 42.0: ("cutter radius compensation", _NO_COMP),
    41.1: ("dynamic cutter radius compensation", _NO_COMP), 42.1: ("dynamic cutter radius compensation", _NO_COMP),
    93.0: ("inverse-time feed (G93)", "post feeds in units per minute (G94)"),
    95.0: ("feed per revolution (G95)", "post feeds in units per minute (G94)"),
    90.1: ("absolute arc centres (G90.1)", "post arc centres incremental (G91.1, LinuxCNC's default)"),
    92.0: ("a coordinate offset (G92)", _PLACE), 92.1: ("resetting G92 offsets", _PLACE),
    92.2: ("suspending G92 offsets", _PLACE), 92.3: ("restoring G92 offsets", _PLACE),
    10.0: ("setting offsets or tool data (G10)", _PLACE),
    28.1: ("storing the home position (G28.1)", "remove it"),
    30.0: ("a return to the G30 position", _RETRACT), 30.1: ("storing the G30 position", "remove it"),
    53.0: ("a move in machine coordinates (G53)", _RETRACT),
    43.2: ("an additional tool length offset (G43.2)", "post a single tool length offset (G43 H)"),
    5.0: ("a spline (G5)", "post lines and arcs (spline output off, or arc fitting on)"),
    5.1: ("a quadratic spline (G5.1)", "post lines and arcs (spline output off, or arc fitting on)"),
    5.2: ("a NURBS block (G5.2)", "post lines and arcs (spline output off, or arc fitting on)"),
    33.0: ("spindle-synchronised motion (G33)", "remove threading operations"),
    33.1: ("rigid tapping (G33.1)", "remove tapping operations"),
    76.0: ("a threading cycle (G76)", "remove threading operations"),
    7.0: ("lathe diameter mode (G7)", "post with a mill post, not a lathe post"),
    8.0: ("lathe radius mode (G8)", "post with a mill post, not a lathe post"),
    96.0: ("constant surface speed (G96)", "post a spindle speed in rpm (G97)"),
    52.0: ("a local coordinate offset (G52)", _PLACE),
}
_CYCLE = ("a canned cycle", "expand it into G0/G1 moves in the CAM (a post without canned cycles), or post "
          "drilling as a separate program: a planar contour has no plunge cycles")
_SUBS = "post without subroutines, loops and macros (the CAM expanded, as plain moves)"


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
    plane = 17.0
    tool_offset = 0.0  # the tool length offset in force [m]: G43.1's; G43 H's is unknown here, read as 0
    work_offsets: list[str] = []
    ended = False
    # the machine's Z before the program's first Z move and after a G28 Z, until the next: unknown
    # (the moves there are travel at the Z of that next move; the export gives them no Z)
    z_unknown, unknown_from, unknown_why = not readback, 0, "the program's start"
    lines = text.splitlines()
    n_lines = 0

    def add_dwell(line: int, duration: float, reason: str, z: tuple[float, float] | None = None) -> None:
        """A dwell of ``duration`` [s], joined to the one before of the same reason; ``z``: Z at
        its start and end [m] (the position's Z, still, if not given)."""
        if duration <= 0 and reason != "pause":
            return
        z0, z1 = z if z is not None else (float(pos[2]), float(pos[2]))
        if blocks and blocks[-1].kind == "dwell" and blocks[-1].reason == reason:
            blocks[-1].duration_s += duration
            blocks[-1].z_moves.append((duration, z1, line))
        else:
            blocks.append(ProgramBlock(kind="dwell", line=line, duration_s=duration, reason=reason, z_start_m=z0,
                                       z_moves=[(duration, z1, line)]))

    for ln, raw in enumerate(lines, start=1):
        n_lines = ln
        body = _strip_comments(raw, ln, comments).strip().upper()
        if not body or body == "%":
            continue
        if body.startswith("/"):
            raise _fail(ln, "'/': block delete is not supported: post without optional blocks")
        program_number = re.fullmatch(r"O\s*(\d+)", "".join(body.split()))
        if program_number:  # a program number (Fusion 360: O1001): a name, no control flow
            words.append(ProgramWord(line=ln, word=f"O{int(program_number.group(1))}"))
            continue
        for bad in ("#", "[", "O"):
            if bad in body:
                what = {"#": "'#': parameters are", "[": "'[': expressions are",
                        "O": "O-word subroutines and control flow are"}[bad]
                raise _fail(ln, f"{what} not supported ('{body[:40]}'): {_SUBS}")
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
                what, remedy = _WHY_G.get(g) or (_CYCLE if 73 <= g <= 89 else
                                                 ("not a word for a planar contour", "post G0/G1/G2/G3 moves"))
                raise _fail(ln, f"G{g:g}: {what} is not supported: {remedy}")
        for k in vals:
            if k not in "XYZIJKRFPSTNH" and not (readback and k == "C"):
                why = ("another axis: this robot moves in X and Y only: post for a 3-axis mill (XYZ)"
                       if k in "ABCUVW" else
                       "a tool diameter offset, used only by cutter compensation: post without G41/G42 (remove D)"
                       if k == "D" else "a canned cycle's word: expand canned cycles into G0/G1 moves in the CAM"
                       if k in "QL" else "not supported: post without it")
                raise _fail(ln, f"the word {k}{vals[k]:g} is {why}")
        for m in ms:
            if m not in _ACCEPTED_M:
                why = (f"a subroutine call or return: {_SUBS}" if m in (98, 99) else
                       "a user M-code: post without it" if isinstance(m, int) and 100 <= m <= 199 else
                       "not supported: post spindle (M3 M4 M5), coolant (M7 M8 M9), tool change (M6), stops (M0 M1) "
                       "and ends (M2 M30) only")
                raise _fail(ln, f"M{m:g}: {why}")
        if "H" in vals and 43.0 not in gs:
            raise _fail(ln, f"the word H{vals['H']:g} without G43 is not supported: post H with G43 only")
        # modal settings in RS274NGC order: feed, spindle, tool, units, plane, distance mode, path mode
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
                warnings.append(f"line {ln}: M{m:g} ({'program pause' if m == 0 else 'optional stop'}) is planned "
                                "as a stop at rest of 0 s: the operator's wait is not in the cycle time")
        planes = [g for g in gs if g in _PLANE_AXES]
        if len(planes) > 1:
            raise _fail(ln, f"two plane words on one line (G{planes[0]:g}, G{planes[1]:g})")
        if planes:
            plane = planes[0]
        offset_words = {k: vals.pop(k) for k in "XYZ" if 43.1 in gs and k in vals}  # G43.1: offsets, not a move
        for g in gs:
            if g in _MODE_G:
                extra = {43.0: "H", 64.0: "P"}.get(g)
                word = f"G{g:g}" + (f" {extra}{vals[extra]:g}" if extra and extra in vals else "")
                word += "".join(f" {k}{v:g}" for k, v in offset_words.items()) if g == 43.1 else ""
                words.append(ProgramWord(line=ln, word=word))
            if g in (43.0, 43.1, 49.0):  # as LinuxCNC: the position in program Z moves by the change of offset
                new_offset = offset_words.get("Z", 0.0) * u if g == 43.1 else 0.0
                pos = pos - np.array([0.0, 0.0, new_offset - tool_offset])
                tool_offset = new_offset
            if g in _WORK_OFFSETS and f"G{g:g}" not in work_offsets:
                work_offsets.append(f"G{g:g}")
        if 90.0 in gs:
            absolute = True
        if 91.0 in gs:
            absolute = False
        if 61.0 in gs or 61.1 in gs:
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
        if 28.0 in gs and readback:  # the export's G28 Z as written: the machine's, its time not counted
            _home_words(ln, gs, vals, u, absolute)
            continue
        if 28.0 in gs:  # the machine goes to its Z home, unknown here: issued as written
            words.extend(ProgramWord(line=ln, word=w) for w in _home_words(ln, gs, vals, u, absolute))
            warnings.append(f"line {ln}: G28 Z (return to Z home) is issued as written; Z home is unknown here: its "
                            "time is not counted, and the output gives no Z until the program's next Z move")
            if not z_unknown:
                z_unknown, unknown_from, unknown_why = True, len(blocks), f"the G28 at line {ln}"
            continue
        if moving:
            motion = moving[0]
        axes = {k: vals[k] for k in axis_letters if k in vals}
        arcw = {k: vals[k] for k in "IJKR" if k in vals}
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
            if z_unknown and "Z" in axes:  # the first Z move from the machine's (unknown) height
                approach = _approach_words(ln, motion, absolute, target[2], feed, u, cut_below, unknown_why,
                                           bool((target[:2] != pos[:2]).any()) or bool(arcw))
                words.extend(ProgramWord(line=ln, word=w) for w in approach)
                _at_height(blocks[unknown_from:], float(target[2]), cut_below)
                pos[2] = target[2]
                z_unknown = False
            if first_xy is None and (target[:2] != pos[:2]).any():
                first_xy = pos[:2].copy()
            _move(ln, motion, pos, target, arcw, u, feed, exact, -math.inf if z_unknown else cut_below, z_rapid_m_s,
                  blocks, add_dwell, (c_pos, c_target) if readback else None, duration, plane)
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
    if work_offsets != ["G54"] and work_offsets:
        warnings.append(f"work offsets {', '.join(work_offsets)}: with no offsets table each is read as the identity "
                        "(program X0 Y0 is at `origin`)" + (": the program's parts in different work offsets "
                                                           "overlap here" if len(work_offsets) > 1 else ""))
    if not readback and not any(b.kind == "cut" for b in blocks):
        raise PlannerError("invalid_input", f"the program has no cutting move (no feed move with Z below "
                           f"{cut_below * 1e3:g} mm): nothing to contour", "program")
    if not readback:  # tabs inside a pass, Z within its axis speed (planner.exchange._tabs)
        blocks = join_tabs(blocks)
        cap_z_speed(blocks, z_rapid_m_s)
    return Program(blocks=blocks, tolerance_m=tolerance, units=units, lines=n_lines, words=words, comments=comments,
                   warnings=warnings, start=first_xy if first_xy is not None else np.zeros(2))


def _home_words(ln: int, gs: list[float], vals: dict[str, float], u: float, absolute: bool) -> list[str]:
    """``G28`` with Z alone as the export issues it (mm): ``G28 Z..`` or, in incremental mode,
    ``G91 G28 Z..`` (the export goes back to ``G90`` after it)."""
    if any(g in (0.0, 1.0, 2.0, 3.0) for g in gs):
        raise _fail(ln, "G28 and a motion word on one line")
    if "X" in vals or "Y" in vals or "Z" not in vals:
        which = " ".join(k for k in "XY" if k in vals) or "all axes"
        raise _fail(ln, f"G28: a return to the home position in {which} is not supported (only 'G28 Z...', a Z "
                    f"retract): {_RETRACT}")
    z_mm = f"Z{vals['Z'] * u * 1e3:.4f}"
    return [f"G28 {z_mm}" if absolute else f"G91 G28 {z_mm}"]


def _approach_words(ln: int, motion: float, absolute: bool, z: float, feed: float, u: float, cut_below: float,
                    why: str, xy_moves: bool) -> list[str]:
    """The first Z move after ``why`` (the machine's Z unknown) as the export issues it: a
    rapid ``G0 Z..`` or a feed move at its F in units per minute (``G94 G1 Z.. F..``: the export
    goes back to ``G93`` after it), mm; the XY part of the move, if any, then follows at that Z.
    Refused where its start matters: incremental, or a ramp into the cut."""
    if not absolute:
        raise _fail(ln, f"an incremental Z move (G91) after {why}: the machine's Z there is unknown: make the first Z "
                    "move after it absolute (G90), e.g. a rapid to the clearance height")
    if z < cut_below and xy_moves:
        raise _fail(ln, f"the first Z move after {why} goes into the cut (Z{z / u:g}) while moving in XY, from the "
                    "machine's height, unknown here: move to a clearance height first (G0 Z...)")
    if motion == 0.0:
        return [f"G0 Z{z * 1e3:.4f}"]
    return [f"G94 G1 Z{z * 1e3:.4f} F{feed * 60e3:.4f}"]


def _at_height(blocks: list[ProgramBlock], z: float, cut_below: float) -> None:
    """The travel and dwells read while the machine's Z was unknown: at ``z`` (the Z of the move
    that ends it) or at ``cut_below`` if that is lower, in place."""
    zt = max(z, cut_below)
    for b in blocks:
        for e in b.elements:
            e.z_start_m = e.z_end_m = zt
        if b.kind == "dwell":
            b.z_start_m = zt
            b.z_moves = [(t, zt, line) for t, _, line in b.z_moves]


def _move(ln: int, motion: float, pos: np.ndarray, target: np.ndarray, arcw: dict[str, float], u: float,
          feed: float, exact: bool, cut_below: float, z_rapid: float, blocks: list[ProgramBlock], add_dwell,
          c: tuple[float, float] | None = None, duration: float | None = None, plane: float = 17.0) -> None:
    """Append one move to ``blocks``: XY moves as lines/arcs (cut or travel), Z-only moves as
    dwells, an arc in the XZ (G18) or YZ (G19) plane as the lines its XY path runs along.
    ``c``: the C axis at the start and end [rad] (readback; a C-only move is a line of
    length 0); ``duration`` [s]: the move's inverse-time (G93) duration."""
    dz = target[2] - pos[2]
    xy_same = bool(np.all(np.abs(target[:2] - pos[:2]) < 1e-12))
    c_moves = c is not None and c[1] != c[0]
    if motion in (0.0, 1.0) and xy_same and not c_moves:
        if c is not None and duration is None:  # read back: a Z move the export issues as written
            return
        if dz != 0.0:
            speed = z_rapid if motion == 0.0 else feed
            add_dwell(ln, duration if duration is not None else abs(dz) / speed, "plunge" if dz < 0 else "retract",
                      (float(pos[2]), float(target[2])))
        return
    if motion in (2.0, 3.0) and plane != 17.0:
        pts, stops = _vertical_arc(ln, motion, pos, target, arcw, u, plane)
        for k in range(len(pts) - 1):
            p0, p1 = pts[k], pts[k + 1]
            length = float(np.hypot(*(p1[:2] - p0[:2])))
            if length < 1e-12:  # a piece that moves Z alone (the arc is tangent to Z there)
                add_dwell(ln, abs(p1[2] - p0[2]) / feed, "plunge" if p1[2] < p0[2] else "retract",
                          (float(p0[2]), float(p1[2])))
                continue
            el = PathElement(kind="line", line=ln, start=p0[:2].copy(), end=p1[:2].copy(), length_m=length,
                             z_start_m=float(p0[2]), z_end_m=float(p1[2]), feed_m_s=feed, exact_stop=exact or stops[k])
            _append(blocks, el, ln, motion, min(p0[2], p1[2]) < cut_below)
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
    _append(blocks, el, ln, motion, motion != 0.0 and min(pos[2], target[2]) < cut_below)


def _append(blocks: list[ProgramBlock], el: PathElement, ln: int, motion: float, cutting: bool) -> None:
    """Append ``el`` to the current pass when it cuts and one is open, else as a block of its own."""
    if cutting:
        if blocks and blocks[-1].kind == "cut":
            blocks[-1].elements.append(el)
        else:
            blocks.append(ProgramBlock(kind="cut", line=ln, elements=[el]))
    else:
        blocks.append(ProgramBlock(kind="travel", line=ln, elements=[el], rapid=motion == 0.0))


def _centre(ln: int, motion: float, p0: np.ndarray, p1: np.ndarray, arcw: dict[str, float], u: float,
            offsets: tuple[str, str]) -> tuple[np.ndarray, float, float, float]:
    """An arc's centre, radius, start angle and sweep in its plane's (first, second) axes, from
    the offset words ``offsets`` or R; G3 turns counter-clockwise in those axes."""
    ccw = motion == 3.0
    if "R" in arcw:
        if set(arcw) & {"I", "J", "K"}:
            raise _fail(ln, "an arc with both R and I/J/K")
        r = abs(arcw["R"]) * u
        d = p1 - p0
        chord = float(np.hypot(*d))
        if chord < 1e-12:
            raise _fail(ln, f"G{motion:g} R: a full circle needs {' and '.join(offsets)} (R gives no centre)")
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
        wrong = sorted(set(arcw) - set(offsets))
        if wrong:
            raise _fail(ln, f"G{motion:g}: the word {wrong[0]} is not a centre offset in this plane (its offsets are "
                        f"{' and '.join(offsets)}; G17 XY: I J, G18 XZ: I K, G19 YZ: J K)")
        if not set(arcw) & set(offsets):
            raise _fail(ln, f"G{motion:g} needs {' and '.join(offsets)} (centre offsets) or R")
        centre = p0 + np.array([arcw.get(offsets[0], 0.0), arcw.get(offsets[1], 0.0)]) * u
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
    return centre, r0, a0, sweep


def _vertical_arc(ln: int, motion: float, pos: np.ndarray, target: np.ndarray, arcw: dict[str, float], u: float,
                  plane: float) -> tuple[list[np.ndarray], list[bool]]:
    """An arc in the XZ (G18) or YZ (G19) plane: its XY path runs along a straight line (X for
    G18, Y for G19), so it is cut at the quarter points of its circle, where X (Y) or Z turns:
    the XYZ points in order, and for each piece whether its XY direction reverses at its end
    (the tool stops there). A helix along Y (G18) or X (G19) is refused."""
    i, j, k = _PLANE_AXES[plane]
    if abs(target[k] - pos[k]) > 1e-12:
        raise _fail(ln, f"G{motion:g} in G{plane:g} with a {'XYZ'[k]} move: a helix across the XY plane is not "
                    "supported: post lead-in and lead-out arcs in the XY plane (G17) or as straight moves")
    centre, r, a0, sweep = _centre(ln, motion, pos[[i, j]], target[[i, j]], arcw, u, _PLANE_OFFSETS[plane])
    direction = 1.0 if sweep > 0 else -1.0
    quarters = []
    q = math.floor(a0 / (math.pi / 2)) if direction > 0 else math.ceil(a0 / (math.pi / 2))
    while True:  # the quarter angles strictly inside the sweep, in order
        q += direction
        t = (q * math.pi / 2 - a0) * direction
        if t >= abs(sweep) - 1e-12:
            break
        if t > 1e-12:
            quarters.append(q)
    pts, stops = [pos.copy()], []
    for q in quarters:
        p = pos.copy()
        angle = q * math.pi / 2
        p[i], p[j] = centre[0] + r * math.cos(angle), centre[1] + r * math.sin(angle)
        # exact quarter points: the turning axis's coordinate is centre +- r, the other the centre's
        if q % 2 == 0:
            p[j] = centre[1]
        else:
            p[i] = centre[0]
        pts.append(p)
        # the XY axis is the plane's second (G18: X) or first (G19: Y) one; it turns where its sine/cosine is +-1
        stops.append(bool(q % 2 == (1 if plane == 18.0 else 0)))
    pts.append(target.copy())
    stops.append(False)
    return pts, stops


def _arc(ln: int, motion: float, pos: np.ndarray, target: np.ndarray, arcw: dict[str, float], u: float,
         feed: float, exact: bool) -> PathElement:
    """G2 (clockwise) / G3 (counter-clockwise) in the XY plane (G17), by I J or R; a Z move
    makes it a helix (its XY path the arc)."""
    p0, p1 = pos[:2], target[:2]
    centre, r0, a0, sweep = _centre(ln, motion, p0, p1, arcw, u, ("I", "J"))
    z0, z1 = float(pos[2]), float(target[2])
    return PathElement(kind="arc", line=ln, start=p0.copy(), end=p1.copy(), centre=centre, radius_m=r0,
                       start_angle_rad=a0, sweep_rad=sweep, length_m=r0 * abs(sweep), z_start_m=z0, z_end_m=z1,
                       feed_m_s=feed, exact_stop=exact)
