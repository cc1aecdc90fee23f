"""The command line's start-up and warm plan (issue 34 goal 3), this tree against another
revision, side by side: median wall and CPU seconds of each command in its own process, and
its wall time less the time it waited for a CPU ("core free": what it takes on an idle
machine; the main thread's run-queue wait from ``/proc/PID/schedstat``).

    python benchmarks/bench_cli.py [--base REV] [--rounds 7] [--imports] [--phases]

- ``--help``: ``python -m app.cli --help`` (goal <= 0.2 s)
- ``plan warm``: ``python -m app.cli plan app/static/examples/table1.json -o OUT.json``, the
  kernels cached, planned in the command's own process (goal <= 1.5 s); the base runs it with
  ``RANGEPLAN_RESIDENT_S=0`` where it has the resident planner (``app/resident.py``)
- ``plan warm, resident`` (base only, where it has one): the same command handed to the base's
  resident planner (started once before the rounds by an in-process plan, ended after them; a
  key of this run's own): the client's wall and CPU, the resident's CPU not counted (no child)
- ``10 plans, batch --inline``: ``rangeplan batch TEN.jsonl -o DIR --inline`` (ten Table I
  requests planned one after another in the command's own process; a new DIR each run): what
  repeated planning costs without any process that outlives its command
- ``--phases``: where a warm plan's CPU time goes in this tree (:data:`PHASES`, run in a new
  process per round: each phase's ``time.process_time`` difference, median over the rounds)
- ``--imports``: the heaviest top-level imports of ``plan warm`` (``python -X importtime``, one
  run each, ms cumulative)

The base (default ``main``) is ``git archive``'d into a temporary directory (its kernels are
the same sources, so the same cached kernels load). Every command runs with
``OPENBLAS_NUM_THREADS=1``, no ``PYTHONPATH`` and no ``PYTHONDONTWRITEBYTECODE`` (the untimed
first run of each tree writes its ``__pycache__``, as an installed package has it), the tree
as working directory (``-m app.cli`` finds that tree's code first); head and base alternate
within each round. On a shared machine the CPU column is the steadier figure.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TABLE1 = ROOT / "app" / "static" / "examples" / "table1.json"
PY = sys.executable


def _env(extra: dict[str, str] | None = None) -> dict[str, str]:
    # as users run it: byte-compiled modules cached (the untimed first run writes them)
    e = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONDONTWRITEBYTECODE")}
    return {**e, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
            "RANGEPLAN_RESIDENT_S": "0", **(extra or {})}


def timed(cmd: list[str], cwd: Path, env: dict[str, str] | None = None) -> tuple[float, float, float]:
    """Run ``cmd``; (wall s, CPU s of the child, wall s less the time it waited for a CPU).
    The last is the wall time the command takes with a core free for it (its I/O and sleeps
    included): the kernel's run-queue wait of the process's main thread
    (``/proc/PID/schedstat``, read while the exited child is not yet reaped), subtracted
    from the wall time. Raises on failure, with its stderr."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    with tempfile.TemporaryFile("w+") as err:
        p = subprocess.Popen(cmd, cwd=cwd, env=_env(env), stdout=subprocess.DEVNULL, stderr=err, text=True)
        os.waitid(os.P_PID, p.pid, os.WEXITED | os.WNOWAIT)
        wall = time.perf_counter() - t0
        try:
            waited = int(Path(f"/proc/{p.pid}/schedstat").read_text().split()[1]) / 1e9
        except (OSError, IndexError, ValueError):
            waited = float("nan")
        code = p.wait()
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if code != 0:
            err.seek(0)
            raise RuntimeError(f"{' '.join(cmd)} in {cwd}: exit {code}\n{err.read()[-2000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), wall - waited


#: the base's resident (if it has one): a key of this run's own (any RANGEPLAN_* variable keys it)
RESIDENT_ENV = {"RANGEPLAN_RESIDENT_S": "600", "RANGEPLAN_BENCH_TAG": f"bench-cli-{os.getpid()}"}


def resident_env(tree: Path) -> dict[str, str]:
    """The environment of the resident's row: ``RESIDENT_ENV`` and the tree on ``PYTHONPATH``
    (the resident runs ``python -P``: without it, it would load the installed code, whose key
    differs; the variable keys the resident, so the timed commands have it too)."""
    return {**RESIDENT_ENV, "PYTHONPATH": str(tree)}


def start_resident(tree: Path) -> int:
    """Start the resident planner of ``tree`` as its CLI does (after an in-process plan) and
    wait until it listens; its pid."""
    import socket

    code = ("import os, app.cli; from app import resident; env = dict(os.environ); "
            "d = resident.resident_dir(env, True); "
            "print(resident.start_resident(env), resident.socket_path(d, resident.resident_key(env)))")
    out = subprocess.run([PY, "-c", code], cwd=tree, env=_env(resident_env(tree)), capture_output=True, text=True,
                         check=True)
    pid, path = out.stdout.split()
    deadline = time.monotonic() + 120
    while True:
        with socket.socket(socket.AF_UNIX) as s:
            try:
                s.connect(path)
                return int(pid)
            except OSError:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"no resident at {path}") from None
        time.sleep(0.2)


def importtime(tree: Path, out: Path, top: int = 8) -> list[tuple[str, float]]:
    """The ``top`` heaviest top-level imports of a warm plan (ms, cumulative)."""
    r = subprocess.run([PY, "-X", "importtime", "-m", "app.cli", "plan", str(TABLE1), "-o", str(out)], cwd=tree,
                       env=_env(), capture_output=True, text=True, check=True)
    rows = []
    for line in r.stderr.splitlines():
        if line.startswith("import time:") and line.count("|") == 2:
            _, cum, name = line.split("|")
            if cum.strip().isdigit() and not name.startswith("  "):  # top level: one leading space only
                rows.append((name.strip(), int(cum) / 1000))
    rows.sort(key=lambda x: -x[1])
    return [("(all top-level imports)", sum(ms for _, ms in rows)), *rows[:top]]


#: a warm plan of Table I as ``rangeplan plan`` runs it, phase by phase (CPU ms each, as JSON)
PHASES = """
import json, sys, time
T = time.process_time
marks = [("interpreter start", T())]
def m(name):
    marks.append((name, T()))
from app import cli
m("app.cli")
args = cli.build_parser("plan").parse_args(["plan", sys.argv[1], "-o", sys.argv[2]])
m("argument parser")
cli.seed_kernels()
m("settings (kernel seed; pydantic)")
request = cli.load_request(args.input)
m("request model (planner.schema)")
import numba
m("numba")
import app.formats
m("orchestrator and constraint modules (app.formats)")
from app.jobs import PlanJob, run_job
m("app.jobs")
import scipy.linalg.cython_blas
m("scipy.linalg (numba's BLAS binding)")
job = PlanJob(request, format="json")
out = run_job(job)
m("load the cached kernels and plan")
run_job(job)
m("(the same plan again: the plan alone)")
cli.write_output(out.payload, args, "json", "")
m("write the indented JSON")
print(json.dumps([(marks[0][0], marks[0][1] * 1e3)] + [(n, (t - marks[i][1]) * 1e3) for i, (n, t) in
                  enumerate(marks[1:])] + [("total", T() * 1e3)]))
"""


def phases(rounds: int, out: Path) -> None:
    """Print the median CPU ms of each phase of :data:`PHASES` in this tree."""
    runs = []
    for _ in range(rounds):
        r = subprocess.run([PY, "-c", PHASES, str(TABLE1), str(out)], cwd=ROOT, env=_env(), capture_output=True,
                           text=True, check=True)
        runs.append(json.loads(r.stdout.strip().splitlines()[-1]))
    print(f"\nwhere a warm plan's CPU goes, head (ms, median of {rounds}):")
    for i, (name, _) in enumerate(runs[0]):
        print(f"  {statistics.median(run[i][1] for run in runs):8.1f}  {name}")


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--base", default="main", help="revision to compare with (default main)")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--imports", action="store_true", help="also the heaviest imports of a warm plan")
    ap.add_argument("--phases", action="store_true", help="also where a warm plan's CPU time goes (this tree)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-cli-") as tmpdir:
        tmp = Path(tmpdir)
        base = tmp / "base"
        base.mkdir()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.base], capture_output=True, check=True)
        subprocess.run(["tar", "-x", "-C", str(base)], input=archive.stdout, check=True)
        trees = {"head": ROOT, "base": base}
        ten = tmp / "ten.jsonl"
        req = json.loads(TABLE1.read_text())
        ten.write_text("".join(json.dumps({**req, "name": f"table1-{i}"}) + "\n" for i in range(10)))
        cmds = {"--help": [PY, "-m", "app.cli", "--help"],
                "plan warm": [PY, "-m", "app.cli", "plan", str(TABLE1), "-o", str(tmp / "out.json")]}
        batch = [PY, "-m", "app.cli", "batch", str(ten), "--inline", "--progress", "none", "-o"]
        rows: dict[tuple[str, str], list[tuple[float, float, float]]] = {}
        for name, tree in trees.items():  # once each, untimed: byte-compiled sources, kernels in the page cache
            timed(cmds["plan warm"], tree)
            timed([*batch, str(tmp / f"batch-{name}-warm")], tree)
        resident = None
        if (base / "app" / "resident.py").exists():
            resident = start_resident(base)
        try:
            for _ in range(args.rounds):
                for label, cmd in cmds.items():
                    for name, tree in trees.items():
                        rows.setdefault((label, name), []).append(timed(cmd, tree))
                for name, tree in trees.items():
                    rows.setdefault(("10 plans, batch --inline", name), []).append(
                        timed([*batch, str(tmp / f"batch-{name}-{len(rows[('--help', name)])}")], tree))
                if resident is not None:
                    rows.setdefault(("plan warm, resident", "base"), []).append(
                        timed(cmds["plan warm"], base, resident_env(base)))
        finally:
            if resident is not None:
                os.kill(resident, signal.SIGTERM)

        def med(key: tuple[str, str], i: int) -> float | None:
            v = rows.get(key)
            return statistics.median(x[i] for x in v) if v else None

        def cell(x: float | None) -> str:
            return f"{x:.3f}" if x is not None else "-"

        head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True).stdout.strip()
        print(f"median of {args.rounds} rounds; head = {ROOT} (HEAD {head}, uncommitted changes included), "
              f"base = {args.base}; load average {os.getloadavg()[0]:.2f}")
        print("| command | base wall s | head wall s | base wall, core free s | head wall, core free s | head/base "
              "(core free) | base CPU s | head CPU s |")
        print("|---|---|---|---|---|---|---|---|")
        for label in [*cmds, "plan warm, resident", "10 plans, batch --inline"]:
            bw, hw = med((label, "base"), 0), med((label, "head"), 0)
            bc, hc = med((label, "base"), 1), med((label, "head"), 1)
            bf, hf = med((label, "base"), 2), med((label, "head"), 2)
            if bw is None and hw is None:
                continue
            ratio = f"{hf / bf:.2f}" if hf is not None and bf is not None else "-"
            print(f"| {label} | {cell(bw)} | {cell(hw)} | {cell(bf)} | {cell(hf)} | {ratio} | {cell(bc)} | "
                  f"{cell(hc)} |")
        if args.imports:
            for name, tree in trees.items():
                print(f"\nheaviest top-level imports of `plan warm`, {name} (ms, cumulative, one run):")
                for mod, ms in importtime(tree, tmp / "imp.json"):
                    print(f"  {ms:8.1f}  {mod}")
        if args.phases:
            phases(args.rounds, tmp / "phases.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
