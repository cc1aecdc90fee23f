"""A plan as RS274NGC G-code for LinuxCNC: one ``G1`` per sample in inverse-time feed.

The program (tested with LinuxCNC's own interpreter, ``rs274``)::

    (rangeplan plan: NAME)            comment header: plan, robot, units, sample time, source
    G21 G90 G17                       mm, absolute, XY plane
    G0 X.. Y.. C..                    rapid to the first pose (the plan starts at rest there)
    G93                               inverse-time feed: F = 1 / (minutes the move takes)
    G1 X.. Y.. C.. F6000.000000       sample k -> k+1: takes exactly Ts (F = 60 / Ts)
    G4 P0.010000                      a sample where the printed pose does not change: dwell Ts
    ...
    G94                               back to units per minute
    M2

X and Y are the tool point in mm, C the platform angle psi in degrees (a rotary axis);
coordinates are printed with ``DECIMALS`` decimals (0.1 um, 0.0001 degree). A move whose
printed coordinates equal the previous ones becomes a dwell of one sample time, since
LinuxCNC does not time zero-length moves.

A contour plan (its ``contour`` section with ``z_m``, issue 32) is the part program: each
``G1`` also carries Z in mm (the source program's frame), Z alone moving for a plunge or
retract; the source's spindle, tool, coolant, stop, tool length and work offset words are
issued before the first sample that reaches their source line (:func:`._schedule.word_schedule`),
and a source ``G4`` is one ``G4`` of the samples it takes. The machine's Z is unknown before the
source's first Z move and after a ``G28 Z`` until the next Z move: those samples carry no Z
word, and that next move is issued as written (``G0 Z..``, or ``G94 G1 Z.. F..`` then ``G93``)
as is the ``G28`` (``G91 G28 Z..`` then ``G90``). Any other plan's program is as above.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

import numpy as np

from ..schema import PlanResult
from ._schedule import STATEMENT, word_schedule

__all__ = ["DECIMALS", "to_gcode"]

DECIMALS = 4  #: decimals of X, Y [mm] and C [degree]


def _comment(text: str) -> str:
    """``text`` as one RS274NGC comment: no parentheses or line breaks inside."""
    return "(" + re.sub(r"[()\r\n]+", " ", text).strip() + ")"


def to_gcode(result: PlanResult, source: str | None = None, header: Sequence[str] = ()) -> str:
    """The plan's poses as a LinuxCNC program (see the module doc); ``source`` names where
    the plan came from (a file, a corridor id) in the header, ``header`` adds comment lines
    after it (the editor's design, plan id and request hash)."""
    ts = float(result.settings.Ts)
    if not math.isfinite(ts) or ts <= 0:  # a validated result never has this; a guard for hand-made ones
        raise ValueError("the result's sample time must be a positive number")
    pose = np.asarray(result.pose, float)
    xy = np.round(pose[:, :2] * 1e3, DECIMALS) + 0.0  # + 0.0: no "-0.0000"
    c = np.round(np.degrees(pose[:, 2]), DECIMALS) + 0.0
    fmt = f"{{:.{DECIMALS}f}}"
    rows = [" ".join(f"{a}{fmt.format(v)}" for a, v in zip("XYC", (x, y, cc)))
            for (x, y), cc in zip(xy.tolist(), c.tolist())]
    feed = f"F{60.0 / ts:.6f}"
    lines = [
        _comment(f"rangeplan plan: {result.name or 'unnamed'}" + (f", id {result.plan_id}" if result.plan_id else "")),
        _comment(f"robot: {result.robot}, mode {result.mode}, {len(pose)} samples, "
                 f"duration {(len(pose) - 1) * ts:g} s"),
        _comment("units: X Y tool point in mm, C platform angle psi in degrees; G93 inverse time: each G1 takes "
                 "one sample time"),
        _comment(f"sample time Ts = {ts:g} s, F = 60 / Ts = {60.0 / ts:g} per minute"),
        _comment(f"source: {source or 'rangeplan'}"),
        *(_comment(h) for h in header),
        "G21 G90 G17",
        f"G0 {rows[0]}",
        "G93",
    ]
    if result.contour is not None and result.contour.z_m is not None and result.contour.source_line is not None:
        return "\n".join(lines[:2] + _contour_body(result, rows, xy, c, ts, header, source)) + "\n"
    dwell = f"G4 P{ts:.6f}"
    for k in range(1, len(rows)):
        lines.append(dwell if rows[k] == rows[k - 1] else f"G1 {rows[k]} {feed}")
    lines += ["G94", "M2"]
    return "\n".join(lines) + "\n"


def _contour_body(result: PlanResult, xyc_rows: list[str], xy: np.ndarray, c: np.ndarray, ts: float,
                  header: Sequence[str], source: str | None) -> list[str]:
    """A contour plan's program after its first two comment lines: the tool point with Z at
    each sample, the source's words at the samples that reach their lines (:func:`word_schedule`),
    each of its G4 dwells as one G4 of the samples it takes."""
    contour = result.contour
    assert contour is not None and contour.z_m is not None
    z = np.round(np.asarray(contour.z_m, float) * 1e3, DECIMALS) + 0.0
    fmt = f"{{:.{DECIMALS}f}}"
    rows = [" ".join(f"{a}{fmt.format(v)}" for a, v in zip("XYZC", (x, y, zz, cc)))
            for (x, y), zz, cc in zip(xy.tolist(), z.tolist(), c.tolist())]
    feed = f"F{60.0 / ts:.6f}"
    dwell = contour.dwell or [None] * len(rows)
    line_of = contour.source_line or [0] * len(rows)
    due: dict[int, list[str]] = {}
    # no Z word while the machine's Z is unknown: before the program's first Z move and after a
    # G28 Z until the next (those moves are issued as written: word_schedule)
    known = np.zeros(len(rows) + 1, bool)
    for k, _, words in word_schedule(result):
        due.setdefault(k, []).append(words)
        if words.startswith("G94 ") and k > 0:  # a feed move from the machine's height, in units per minute
            due[k].append("G93")
        elif words.startswith("G91 "):
            due[k].append("G90")
        if STATEMENT.match(words):
            known[k:] = not words.startswith(("G28", "G91 G28"))
    rows = [r if known[k] else xyc for k, (r, xyc) in enumerate(zip(rows, xyc_rows))]
    out = [
        _comment("units: X Y tool point in mm (robot frame), C platform angle psi in degrees, Z in mm (the "
                 "source program's frame: its tool length and work offsets as it sets them)"),
        _comment(f"G93 inverse time: each G1 takes one sample time Ts = {ts:g} s (F = 60 / Ts = {60.0 / ts:g}); a "
                 "Z move alone (plunge, retract) is at most its programmed feed or the Z rapid speed"),
        _comment("a source G4 is one G4 of the planned samples it takes; spindle, tool, coolant, stop and offset "
                 "words are where the source issues them"),
        _comment("Z is the machine's (no Z word) before the source's first Z move and after a G28 Z until the "
                 "next; that move is issued as written, its time not counted"),
        _comment(f"source: {source or 'rangeplan'}"),
        *(_comment(h) for h in header),
        "G21 G90 G17",
        *due.pop(0, []),
        f"G0 {rows[0]}",
        "G93",
    ]
    k = 1
    while k < len(rows):
        out += due.pop(k, [])
        if rows[k] == rows[k - 1] and dwell[k] == "G4":
            m = k + 1  # the samples of this source G4: one dwell
            while m < len(rows) and rows[m] == rows[k] and dwell[m] == "G4" and line_of[m] == line_of[k] \
                    and m not in due:
                m += 1
            out.append(f"G4 P{(m - k) * ts:.6f}")
            k = m
            continue
        out.append(f"G4 P{ts:.6f}" if rows[k] == rows[k - 1] else f"G1 {rows[k]} {feed}")
        k += 1
    for k in sorted(due):
        out += due[k]
    return out + ["G94", "M2"]
