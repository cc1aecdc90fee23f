"""Z in the material planned with the XY motion (issue 32, goal 3): a pass is not ended by a
tab, and its Z follows the path within the machine's Z speed.

* :func:`join_tabs`: feed moves above the cutting height between two cut passes, with no rapid
  and no Z-only move between (the tool ramps up over a tab, runs along its top and ramps
  down again, or hops over a clamp at the feed), join the passes into one: the robot follows
  the programmed path through them without stopping (the contour planner's Z per sample is
  the path's Z where the sample projects, :func:`planner.contour.join.cut_z`). A Z-only move
  (a vertical step) still stops XY: it is a dwell between passes.
* :func:`cap_z_speed`: a move whose Z changes (a ramp, a helix, a tab's flank) is cut at an
  XY feed whose Z speed ``F_xy |dZ| / L`` is at most the Z axis speed (``z_rapid_m_s``, the
  speed of Z rapids: the axis's own limit).
"""

from __future__ import annotations

from ..schema.contour import ProgramBlock

__all__ = ["cap_z_speed", "join_tabs"]


def join_tabs(blocks: list[ProgramBlock]) -> list[ProgramBlock]:
    """``blocks`` with every run ``cut, travel at feed..., cut`` (the travels feed moves, not
    rapids) joined into one cut block (its line the first cut's)."""
    out: list[ProgramBlock] = []
    k = 0
    while k < len(blocks):
        b = blocks[k]
        if b.kind == "cut" and out and out[-1].kind == "cut":  # two cuts met (after a tab joined below)
            out[-1].elements.extend(b.elements)
            k += 1
            continue
        if b.kind == "travel" and not b.rapid and out and out[-1].kind == "cut":
            j = k
            while j < len(blocks) and blocks[j].kind == "travel" and not blocks[j].rapid:
                j += 1
            if j < len(blocks) and blocks[j].kind == "cut":  # a tab: the pass goes on after it
                for t in blocks[k:j]:
                    out[-1].elements.extend(t.elements)
                k = j
                continue
            out.extend(blocks[k:j])
            k = j
            continue
        out.append(b)
        k += 1
    return out


def cap_z_speed(blocks: list[ProgramBlock], z_max_m_s: float) -> None:
    """Lower the feed of every cut move whose Z changes to at most ``z_max_m_s`` of Z speed
    (the XY feed times ``|dZ| / L``, ``L`` its XY length), in place."""
    for b in blocks:
        if b.kind != "cut":
            continue
        for e in b.elements:
            dz = abs(e.z_end_m - e.z_start_m)
            if dz > 0 and e.length_m > 0 and e.duration_s is None:
                e.feed_m_s = min(e.feed_m_s, z_max_m_s * e.length_m / dz)
