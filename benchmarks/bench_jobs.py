"""Long contours as HTTP jobs (issue 35 goal 6): what a job costs against the synchronous call,
how its progress and time left look while it runs.

For programs of P cut passes (a 20 x 20 mm square with a rounded corner per depth), on an app
with one planning process (as tests/test_jobs_api.py):

* ``sync_s``: ``POST /v1/contour`` answered 200 (``Prefer: wait=1000``: synchronous at any
  estimate), wall time;
* ``job_s``: ``Prefer: respond-async`` -> 202, polled every 50 ms until ``done``: submit to the
  poll that saw it done; ``ratio`` job / sync;
* ``auto``: the status a request without ``Prefer`` gets (202 over the 10 s threshold);
* ``seen``: the distinct ``progress.done`` values the polls saw (of P + 1);
* ``eta@25/50/75%``: ``eta_s`` at the first poll with at least that share of the passes done,
  divided by the time the job actually still took from that poll (1.0: exact);
* ``tail``: the share of ``job_s`` after the last pass was reported (joining the passes,
  the contour section, storing the plan; the polls' 50 ms included).

    PYTHONPATH=$PWD OPENBLAS_NUM_THREADS=1 python benchmarks/bench_jobs.py [P ...]
"""

from __future__ import annotations

import sys
import tempfile
import time

from app.api import create_app
from app.storage import Store
from tests.support import api_client

ORIGIN = [-0.01, -0.01]


def program(passes: int) -> str:
    return "G21 G90 G17\nG64 P0.05\nF1200\nG0 X0 Y0 Z2\n" + "".join(
        f"G1 Z-{d} F300\nG1 X20 F1200\nG3 X25 Y5 I0 J5\nG1 Y20\nG1 X0\nG1 Y0\nG0 Z2\n"
        for d in range(1, passes + 1)) + "G0 X-10 Y-10\nM2\n"


def run_job(c, body: dict) -> tuple[float, list[tuple[float, dict]]]:
    t0 = time.perf_counter()
    r = c.post("/v1/contour", json=body, headers={"Prefer": "respond-async"})
    assert r.status_code == 202, r.text
    seen = []
    while True:
        s = c.get(r.headers["Location"]).json()
        seen.append((time.perf_counter() - t0, s))
        if s["state"] in ("done", "failed"):
            assert s["state"] == "done", s
            return seen[-1][0], seen
        time.sleep(0.05)


def main(passes: list[int]) -> None:
    with tempfile.TemporaryDirectory() as d:
        app = create_app(Store(d), workers=1, timeout_s=120)
        with api_client(app) as c:
            c.post("/v1/contour", json={"program": program(1), "origin": ORIGIN})  # warm the worker
            print("| passes | estimate_s | sync_s | job_s | ratio | auto | seen | eta@25% | eta@50% | eta@75% | tail |")
            print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
            for p in passes:
                body = {"program": program(p), "origin": ORIGIN, "feed": "program"}
                t0 = time.perf_counter()
                r = c.post("/v1/contour", json=body, headers={"Prefer": "wait=1000"})
                sync_s = time.perf_counter() - t0
                assert r.status_code == 200, r.text
                job_s, seen = run_job(c, body)
                final = seen[-1][1]
                assert final["plan_id"] and c.get(final["result"]).json()["contour"]["cycle_time_s"] == \
                    r.json()["contour"]["cycle_time_s"]
                dones = sorted({s["progress"]["done"] for _, s in seen})
                etas = []
                for share in (0.25, 0.5, 0.75):
                    at = next(((t, s) for t, s in seen if s["state"] == "running"
                               and s["progress"]["done"] >= share * p and s["progress"]["done"] < p), None)
                    etas.append("-" if at is None else f"{at[1]['eta_s'] / max(job_s - at[0], 1e-3):.2f}")
                t_all = next(t for t, s in seen if s["progress"]["done"] == p)
                tail = (job_s - t_all) / job_s
                auto = c.post("/v1/contour", json=body)
                if auto.status_code == 202:  # let it finish before the next row
                    while c.get(auto.headers["Location"]).json()["state"] not in ("done", "failed"):
                        time.sleep(0.1)
                print(f"| {p} | {final['estimate_s']:.2f} | {sync_s:.2f} | {job_s:.2f} | {job_s / sync_s:.2f} | "
                      f"{auto.status_code} | {len(dones)} | {' | '.join(etas)} | {tail:.2f} |", flush=True)


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [4, 15, 40])
