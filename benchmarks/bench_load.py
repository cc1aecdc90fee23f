"""Latency under load (issue 21): ``/ready`` and every kind of request while 200 concurrent
clients mix plans (Table I), saves and corridor list pages against a real ``rangeplan serve``
on 127.0.0.1 (a free port, no token, 2 planning workers).

    python benchmarks/bench_load.py [--clients 200] [--per-client 6] [--base-src DIR]

The load runs in a process of its own (bounded: ``clients x per_client`` requests, each
client one after another as answers come back); this process probes ``/ready`` every 50 ms
meanwhile. With ``--base-src`` the same load runs against the service of another source
tree first (e.g. main's ``app/`` over a copy of this tree), then against this one: one table,
side by side. Prints per request kind: count, statuses, p50, p99, max [ms].
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
TABLE1 = json.loads((ROOT / "static" / "examples" / "table1.json").read_text())


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(src: Path, data: Path, workers: int) -> tuple[subprocess.Popen, str]:
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("RANGEPLAN_")}
    env.update({"RANGEPLAN_DATA_DIR": str(data), "RANGEPLAN_WORKERS": str(workers), "RANGEPLAN_ACCESS_LOG": "0",
                "PYTHONPATH": str(src), "OPENBLAS_NUM_THREADS": "1"})
    proc = subprocess.Popen([sys.executable, "-m", "app.cli", "serve", "--host", "127.0.0.1", "--port", str(port),
                             "--no-editor"], cwd=src, env=env, stdout=subprocess.DEVNULL,
                            stderr=open(data / "server.log", "w"))
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"server exited: {(data / 'server.log').read_text()[-2000:]}")
        try:
            if httpx.get(url + "/ready", timeout=2).status_code == 200:
                return proc, url
        except httpx.HTTPError:
            pass
        time.sleep(0.3)
    proc.kill()
    raise RuntimeError("server not ready")


# -- the load (child process) --------------------------------------------------------------

async def _client(http: httpx.AsyncClient, i: int, n: int, out: list) -> None:
    for k in range(n):
        kind = ("plan", "save", "list")[(i + k) % 3]
        t0 = time.perf_counter()
        try:
            if kind == "plan":
                r = await http.post("/v1/plan", json=TABLE1)
            elif kind == "save":
                r = await http.post("/v1/corridors", json={**TABLE1, "name": f"load {i}-{k}-{time.time_ns()}"})
            else:
                r = await http.get("/v1/corridors", params={"limit": 50})
            await r.aread()
            status = r.status_code
        except httpx.HTTPError as exc:
            status = type(exc).__name__
        out.append((kind, status, time.perf_counter() - t0))


async def _load(url: str, clients: int, per_client: int) -> list:
    out: list = []
    limits = httpx.Limits(max_connections=clients, max_keepalive_connections=clients)
    async with httpx.AsyncClient(base_url=url, timeout=300, limits=limits) as http:
        await asyncio.gather(*(_client(http, i, per_client, out) for i in range(clients)))
    return out


# -- the run ---------------------------------------------------------------------------------

def run(src: Path, clients: int, per_client: int, workers: int) -> dict[str, list]:
    with tempfile.TemporaryDirectory(prefix="rangeplan-load-") as tmp:
        server, url = start_server(src, Path(tmp), workers)
        try:
            load = subprocess.Popen([sys.executable, __file__, "--child", url, str(clients), str(per_client)],
                                    cwd=ROOT, stdout=subprocess.PIPE, text=True)
            ready = []
            with httpx.Client(base_url=url, timeout=60) as c:
                while load.poll() is None:
                    t0 = time.perf_counter()
                    status = c.get("/ready").status_code
                    ready.append(("ready", status, time.perf_counter() - t0))
                    time.sleep(0.05)
            rows = json.loads(load.communicate()[0])
        finally:
            server.terminate()
            server.wait(60)
    out: dict[str, list] = {"ready": ready}
    for kind, status, s in rows:
        out.setdefault(kind, []).append((kind, status, s))
    return out


def pct(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(q * (len(xs) - 1))))]


def table(results: dict[str, dict[str, list]]) -> str:
    lines = ["| tree | request | n | statuses | p50 [ms] | p99 [ms] | max [ms] |", "|---|---|---|---|---|---|---|"]
    for tree, res in results.items():
        for kind in ("ready", "list", "save", "plan"):
            rows = res.get(kind, [])
            if not rows:
                continue
            t = [s for _, _, s in rows]
            st: dict = {}
            for _, status, _ in rows:
                st[status] = st.get(status, 0) + 1
            sts = ", ".join(f"{k}: {v}" for k, v in sorted(st.items(), key=str))
            lines.append(f"| {tree} | {kind} | {len(rows)} | {sts} | {pct(t, .5) * 1e3:.0f} | {pct(t, .99) * 1e3:.0f} "
                         f"| {max(t) * 1e3:.0f} |")
    return "\n".join(lines)


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        url, clients, per_client = sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
        print(json.dumps(asyncio.run(_load(url, clients, per_client))))
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clients", type=int, default=200)
    ap.add_argument("--per-client", type=int, default=6)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--base-src", type=Path, help="another source tree to measure first (side by side)")
    a = ap.parse_args()
    results = {}
    if a.base_src:
        results["base"] = run(a.base_src.resolve(), a.clients, a.per_client, a.workers)
    results["this"] = run(ROOT, a.clients, a.per_client, a.workers)
    print(f"{a.clients} clients x {a.per_client} requests (plan, save, list in turn), {a.workers} planning workers; "
          f"/ready probed every 50 ms; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(table(results))
    for tree, res in results.items():
        med = {k: statistics.median(s for _, _, s in v) for k, v in res.items() if v}
        print(tree, json.dumps({k: round(v * 1e3, 1) for k, v in med.items()}))


if __name__ == "__main__":
    main()
