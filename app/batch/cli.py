"""``rangeplan batch INPUT... -o OUTDIR``: plan many requests (plan requests and contour
requests: G-code programs) on a local process pool or a Dask cluster, with progress, one
result file per item and ``summary.csv``.

Exit status: 0 every item planned; 1 some items failed (``summary.csv`` says which and why);
2 a usage error (a missing input, an unreachable scheduler); 130 interrupted (Ctrl-C: every
finished result and the summary of what finished are kept; the same command resumes).
"""

from __future__ import annotations

import argparse
import itertools
import os
import sys
import time
from pathlib import Path
from typing import Any

from .config import FORMAT_NAMES, SCHEDULER_ENV

__all__ = ["add_parser", "cmd_batch", "run_batch"]

SUMMARY = "summary.csv"


def add_parser(sub: Any) -> None:
    """Register the ``batch`` sub-command on the ``rangeplan`` parser's sub-parsers."""
    pb = sub.add_parser(
        "batch", help="plan many requests: a local process pool, or a Dask cluster with --scheduler",
        description="Plan every request in INPUT (request files, directories of them, JSON Lines files with one "
                    "request per line). A request is a plan request (as 'rangeplan plan' and POST /v1/plan take) or "
                    "a contour request (an object with 'program', the G-code text, as POST /v1/contour takes). "
                    "Writes OUTDIR/<key>.<format> per item and OUTDIR/summary.csv. A failing "
                    "item never stops the batch; re-running with the same OUTDIR skips items already done.")
    pb.add_argument("inputs", nargs="+", metavar="INPUT", help="request .json file, directory, or .jsonl file")
    pb.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="output directory (created)")
    pb.add_argument("--workers", type=int, help="local worker processes (default: the CPU count)")
    pb.add_argument("--scheduler", metavar="ADDRESS",
                    help=f"Dask scheduler, e.g. tcp://10.0.0.5:8786 (env {SCHEDULER_ENV}); default: a local pool")
    pb.add_argument("--format", choices=list(FORMAT_NAMES), default="json",
                    help="result file format (none: summary.csv only)")
    pb.add_argument("--resume", action=argparse.BooleanOptionalAction, default=True,
                    help="skip items already done in OUTDIR (default: on)")
    pb.add_argument("--progress", choices=["auto", "bar", "lines", "none"], default="auto",
                    help="progress bar on a terminal, a line per item otherwise (default: auto)")
    pb.add_argument("--timeout", type=float, metavar="SECONDS",
                    help="compute limit per item, s (env RANGEPLAN_PLAN_TIMEOUT_S; default 0: none)")
    pb.add_argument("--inline", action="store_true", help="plan in this process, one item at a time (no pool)")
    pb.add_argument("--worker-writes", action=argparse.BooleanOptionalAction, default=True,
                    help="workers write the result files into OUTDIR themselves where they see it (always on the "
                         "local pool; on Dask, each worker checks that it sees this run's staging directory in "
                         "OUTDIR, else sends its results back); --no-worker-writes: every result travels back "
                         "and this process writes it (default: on)")
    pb.set_defaults(func=cmd_batch)


class _Usage(Exception):
    pass


def run_batch(inputs: list[str], outdir: str | Path, *, workers: int | None = None, scheduler: str | None = None,
              fmt: str = "json", resume: bool = True, progress: str = "auto", timeout_s: float = 0.0,
              inline: bool = False, engine: Any = None, stream: Any = None,
              worker_writes: bool = True) -> dict[str, Any]:
    """The batch command as a function (the CLI, tests and benchmarks call it). Returns
    ``{"ok", "failed", "skipped", "total", "interrupted", "elapsed_s", "engine", ...}``;
    raises :class:`app.batch.inputs.InputError` or ``OSError`` (scheduler) for usage errors.
    ``engine``: an already open engine to use (not closed here).

    ``worker_writes``: the run makes a staging directory in ``outdir``
    (``.rangeplan-staging-<token>``); a worker that sees it writes each result there and
    sends back only the outcome's summary, and this process renames the file into place when
    it records the item (one ``rename`` instead of receiving ~145 kB and writing it). A
    worker that does not see it (a Dask worker without the shared filesystem) sends the
    result back as without the option. The staging directory, and with it any file of a
    worker that died or of an item that was cancelled, is removed at the end (and any left by
    a run that was killed, at the start of the next)."""
    from .inputs import count_items, resolve_inputs

    files = resolve_inputs(inputs)
    run = _BatchRun(files, count_items(files), Path(outdir), fmt, resume, worker_writes)
    return run.execute(workers, scheduler, progress, timeout_s, inline, engine, stream)


class _BatchRun:
    """One run of :func:`run_batch`: the output directory, its staging directory, the
    summary journal and the counts; :meth:`execute` runs the items on an engine."""

    def __init__(self, files: list, total: int, out: Path, fmt: str, resume: bool, worker_writes: bool):
        import shutil
        import uuid

        from .engine import FORMATS, STAGING_PREFIX
        from .summary import read_summary

        self.files, self.total, self.out, self.fmt = files, total, out, fmt
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise _Usage(f"{out}: cannot create the output directory: {exc.strerror or exc}") from None
        self.ext = FORMATS[fmt][0]
        for old in out.glob(STAGING_PREFIX + "*"):  # a run killed before it could clean up
            shutil.rmtree(old, ignore_errors=True)
        self.stage: Path | None = None
        if worker_writes and self.ext is not None:
            self.stage = out.resolve() / f"{STAGING_PREFIX}{uuid.uuid4().hex}"
            self.stage.mkdir()
        self.summary_path = out / SUMMARY
        self.previous = read_summary(self.summary_path) if resume else {}
        self.lines: dict[str, tuple[int, str]] = {}
        self.statuses: dict[str, str] = {}
        self.shas: dict[int, str] = {}
        self.counts = {"ok": 0, "error": 0, "failed": 0, "cancelled": 0, "skipped": 0, "worker_written": 0}
        self.prog: Any = None
        self.journal: Any = None

    def done_before(self, item: Any, sha: str) -> bool:
        row = self.previous.get(item.key)
        if row is None or row.get("request_sha") != sha or row["status"] not in ("ok", "error"):
            return False
        if row["status"] == "ok" and self.ext is not None and not (self.out / f"{item.key}{self.ext}").is_file():
            return False
        return True

    def todo(self):
        """The items still to plan (those done by a previous run are counted as skipped)."""
        from .inputs import iter_items
        from .summary import row_line

        for item, sha in iter_items(self.files):
            if sha and self.done_before(item, sha):
                row = dict(self.previous[item.key], item=str(item.index))
                self.lines[item.key] = (item.index, row_line(row))
                self.statuses[item.key] = row["status"]
                self.counts["skipped"] += 1
                self.prog.skip()
                continue
            self.shas[item.index] = sha
            yield item

    def _result_file(self, item: Any, outcome: dict[str, Any]) -> tuple[str, dict[str, Any]]:
        """Put an item's result in place: the worker's staged file renamed, or the payload
        written; its file name ("" for none) and the outcome (failed if it cannot be moved)."""
        from .runner import failed_outcome

        if outcome["status"] != "ok" or self.ext is None:
            return "", outcome
        file = f"{item.key}{self.ext}"
        if outcome.get("staged") and self.stage is not None:
            try:  # the worker wrote it whole under a temporary name: now it is the result
                os.replace(self.stage / outcome["staged"], self.out / file)
                self.counts["worker_written"] += 1
            except OSError as exc:
                where = {k: outcome.get(k) for k in ("engine", "worker", "attempts")}
                return "", {**failed_outcome("internal_error", f"the result file written by the worker cannot be "
                                             f"moved into {self.out}: {exc.strerror or exc}", status="failed"),
                            **where}
            return file, outcome
        if outcome.get("payload") is not None:
            tmp = self.out / (file + ".tmp")
            tmp.write_bytes(outcome["payload"])
            os.replace(tmp, self.out / file)
            return file, outcome
        return "", outcome

    def on_done(self, item: Any, outcome: dict[str, Any]) -> None:
        from .summary import row_line, summary_row

        file, outcome = self._result_file(item, outcome)
        line = row_line(summary_row(item.index, item.key, outcome, self.shas.pop(item.index, ""), file))
        self.lines[item.key] = (item.index, line)
        self.statuses[item.key] = outcome["status"]
        self.journal.write(line)
        self.journal.flush()
        self.counts[outcome["status"]] = self.counts.get(outcome["status"], 0) + 1
        self.prog.item(item.key, outcome)

    def execute(self, workers: int | None, scheduler: str | None, progress: str, timeout_s: float, inline: bool,
                engine: Any, stream: Any) -> dict[str, Any]:
        import shutil

        from .executors import open_engine
        from .progress import make_progress
        from .runner import Runner
        from .summary import header_line, write_summary

        self.prog = make_progress(progress, self.total, 0, stream)
        self.journal = open(self.summary_path, "a" if self.previous else "w", newline="")
        if not self.previous:
            self.journal.write(header_line())
        own_engine = engine is None
        try:
            if own_engine:
                engine = open_engine(workers, scheduler, inline=inline)
        except BaseException:
            self.journal.close()
            if self.stage is not None:
                shutil.rmtree(self.stage, ignore_errors=True)
            raise
        interrupted = False
        t0 = time.perf_counter()
        runner = Runner(engine, self.on_done, fmt=self.fmt, timeout_s=timeout_s or None,
                        stage=str(self.stage) if self.stage else None)
        try:
            todo = self.todo()
            first = next(todo, None)  # items already done before the first to plan: the bar starts past them
            self.prog.start(engine.describe())
            runner.run(itertools.chain(() if first is None else (first,), todo),
                       remaining=lambda: max(0, self.total - self.prog.done - runner.running))
        except KeyboardInterrupt:
            interrupted = True
        finally:
            elapsed = time.perf_counter() - t0
            self.prog.close()
            if own_engine:
                engine.close(cancel=interrupted)
            if self.stage is not None:  # what is left there was never reported: a dead worker's, a cancelled item's
                shutil.rmtree(self.stage, ignore_errors=True)
            self.journal.close()
            write_summary(self.summary_path, self.lines.values())
        return self._result(engine, runner, interrupted, elapsed)

    def _result(self, engine: Any, runner: Any, interrupted: bool, elapsed: float) -> dict[str, Any]:
        counts, total = self.counts, self.total
        failed = counts["error"] + counts["failed"]
        return {"ok": counts["ok"], "failed": failed, "skipped": counts["skipped"], "total": total,
                "finished": len(self.lines), "interrupted": interrupted, "elapsed_s": elapsed,
                "rate": (counts["ok"] + failed) / elapsed if elapsed > 0 else 0.0, "engine": engine.name,
                "summary": str(self.summary_path), "lost_workers": runner.stats.lost_workers,
                "resubmitted": runner.stats.resubmitted_items, "worker_written": counts["worker_written"],
                "all_ok": not interrupted and len(self.statuses) == total
                and all(v == "ok" for v in self.statuses.values())}


def cmd_batch(args: argparse.Namespace) -> int:
    from .inputs import InputError

    def usage(msg: str) -> int:
        print(f"rangeplan: error: {msg}", file=sys.stderr)
        return 2

    from app.settings import SettingsError, settings

    try:  # the flags' defaults: RANGEPLAN_DASK_SCHEDULER, RANGEPLAN_PLAN_TIMEOUT_S (if set; else no limit)
        cfg = settings()
    except SettingsError as exc:
        return usage(str(exc))
    if args.scheduler is None:
        args.scheduler = cfg.dask_scheduler
    if args.timeout is None:
        args.timeout = cfg.plan_timeout_s if "plan_timeout_s" in cfg.model_fields_set else 0.0

    if args.workers is not None and args.workers < 1:
        return usage(f"--workers must be >= 1, got {args.workers}")
    if args.workers is not None and args.scheduler:
        return usage("--workers sets the local pool; a Dask cluster's size is set by its workers (drop one of "
                     "--workers and --scheduler)")
    if args.timeout < 0:
        return usage(f"--timeout must be >= 0 s, got {args.timeout:g}")
    try:
        res = run_batch(args.inputs, args.output, workers=args.workers, scheduler=args.scheduler, fmt=args.format,
                        resume=args.resume, progress=args.progress, timeout_s=args.timeout, inline=args.inline,
                        worker_writes=args.worker_writes)
    except (InputError, _Usage, OSError) as exc:
        return usage(str(exc))
    done = res["ok"] + res["failed"]
    tail = f" ({res['skipped']} already done)" if res["skipped"] else ""
    print(f"rangeplan: {res['ok']} ok, {res['failed']} failed of {res['total']}{tail} in {res['elapsed_s']:.1f} s "
          f"({res['rate']:.1f} plans/s); summary: {res['summary']}", file=sys.stderr)
    if args.scheduler and args.format != "none":  # whether the workers share OUTDIR with this host
        print(f"rangeplan: {res['worker_written']} result files written by the Dask workers into {args.output}, "
              f"{res['ok'] - res['worker_written']} sent back to this process", file=sys.stderr)
    if res["interrupted"]:
        print(f"rangeplan: interrupted: {done} finished results kept ({res['finished']} of {res['total']} in the "
              "summary); run the same command again to resume", file=sys.stderr)
        return 130
    return 0 if res["all_ok"] else 1
