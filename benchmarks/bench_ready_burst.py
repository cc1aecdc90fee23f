"""``/ready`` while a burst of clients starts (issues 15, 21): tests/test_load.py's load (a
real ``rangeplan serve`` with 2 workers; 200 clients x 3 requests mixing plans, saves and
list pages, sent by :mod:`tests.loadgen` in a process of its own) ``--runs`` times, a new
server each run; this process probes ``/ready`` every 50 ms. Prints per run the probes'
median and maximum and when the slow ones (> 100 ms) came, counted from the load's start
(the first requests all arrive within ~1 s of it), then the maximum over the runs.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_ready_burst.py [--runs 6] [--load-nice 0]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.fuzz.runner import _start_server  # noqa: E402
from tests.loadgen import probe_under_load  # noqa: E402


def one_run(clients: int, per_client: int, nice: int) -> tuple[list[tuple[float, float]], dict]:
    """[(seconds since the load started, latency)] of the probes, and the load's summary."""
    with tempfile.TemporaryDirectory(prefix="rangeplan-burst-") as tmp:
        server, log, url = _start_server(Path(tmp), timeout_s=30, workers=2, token=None)
        try:
            timeline, summary = probe_under_load(url, clients, per_client, nice)
        finally:
            server.terminate()
            server.wait(30)
            log.close()
    assert all(status == 200 for _, _, status in timeline)
    return [(at, t) for at, t, _ in timeline], summary


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=6)
    ap.add_argument("--clients", type=int, default=200)
    ap.add_argument("--per-client", type=int, default=3)
    ap.add_argument("--load-nice", type=int, default=0, help="the load process's CPU priority offset")
    args = ap.parse_args()
    print("| run | probes | median [ms] | max [ms] | slow probes (> 100 ms): at s after the load's start: ms | "
          "answers |\n|---|---:|---:|---:|---|---|")
    worst = 0.0
    for r in range(args.runs):
        probes, summary = one_run(args.clients, args.per_client, args.load_nice)
        lat = sorted(t for _, t in probes)
        slow = ", ".join(f"{at:.2f}: {t * 1e3:.0f}" for at, t in probes if t > 0.1) or "-"
        worst = max(worst, lat[-1])
        print(f"| {r + 1} | {len(lat)} | {lat[len(lat) // 2] * 1e3:.1f} | {lat[-1] * 1e3:.0f} | {slow} | "
              f"{summary['statuses']} |", flush=True)
    print(f"\n/ready max over {args.runs} runs: {worst * 1e3:.0f} ms")


if __name__ == "__main__":
    main()
