"""Plans per second over HTTP, and latency percentiles, with concurrent clients on loopback.

Starts a real ``rangeplan serve`` (uvicorn, no editor) on a free 127.0.0.1 port with a
temporary data directory, warms it up, then for each executor (worker processes, or threads
in the server process) and each client concurrency posts the Table I corridor for a fixed
number of requests per run. Prints, per row, the median over ``--runs`` runs of: plans/s,
and latency p50 / p90 / p99 (ms) of the median run; plus the planner's own compute time
(``metrics.compute_ms``) for reference. Clients run in this process (asyncio + httpx) and
share the machine's cores with the server, as a CAD tool on the same host would.

    .venv/bin/python benchmarks/bench_http.py                # default matrix
    .venv/bin/python benchmarks/bench_http.py --executor process --concurrency 1 2 4 8 --requests 200
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parent.parent
TABLE1 = json.loads((ROOT / "static" / "examples" / "table1.json").read_text())


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(executor: str, workers: int, data_dir: str) -> tuple[subprocess.Popen, str]:
    port = free_port()
    env = {**os.environ, "RANGEPLAN_DATA_DIR": data_dir, "RANGEPLAN_EXECUTOR": executor,
           "RANGEPLAN_WORKERS": str(workers), "RANGEPLAN_ACCESS_LOG": "0", "RANGEPLAN_LOG_LEVEL": "warning",
           "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "app.cli", "serve", "--no-editor", "--port", str(port)],
                            env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            if httpx.get(url + "/health", timeout=1).status_code == 200:
                return proc, url
        except httpx.HTTPError:
            time.sleep(0.1)
    proc.kill()
    raise RuntimeError("server did not start")


def stop_server(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


async def run_load(url: str, concurrency: int, n_requests: int, path: str = "/v1/plan") -> dict:
    body = json.dumps(TABLE1).encode()
    latencies: list[float] = []
    compute: list[float] = []
    errors = 0
    remaining = n_requests
    limits = httpx.Limits(max_connections=concurrency, max_keepalive_connections=concurrency)
    async with httpx.AsyncClient(base_url=url, timeout=120, limits=limits) as client:
        async def one_client():
            nonlocal remaining, errors
            while remaining > 0:
                remaining -= 1
                t0 = time.perf_counter()
                if path == "/health":
                    r = await client.get(path)
                else:
                    r = await client.post(path, content=body, headers={"Content-Type": "application/json"})
                latencies.append(time.perf_counter() - t0)
                if r.status_code != 200:
                    errors += 1
                elif path != "/health":
                    compute.append(r.json()["metrics"]["compute_ms"])

        t0 = time.perf_counter()
        await asyncio.gather(*(one_client() for _ in range(concurrency)))
        wall = time.perf_counter() - t0
    lat = sorted(latencies)

    def pct(p):
        return lat[min(len(lat) - 1, int(round(p / 100 * (len(lat) - 1))))] * 1e3

    return {"rate": len(lat) / wall, "p50": pct(50), "p90": pct(90), "p99": pct(99), "errors": errors,
            "compute_ms": statistics.median(compute) if compute else float("nan")}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--executor", nargs="+", default=["process", "thread"], choices=["process", "thread"])
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="server workers (default: cores)")
    ap.add_argument("--concurrency", type=int, nargs="+", default=[1, 2, 4, 8])
    ap.add_argument("--requests", type=int, default=100, help="requests per run")
    ap.add_argument("--runs", type=int, default=3, help="runs per row (median reported)")
    args = ap.parse_args()

    print(f"Table I plans over HTTP on loopback; {os.cpu_count()} cores, server workers = {args.workers}, "
          f"{args.requests} requests per run, median of {args.runs} runs")
    print(f"{'executor':<9} {'clients':>7} {'plans/s':>8} {'p50 ms':>8} {'p90 ms':>8} {'p99 ms':>8} "
          f"{'planner ms':>10} {'errors':>6}")
    for executor in args.executor:
        with tempfile.TemporaryDirectory(prefix="rangeplan-bench-") as data_dir:
            proc, url = start_server(executor, args.workers, data_dir)
            try:
                asyncio.run(run_load(url, args.workers, 2 * args.workers))  # warm-up
                h = [asyncio.run(run_load(url, 8, 2000, "/health")) for _ in range(args.runs)]
                h.sort(key=lambda r: r["rate"])
                hm = h[len(h) // 2]
                print(f"{executor:<9} {'8':>7} {hm['rate']:8.0f} {hm['p50']:8.2f} {hm['p90']:8.2f} {hm['p99']:8.2f} "
                      f"{'(GET /health)':>10} {hm['errors']:>6}")
                for c in args.concurrency:
                    runs = [asyncio.run(run_load(url, c, args.requests)) for _ in range(args.runs)]
                    runs.sort(key=lambda r: r["rate"])
                    m = runs[len(runs) // 2]
                    print(f"{executor:<9} {c:>7} {m['rate']:8.1f} {m['p50']:8.1f} {m['p90']:8.1f} {m['p99']:8.1f} "
                          f"{m['compute_ms']:10.1f} {sum(r['errors'] for r in runs):>6}", flush=True)
            finally:
                stop_server(proc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
