"""Progress of a CLI batch: a rich progress bar on a terminal (done/total, failed, rate,
ETA), a plain line per item otherwise (logs, pipes, CI)."""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO

__all__ = ["Progress", "make_progress"]


def _describe(key: str, outcome: dict[str, Any]) -> str:
    status = outcome.get("status")
    where = outcome.get("worker") or ""
    if status == "ok":
        s = outcome.get("summary") or {}
        return (f"{key} ok {s.get('duration_s', 0):.2f} s, energy {s.get('energy', 0):.4g} N^2 s, "
                f"max force ratio {s.get('max_force_ratio', 0):.3f}, compute {s.get('compute_ms', 0):.0f} ms "
                f"({outcome.get('engine')} {where})")
    err = outcome.get("error") or {}
    field = f" {err['field']}:" if err.get("field") else ""
    return f"{key} {status} {err.get('code')}:{field} {err.get('message')}"


class Progress:
    """Plain lines: ``[done/total] key status details``."""

    def __init__(self, total: int, skipped: int = 0, stream: TextIO | None = None):
        self.total, self.done, self.failed = total, skipped, 0
        self.stream = stream or sys.stderr
        self.t0 = time.monotonic()
        self.new = 0

    def start(self, description: str) -> None:
        print(f"rangeplan: batch of {self.total} items on {description}"
              + (f"; {self.done} already done" if self.done else ""), file=self.stream, flush=True)

    def skip(self) -> None:
        """An item done in an earlier run (resumed batch): counted as done, not as planned now."""
        self.done += 1

    def item(self, key: str, outcome: dict[str, Any]) -> None:
        self.done += 1
        self.new += 1
        if outcome.get("status") != "ok":
            self.failed += 1
        width = len(str(self.total))
        print(f"[{self.done:>{width}}/{self.total}] {_describe(key, outcome)}", file=self.stream, flush=True)

    def rate(self) -> float:
        dt = time.monotonic() - self.t0
        return self.new / dt if dt > 0 else 0.0

    def close(self) -> None:
        pass


class QuietProgress(Progress):
    """Counts only (``--progress none``): nothing is formatted or kept per item."""

    def start(self, description: str) -> None:
        pass

    def item(self, key: str, outcome: dict[str, Any]) -> None:
        self.done += 1
        self.new += 1
        if outcome.get("status") != "ok":
            self.failed += 1


class RichProgress(Progress):
    """A rich progress bar; failed items are also printed above it."""

    def __init__(self, total: int, skipped: int = 0, stream: TextIO | None = None):
        super().__init__(total, skipped, stream)
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn
        from rich.progress import Progress as Bar

        self.console = Console(file=self.stream)
        self.bar = Bar(TextColumn("[bold]batch"), BarColumn(), MofNCompleteColumn(),
                       TextColumn("[red]{task.fields[failed]} failed"), TextColumn("{task.fields[rate]} plans/s"),
                       TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), console=self.console,
                       transient=False)
        self.task = self.bar.add_task("batch", total=total, completed=skipped, failed=0, rate="-")

    def start(self, description: str) -> None:
        self.console.print(f"rangeplan: batch of {self.total} items on {description}"
                           + (f"; {self.done} already done" if self.done else ""))
        self.bar.update(self.task, completed=self.done)  # a resumed batch starts at what is done
        self.bar.start()

    def skip(self) -> None:
        super().skip()
        self.bar.update(self.task, completed=self.done)

    def item(self, key: str, outcome: dict[str, Any]) -> None:
        self.done += 1
        self.new += 1
        if outcome.get("status") != "ok":
            self.failed += 1
            self.bar.console.print(_describe(key, outcome), style="red", markup=False, highlight=False)
        self.bar.update(self.task, completed=self.done, failed=self.failed, rate=f"{self.rate():.1f}")

    def close(self) -> None:
        self.bar.stop()


def make_progress(kind: str, total: int, skipped: int = 0, stream: TextIO | None = None) -> Progress:
    """``kind``: ``auto`` (a bar on a terminal, else lines), ``bar``, ``lines`` or ``none``."""
    stream = stream if stream is not None else sys.stderr
    if kind == "auto":
        kind = "bar" if stream is not None and stream.isatty() else "lines"
    if kind == "bar":
        return RichProgress(total, skipped, stream)
    if kind == "none":
        return QuietProgress(total, skipped, stream)
    return Progress(total, skipped, stream)
