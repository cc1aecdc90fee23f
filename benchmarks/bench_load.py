"""Latency under load (issue 21): ``/ready`` and every kind of request while 200 concurrent
clients mix plans (Table I), saves and corridor list pages against a real ``rangeplan serve``
on 127.0.0.1 (a free port, no token, 2 planning workers).

    python benchmarks/bench_load.py [--clients 200] [--per-client 6] [--base-src DIR] [--rounds N]
                                    [--client lean|httpx]

The load runs in processes of their own (bounded: ``clients x per_client`` requests, each
client one after another as answers come back); this process probes ``/ready`` every 50 ms
meanwhile. With ``--base-src`` the same load runs against the service of another source
tree first (e.g. main's checkout), then against this one, ``--rounds`` times alternating: one
table, side by side. A tree's server runs on that tree's own ``.venv`` interpreter when it has
one (its own dependencies). Prints per request kind: count, statuses, p50, p99, max [ms]; and
the server process's own CPU time per request (its event loop and threads, not the planning
workers), a figure the machine's other load changes little.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import resource
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
TABLE1 = json.loads((ROOT / "app" / "static" / "examples" / "table1.json").read_text())
#: processes the clients are spread over
LOAD_PROCESSES = 4


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def python_of(src: Path) -> str:
    """The interpreter of the tree ``src``: its own ``.venv`` when it has one."""
    own = src / ".venv" / "bin" / "python"
    return str(own) if own.exists() else sys.executable


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` so far [s] (Linux ``/proc``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def start_server(src: Path, data: Path, workers: int) -> tuple[subprocess.Popen, str]:
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("RANGEPLAN_")}
    env.update({"RANGEPLAN_DATA_DIR": str(data), "RANGEPLAN_WORKERS": str(workers), "RANGEPLAN_ACCESS_LOG": "0",
                "PYTHONPATH": str(src), "OPENBLAS_NUM_THREADS": "1"})
    proc = subprocess.Popen([python_of(src), "-m", "app.cli", "serve", "--host", "127.0.0.1", "--port", str(port),
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

async def _client(http: httpx.AsyncClient, i: int, n: int, out: list, tag: str) -> None:
    for k in range(n):
        kind = ("plan", "save", "list")[(i + k) % 3]
        t0 = time.perf_counter()
        try:
            if kind == "plan":
                r = await http.post("/v1/plan", json=TABLE1)
            elif kind == "save":
                r = await http.post("/v1/corridors", json={**TABLE1, "name": f"load {tag}-{i}-{k}-{time.time_ns()}"})
            else:
                r = await http.get("/v1/corridors", params={"limit": 50})
            await r.aread()
            status = r.status_code
        except httpx.HTTPError as exc:
            status = type(exc).__name__
        out.append((kind, status, time.perf_counter() - t0))


async def _load(url: str, clients: int, per_client: int, tag: str, lean: bool) -> list:
    out: list = []
    if lean:
        await asyncio.gather(*(_lean_client(url, i, per_client, out, tag) for i in range(clients)))
        return out
    limits = httpx.Limits(max_connections=clients, max_keepalive_connections=clients)
    async with httpx.AsyncClient(base_url=url, timeout=300, limits=limits) as http:
        await asyncio.gather(*(_client(http, i, per_client, out, tag) for i in range(clients)))
    return out


class _Conn:
    """One keep-alive HTTP/1.1 connection on asyncio streams: what a client on another machine
    costs the server, without httpx's per-request CPU in the load processes (which on 2 shared
    cores took 2.5x the server's CPU and queued every answer behind it)."""

    def __init__(self, host: str, port: int):
        self.host, self.port = host, port
        self.reader: asyncio.StreamReader | None = None
        self.writer: asyncio.StreamWriter | None = None

    async def request(self, method: str, path: str, body: bytes | None = None) -> int:
        if self.writer is None:
            self.reader, self.writer = await asyncio.open_connection(self.host, self.port)
        assert self.reader is not None
        head = f"{method} {path} HTTP/1.1\r\nHost: {self.host}:{self.port}\r\n"
        if body is not None:
            head += f"Content-Type: application/json\r\nContent-Length: {len(body)}\r\n"
        self.writer.write(head.encode() + b"\r\n" + (body or b""))
        await self.writer.drain()
        status_line = await self.reader.readline()
        if not status_line:
            raise ConnectionError("closed")
        status = int(status_line.split()[1])
        length, chunked, close = 0, False, False
        while (line := await self.reader.readline()) not in (b"\r\n", b""):
            name, _, value = line.decode("latin-1").partition(":")
            name, value = name.strip().lower(), value.strip().lower()
            if name == "content-length":
                length = int(value)
            elif name == "transfer-encoding" and "chunked" in value:
                chunked = True
            elif name == "connection" and value == "close":
                close = True
        if chunked:
            while (size := int((await self.reader.readline()).split(b";")[0], 16)) > 0:
                await self.reader.readexactly(size + 2)
            await self.reader.readline()
        else:
            await self.reader.readexactly(length)
        if close:
            self.writer.close()
            self.writer = None
        return status


async def _lean_client(url: str, i: int, n: int, out: list, tag: str) -> None:
    host, port = url.split("//", 1)[1].rsplit(":", 1)
    conn = _Conn(host, int(port))
    plan_body = json.dumps(TABLE1).encode()
    for k in range(n):
        kind = ("plan", "save", "list")[(i + k) % 3]
        t0 = time.perf_counter()
        try:
            if kind == "plan":
                status = await conn.request("POST", "/v1/plan", plan_body)
            elif kind == "save":
                body = json.dumps({**TABLE1, "name": f"load {tag}-{i}-{k}-{time.time_ns()}"}).encode()
                status = await conn.request("POST", "/v1/corridors", body)
            else:
                status = await conn.request("GET", "/v1/corridors?limit=50")
        except (OSError, ValueError, asyncio.IncompleteReadError) as exc:
            status = type(exc).__name__
            conn = _Conn(host, int(port))
        out.append((kind, status, time.perf_counter() - t0))
    if conn.writer is not None:
        conn.writer.close()


# -- the run ---------------------------------------------------------------------------------

def run(src: Path, clients: int, per_client: int, workers: int, client: str = "lean",
        load_nice: int = 0) -> dict[str, list]:
    with tempfile.TemporaryDirectory(prefix="rangeplan-load-") as tmp:
        server, url = start_server(src, Path(tmp), workers)
        try:
            # the clients in LOAD_PROCESSES processes: one Python process reading 200 connections
            # (plan results are ~120 kB each) is itself a bottleneck that delays every answer
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            share = [clients // LOAD_PROCESSES + (i < clients % LOAD_PROCESSES) for i in range(LOAD_PROCESSES)]
            loads = [subprocess.Popen([sys.executable, __file__, "--child", url, str(n), str(per_client), str(i),
                                       client], cwd=ROOT, stdout=subprocess.PIPE, text=True,
                                      preexec_fn=(lambda: os.nice(load_nice)) if load_nice else None)
                     for i, n in enumerate(share) if n]
            ready = []
            cpu0 = cpu_seconds(server.pid)
            with httpx.Client(base_url=url, timeout=60) as c:
                while any(p.poll() is None for p in loads):
                    t0 = time.perf_counter()
                    status = c.get("/ready").status_code
                    ready.append(("ready", status, time.perf_counter() - t0))
                    time.sleep(0.05)
                server_cpu = cpu_seconds(server.pid) - cpu0
                server_side = c.get("/metrics").text if c.get("/metrics").status_code == 200 else ""
            rows = [row for p in loads for row in json.loads(p.communicate()[0])]
            after = resource.getrusage(resource.RUSAGE_CHILDREN)  # the load processes (waited for above)
            load_cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
        finally:
            server.terminate()
            server.wait(60)
    out: dict[str, list] = {"ready": ready}
    for kind, status, s in rows:
        out.setdefault(kind, []).append((kind, status, s))
    out["server"] = server_quantiles(server_side)
    out["cpu"] = [("cpu", len(rows) + len(ready), server_cpu, load_cpu)]
    return out


ROUTES = {"ready": ("/ready", "GET"), "list": ("/v1/corridors", "GET"), "save": ("/v1/corridors", "POST"),
          "plan": ("/v1/plan", "POST")}


def server_quantiles(text: str) -> list:
    """Per request kind, the server's own p50 and p99 [s] (upper bucket bounds of its latency
    histogram, /metrics), where the tree has one."""
    if not text:
        return []
    from prometheus_client.parser import text_string_to_metric_families

    buckets: dict[tuple, list] = {}
    for fam in text_string_to_metric_families(text):
        for smp in fam.samples:
            if smp.name == "rangeplan_http_request_duration_seconds_bucket":
                key = (smp.labels["route"], smp.labels["method"])
                buckets.setdefault(key, []).append((float(smp.labels["le"]), smp.value))
    out = []
    for kind, key in ROUTES.items():
        b = sorted(buckets.get(key, []))
        if not b or b[-1][1] == 0:
            continue
        total = b[-1][1]
        q = [next(le for le, n in b if n >= f * total) for f in (0.5, 0.99)]
        out.append((kind, q[0], q[1]))
    return out


def pct(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(q * (len(xs) - 1))))]


def table(results: dict[str, dict[str, list]]) -> str:
    lines = ["| tree | request | n | statuses | p50 [ms] | p99 [ms] | max [ms] | server p50 / p99 [ms] |",
             "|---|---|---|---|---|---|---|---|"]
    for tree, res in results.items():
        server = {k: (p50, p99) for k, p50, p99 in res.get("server", [])}
        for kind in ("ready", "list", "save", "plan"):
            rows = res.get(kind, [])
            if not rows:
                continue
            t = [s for _, _, s in rows]
            st: dict = {}
            for _, status, _ in rows:
                st[status] = st.get(status, 0) + 1
            sts = ", ".join(f"{k}: {v}" for k, v in sorted(st.items(), key=str))
            srv = (f"<= {server[kind][0] * 1e3:.0f} / <= {server[kind][1] * 1e3:.0f}" if kind in server else "-")
            lines.append(f"| {tree} | {kind} | {len(rows)} | {sts} | {pct(t, .5) * 1e3:.0f} | {pct(t, .99) * 1e3:.0f} "
                         f"| {max(t) * 1e3:.0f} | {srv} |")
    return "\n".join(lines)


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        url, clients, per_client, tag = sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
        print(json.dumps(asyncio.run(_load(url, clients, per_client, tag, sys.argv[6] == "lean"))))
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clients", type=int, default=200)
    ap.add_argument("--per-client", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--base-src", type=Path, help="another source tree to measure first (side by side)")
    ap.add_argument("--rounds", type=int, default=1, help="rounds, base and this alternating in each")
    ap.add_argument("--client", choices=("lean", "httpx"), default="lean",
                    help="the load's HTTP client: keep-alive HTTP/1.1 on asyncio streams (default), or httpx")
    ap.add_argument("--load-nice", type=int, default=0,
                    help="run the load processes at this CPU priority offset (> 0: they yield to the server "
                         "and its workers, as clients on other machines would; the /ready probe stays at 0)")
    a = ap.parse_args()
    results: dict[str, dict[str, list]] = {}
    loads = [os.getloadavg()[0]]
    for r in range(a.rounds):
        trees = ([("base", a.base_src.resolve())] if a.base_src else []) + [("this", ROOT)]
        for name, src in trees:
            res = run(src, a.clients, a.per_client, a.workers, a.client, a.load_nice)
            tree = f"{name} r{r + 1}" if a.rounds > 1 else name
            results[tree] = res
            loads.append(os.getloadavg()[0])
            print(f"# {tree}: {python_of(src)} on {src}; load average {loads[-1]:.1f}", flush=True)
    print(f"{a.clients} clients x {a.per_client} requests (plan, save, list in turn; {a.client} client), "
          f"{a.workers} planning workers; load processes at nice {a.load_nice}; "
          f"/ready probed every 50 ms; load average {min(loads):.1f}-{max(loads):.1f} on {os.cpu_count()} cores")
    print(table(results))
    for tree, res in results.items():
        med = {k: statistics.median(s for _, _, s in v) for k, v in res.items() if v and k not in ("server", "cpu")}
        (_, n, cpu, load_cpu), = res["cpu"]
        print(tree, json.dumps({k: round(v * 1e3, 1) for k, v in med.items()}),
              f"server process CPU {cpu:.2f} s for {n} requests ({cpu / n * 1e3:.2f} ms a request); "
              f"the {LOAD_PROCESSES} load processes' CPU {load_cpu:.2f} s")


if __name__ == "__main__":
    main()
