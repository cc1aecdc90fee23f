"""Load for the readiness test (issue 15): ``clients`` concurrent HTTP clients (asyncio,
one connection each), each sending ``per_client`` requests that mix plans (Table I), saves
(a corridor under a name of its own) and list pages, as fast as answers come back. Prints a
JSON summary: answers per status, errors, wall time.

    python -m tests.loadgen URL [CLIENTS] [PER_CLIENT]

:func:`probe_under_load` runs that load in a process of its own and probes ``/ready``
meanwhile (tests/test_load.py, benchmarks/bench_ready_burst.py).
"""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import httpx

TABLE1 = json.loads((Path(__file__).resolve().parents[1] / "app" / "static" / "examples" / "table1.json").read_text())


async def client(http: httpx.AsyncClient, i: int, n: int, statuses: Counter, errors: list) -> None:
    for k in range(n):
        kind = (i + k) % 3
        try:
            if kind == 0:
                r = await http.post("/v1/plan", json=TABLE1)
            elif kind == 1:
                r = await http.post("/v1/corridors", json={**TABLE1, "name": f"load {i}-{k}"})
            else:
                r = await http.get("/v1/corridors", params={"limit": 50})
            await r.aread()
            statuses[f"{('plan', 'save', 'list')[kind]} {r.status_code}"] += 1
        except httpx.HTTPError as exc:
            errors.append(f"{type(exc).__name__}: {exc}")


async def main(url: str, clients: int, per_client: int) -> dict:
    statuses: Counter = Counter()
    errors: list = []
    limits = httpx.Limits(max_connections=clients, max_keepalive_connections=clients)
    t0 = time.monotonic()
    async with httpx.AsyncClient(base_url=url, timeout=120, limits=limits) as http:
        await asyncio.gather(*(client(http, i, per_client, statuses, errors) for i in range(clients)))
    return {"statuses": dict(statuses), "errors": errors[:20], "n_errors": len(errors),
            "seconds": time.monotonic() - t0}


def probe_under_load(url: str, clients: int = 200, per_client: int = 3,
                     nice: int = 10) -> tuple[list[tuple[float, float, int]], dict]:
    """The load of :func:`main` in a process of its own at CPU priority offset ``nice``, and
    ``GET /ready`` every 50 ms from this process until it ends: ``[(seconds since the load
    started, latency [s], status)]`` and the load's summary."""
    root = Path(__file__).resolve().parents[1]
    t00 = time.monotonic()
    load = subprocess.Popen([sys.executable, "-m", "tests.loadgen", url, str(clients), str(per_client)], cwd=root,
                            stdout=subprocess.PIPE, text=True, preexec_fn=(lambda: os.nice(nice)) if nice else None)
    probes = []
    with httpx.Client(base_url=url, timeout=10) as c:
        while load.poll() is None:
            t0 = time.monotonic()
            status = c.get("/ready").status_code
            probes.append((t0 - t00, time.monotonic() - t0, status))
            time.sleep(0.05)
    return probes, json.loads(load.communicate(timeout=300)[0])


if __name__ == "__main__":
    url = sys.argv[1]
    clients = int(sys.argv[2]) if len(sys.argv) > 2 else 200
    per_client = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    print(json.dumps(asyncio.run(main(url, clients, per_client))))
