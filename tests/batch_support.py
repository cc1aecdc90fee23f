"""Helpers of the batch tests: corridor variants, reading a batch's outputs, comparing with
single plans."""

from __future__ import annotations

import copy
import csv
import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from tests.support import ROOT, TABLE1

CLI = [sys.executable, "-m", "app.cli"]
BAD_RANGE = {"segments": [{"lower": [0, 0, 0], "upper": [-1, 0, 0]}, {"lower": [0, 0, 0], "upper": [0, 0, 0]}]}
UNREACHABLE = {"segments": [{"lower": [0, 0, 0], "upper": [0, 0, 0]}, {"lower": [0.3, 0, 0], "upper": [0.3, 0, 0]}]}


def env() -> dict[str, str]:
    """Subprocess environment: this tree first on the path, single-threaded BLAS."""
    return {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}


def variant(i: int, mode: str = "paper") -> dict[str, Any]:
    """Table I shifted by 1 mm per ``i`` along x (a design study's corridor variants)."""
    r = copy.deepcopy(TABLE1)
    r["name"] = f"variant {i} {mode}"
    for s in r["segments"]:
        for k in ("lower", "upper"):
            s[k][0] += 0.001 * i
    r["settings"] = {"mode": mode}  # named: the default mode is constrained
    return r


def write_jsonl(path: Path, requests: list[Any]) -> Path:
    path.write_text("".join((r if isinstance(r, str) else json.dumps(r)) + "\n" for r in requests))
    return path


def read_summary(outdir: Path) -> list[dict[str, str]]:
    with open(outdir / "summary.csv", newline="") as f:
        return list(csv.DictReader(f))


def single_plan(request: dict[str, Any], tmp: Path) -> dict[str, Any]:
    """``rangeplan plan`` on ``request`` (a separate process), its JSON result."""
    src, out = tmp / "single-in.json", tmp / "single-out.json"
    src.write_text(json.dumps(request))
    r = subprocess.run([*CLI, "plan", str(src), "-o", str(out)], capture_output=True, text=True, env=env(),
                       timeout=300)
    assert r.returncode == 0, r.stderr
    return json.loads(out.read_text())


def assert_same_plan(a: dict[str, Any], b: dict[str, Any], tol: float = 1e-9) -> None:
    """Same trajectory and forces to ``tol`` (m, N)."""
    for key in ("pose", "velocity"):
        pa, pb = np.asarray(a[key]), np.asarray(b[key])
        assert pa.shape == pb.shape
        assert np.max(np.abs(pa - pb)) <= tol, key
    fa, fb = np.asarray(a["drives"]["force"]), np.asarray(b["drives"]["force"])
    assert np.max(np.abs(fa - fb)) <= tol
    assert a["metrics"]["energy"] == b["metrics"]["energy"] or abs(a["metrics"]["energy"] - b["metrics"]["energy"]) \
        <= tol * max(1.0, abs(a["metrics"]["energy"]))


def planning_children() -> list[int]:
    """The pids of this process's planning processes (:func:`app.executors.child_pool`; run
    in a batch worker: its children that enforce the time limit)."""
    from app.executors import child_pool

    return sorted(p for p in (w.pid for w in child_pool()._workers) if p is not None)


def worker_pid() -> int:
    """The pid of the process this runs in (a batch worker's)."""
    return os.getpid()


def contour_items() -> list[dict[str, Any]]:
    """Contour requests (bodies of POST /v1/contour): the small program of tests/test_contour.py
    at three origins and two tolerances, and one the reader refuses (G41, cutter compensation,
    on line 11)."""
    from tests.test_contour import ORIGIN, SMALL

    ox, oy = ORIGIN
    return [{"name": "small", "program": SMALL, "origin": ORIGIN, "feed": "program"},
            {"name": "small right", "program": SMALL, "origin": [ox + 0.002, oy], "tolerance_m": 3e-5},
            {"name": "small fastest", "program": SMALL, "origin": [ox, oy + 0.001], "feed": "fastest"},
            {"name": "compensated", "program": SMALL.replace("G1 X0", "G41 X0"), "origin": ORIGIN}]


def assert_same_contour(result: dict[str, Any], request: dict[str, Any]) -> None:
    """``result`` (a batch item's JSON) equals ``request`` contoured directly in this process
    (:func:`planner.contour.plan_contour`): the same trajectory and the same contour metrics."""
    from planner.contour import plan_contour

    direct = plan_contour(request).to_json_dict()
    assert_same_plan(result, direct)
    a, b = result["contour"], direct["contour"]
    for key in ("max_deviation_m", "max_path_deviation_m", "tolerance_m", "cycle_time_s", "cut_time_s", "origin",
                "program_line", "cutting", "feed"):
        assert a[key] == b[key], key
    assert len(a["passes"]) == len(b["passes"]) and a["max_deviation_m"] <= a["tolerance_m"]


def jobs_run_here() -> int:
    """Jobs this process has run through :func:`app.executors.run_bounded` (on a Dask worker:
    the service's jobs and batch items sent to it)."""
    from app.executors import WORKER

    return int(WORKER.get("jobs", 0))


@dataclass(frozen=True)
class SleepChunk:
    """A chunk of :class:`app.jobs.SleepJob` s (an :class:`app.jobs.ChunkJob`, as a batch's chunk):
    each run through :func:`app.executors.run_bounded` with ``limit_s`` where the chunk runs.
    Answers this process's pid and, per sleep, whether it finished, its error, the seconds it
    took and this process's planning processes afterwards."""

    seconds: tuple[float, ...]
    limit_s: float
    kind: ClassVar[str] = "sleep-chunk"

    def run(self):
        import time

        from app.executors import run_bounded
        from app.jobs import Done, SleepJob

        runs = []
        for s in self.seconds:
            t0 = time.perf_counter()
            out = run_bounded(SleepJob(s), self.limit_s)
            err = getattr(out, "error", None)
            runs.append({"ok": out.ok, "code": err.code if err else None, "message": err.message if err else None,
                         "took_s": time.perf_counter() - t0, "children": planning_children()})
        return Done(b"", summary={"pid": os.getpid(), "runs": runs})
