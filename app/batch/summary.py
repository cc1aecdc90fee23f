"""``summary.csv``: one row per item (CLI output directory, ``GET /v1/batches/{id}/results?
format=csv``), SI units in the column names."""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

__all__ = ["COLUMNS", "summary_row", "row_line", "read_summary", "write_summary", "csv_text", "header_line"]

#: the columns, in order: the item's position (0-based) and key, the request's name, its
#: status (ok | error | failed | cancelled), the error (a planner code such as unreachable
#: or invalid_input, its message and field), figures of the plan (s, N^2 s, ratios, m, ms),
#: where it ran, attempts, a hash of the request text and the result file; then the item's
#: kind (plan | contour) and a contour item's figures (the two-sided deviation from the
#: program and the tolerance, m; the cycle and cut times, s; the cut passes; empty for a plan)
COLUMNS = ["item", "key", "name", "status", "error_code", "error_message", "error_field", "duration_s",
           "energy_n2_s", "max_force_ratio", "contained", "settled", "end_error_m", "max_corridor_violation_m",
           "compute_ms", "engine", "worker", "attempts", "request_sha", "file", "kind", "max_deviation_m",
           "tolerance_m", "cycle_time_s", "cut_time_s", "passes"]

_FROM_SUMMARY = {"duration_s": "duration_s", "energy_n2_s": "energy", "max_force_ratio": "max_force_ratio",
                 "contained": "contained", "settled": "settled", "end_error_m": "end_error_m",
                 "max_corridor_violation_m": "max_corridor_violation_m", "compute_ms": "compute_ms",
                 "max_deviation_m": "max_deviation_m", "tolerance_m": "tolerance_m", "cycle_time_s": "cycle_time_s",
                 "cut_time_s": "cut_time_s", "passes": "passes"}


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return str(v)


def summary_row(index: int, key: str, outcome: dict[str, Any], request_sha: str = "", file: str = "") -> dict[str, str]:
    """The summary row of one item's outcome (:func:`app.batch.engine.plan_item`'s dict)."""
    err = outcome.get("error") or {}
    summ = outcome.get("summary") or {}
    row = {"item": str(index), "key": key, "name": outcome.get("name") or "", "status": outcome.get("status", ""),
           "error_code": err.get("code") or "", "error_message": err.get("message") or "",
           "error_field": err.get("field") or "", "engine": outcome.get("engine") or "",
           "worker": outcome.get("worker") or "", "attempts": _cell(outcome.get("attempts")),
           "request_sha": request_sha, "file": file, "kind": outcome.get("kind") or ""}
    for col, k in _FROM_SUMMARY.items():
        row[col] = _cell(summ.get(k))
    return row


def read_summary(path: Path) -> dict[str, dict[str, str]]:
    """Rows of an existing summary by key (a later row of a key wins: the file is appended
    to while a batch runs); an unreadable or truncated last row is ignored."""
    rows: dict[str, dict[str, str]] = {}
    try:
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                if row.get("key") and row.get("status") and None not in row:
                    rows[row["key"]] = row
    except (OSError, csv.Error, UnicodeDecodeError):
        pass
    return rows


def csv_text(rows: Iterable[dict[str, str]]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, COLUMNS, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def row_line(row: dict[str, str]) -> str:
    """One row as a CSV line (a batch keeps its rows as lines: ~0.3 kB an item)."""
    buf = io.StringIO()
    csv.DictWriter(buf, COLUMNS, extrasaction="ignore", lineterminator="\n").writerow(row)
    return buf.getvalue()


def header_line() -> str:
    return ",".join(COLUMNS) + "\n"


def write_summary(path: Path, lines: Iterable[tuple[int, str]]) -> None:
    """Write ``(item, line)`` rows in item order, atomically."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="") as f:
        f.write(header_line())
        for _, line in sorted(lines, key=lambda r: r[0]):
            f.write(line)
    os.replace(tmp, path)
