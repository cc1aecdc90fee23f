"""Plans per second over HTTP, and latency percentiles, with concurrent clients on loopback.

Starts a real ``rangeplan serve`` (uvicorn, no editor) on a free 127.0.0.1 port with a
temporary data directory, warms it up, then for each executor (worker processes, or threads
in the server process) and each client concurrency posts the Table I corridor for a fixed
number of requests per run. Prints, per row, the median over ``--runs`` runs of: plans/s,
and latency p50 / p90 / p99 (ms) of the median run; plus the planner's own compute time
(``metrics.compute_ms``) for reference. Clients run in this process (asyncio) and share the
machine's cores with the server, as a CAD tool on the same host would.

The client is ``--client raw`` by default: a minimal HTTP/1.1 keep-alive client on asyncio
streams (one connection per concurrent client), ~0.5 ms of CPU per plan request, so that on
a 2-core machine the load generator takes little from the server it measures. ``--client
httpx`` uses httpx.AsyncClient instead (~2 ms of CPU per request here, mostly its own
overhead; without ``sniffio`` installed, httpcore retries a failing import on every request).
Either way every response is checked (status 200, JSON, the whole body read), the first of
each client is parsed in full, and only ``metrics`` is parsed from the others (parsing every
~150 kB result took the client ~3 ms a request, as much CPU as the server's own work).

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
TABLE1 = json.loads((ROOT / "app" / "static" / "examples" / "table1.json").read_text())


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


class RawConnection:
    """One keep-alive HTTP/1.1 connection on asyncio streams: just enough HTTP for this
    benchmark (Content-Length or chunked response bodies)."""

    def __init__(self, url: str):
        host, _, port = url.removeprefix("http://").partition(":")
        self.host, self.port = host, int(port or 80)
        self.reader = self.writer = None

    async def request(self, method: str, path: str, body: bytes = b"", timeout: float = 120) -> tuple[int, dict, bytes]:
        return await asyncio.wait_for(self._request(method, path, body), timeout)

    async def _request(self, method: str, path: str, body: bytes) -> tuple[int, dict, bytes]:
        if self.writer is None:
            self.reader, self.writer = await asyncio.open_connection(self.host, self.port)
        head = f"{method} {path} HTTP/1.1\r\nHost: {self.host}:{self.port}\r\n"
        if body or method == "POST":
            head += f"Content-Type: application/json\r\nContent-Length: {len(body)}\r\n"
        self.writer.write(head.encode() + b"\r\n" + body)
        status_line, *lines = (await self.reader.readuntil(b"\r\n\r\n")).decode("latin-1").split("\r\n")
        status = int(status_line.split()[1])
        headers = {}
        for line in lines:
            if line:
                k, _, v = line.partition(":")
                headers[k.strip().lower()] = v.strip()
        if "content-length" in headers:
            data = await self.reader.readexactly(int(headers["content-length"]))
        elif headers.get("transfer-encoding", "").lower() == "chunked":
            parts = []
            while n := int((await self.reader.readuntil(b"\r\n")).split(b";")[0], 16):
                parts.append(await self.reader.readexactly(n))
                await self.reader.readexactly(2)
            await self.reader.readuntil(b"\r\n")
            data = b"".join(parts)
        else:
            raise RuntimeError(f"response without a length: {headers}")
        if headers.get("connection", "").lower() == "close":
            await self.close()
        return status, headers, data

    async def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.reader = self.writer = None


def metrics_of(data: bytes) -> dict:
    """The result's ``metrics`` object, without parsing the whole ~150 kB result."""
    i = data.rfind(b'"metrics":')
    if i < 0:
        raise ValueError("no metrics in the result")
    obj, _ = json.JSONDecoder().raw_decode(data[i + len(b'"metrics":'):].decode())
    return obj


async def run_load(url: str, concurrency: int, n_requests: int, path: str = "/v1/plan",
                   client: str = "raw") -> dict:
    body = json.dumps(TABLE1).encode()
    latencies: list[float] = []
    compute: list[float] = []
    errors = 0
    remaining = n_requests
    method = "GET" if path == "/health" else "POST"

    def check(status: int, ctype: str, data: bytes, first: bool) -> None:
        nonlocal errors
        if status != 200 or not ctype.startswith("application/json"):
            errors += 1
        elif method == "POST":
            if first:  # the whole result, once per client
                full = json.loads(data)
                if len(full["pose"]) != full["metrics"]["steps"] + 1:
                    errors += 1
            compute.append(metrics_of(data)["compute_ms"])

    async def one_raw_client():
        nonlocal remaining
        conn, first = RawConnection(url), True
        try:
            while remaining > 0:
                remaining -= 1
                t0 = time.perf_counter()
                status, headers, data = await conn.request(method, path, body if method == "POST" else b"")
                latencies.append(time.perf_counter() - t0)
                check(status, headers.get("content-type", ""), data, first)
                first = False
        finally:
            await conn.close()

    if client == "raw":
        t0 = time.perf_counter()
        await asyncio.gather(*(one_raw_client() for _ in range(concurrency)))
        wall = time.perf_counter() - t0
    else:
        limits = httpx.Limits(max_connections=concurrency, max_keepalive_connections=concurrency)
        async with httpx.AsyncClient(base_url=url, timeout=120, limits=limits) as hc:
            async def one_httpx_client():
                nonlocal remaining
                first = True
                while remaining > 0:
                    remaining -= 1
                    t0 = time.perf_counter()
                    if method == "GET":
                        r = await hc.get(path)
                    else:
                        r = await hc.post(path, content=body, headers={"Content-Type": "application/json"})
                    latencies.append(time.perf_counter() - t0)
                    check(r.status_code, r.headers.get("content-type", ""), r.content, first)
                    first = False

            t0 = time.perf_counter()
            await asyncio.gather(*(one_httpx_client() for _ in range(concurrency)))
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
    ap.add_argument("--client", choices=["raw", "httpx"], default="raw",
                    help="load generator: minimal asyncio HTTP/1.1 client (default) or httpx.AsyncClient")
    ap.add_argument("--mode", choices=["constrained", "paper"], default=None,
                    help="plan Table I in this mode (default: the request's own, i.e. the default mode; the "
                         "figures of issue 4 were taken when that was the paper mode)")
    args = ap.parse_args()
    if args.mode is not None:
        TABLE1["settings"] = {**TABLE1.get("settings", {}), "mode": args.mode}

    print(f"Table I plans ({args.mode or 'default'} mode) over HTTP on loopback; {os.cpu_count()} cores, "
          f"server workers = {args.workers}, "
          f"{args.requests} requests per run, median of {args.runs} runs, client {args.client}")
    print(f"{'executor':<9} {'clients':>7} {'plans/s':>8} {'p50 ms':>8} {'p90 ms':>8} {'p99 ms':>8} "
          f"{'planner ms':>10} {'errors':>6}")
    for executor in args.executor:
        with tempfile.TemporaryDirectory(prefix="rangeplan-bench-") as data_dir:
            proc, url = start_server(executor, args.workers, data_dir)
            try:
                asyncio.run(run_load(url, args.workers, 2 * args.workers, client=args.client))  # warm-up
                h = [asyncio.run(run_load(url, 8, 2000, "/health", args.client)) for _ in range(args.runs)]
                h.sort(key=lambda r: r["rate"])
                hm = h[len(h) // 2]
                print(f"{executor:<9} {'8':>7} {hm['rate']:8.0f} {hm['p50']:8.2f} {hm['p90']:8.2f} {hm['p99']:8.2f} "
                      f"{'(GET /health)':>10} {hm['errors']:>6}")
                for c in args.concurrency:
                    runs = [asyncio.run(run_load(url, c, args.requests, client=args.client))
                            for _ in range(args.runs)]
                    runs.sort(key=lambda r: r["rate"])
                    m = runs[len(runs) // 2]
                    print(f"{executor:<9} {c:>7} {m['rate']:8.1f} {m['p50']:8.1f} {m['p90']:8.1f} {m['p99']:8.1f} "
                          f"{m['compute_ms']:10.1f} {sum(r['errors'] for r in runs):>6}", flush=True)
            finally:
                stop_server(proc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
