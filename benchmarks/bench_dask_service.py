"""Plans per second over HTTP with the service's jobs on a Dask cluster (``RANGEPLAN_EXECUTOR=dask``)
at 1 and 2 Dask workers, against the local process pool at 1 and 2 workers, in one run.

For each configuration: a Dask ``LocalCluster`` of N worker processes (1 thread each, on this
host; none for the local pool), a real ``rangeplan serve`` (uvicorn, no editor) on a free
loopback port pointed at it, a warm-up (every worker's planning process started). All four
are started first (idle, they take no CPU), then measured in interleaved rounds (a change in
the shared machine's load hits all four alike): ``--runs`` rounds of ``--requests`` Table I
plans (``POST /v1/plan``, the default constrained mode) from ``--concurrency`` keep-alive
clients (benchmarks/bench_http.py's client). Prints per configuration the median plans/s,
latency p50/p90 (ms) of the median run, the planner's compute time, the CPU per plan of all
the processes involved (the server, its workers or the Dask workers and their planning
processes, and this process: load generator and Dask scheduler; a figure the load of other jobs
on a shared machine changes far less than plans/s), and the ratios (median of each round's):
2 workers against 1 of the same executor, and Dask against the local pool at the same worker
count, in plans/s and in CPU per plan.

    .venv/bin/python benchmarks/bench_dask_service.py                      # defaults
    .venv/bin/python benchmarks/bench_dask_service.py --requests 80 --runs 3 --concurrency 4
"""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_http import free_port, run_load  # noqa: E402


def start_server(env_extra: dict[str, str], data_dir: str) -> tuple[subprocess.Popen, str]:
    port = free_port()
    env = {**os.environ, "RANGEPLAN_DATA_DIR": data_dir, "RANGEPLAN_ACCESS_LOG": "0",
           "RANGEPLAN_LOG_LEVEL": "warning", "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1", "PYTHONPATH": str(ROOT), **env_extra}
    proc = subprocess.Popen([sys.executable, "-m", "app.cli", "serve", "--no-editor", "--port", str(port)],
                            env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        try:
            if httpx.get(url + "/ready", timeout=2).status_code == 200:
                return proc, url
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    proc.kill()
    raise RuntimeError("server did not become ready")


def stop_server(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


class Config:
    """One configuration, started and warmed: a server (and for Dask its cluster)."""

    def __init__(self, executor: str, workers: int, concurrency: int):
        from contextlib import ExitStack

        self.executor, self.workers = executor, workers
        self.stack = ExitStack()
        env = {"RANGEPLAN_EXECUTOR": executor, "RANGEPLAN_WORKERS": str(workers)}
        if executor == "dask":
            from distributed import LocalCluster

            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                   dashboard_address=None, env={"PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"})
            self.stack.callback(cluster.close)
            env["RANGEPLAN_DASK_SCHEDULER"] = cluster.scheduler_address
        data = self.stack.enter_context(tempfile.TemporaryDirectory())
        proc, self.url = start_server(env, data)
        self.stack.callback(stop_server, proc)
        warm = asyncio.run(run_load(self.url, max(concurrency, 2 * workers), 4 * workers))
        assert warm["errors"] == 0, warm
        # the processes that do this configuration's work: the server and its workers, and for
        # Dask the cluster's worker processes and their planning processes (the scheduler runs
        # in this process, with the load generator: counted for every configuration alike)
        import psutil

        roots = [psutil.Process(proc.pid)]
        if executor == "dask":
            from distributed import Client

            with Client(env["RANGEPLAN_DASK_SCHEDULER"], timeout="20s") as c:
                roots += [psutil.Process(pid) for pid in c.run(os.getpid).values()]
        self.procs = [q for r in roots for q in (r, *r.children(recursive=True))]
        self.runs: list[dict] = []

    def cpu_s(self) -> float:
        """CPU time [s] of this configuration's processes and of this process so far."""
        total = time.process_time()
        for q in self.procs:
            try:
                t = q.cpu_times()
                total += t.user + t.system
            except Exception:  # a process that ended (a replaced worker): its time is lost
                pass
        return total

    def run(self, concurrency: int, requests: int) -> dict:
        cpu0 = self.cpu_s()
        r = asyncio.run(run_load(self.url, concurrency, requests))
        r["cpu_ms"] = (self.cpu_s() - cpu0) / requests * 1e3
        assert r["errors"] == 0, r
        self.runs.append(r)
        return r

    def median(self) -> dict:
        runs = sorted(self.runs, key=lambda r: r["rate"])
        return runs[len(runs) // 2]

    def close(self) -> None:
        self.stack.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--requests", type=int, default=60, help="plans per run (default 60)")
    ap.add_argument("--runs", type=int, default=3, help="runs per configuration; the median is shown (default 3)")
    ap.add_argument("--concurrency", type=int, default=4, help="concurrent clients (default 4)")
    args = ap.parse_args()
    configs: dict[tuple[str, int], Config] = {}
    try:
        for executor in ("process", "dask"):  # all started (idle ones take no CPU), then measured interleaved
            for workers in (1, 2):
                configs[executor, workers] = Config(executor, workers, args.concurrency)
        for rnd in range(args.runs):
            for (executor, workers), cfg in configs.items():
                r = cfg.run(args.concurrency, args.requests)
                print(f"# round {rnd + 1} {executor} x{workers}: {r['rate']:.1f} plans/s, {r['cpu_ms']:.1f} ms CPU "
                      f"a plan, load "
                      f"{os.getloadavg()[0]:.2f}", file=sys.stderr, flush=True)
    finally:
        for cfg in configs.values():
            cfg.close()
    rows = {k: {**cfg.median(), "ratios": cfg.runs} for k, cfg in configs.items()}

    def ratio(a: tuple[str, int], b: tuple[str, int]) -> float:
        """The median over rounds of each round's ratio of plans/s (a shared machine's load hits both alike)."""
        return statistics.median(x["rate"] / y["rate"] for x, y in zip(configs[a].runs, configs[b].runs))

    print(f"\nTable I (constrained) over HTTP, {args.concurrency} clients, {args.requests} plans x {args.runs} "
          f"interleaved rounds (median; ratios: median of each round's ratio), {os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.2f}\n")
    print("| executor | workers | plans/s | 2 workers vs 1 | Dask vs local pool | p50 [ms] | p90 [ms] | "
          "compute [ms] | all CPU per plan [ms] | Dask CPU vs local pool |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for (executor, workers), r in rows.items():
        scale = f"{ratio((executor, 2), (executor, 1)):.2f}x" if workers == 2 else ""
        vs = f"{ratio((executor, workers), ('process', workers)):.2f}x" if executor == "dask" else ""
        runs = configs[executor, workers].runs
        cpu = statistics.median(x["cpu_ms"] for x in runs)
        cpu_vs = ""
        if executor == "dask":
            pool = configs["process", workers].runs
            cpu_vs = f"{statistics.median(x['cpu_ms'] / y['cpu_ms'] for x, y in zip(runs, pool)):.2f}x"
        print(f"| {executor} | {workers} | {r['rate']:.1f} | {scale} | {vs} | {r['p50']:.0f} | {r['p90']:.0f} | "
              f"{r['compute_ms']:.1f} | {cpu:.1f} | {cpu_vs} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
