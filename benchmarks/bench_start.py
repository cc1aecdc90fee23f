"""Start-up costs (issue 24), side by side with another revision: wall and CPU seconds.

    python benchmarks/bench_start.py [--base REV] [--rounds 3] [--cold] [--install]
    python benchmarks/bench_start.py --profile-compile      # each kernel's compile time
    python benchmarks/bench_start.py --workers [--rounds 5]  # the service's workers, by start method
    python benchmarks/bench_start.py --breakdown [--refresh] # where a warm plan's time goes
    python benchmarks/bench_start.py --load-order            # gone (issue 34): numba always refreshes now
    python benchmarks/bench_start.py --make-run              # make run on a fresh clone to the first answer

Every figure is one child process (``OPENBLAS_NUM_THREADS=1``), timed by wall clock and by
the CPU seconds it used (``resource.getrusage(RUSAGE_CHILDREN)``: on a shared machine the
CPU time is the steadier figure); the table gives the median over ``--rounds``.

- ``--help``: ``python -m app.cli --help``
- ``import planner``: ``python -c "import planner"``
- ``plan warm``: ``python -m app.cli plan app/static/examples/table1.json -o OUT.json``, kernels cached,
  in-process (``RANGEPLAN_RESIDENT_S=0``, as every row but the next)
- ``plan warm, resident``: the same command handed to the CLI's resident planner
  (``app/resident.py``; started once before the rounds, ended after them; a key of this run's
  own): the client's wall and CPU, the resident's CPU not counted (it is no child)
- ``worker ready``: ``import planner; planner.warm_up()`` (what a service or batch worker does)
- ``--cold``: ``plan cold``, the first plan with an empty kernel cache (before issue 24's
  fallback: compiles; since: plans on the numpy reference while a background compile starts,
  which is ended after the plan)
- ``--install``: ``pip install --no-deps .`` into a new venv (the runtime dependencies of this
  venv reached by a ``.pth`` file, as after installing the lock) and the first plan from it,
  with this machine's kernel cache (``install + plan``) and with an empty one (``--cold`` too):
  as the CLI plans by default (on the numpy reference, the kernels compiling in the background)
  and with ``--compile`` (compiled in the foreground first)
- ``--make-run``: ``make run`` on a fresh clone (:func:`make_run`)

``--base REV`` checks REV out in a temporary git worktree and runs the same commands there
(its kernels compile there first, ~1-3 minutes), alternating base and head in each round.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TABLE1 = ROOT / "app" / "static" / "examples" / "table1.json"
PY = sys.executable


def timed(cmd: list[str], cwd: Path, env: dict | None = None) -> tuple[float, float]:
    """Run ``cmd``; (wall s, CPU s of the child). Raises on failure, with its stderr."""
    e = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
         "RANGEPLAN_RESIDENT_S": "0", **(env or {})}
    e.pop("PYTHONPATH", None)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run(cmd, cwd=cwd, env=e, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if out.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} in {cwd}: exit {out.returncode}\n{out.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def cases(tree: Path, tmp: Path, cold: bool) -> dict[str, list[str]]:
    out = str(tmp / "x.json")
    c = {"--help": [PY, "-m", "app.cli", "--help"],
         "import planner": [PY, "-c", "import planner"],
         "plan warm": [PY, "-m", "app.cli", "plan", str(TABLE1), "-o", out],
         "worker ready": [PY, "-c", "import planner; planner.warm_up()"]}
    if (tree / "app" / "resident.py").exists():
        c["plan warm, resident"] = c["plan warm"]
    if cold:
        c["plan cold"] = c["plan warm"]
    return c


#: the environment of the resident's row: a key of this run's own (any RANGEPLAN_* variable keys it)
RESIDENT_ENV = {"RANGEPLAN_RESIDENT_S": "600", "RANGEPLAN_RESIDENT_TAG": f"bench-{os.getpid()}"}


def start_resident(tree: Path) -> int:
    """Start the resident planner of ``tree`` (as the CLI does after an in-process plan) and
    wait until it listens; its pid."""
    import socket

    code = ("import os, app.cli; from app import resident; env = dict(os.environ); "
            "d = resident.resident_dir(env, True); "
            "print(resident.start_resident(env), resident.socket_path(d, resident.resident_key(env)))")
    e = {**os.environ, "OPENBLAS_NUM_THREADS": "1", **RESIDENT_ENV}
    e.pop("PYTHONPATH", None)
    out = subprocess.run([PY, "-c", code], cwd=tree, env=e, capture_output=True, text=True, check=True)
    pid, path = out.stdout.split()
    deadline = time.monotonic() + 300
    while True:
        with socket.socket(socket.AF_UNIX) as s:
            try:
                s.connect(path)
                return int(pid)
            except OSError:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"no resident at {path}") from None
        time.sleep(0.2)


def cold_env(tmp: Path, round_: int, tree: Path) -> dict[str, str]:
    """An empty kernel cache for this tree (before issue 24 numba's cache beside the sources:
    NUMBA_CACHE_DIR moves it)."""
    d = tmp / f"cold-{tree.name}-{round_}"
    return {"NUMBA_CACHE_DIR": str(d), "RANGEPLAN_KERNEL_CACHE": str(d)}


def stop_background_compile(cache_root: Path) -> None:
    """End the background compile a cold-cache plan started (its pid in the lock file of
    :mod:`planner.orchestrator.background`; its own session: its process group)."""
    import signal

    for lock in cache_root.glob("*/compile.lock"):
        try:
            pid = json.loads(lock.read_text() or "{}").get("pid")
            if pid:
                os.killpg(int(pid), signal.SIGKILL)
        except (OSError, ValueError):
            pass


def install_rounds(rounds: int, tmp: Path, cold: bool) -> dict[str, list[tuple[float, float]]]:
    """``pip install --no-deps .`` into a new venv, then its first plan of Table I: with this
    machine's kernel cache; with an empty one (``cold``) as the CLI does by default (it plans
    on the numpy reference and compiles the kernels in the background: the issue's goal), and
    with ``--compile`` (compiled in the foreground first). The background compile's CPU is not
    in the CPU column (it is no child waited for; it competes for the CPU meanwhile); it is
    ended after the plan."""
    site = next(Path(sys.prefix).glob("lib/python3*/site-packages"))
    res: dict[str, list[tuple[float, float]]] = {}
    variants: list[tuple[str, str | None, list[str]]] = [("install + plan", None, [])]
    if cold:
        variants += [("install + plan, cold cache (reference meanwhile)", "icold", []),
                     ("install + plan, cold cache, --compile (foreground)", "icomp", ["--compile"])]
    for r in range(rounds):
        for label, cache, flags in variants:
            env = {"RANGEPLAN_KERNEL_CACHE": str(tmp / f"{cache}-{r}")} if cache else {}
            venv = tmp / f"venv-{r}-{len(label)}"
            subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
            vsite = next(venv.glob("lib/python3*/site-packages"))
            (vsite / "deps.pth").write_text(str(site) + "\n")  # the locked dependencies of this venv
            wall0, cpu0 = timed([PY, "-m", "pip", "--python", str(venv / "bin" / "python"), "install", "--quiet",
                                 "--no-deps", str(ROOT)], tmp)
            try:
                wall1, cpu1 = timed([str(venv / "bin" / "rangeplan"), "plan", str(TABLE1), "-o",
                                     str(tmp / "i.json"), *flags], tmp, env)
            finally:
                if cache:
                    stop_background_compile(tmp / f"{cache}-{r}")
            res.setdefault(label, []).append((wall0 + wall1, cpu0 + cpu1))
            res.setdefault(label + ": install only", []).append((wall0, cpu0))
            shutil.rmtree(venv)
    return res


def make_run(tmp: Path) -> None:
    """``make run`` on a fresh clone (``git clone`` of this checkout's committed HEAD), an empty
    kernel cache and data directory, the API and editor on free ports: the seconds to the venv
    installed (pip, from the registry or pip's cache), to ``/ready`` 200 and to the first
    200 of ``POST /v1/plan`` (Table I); then the server and its background compile are ended."""
    import signal
    import socket
    import urllib.error
    import urllib.request

    def port() -> int:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            return s.getsockname()[1]

    clone = tmp / "clone"
    subprocess.run(["git", "clone", "--quiet", str(ROOT), str(clone)], check=True)
    api = port()
    env = {**os.environ, "RANGEPLAN_PORT": str(api), "RANGEPLAN_EDITOR_PORT": str(port()),
           "RANGEPLAN_DATA_DIR": str(tmp / "data"), "RANGEPLAN_KERNEL_CACHE": str(tmp / "kernels"),
           "RANGEPLAN_ACCESS_LOG": "0"}
    env.pop("NUMBA_CACHE_DIR", None)
    env.pop("VIRTUAL_ENV", None)
    log = open(tmp / "make-run.log", "w+")
    body = TABLE1.read_bytes()
    t0 = time.perf_counter()
    proc = subprocess.Popen(["make", "run"], cwd=clone, env=env, stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True)
    marks: dict[str, float] = {}
    try:
        while "plan 200" not in marks:
            if proc.poll() is not None:
                log.seek(0)
                raise RuntimeError(f"make run exited {proc.returncode}: {log.read()[-3000:]}")
            now = time.perf_counter() - t0
            if "installed" not in marks and (clone / ".venv" / ".runtime-stamp").exists():
                marks["installed"] = now
            if "installed" in marks:
                try:
                    if "ready 200" not in marks:
                        with urllib.request.urlopen(f"http://127.0.0.1:{api}/ready", timeout=2) as r:
                            if r.status == 200:
                                marks["ready 200"] = time.perf_counter() - t0
                    req = urllib.request.Request(f"http://127.0.0.1:{api}/v1/plan", data=body, method="POST",
                                                 headers={"Content-Type": "application/json"})
                    with urllib.request.urlopen(req, timeout=60) as r:
                        if r.status == 200:
                            marks["plan 200"] = time.perf_counter() - t0
                            marks["backend"] = json.loads(r.read())["settings"]["backend"] == "compiled"
                except (urllib.error.URLError, OSError):
                    pass
            time.sleep(0.2)
    finally:
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
        stop_background_compile(tmp / "kernels")
    log.seek(0)
    text = log.read()
    print("\n| make run, fresh clone (empty kernel cache) | s |\n|---|---:|")
    print(f"| venv installed (venv, pip upgraded, the lock, -e .) | {marks['installed']:.1f} |")
    print(f"| GET /ready 200 | {marks.get('ready 200', float('nan')):.1f} |")
    print(f"| first POST /v1/plan 200 (Table I, on the {'compiled kernels' if marks['backend'] else 'reference'}) "
          f"| {marks['plan 200']:.1f} |")
    print("\n" + "\n".join(ln for ln in text.splitlines() if "kernels" in ln)[-1500:])


def profile_compile() -> None:
    """Each kernel's compile time in a full warm-up with an empty cache, own and inclusive."""
    code = r"""
import json, sys, time
from numba.core import event as ev
stack, rows = [], []
class L(ev.Listener):
    def on_start(self, e):
        stack.append([e.data["dispatcher"].py_func.__name__, time.perf_counter(), 0.0])
    def on_end(self, e):
        name, t0, child = stack.pop()
        dt = time.perf_counter() - t0
        if stack:
            stack[-1][2] += dt
        rows.append((name, dt, dt - child))
ev.register("numba:compile", L())
import planner
t = time.perf_counter()
planner.warm_up()
print(json.dumps({"total": time.perf_counter() - t, "rows": rows}))
"""
    with tempfile.TemporaryDirectory() as tmp:
        e = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "NUMBA_CACHE_DIR": tmp, "RANGEPLAN_KERNEL_CACHE": tmp}
        out = subprocess.run([PY, "-c", code], cwd=ROOT, env=e, capture_output=True, text=True, check=True)
    data = json.loads(out.stdout.strip().splitlines()[-1])
    own: dict[str, float] = {}
    for name, _, excl in data["rows"]:
        own[name] = own.get(name, 0.0) + excl
    print(f"# warm-up with an empty cache: {data['total']:.1f} s, {len(data['rows'])} compiles; load {load()}")
    print("| kernel | own compile [s] | inclusive [s] |\n|---|---:|---:|")
    for name, incl, excl in sorted(data["rows"], key=lambda r: -r[2]):
        print(f"| {name} | {excl:.2f} | {incl:.2f} |")
    print("\nCOMPILE_COST = " + json.dumps({k: round(v, 2) for k, v in sorted(own.items(), key=lambda kv: -kv[1])}))


WORKERS_CODE = r"""
import json, sys, time
from app.workers import PlanPool
t = time.perf_counter()
pool = PlanPool(workers=1, timeout_s=60, start=sys.argv[1])
def ready(w):
    w.started.wait(300)
    assert w.ready, w.failure
ready(pool._workers[0])
first = time.perf_counter() - t
again = []
for _ in range(int(sys.argv[2])):
    old = pool._workers[0]
    t = time.perf_counter()
    ready(pool._replace(old))
    again.append(time.perf_counter() - t)
    old.kill()
pool.close()
print(json.dumps({"first": first, "again": again}))
"""


def bench_workers(rounds: int) -> None:
    """The service's planning pool (:class:`app.workers.PlanPool`) by start method, one child
    process per method and round: its first worker ready (for the fork server: the fork
    server's own start and warm-up included), then a new worker (what replaces a worker after
    a time limit, a memory error or a crash) ready, ``rounds`` times."""
    print(f"# {os.cpu_count()} CPUs; load average before: {load()}")
    res: dict[str, dict[str, list[float]]] = {}
    for _ in range(rounds):
        for method in ("exec", "forkserver"):
            out = subprocess.run([PY, "-c", WORKERS_CODE, method, "3"], cwd=ROOT, capture_output=True, text=True,
                                 env={**os.environ, "OPENBLAS_NUM_THREADS": "1"}, check=True)
            d = json.loads(out.stdout.strip().splitlines()[-1])
            res.setdefault(method, {"first": [], "again": []})
            res[method]["first"].append(d["first"])
            res[method]["again"] += d["again"]
    print("\n| start | pool's first worker ready [s] | a new worker ready [s] (median) | max [s] |")
    print("|---|---:|---:|---:|")
    for method, v in res.items():
        print(f"| {method} | {statistics.median(v['first']):.2f} | {statistics.median(v['again']):.3f} | "
              f"{max(v['again']):.3f} |")
    print(f"\n# load average after: {load()}")


BREAKDOWN_CODE = r"""
import json, sys, time
rows = []
w0, c0 = time.perf_counter(), time.process_time()
def mark(label):
    global w0, c0
    w, c = time.perf_counter(), time.process_time()
    rows.append((label, w - w0, c - c0))
    w0, c0 = w, c
import numpy
mark("import numpy")
import numba
mark("import numba")
from numba.core.registry import cpu_target
cpu_target.target_context
mark("numba's CPU target context")
if "--refresh" in sys.argv:
    cpu_target.target_context.refresh()
    mark("numba's refresh: every typing and lowering registry")
import pydantic, planner.schema
mark("import pydantic, planner.schema (the models)")
from planner import plan
import planner.orchestrator.plan
mark("import the planner (scipy, shapely, the kernel modules)")
from numba.core import caching
loaded = {}
_load = caching.Cache._load_overload
def load_overload(self, sig, ctx):
    t = time.process_time()
    try:
        return _load(self, sig, ctx)
    finally:
        name = self._py_func.__name__
        loaded[name] = loaded.get(name, 0.0) + time.process_time() - t
caching.Cache._load_overload = load_overload
req = json.loads(open(sys.argv[1]).read())
planner.schema.PlanRequest.model_validate(req)
mark("read and validate the request")
plan(req)
mark("first plan: load the kernels it needs, dispatch, plan")
plan(req)
mark("the same plan again (kernels loaded)")
import app.formats
mark("import app.formats (the output writers)")
print(json.dumps({"rows": rows, "loaded": loaded}))
"""


def breakdown(rounds: int, refresh: bool) -> None:
    """Where a warm ``rangeplan plan table1.json`` spends its time, step by step in one process
    (median of ``rounds`` processes), and the CPU seconds of each kernel's load from the cache;
    ``refresh``: numba's own order (its whole target context refreshed before the first load)."""
    print(f"# load average before: {load()}")
    runs = []
    for _ in range(rounds):
        out = subprocess.run([PY, "-c", BREAKDOWN_CODE, str(TABLE1)] + (["--refresh"] if refresh else []), cwd=ROOT,
                             capture_output=True, text=True, check=True,
                             env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    start = [timed([PY, "-c", "pass"], ROOT) for _ in range(rounds)]
    print("\n| step | wall [s] | CPU [s] |\n|---|---:|---:|")
    print(f"| python start | {statistics.median(w for w, _ in start):.3f} | "
          f"{statistics.median(c for _, c in start):.3f} |")
    for i, (label, _, _) in enumerate(runs[0]["rows"]):
        print(f"| {label} | {statistics.median(r['rows'][i][1] for r in runs):.3f} | "
              f"{statistics.median(r['rows'][i][2] for r in runs):.3f} |")
    names = sorted({k for r in runs for k in r["loaded"]})
    print("\nkernels loaded from the cache by the first plan, CPU s: " + ", ".join(
        f"{n} {statistics.median(r['loaded'].get(n, 0.0) for r in runs):.3f}"
        for n in names))
    print(f"# load average after: {load()}")


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", help="git revision to compare with (a temporary worktree)")
    ap.add_argument("--base-tree", type=Path, help="an existing checkout of the base instead of --base")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--cold", action="store_true", help="also the first plan with an empty kernel cache")
    ap.add_argument("--install", action="store_true", help="also pip install --no-deps . + first plan")
    ap.add_argument("--profile-compile", action="store_true", help="each kernel's compile time, then exit")
    ap.add_argument("--workers", action="store_true", help="the planning pool's workers by start method, then exit")
    ap.add_argument("--breakdown", action="store_true", help="where a warm plan's time goes, then exit")
    ap.add_argument("--refresh", action="store_true", help="with --breakdown: numba's own order of loading")
    ap.add_argument("--load-order", action="store_true", help="first plan's CPU, numba's order against ours")
    ap.add_argument("--make-run", action="store_true", help="make run on a fresh clone to the first answer, then exit")
    args = ap.parse_args()
    if args.make_run:
        print(f"# {os.cpu_count()} CPUs; load average before: {load()}")
        with tempfile.TemporaryDirectory() as tmpdir:
            make_run(Path(tmpdir))
        print(f"# load average after: {load()}")
        return
    if args.profile_compile:
        profile_compile()
        return
    if args.workers:
        bench_workers(args.rounds)
        return
    if args.breakdown:
        breakdown(args.rounds, args.refresh)
        return
    if args.load_order:  # planner._jit no longer skips numba's refresh (public API only, issue 34)
        sys.exit("--load-order is gone: planner._jit loads kernels through numba's public API, which refreshes "
                 "numba's target context first (compare revisions with --base instead)")
    print(f"# {os.cpu_count()} CPUs; load average before: {load()}")
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        trees = [("head", ROOT)]
        residents: list[int] = []  # the resident planners started for the row "plan warm, resident"
        if args.base_tree:
            trees.insert(0, ("base", args.base_tree.resolve()))
        elif args.base:
            base = tmp / "base"
            subprocess.run(["git", "worktree", "add", "--detach", str(base), args.base], cwd=ROOT, check=True,
                           capture_output=True)
            trees.insert(0, ("base", base))
        try:
            for _, tree in trees:  # the kernels of each tree compiled (or loaded) once before timing
                timed([PY, "-c", "import planner; planner.warm_up()"], tree)
            residents += [start_resident(tree) for _, tree in trees if (tree / "app" / "resident.py").exists()]
            results: dict[tuple[str, str], list[tuple[float, float]]] = {}
            for r in range(args.rounds):
                for name, tree in trees:
                    for label, cmd in cases(tree, tmp, args.cold).items():
                        env = (cold_env(tmp, r, tree) if label == "plan cold" else
                               RESIDENT_ENV if label == "plan warm, resident" else None)
                        try:
                            results.setdefault((label, name), []).append(timed(cmd, tree, env))
                        finally:
                            if label == "plan cold":  # the CLI's background compile (issue 24): ended
                                stop_background_compile(Path(env["RANGEPLAN_KERNEL_CACHE"]))
                print(f"# round {r + 1}: load {load()}", flush=True)
            if args.install:
                for label, v in install_rounds(args.rounds, tmp, args.cold).items():
                    results[(label, "head")] = v
        finally:
            import signal

            for pid in residents:
                try:
                    os.kill(pid, signal.SIGTERM)
                except OSError:
                    pass
            if args.base:
                subprocess.run(["git", "worktree", "remove", "--force", str(tmp / "base")], cwd=ROOT,
                               capture_output=True)
    labels = list(dict.fromkeys(k[0] for k in results))
    names = [n for n, _ in trees]
    head = " | ".join(f"{n} wall [s] | {n} CPU [s]" for n in names)
    ratio = " | head / base wall | head / base CPU" if len(names) == 2 else ""
    print(f"\n| what | {head}{ratio} |")
    print("|---|" + "---:|" * (2 * len(names) + (2 if len(names) == 2 else 0)))
    for label in labels:
        cells, med = [], {}
        for n in names:
            v = results.get((label, n))
            if v is None:
                cells += ["", ""]
                continue
            med[n] = (statistics.median(w for w, _ in v), statistics.median(c for _, c in v))
            cells += [f"{med[n][0]:.2f}", f"{med[n][1]:.2f}"]
        if len(names) == 2 and len(med) == 2:
            cells += [f"{med['head'][0] / med['base'][0]:.2f}x", f"{med['head'][1] / med['base'][1]:.2f}x"]
        elif len(names) == 2:
            cells += ["", ""]
        print(f"| {label} | " + " | ".join(cells) + " |")
    print(f"\n# load average after: {load()}; {(time.perf_counter() - t_start) / 60:.1f} min")


if __name__ == "__main__":
    main()
