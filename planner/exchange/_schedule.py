"""When a contour plan issues its source program's words: the spindle, tool, coolant, stop,
tool length and work offset words, each at the first sample that reaches its source line."""

from __future__ import annotations

import re

from ..schema import PlanResult

__all__ = ["ISSUED", "word_schedule"]

#: the words a machine program carries over (the motion modes, planes, feed and path modes are
#: the export's own: G93/G94 feed, one move per sample)
ISSUED = re.compile(r"^(S|T|M|G43(\.1)?\b|G49\b|G5[4-9](\.[123])?\b)")


def word_schedule(result: PlanResult) -> list[tuple[int, int, str]]:
    """The issued words of a contour plan as ``(sample, source line, words of that line)`` in
    order: a line's words are due before the step into the first sample whose ``source_line``
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
        out.append((k, line, " ".join(by_line[line])))
    return out
