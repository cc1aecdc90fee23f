"""A plan as a leg-space stream: one line per sample with the leg lengths (and optionally
the drive forces), whitespace-separated, for LinuxCNC's ``halstreamer`` and the realtime
``streamer`` component (``loadrt streamer cfg=ffff``: one float pin per column).

Lines starting with ``#`` are comments (``halstreamer`` skips them); the header states
the plan, the sample time (the streaming thread's period must equal it) and each column
with its unit. Leg lengths are in mm (base pivot to platform pivot, as
:func:`planner.model.kinematics.leg_lengths` computes them, the result's
``drives.length``), forces in N. A contour plan's header also names the source program's
spindle, tool, coolant, stop and offset words with the sample they are due at.
"""

from __future__ import annotations

import io
from collections.abc import Sequence

import numpy as np

from ..schema import PlanResult
from ._schedule import word_schedule

__all__ = ["joint_columns", "to_joints"]


def joint_columns(n_legs: int, forces: bool = False) -> list[str]:
    """The column names, each with its unit."""
    cols = [f"leg{i + 1}_length_mm" for i in range(n_legs)]
    return cols + [f"leg{i + 1}_force_n" for i in range(n_legs)] if forces else cols


def to_joints(result: PlanResult, forces: bool = False, source: str | None = None, header: Sequence[str] = ()) -> str:
    """The stream (see the module doc); ``forces`` adds one drive-force column per leg,
    ``header`` comment lines after the first (the editor's design, plan id, request hash)."""
    length = np.asarray(result.drives.length, float) * 1e3
    table = np.column_stack((length, np.asarray(result.drives.force, float))) if forces else length
    table = np.round(table, 6) + 0.0  # + 0.0: "0.000000", never "-0.000000" for a tiny negative
    n_legs = length.shape[1]
    ts = float(result.settings.Ts)
    cols = joint_columns(n_legs, forces)
    buf = io.StringIO()
    buf.write(f"# rangeplan leg-space stream: plan {result.name or 'unnamed'}"
              + (f", id {result.plan_id}" if result.plan_id else "") + f", source {source or 'rangeplan'}\n")
    for line in header:
        buf.write("# " + " ".join(str(line).splitlines()) + "\n")
    buf.write(f"# robot {result.robot}: {n_legs} legs, {len(length)} samples, one line per sample time "
              f"Ts = {ts:g} s (the streaming thread's period)\n")
    buf.write(f"# units: leg lengths in mm{', drive forces in N' if forces else ''}; "
              f"streamer cfg={'f' * len(cols)}\n")
    for k, line, words in word_schedule(result):
        buf.write(f"# at sample {k} (t = {k * ts:g} s), source line {line}: {words}\n")
    if result.contour is not None and result.contour.z_m is not None:
        buf.write("# Z (the tool's height) is not a leg: the part program's Z and words are in the G-code export\n")
    buf.write("# " + " ".join(cols) + "\n")
    np.savetxt(buf, table, fmt="%.6f", delimiter=" ")
    return buf.getvalue()
