"""A synchronous plan while long jobs run (issue 33 goal: a synchronous request is never
starved by jobs): the wall time of a synchronous Table I plan (``POST /v1/plan``) alone, then
while jobs (``Prefer: respond-async``; Table I with ``fastest`` at Ts 2 ms, N 30: ~46 CPU s)
run on every slot the server gives jobs, on a real pool of planning processes (in-process
ASGI client).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_job_share.py [--workers 2] [--plans 5]

It sets RANGEPLAN_JOB_WORKERS per row (a revision without the setting ignores it: every
worker may run a job there, which is how the 'before' figures are measured, with PYTHONPATH at
that revision). A synchronous plan not answered within ``--wait-s`` counts as that long.
Prints one table: medians and the largest of ``--plans`` synchronous plans per row.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

TABLE1 = json.loads((ROOT / "app" / "static" / "examples" / "table1.json").read_text())
LONG = {**TABLE1, "settings": {"fastest": True, "Ts": 0.002, "N": 30}}


def wait_for(check, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not check():
        if time.monotonic() > deadline:
            raise SystemExit("timed out")
        time.sleep(0.02)


def sync_plan(c, wait_s: float) -> tuple[str, float]:
    """(status, seconds) of one synchronous Table I plan; ('waiting', wait_s) past wait_s."""
    box: dict = {}

    def go():
        t0 = time.perf_counter()
        try:
            box["status"] = str(c.post("/v1/plan", json=TABLE1).status_code)
        except Exception as exc:  # the client closed under it
            box["status"] = type(exc).__name__
        box["s"] = time.perf_counter() - t0

    t = threading.Thread(target=go, daemon=True)
    t.start()
    t.join(wait_s)
    return (box["status"], box["s"]) if "s" in box else ("waiting", wait_s)


def row(workers: int, job_workers: int | None, jobs: int, plans: int, wait_s: float) -> dict:
    from app.api import create_app
    from app.security import AccessPolicy
    from app.storage import Store
    from tests.support import api_client

    if job_workers is None:
        os.environ.pop("RANGEPLAN_JOB_WORKERS", None)
    else:
        os.environ["RANGEPLAN_JOB_WORKERS"] = str(job_workers)
    tmp = tempfile.mkdtemp()  # this row's process ends without closing the app (os._exit): no cleanup waits
    app = create_app(Store(Path(tmp)), workers=workers, timeout_s=30, access=AccessPolicy())
    c = api_client(app).__enter__()
    wait_for(lambda: c.get("/ready").status_code == 200 and c.get("/ready").json()["workers_ready"] == workers)
    share = c.get("/ready").json().get("jobs", {}).get("workers", workers)
    c.post("/v1/plan", json=TABLE1)  # the first plan outside the figures
    results, urls = [], []
    if jobs:
        urls = [c.post("/v1/plan", json=LONG, headers={"Prefer": "respond-async"}).headers["Location"]
                for _ in range(jobs)]
        running = min(jobs, share, workers)
        wait_for(lambda: sum(c.get(u).json()["state"] == "running" for u in urls) == running)
    for _ in range(plans):
        results.append(sync_plan(c, wait_s))
    states = [c.get(u).json()["state"] for u in urls]
    shutil.rmtree(tmp, ignore_errors=True)
    statuses = sorted({s for s, _ in results})
    seconds = [s for _, s in results]
    return {"workers": workers, "share": share, "jobs": jobs, "job_states": ",".join(states) or "-",
            "status": ",".join(statuses), "median_s": statistics.median(seconds), "max_s": max(seconds)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--plans", type=int, default=5)
    ap.add_argument("--wait-s", type=float, default=15.0, help="a synchronous plan not answered by then: that long")
    ap.add_argument("--row", help=argparse.SUPPRESS)  # one row, in a process of its own
    args = ap.parse_args()
    w = args.workers
    if args.row is not None:
        share, jobs = json.loads(args.row)
        print(json.dumps(row(w, share, jobs, args.plans, args.wait_s)), flush=True)
        os._exit(0)  # the workers end with this process; a plan still waiting (the 'before') cannot hold it
    rows = []
    for share, jobs in ((None, 0), (None, w), (w, w)):  # alone; as many jobs as workers on the default share;
        # jobs may hold every worker
        out = subprocess.run([sys.executable, __file__, "--workers", str(w), "--plans", str(args.plans),
                              "--wait-s", str(args.wait_s), "--row", json.dumps([share, jobs])],
                             capture_output=True, text=True, timeout=600)
        if out.returncode != 0:
            raise SystemExit(out.stderr)
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    print("| workers | jobs' share | jobs submitted | their states | sync plan status | median s | max s |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['workers']} | {r['share']} | {r['jobs']} | {r['job_states']} | {r['status']} | "
              f"{r['median_s']:.3f} | {r['max_s']:.3f} |")
    print(f"median with jobs on the default share / alone: {rows[1]['median_s'] / rows[0]['median_s']:.2f}")


if __name__ == "__main__":
    main()
