"""Batch throughput: 1000 Table I-sized corridors on 1 process, a local pool and a 2-worker
Dask cluster, side by side in one run.

For each mode (paper, constrained) and each round, the three engines run one after another
(interleaved, so a change in the machine's load hits all three alike), each in a fresh
child process that opens its engine, warms it (workers start and load the compiled kernels:
not timed), then times ``app.batch.cli.run_batch`` over the same JSON Lines file of
corridor variants, writing one JSON result per item and summary.csv to a temporary
directory, exactly as ``rangeplan batch`` does. Engines:

* ``1 process``: the calling process plans the items one after another (``--inline``);
* ``local pool``: ``--workers`` processes (``ProcessPoolExecutor``, default 2);
* ``dask``: a ``distributed.LocalCluster`` of ``--workers`` worker processes x 1 thread
  (its scheduler in the child process, as with a scheduler on the client's host);
* with ``--engines``, also ``local pool, results sent`` and ``dask, results sent``: the same
  with ``--no-worker-writes`` (every result travels back to the main process, which writes
  it: what every run did before the workers wrote their own result files).

Prints, per mode, the median over rounds of: throughput (plans/s), efficiency against one
process (throughput ratio; the goal with 2 workers on 2 cores is >= 1.8), Dask's overhead
against the local pool in wall time (goal <= 15 %) and in CPU (all processes' CPU per plan),
CPU per plan of the main process (client, and for Dask its scheduler) and of all processes
together, and peak resident memory of the main process and of the largest worker. Ratios are
the median of each round's ratio. Also the load average before and after: on a shared
machine wall-clock ratios move with the other jobs, so the table also gives the speed-up the
CPU figures allow on idle cores, ``min(cores x cpu_1 / cpu_all, workers x cpu_1 /
cpu_worker)`` where ``cpu_1`` is one process's CPU per plan (a bound that no other job's load
changes much; CPU time per plan still grows by a few per cent when other jobs share the
caches).

    .venv/bin/python benchmarks/bench_batch.py --rounds 3         # the goal table: 1000 corridors, both modes
    .venv/bin/python benchmarks/bench_batch.py --items 400 --rounds 3 --modes paper \
        --engines "1 process" "local pool" dask "local pool, results sent" "dask, results sent"
    .venv/bin/python benchmarks/bench_batch.py --dask-config '{"distributed.worker.profile.enabled": false}'
"""

from __future__ import annotations

import argparse
import copy
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

ROOT = Path(__file__).resolve().parent.parent
TABLE1 = json.loads((ROOT / "app" / "static" / "examples" / "table1.json").read_text())
#: the engines of the goal table, and the same with every result sent back to the main process
#: (``--no-worker-writes``: what every run did before workers wrote their own result files)
ENGINES = ("1 process", "local pool", "dask")
SENT = ("local pool, results sent", "dask, results sent")


def corridors(n: int, mode: str) -> list[dict]:
    """``n`` Table I variants: the corridor shifted on a grid of +-10 mm in x and y and every
    free segment widened or narrowed by up to 2 mm (12 segments, 288 samples each)."""
    out = []
    for i in range(n):
        r = copy.deepcopy(TABLE1)
        dx, dy = 0.002 * (i % 11 - 5), 0.002 * ((i // 11) % 11 - 5)
        grow = 0.001 * ((i // 121) % 5 - 2)
        r["name"] = f"variant {i}"
        for k, s in enumerate(r["segments"]):
            free = s["lower"] != s["upper"]
            for key, sign in (("lower", -1), ("upper", 1)):
                s[key][0] += dx + (sign * grow if free and k % 2 else 0.0)
                s[key][1] += dy
        r["settings"] = {"mode": mode}  # named: the default mode is constrained since issue 17
        out.append(r)
    return out


def _rss_mb(ru_maxrss_kb: int) -> float:
    return ru_maxrss_kb / 1024.0


def worker_cpu(eng) -> float:
    """CPU seconds the engine's worker processes have used so far (0 for inline)."""
    if eng.name == "local":
        import psutil

        return sum(sum(psutil.Process(pid).cpu_times()[:2]) for pid in eng.pids())
    if eng.name == "dask":
        return sum(eng.client.run(time.process_time).values())
    return 0.0


def child(engine: str, workers: int, jsonl: str, out: str, warm_jsonl: str) -> dict:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from app.batch.cli import run_batch
    from app.batch.executors import InlineEngine, LocalEngine

    cluster = None
    writes = not engine.endswith(", results sent")
    engine = engine.removesuffix(", results sent")
    if engine == "1 process":
        eng = InlineEngine()
        from planner import warm_up
        warm_up()
    elif engine == "local pool":
        eng = LocalEngine(workers)
    else:
        from distributed import LocalCluster

        from app.batch.cluster import DaskEngine

        if os.environ.get("BENCH_DASK_CONFIG"):  # --dask-config: the workers get it from their nannies
            import dask

            dask.config.set(json.loads(os.environ["BENCH_DASK_CONFIG"]))
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, env={"OPENBLAS_NUM_THREADS": "1",
                                                            "PYTHONPATH": str(ROOT)})
        eng = DaskEngine(cluster.scheduler_address)
    # warm: workers started, kernels loaded, a first small batch through the whole path
    run_batch([warm_jsonl], Path(out) / "warm", engine=eng, progress="none", resume=False, worker_writes=writes)
    w0 = worker_cpu(eng)
    t0, cpu0 = time.perf_counter(), time.process_time()
    res = run_batch([jsonl], Path(out) / "run", engine=eng, progress="none", resume=False, worker_writes=writes)
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    wcpu = worker_cpu(eng) - w0
    worker_rss = 0.0
    if engine == "dask":
        def peak() -> int:
            import resource as r
            return r.getrusage(r.RUSAGE_SELF).ru_maxrss

        worker_rss = max(_rss_mb(v) for v in eng.client.run(peak).values())  # type: ignore[attr-defined]
        eng.close()
        assert cluster is not None
        cluster.close()
    elif engine == "local pool":
        eng.close()
        worker_rss = _rss_mb(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
    rows = (Path(out) / "run" / "summary.csv").read_text().splitlines()[1:]
    energy = 0.0
    for p in sorted((Path(out) / "run").glob("*.json")):
        energy += json.loads(p.read_bytes())["metrics"]["energy"]
    return {"wall_s": wall, "main_cpu_ms": 1e3 * cpu / max(1, len(rows)),
            "worker_cpu_ms": 1e3 * wcpu / max(1, len(rows)), "ok": res["ok"], "failed": res["failed"],
            "rows": len(rows),
            "main_rss_mb": _rss_mb(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss), "worker_rss_mb": worker_rss,
            "energy_sum": energy, "lost": res["lost_workers"]}


def _all_cpu(run: dict) -> float:
    return run["main_cpu_ms"] + run["worker_cpu_ms"]


def run_child(engine: str, workers: int, jsonl: Path, warm: Path) -> dict:
    out = Path(tempfile.mkdtemp(prefix="bench-batch-"))
    try:
        env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
        p = subprocess.run([sys.executable, __file__, "--child", engine, "--workers", str(workers), "--jsonl",
                            str(jsonl), "--warm", str(warm), "--out", str(out)], capture_output=True, text=True,
                           env=env, timeout=7200)
        if p.returncode != 0:
            raise RuntimeError(f"{engine}: {p.stderr[-2000:]}")
        return json.loads(p.stdout.strip().splitlines()[-1])
    finally:
        shutil.rmtree(out, ignore_errors=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--items", type=int, default=1000)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--modes", nargs="+", default=["paper", "constrained"])
    ap.add_argument("--engines", nargs="+", default=list(ENGINES), choices=[*ENGINES, *SENT],
                    help="engines to run (default: the goal table's three; add the 'results sent' ones to see "
                         "what the workers' own result files save)")
    ap.add_argument("--dask-config", metavar="JSON", help="Dask settings for the LocalCluster, e.g. "
                    "'{\"distributed.worker.profile.enabled\": false}' (default: Dask's defaults)")
    ap.add_argument("--child")
    ap.add_argument("--jsonl")
    ap.add_argument("--warm")
    ap.add_argument("--out")
    args = ap.parse_args()
    if args.dask_config:
        os.environ["BENCH_DASK_CONFIG"] = json.dumps(json.loads(args.dask_config))
    if args.child:
        print(json.dumps(child(args.child, args.workers, args.jsonl, args.out, args.warm)))
        return
    tmp = Path(tempfile.mkdtemp(prefix="bench-batch-in-"))
    print(f"# {os.cpu_count()} CPUs; load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if args.dask_config:
        print(f"# Dask settings of the LocalCluster: {args.dask_config}")
    results: dict[str, dict[str, list[dict]]] = {}
    t_start = time.time()
    try:
        for mode in args.modes:
            jsonl, warm = tmp / f"{mode}.jsonl", tmp / f"{mode}-warm.jsonl"
            jsonl.write_text("".join(json.dumps(r) + "\n" for r in corridors(args.items, mode)))
            warm.write_text("".join(json.dumps(r) + "\n" for r in corridors(4 * args.workers, mode)))
            engines = [e for e in (*ENGINES, *SENT) if e in args.engines or e == "1 process"]
            results[mode] = {e: [] for e in engines}
            for rnd in range(args.rounds):
                for engine in engines:
                    r = run_child(engine, args.workers, jsonl, warm)
                    results[mode][engine].append(r)
                    print(f"# {mode} round {rnd + 1} {engine}: {r['wall_s']:.2f} s, {args.items / r['wall_s']:.1f} "
                          f"plans/s, load {os.getloadavg()[0]:.2f}", flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"# load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}; "
          f"{(time.time() - t_start) / 60:.1f} min")
    print()
    print(f"{args.items} corridors per run, {args.workers} workers, median over {args.rounds} interleaved rounds; "
          "ratios: median of each round's ratio")
    print()
    print("| mode | engine | wall [s] | plans/s | vs 1 process | Dask overhead vs local pool: wall | Dask overhead "
          "vs local pool: CPU | main CPU per plan [ms] | all CPU per plan [ms] | speed-up bound from CPU "
          "| main peak RSS [MB] | worker peak RSS [MB] | ok / failed |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for mode, by in results.items():
        one = [r["wall_s"] for r in by["1 process"]]
        energies = {e: runs[0]["energy_sum"] for e, runs in by.items()}
        assert max(energies.values()) - min(energies.values()) <= 1e-6 * max(energies.values()), energies
        cpu1 = statistics.median(r["main_cpu_ms"] for r in by["1 process"])
        for engine, runs in by.items():
            wall = statistics.median(r["wall_s"] for r in runs)
            main_cpu = statistics.median(r["main_cpu_ms"] for r in runs)
            wk_cpu = statistics.median(r["worker_cpu_ms"] for r in runs)
            bound = 1.0 if engine == "1 process" else min(
                (os.cpu_count() or 1) * cpu1 / (main_cpu + wk_cpu), args.workers * cpu1 / max(wk_cpu, 1e-9))
            eff = statistics.median(o / r["wall_s"] for o, r in zip(one, runs))
            over_wall = over_cpu = ""
            pool = engine.replace("dask", "local pool")
            if engine.startswith("dask") and pool in by:
                extra = statistics.median(r["wall_s"] / lp["wall_s"] - 1 for r, lp in zip(runs, by[pool]))
                cpu = statistics.median(_all_cpu(r) / _all_cpu(lp) - 1 for r, lp in zip(runs, by[pool]))
                over_wall, over_cpu = f"{100 * extra:+.1f} %", f"{100 * cpu:+.1f} %"
            print(f"| {mode} | {engine} | {wall:.2f} | {args.items / wall:.1f} | {eff:.2f}x | {over_wall} | "
                  f"{over_cpu} | {main_cpu:.2f} | {main_cpu + wk_cpu:.2f} | {bound:.2f}x | "
                  f"{max(r['main_rss_mb'] for r in runs):.0f} | "
                  f"{max(r['worker_rss_mb'] for r in runs) if engine != '1 process' else 0:.0f} | "
                  f"{runs[0]['ok']} / {runs[0]['failed']} |")


if __name__ == "__main__":
    main()
