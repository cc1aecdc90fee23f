"""Certification run (issue 20): seeded random cases (layouts with rectangles, triangles,
circles and holed polygons, square and triangle cells, clearances, start and end anywhere,
near obstacles, corners and the reach limit; segment corridors of random boxes and psi
ranges; both robots), each planned in the default (constrained) and the paper mode, every
answer certified by the independent checker of ``tests/certify_support.py`` (plans: corridor,
limits, no overshoot, settling, every metric recomputed; errors: confirmed or their advice
applied), and the compute time against the work estimate.

Prints a table of outcomes by code and mode, the problems found (needless failures, wrong
advice, uncertified plans) and the largest measured / estimated time.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/certify.py [--cases 10000] [--seed 20] [--workers 2]

``--users``: the cases of where users go instead (issue 31 goal 1,
:func:`tests.certify_support.user_case`: robots of 3-6 legs, masses x0.1-x10, friction up to
2000 N s/m, leg-speed limits; Ts 1-10 ms with and without N; speeds 0.001-5 m/s, total times,
``fastest`` on every corridor shape, force rates 20 N/s to off; psi ranges), the constrained
mode only, each case ``numpy.random.default_rng([seed, i])``, under a server's compute limit
(``--limit``, 30 s: a request estimated over it is refused up front, ``too_much_work``).

``--profile``: where the run's CPU went, by category (the plan by outcome, ``fastest`` apart;
the planner's advice search behind a refusal; the checker; the confirmation of refusals; the
estimates; calibration; retiming; the workers' start), as a table at the end.

``--resume FILE``: the run in slices across sittings (issue 31 goal 1: 10 000 cases where users
go take hours on 2 cores). Each case's record (outcome, problem, CPU time and estimate, its CPU
by category; the case itself where it has a problem or a plan over 1.3x) is appended to FILE as
it finishes; the cases FILE already holds for the same run (generator, seed, ``--limit``) and
the same code (:func:`code_key`: a hash of ``planner/`` and the checker's modules, uncommitted
edits included) are skipped. ``--summary FILE [FILE ...]`` prints the table of every case the
files hold, by run and code (a case recorded twice counted once): outcomes, checker problems,
the largest CPU / estimate of a plan, plans over 1.5x, CPU s.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/certify.py --users --seed 31 --cases 10000 \\
        --workers 2 --minutes 60 --resume users31.jsonl
    .venv/bin/python benchmarks/certify.py --summary users31.jsonl

``--refusals RATIOS``: the infeasible cases of a run's ``--ratios`` file, each refused request
tried with :data:`tests.certify_support.REMEDIES` (the advice's setting, twice the horizon,
``fastest``, 8 plant sub-steps; :func:`tests.certify_support.try_remedies`): a refusal is
needless where one of them plans (certified) and the advice does not name one that plans.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import collections  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor, as_completed  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from tests.certify_support import (  # noqa: E402
    CPU,
    REMEDIES,
    certify_case,
    cpu_category,
    cpu_spent,
    draw_case,
    try_remedies,
    user_case,
)

#: the machine's speed now against the reference machine of the work estimate: Table I's CPU
#: time measured in each worker every CALIBRATE cases over its time on the quiet reference
#: machine (REFERENCE_S, benchmarks/README.md: constrained ~17-20 ms, paper ~5 ms; the shared
#: 2-core machine's speed changes through a run, and a VM's CPU time counts stolen time)
CALIBRATE = 50
REFERENCE_S = {"constrained": 0.020, "paper": 0.006}
_SPEED: dict[str, float] = {}
_SINCE = [CALIBRATE]


def _calibrate() -> None:
    from planner import plan
    from tests.support import TABLE1, with_settings

    for mode in ("constrained", "paper"):
        req = with_settings(TABLE1, mode=mode)
        best = min(_cpu(plan, req) for _ in range(3))
        _SPEED[mode] = best / REFERENCE_S[mode]


def _cpu(f, *args) -> float:
    t0 = time.process_time()
    f(*args)
    return time.process_time() - t0


#: this worker's CPU time from its start to the end of :func:`_init` (interpreter, imports,
#: kernels loaded or compiled): reported with its first case, then None
_START: list[float | None] = [None]


def _init() -> None:
    from planner import warm_up

    warm_up()
    _time_advice_search()
    _START[0] = time.process_time()


def _time_advice_search() -> None:
    """Count the planner's advice search behind a refusal (``_more_time_advice``,
    ``_other_advice``: the candidates it plans) apart from the plan that was refused, and its
    DAQP calls apart from the rest, in the profile (:data:`tests.certify_support.CPU`): timing
    wrappers, nothing else changes."""
    import importlib

    plan_module = importlib.import_module("planner.orchestrator.plan")  # (the package exports the function)

    for name in ("_more_time_advice", "_other_advice"):
        real = getattr(plan_module, name)
        if getattr(real, "_timed", False):
            continue

        def timed(*args, _real=real, **kw):
            outer = cpu_category() or ""
            if not outer.startswith("plan"):  # (a retiming's or a confirmation's plan: theirs)
                return _real(*args, **kw)
            with cpu_spent("advice search" + (" fastest" if outer.endswith("fastest") else "")):
                return _real(*args, **kw)

        timed._timed = True  # type: ignore[attr-defined]
        setattr(plan_module, name, timed)
    # the DAQP calls (the QP fallback of the compiled stage-wise solve, the slack problem): in
    # their own category beside the one they ran in ("plan infeasible: DAQP", ...)
    qp_module = importlib.import_module("planner.constraints.qp")
    real_qp = qp_module.solve_qp
    if not getattr(real_qp, "_timed", False):

        def timed_qp(*args, **kw):
            with cpu_spent(": DAQP"):
                return real_qp(*args, **kw)

        timed_qp._timed = True  # type: ignore[attr-defined]
        setattr(qp_module, "solve_qp", timed_qp)  # noqa: B010


def _run(job: tuple[int, int, float | None]) -> tuple[dict, dict, dict]:
    """Case ``i`` of ``seed`` certified: the case, its records by mode, and what it cost:
    ``{"cpu_s": the case's CPU time, "cpu": by category (tests.certify_support.CPU),
    "start_s": the worker's start-up CPU (its first case only, else None)}``."""
    seed, i, users_limit = job
    t_case = time.process_time()
    CPU.clear()
    start, _START[0] = _START[0], None
    # drawn here: the workers draw in parallel
    with cpu_spent("case building"):
        case = user_case(np.random.default_rng([seed, i])) if users_limit is not None else draw_case(seed, i)
    if _SINCE[0] >= CALIBRATE:
        with cpu_spent("calibration"):
            _calibrate()
        _SINCE[0] = 0
    _SINCE[0] += 1
    try:
        out = (certify_case(case, ("constrained",), work_limit_s=users_limit) if users_limit is not None
               else certify_case(case))
    except Exception as exc:  # a crash is a finding, not the end of the run
        out = {"constrained": {"outcome": "crash", "problem": repr(exc), "index": i},
               "paper": {"outcome": "skipped", "index": i}}
        return case, out, _cost(t_case, start)
    for mode, rec in out.items():
        rec["speed"] = _SPEED.get(mode, 1.0)
        rec["index"] = i  # the case is user_case(default_rng([seed, i])) or draw_case(seed, i): --only i
        with cpu_spent("retiming (over 1.5x)"):
            _retime(case, mode, rec)
    return case, out, _cost(t_case, start)


def _cost(t_case: float, start: float | None) -> dict:
    return {"cpu_s": time.process_time() - t_case, "cpu": dict(CPU), "start_s": start}


def _retime(case: dict, mode: str, rec: dict) -> None:
    """A case measured over 1.5x its estimate (with its advice bound for an error) is timed
    twice more, right after Table I is timed again for the machine's speed, and keeps the
    least CPU time at that speed: a single timing on a shared machine catches page faults,
    collections and the other processes' cache misses, and the VM's speed drifts up to 2x
    between calibrations (every CALIBRATE cases); ``first`` keeps the first timing (at the
    speed of its own calibration: ``first_speed``), reported beside it."""
    from planner import PlannerError, plan
    from tests.certify_support import _with

    est, sec = rec.get("estimate"), rec.get("seconds")
    if not est or not sec:
        return
    bound = est if rec["outcome"] == "ok" else est + (rec.get("advice") or 0.0)
    if sec / rec["speed"] / bound <= 1.5:
        return
    rec["first"], rec["first_speed"] = sec, rec["speed"]
    req = _with(case, mode=mode)
    _calibrate()
    rec["speed"] = _SPEED.get(mode, 1.0)
    again = []
    for _ in range(2):
        t0 = time.process_time()
        try:
            plan(req)
        except PlannerError:
            pass
        again.append(time.process_time() - t0)
    rec["seconds"] = min(again)


def _remedies(job: tuple[dict, str, float]) -> tuple[dict, str, dict[str, str], float]:
    from planner import PlannerError, plan

    case, message, limit = job
    t0 = time.process_time()
    try:
        if len(message) >= 300:  # cut in the log (runs before the log kept whole messages): refused again
            try:
                plan({**case, "settings": {**case.get("settings", {}), "mode": "constrained"}}, work_limit_s=limit)
            except PlannerError as exc:
                message = str(exc)
        out = try_remedies(case, message, limit)
    except Exception as exc:  # a crash is a finding
        out = {r: f"crash {exc!r}"[:80] for r in REMEDIES}
    return case, message, out, time.process_time() - t0


def refusals(path: Path, workers: int, limit: float, minutes: float, log_path: Path | None = None) -> None:
    """The ``--refusals`` survey (module docstring): prints a table of the remedies' outcomes
    and the needless refusals; ``log_path``: each case's remedies as they come (JSON lines)."""
    jobs = []
    for line in path.open():
        rec = json.loads(line)
        if rec.get("outcome") == "infeasible" and rec.get("mode", "constrained") == "constrained":
            jobs.append((rec["case"], rec.get("message") or "", limit))
    t0 = time.perf_counter()
    deadline = t0 + 60 * minutes
    counts: dict[str, collections.Counter] = {r: collections.Counter() for r in REMEDIES}
    needless, wrong, done, cpu = [], [], 0, 0.0
    log = log_path.open("w") if log_path is not None else None
    # (as they complete: one slow case does not hold the others back; at the deadline the cases
    # still running are stopped and the table printed)
    pool = ProcessPoolExecutor(workers, initializer=_init)
    futures = [pool.submit(_remedies, job) for job in jobs]
    try:
        for future in as_completed(futures, timeout=max(1.0, deadline - time.perf_counter())):
            case, message, out, sec = future.result()
            done += 1
            if log is not None:
                log.write(json.dumps({"remedies": out, "cpu": sec, "message": message, "case": case}) + "\n")
                log.flush()
            cpu += sec
            for r, v in out.items():
                counts[r][v] += 1
            if out["advice"] != "ok" and any(v == "ok" for v in out.values()):
                needless.append((case, message, out))
            if out["advice"] not in ("ok", "none"):
                wrong.append((case, message, out))
    except TimeoutError:
        pass
    _stop(pool, futures)
    print(f"\n{done} of {len(jobs)} refused cases tried in {(time.perf_counter() - t0) / 60:.1f} min "
          f"({cpu:.0f} CPU s; plans over {limit:g} s estimated not tried: too_much_work)\n")
    outcomes = sorted({v for c in counts.values() for v in c})
    print("| remedy | " + " | ".join(outcomes) + " |\n|---|" + "---|" * len(outcomes))
    for r in REMEDIES:
        print(f"| {r} | " + " | ".join(str(counts[r][v]) for v in outcomes) + " |")
    print(f"\nneedless refusals (a remedy plans, the advice names none that does): {len(needless)}; "
          f"advice that does not plan: {len(wrong)}")
    for case, message, out in needless + wrong:
        st = json.dumps(case.get("settings", {}))
        robot = case["robot"] if isinstance(case["robot"], str) else (
            f"{case['robot']['name']} {case['robot']['platform']['mass']:.3g} kg "
            f"{case['robot']['legs']['friction']:g} N s/m")
        print(f"  {robot}, {len(case['segments'])} segments {st}: {out}\n    {message[:400]}")
    sys.stdout.flush()


def _stop(pool: ProcessPoolExecutor, futures: list) -> int:
    """Cancel the cases not started and terminate the workers still planning one (this run's
    own processes): the run ends at its deadline, not when its slowest case does. Returns how
    many cases were still running."""
    running = sum(1 for f in futures if f.running())
    procs = list((getattr(pool, "_processes", None) or {}).values())  # the pool's own workers (shutdown forgets them)
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        if proc.is_alive():
            proc.terminate()
    for proc in procs:
        proc.join(5)
    return running


# ---------------------------------------------------------------- profile, resume, summary

#: the files whose content decides a case's verdict: a record counts for a run only if made by
#: the same content (:func:`code_key`)
CODE_FILES = ("planner/**/*.py", "planner/data/*.json", "tests/certify_support.py", "tests/advice_support.py",
              "tests/support.py")


def code_key() -> str:
    """A hash of the planner's and the checker's source (:data:`CODE_FILES`), uncommitted
    edits included: records made by other code are not summed with these."""
    h = hashlib.sha256()
    for path in sorted({p for pattern in CODE_FILES for p in ROOT.glob(pattern)}):
        h.update(str(path.relative_to(ROOT)).encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def run_key(seed: int, users: bool, limit: float | None) -> dict:
    """What makes two records the same case of the same run: the generator, the seed, the
    compute limit, the code (:func:`code_key`)."""
    return {"users": bool(users), "seed": int(seed), "limit": limit, "code": code_key()}


def _lines(path: Path):
    """The records of a --resume file (a line cut by a run that was stopped mid-write is skipped)."""
    if not path.exists():
        return
    with path.open() as f:
        for line in f:
            try:
                yield json.loads(line)
            except json.JSONDecodeError:
                continue


def _append(path: Path):
    """``path`` opened to append records, after a newline if a stopped run left its last line cut."""
    ends_cut = path.exists() and path.stat().st_size > 0 and path.read_bytes()[-1:] != b"\n"
    f = path.open("a")
    if ends_cut:
        f.write("\n")
    return f


def _held(path: Path, run: dict):
    """The case indices ``path`` holds for ``run``."""
    for rec in _lines(path):
        if rec.get("run") == run:
            yield int(rec["index"])


def _record(run: dict, case: dict, out: dict, cost: dict) -> dict:
    """One case's line of a --resume file: its run, index, records by mode, CPU by category;
    the case itself where it has a problem or a plan over 1.3x its estimate (the others are
    drawn again from (seed, index))."""
    keep = any(rec.get("problem") or rec.get("outcome") == "crash" or _ratio(rec) > 1.3 for rec in out.values())
    i = next((rec["index"] for rec in out.values() if "index" in rec), None)
    return {"run": run, "index": i, "modes": out, **cost, "case": case if keep else None}


def _ratio(rec: dict) -> float:
    """A plan's CPU time over its estimate at the reference machine's speed (0: not a plan)."""
    est, sec = rec.get("estimate"), rec.get("seconds")
    if rec.get("outcome") != "ok" or not est or not sec:
        return 0.0
    return sec / rec.get("speed", 1.0) / est


def print_profile(costs: list[dict], wall: float | None = None, workers: int = 1) -> None:
    """The table of where the CPU went (:data:`tests.certify_support.CPU`), summed over cases."""
    total = sum(c["cpu_s"] for c in costs)
    by: collections.Counter = collections.Counter()
    cases_with: collections.Counter = collections.Counter()
    for c in costs:
        for k, v in c["cpu"].items():
            by[k] += v
            cases_with[k] += 1
        by["harness glue (the rest of a case)"] += c["cpu_s"] - sum(c["cpu"].values())
    starts = [c["start_s"] for c in costs if c.get("start_s") is not None]
    n = max(1, len(costs))
    print(f"\nwhere the CPU went: {len(costs)} cases, {total:.1f} CPU s in the cases ({total / n:.2f} per case)"
          + (f", {wall:.0f} s wall on {workers} workers" if wall is not None else "")
          + f"; worker start (interpreter, imports, kernels loaded): {sum(starts):.1f} CPU s over {len(starts)}")
    print("| category | cases | CPU s | share | per case in it |\n|---|---|---|---|---|")
    for k, v in sorted(by.items(), key=lambda kv: -kv[1]):
        m = cases_with[k] or len(costs)
        print(f"| {k} | {cases_with[k] or '-'} | {v:.1f} | {100 * v / max(total, 1e-9):.1f} % | {v / m:.3f} |")


def summary(paths: list[Path]) -> None:
    """The table of every case of every run the --resume files hold (a case recorded twice for
    the same run, by two sittings that overlapped, counted once): outcomes, checker problems,
    the largest CPU / estimate of a plan, CPU s."""
    runs: dict[str, dict[int, dict]] = {}
    for path in paths:
        for rec in _lines(path):
            runs.setdefault(json.dumps(rec["run"], sort_keys=True), {}).setdefault(int(rec["index"]), rec)
    now = code_key()
    print("| seed | generator | code | cases | outcomes | checker problems | plans | largest CPU / estimate "
          "(case) | over 1.5x | CPU s | CPU s / case |\n|---|---|---|---|---|---|---|---|---|---|---|")
    for key, cases in runs.items():
        run = json.loads(key)
        outcomes: collections.Counter = collections.Counter()
        problems, ratios, cpu = [], [], 0.0
        for i, rec in sorted(cases.items()):
            cpu += rec["cpu_s"]
            for mode, r in rec["modes"].items():
                outcomes[r["outcome"] if len(rec["modes"]) == 1 else f"{mode} {r['outcome']}"] += 1
                if r.get("problem"):
                    problems.append((i, mode, r["outcome"], r["problem"]))
                if _ratio(r):
                    ratios.append((_ratio(r), i))
        worst = max(ratios, default=(0.0, None))
        gen = f"users (limit {run['limit']:g} s)" if run["users"] else "draw_case"
        code = run["code"] + (" (this code)" if run["code"] == now else "")
        print(f"| {run['seed']} | {gen} | {code} | {len(cases)} | "
              + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())) + f" | {len(problems)} | {len(ratios)} | "
              f"{worst[0]:.2f} ({worst[1]}) | {sum(r > 1.5 for r, _ in ratios)} | {cpu:.0f} | "
              f"{cpu / max(1, len(cases)):.2f} |")
        for i, mode, code_, what in problems[:20]:
            print(f"  case {i} {mode} {code_}: {what[:300]}")
        if cases:
            per = cpu / len(cases)
            print(f"  at {per:.2f} CPU s a case, 10 000 cases take {per * 1e4 / 2 / 3600:.1f} h on 2 cores "
                  "(both busy with this run alone)")
    if len(runs) == 1:
        print_profile([rec for cases in runs.values() for rec in cases.values()])
    keys = list(runs)
    for a, b in zip(keys, keys[1:]):
        _compare(json.loads(a), runs[a], json.loads(b), runs[b])


def _compare(run_a: dict, a: dict[int, dict], run_b: dict, b: dict[int, dict]) -> None:
    """The verdicts of two runs of the same cases (another code: before / after a change) side
    by side: the cases both hold, those whose outcome or checker verdict differ, those whose
    refusal message differs (the advice search is bounded by the compute limit in wall time:
    on a loaded machine it may stop sooner), and the CPU of the common cases."""
    if (run_a["users"], run_a["seed"], run_a["limit"]) != (run_b["users"], run_b["seed"], run_b["limit"]):
        return
    common = sorted(set(a) & set(b))
    if not common:
        return

    def verdict(rec: dict) -> list:
        return [(m, r["outcome"], r.get("problem")) for m, r in sorted(rec["modes"].items())]

    def messages(rec: dict) -> list:
        return [r.get("message") or "" for _, r in sorted(rec["modes"].items())]

    differ = [i for i in common if verdict(a[i]) != verdict(b[i])]
    told = [i for i in common if messages(a[i]) != messages(b[i])]
    cpu_a, cpu_b = sum(a[i]["cpu_s"] for i in common), sum(b[i]["cpu_s"] for i in common)
    print(f"\ncode {run_a['code']} -> {run_b['code']} (seed {run_a['seed']}): {len(common)} cases in both; "
          f"outcome or checker verdict differs in {len(differ)} {differ[:20]}; refusal message differs in "
          f"{len(told)} {told[:20]}; CPU {cpu_a:.0f} -> {cpu_b:.0f} s ({cpu_a / len(common):.2f} -> "
          f"{cpu_b / len(common):.2f} a case)")
    for i in differ[:10]:
        print(f"  case {i}: {verdict(a[i])} -> {verdict(b[i])}")


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--cases", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--minutes", type=float, default=30.0,
                    help="stop after this long [min] (the cases still running then are stopped)")
    ap.add_argument("--only", type=str, default=None,
                    help="only these case indices (comma-separated: a run's cases again, e.g. those over 1.5x)")
    ap.add_argument("--problems", type=Path, default=None, help="write the problem cases here (JSON lines)")
    ap.add_argument("--users", action="store_true", help="the cases of where users go (module docstring)")
    ap.add_argument("--limit", type=float, default=30.0, help="with --users: the compute limit [s]")
    ap.add_argument("--ratios", type=Path, default=None, help="write every case's outcome and ratio here (JSON lines; "
                    "with --refusals: each case's remedies)")
    ap.add_argument("--refusals", type=Path, default=None,
                    help="a --ratios file: try the remedies on its infeasible cases (module docstring)")
    ap.add_argument("--profile", action="store_true",
                    help="print where the run's CPU went, by category (plan by outcome, advice search, checker, ...)")
    ap.add_argument("--resume", type=Path, default=None,
                    help="append each case's record to this file as it finishes; skip the cases it already holds "
                    "for the same run (seed, --users, --limit) and code (module docstring)")
    ap.add_argument("--summary", type=Path, nargs="+", default=None,
                    help="print the table of --resume files (every case of each run and code) and exit")
    args = ap.parse_args()
    if args.summary is not None:
        summary(args.summary)
        return
    if args.refusals is not None:
        refusals(args.refusals, args.workers, args.limit, args.minutes, args.ratios)
        return
    users_limit = args.limit if args.users else None
    run = run_key(args.seed, args.users, users_limit)
    held = set(_held(args.resume, run)) if args.resume is not None else set()
    resume = _append(args.resume) if args.resume is not None else None
    costs: list[dict] = []
    t0 = time.perf_counter()
    counts: dict[str, collections.Counter] = {"constrained": collections.Counter(), "paper": collections.Counter()}
    problems, worst, done = [], (0.0, None), 0
    high: list[tuple] = []  # plans over 1.3x their estimate
    first_over: collections.Counter = collections.Counter()  # over 1.5x at the first timing
    ratios: dict[str, list[float]] = {"constrained": [], "paper": []}
    err_ratios: dict[str, list[float]] = collections.defaultdict(list)
    deadline = t0 + 60 * args.minutes
    log = args.ratios.open("w") if args.ratios else None
    # as they complete, up to the deadline: the in-order map waited on one slow case past
    # --minutes (two runs of 15-18 min overran with a case still running); the cases still
    # running at the deadline are stopped (their workers terminated) and counted apart
    pool = ProcessPoolExecutor(args.workers, initializer=_init)
    indices = [int(i) for i in args.only.split(",")] if args.only else range(args.cases)
    skipped = sum(1 for i in indices if i in held)
    futures = [pool.submit(_run, (args.seed, i, users_limit)) for i in indices if i not in held]
    try:
        for future in as_completed(futures, timeout=max(1.0, deadline - time.perf_counter())):
            case, out, cost = future.result()
            done += 1
            costs.append(cost)
            if resume is not None:
                resume.write(json.dumps(_record(run, case, out, cost)) + "\n")
                resume.flush()
            for mode, rec in out.items():
                counts[mode][rec["outcome"]] += 1
                if log is not None:
                    log.write(json.dumps({"mode": mode, **{k: v for k, v in rec.items() if k != "message"},
                                          "message": rec.get("message") or "", "case": case}) + "\n")
                    log.flush()
                if rec.get("problem"):
                    problems.append((mode, rec["outcome"], rec["problem"], case))
                est, sec = rec.get("estimate"), rec.get("seconds")
                if rec.get("first"):
                    first_over[mode if rec["outcome"] == "ok" else f"{mode} {rec['outcome']}"] += 1
                if est and sec and rec["outcome"] == "ok":
                    # measured / estimated on the reference machine (the time now over the speed now)
                    ratio = sec / rec["speed"] / est
                    ratios[mode].append(ratio)
                    if ratio > worst[0]:
                        worst = (ratio, (mode, sec, est, case))
                    if ratio > 1.3:
                        high.append((ratio, mode, sec, est, case))
                elif est and sec:  # an error: its advice checks are bounded by the estimate's advice part
                    est += rec.get("advice") or 0.0
                    err_ratios[f"{mode} {rec['outcome']}"].append(sec / rec["speed"] / est)
            if done % 500 == 0:
                print(f"  {done} cases, {time.perf_counter() - t0:.0f} s, {len(problems)} problems", flush=True)
    except TimeoutError:
        pass
    running = _stop(pool, futures)
    if log is not None:
        log.close()
    if resume is not None:
        resume.close()
    wall = time.perf_counter() - t0
    codes = sorted(set(counts["constrained"]) | set(counts["paper"]))
    print(f"\n{done} cases certified in {wall / 60:.1f} min on {args.workers} workers (seed {args.seed}; "
          f"{running} still running at the deadline, stopped"
          + (f"; {skipped} already in {args.resume}, skipped" if args.resume is not None else "") + ")\n")
    print("| outcome | constrained (default) | paper |\n|---|---|---|")
    for c in codes:
        print(f"| {c} | {counts['constrained'][c]} | {counts['paper'][c]} |")
    print(f"\nproblems (needless failures, wrong advice, uncertified answers): {len(problems)}")
    for mode, code, what, _case in problems[:20]:
        print(f"  {mode} {code}: {what[:300]}")
    print("\nmeasured CPU time / work estimate of the plans, on the reference machine (the CPU time over the "
          "machine's speed now: Table I's time now over its quiet time, REFERENCE_S)")
    print("(a case over 1.5x is timed twice more right after a new calibration and keeps its least time; "
          "'first over 1.5': at its first timing)")
    print("| mode | plans | smallest | median | 99th percentile | largest | over 1.5 | first over 1.5 |\n"
          "|---|---|---|---|---|---|---|---|")
    for mode, r in ratios.items():
        if r:
            a = sorted(r)
            print(f"| {mode} | {len(a)} | {a[0]:.2f} | {a[len(a) // 2]:.2f} | "
                  f"{a[min(len(a) - 1, int(0.99 * len(a)))]:.2f} | {a[-1]:.2f} | {sum(x > 1.5 for x in a)} | "
                  f"{first_over[mode]} |")
    for what, r in sorted(err_ratios.items()):
        a = sorted(r)
        print(f"| {what} (with its advice checks, over estimate + advice bound) | {len(a)} | {a[0]:.2f} | "
              f"{a[len(a) // 2]:.2f} | {a[min(len(a) - 1, int(0.99 * len(a)))]:.2f} | {a[-1]:.2f} | "
              f"{sum(x > 1.5 for x in a)} | {first_over[what]} |")
    if worst[1] is not None:
        mode, sec, est, case = worst[1]
        print(f"\nlargest: {worst[0]:.2f} ({mode}: {sec:.3f} s CPU, {est:.3f} s estimated): {json.dumps(case)[:400]}")
    for ratio, mode, sec, est, case in sorted(high, key=lambda h: -h[0])[:10]:
        what = "layout" if case.get("layout") else f"{len(case['segments'])} segments"
        print(f"  {ratio:.2f}x {mode} {case['robot']} {what} {json.dumps(case.get('settings', {}))}: "
              f"{sec:.3f} s CPU, {est:.3f} s estimated")
    if args.problems:
        with args.problems.open("w") as f:
            for mode, code, what, case in problems:
                f.write(json.dumps({"mode": mode, "code": code, "problem": what, "case": case}) + "\n")
    if args.profile:
        print_profile(costs, wall, args.workers)
    if args.resume is not None:
        print(f"\nthe whole of {args.resume}:")
        summary([args.resume])


if __name__ == "__main__":
    main()
