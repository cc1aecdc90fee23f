"""When a contour plan issues its source program's words: the spindle, tool, coolant, stop,
tool length and work offset words, each at the first sample that reaches its source line."""

from __future__ import annotations

import re

from ..schema import PlanResult

__all__ = ["ISSUED", "STATEMENT", "word_schedule"]

#: the words a machine program carries over (the motion modes, planes, feed and path modes are
#: the export's own: G93/G94 feed, one move per sample), and the moves the reader keeps as
#: written because their start is the machine's (:data:`STATEMENT`)
ISSUED = re.compile(r"^(S|T|M|G43(\.1)?\b|G49\b|G5[4-9](\.[123])?\b|G0 Z|G94 G1 Z|G28 Z|G91 G28 Z)")
#: a move issued as written, on a line of its own: a G28 Z (the machine goes to its Z home,
#: unknown to the plan) or the first Z move after the program's start or a G28 (from that
#: unknown height: ``G0 Z..`` or ``G94 G1 Z.. F..``)
STATEMENT = re.compile(r"^(G0 Z|G94 G1 Z|G28 Z|G91 G28 Z)")


def word_schedule(result: PlanResult) -> list[tuple[int, int, str]]:
    """The issued words of a contour plan as ``(sample, source line, words of that line)`` in
    order (a line's words as one entry, then each of its :data:`STATEMENT` moves as one): a
    line's words are due before the step into the first sample whose ``source_line``
    reaches the line (sample 0: before the plan starts); words after the last line the plan
    reaches are due at the end (sample = the number of samples). Empty without a contour
    section or its ``source_line``."""
    c = result.contour
    if c is None or c.source_line is None:
        return []
    by_line: dict[int, list[str]] = {}
    for w in c.words:
        if ISSUED.match(w.word):
            by_line.setdefault(w.line, []).append(w.word)
    out: list[tuple[int, int, str]] = []
    k, n = 0, len(c.source_line)
    for line in sorted(by_line):
        while k < n and c.source_line[k] < line:
            k += 1
        plain = [w for w in by_line[line] if not STATEMENT.match(w)]  # a line's modes and M words first
        if plain:
            out.append((k, line, " ".join(plain)))
        out.extend((k, line, w) for w in by_line[line] if STATEMENT.match(w))
    return out
