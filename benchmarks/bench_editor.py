"""The editor's responsiveness while it plans: how long a typed value takes to reach the
editing session when a plan is running on the session's worker thread, against the same
with no plan running.

Starts an editor (viser) on a free 127.0.0.1 port, connects one tab without a browser
(``tests/viser_client.py``: the websocket messages a browser sends when a person types into
a field), sets a workload, and for ``--samples`` rounds asks for a plan and, while it runs,
"types" a new clearance into the panel; the latency is the time from sending the message to
the session having applied it (the field's callback ran, the request changed). The
``idle`` row does the same with no plan running. Also printed: the plan's own time, and the
longest the planner held the GIL (the longest gap of a thread that wakes every 1 ms during
the plans): compiled kernels (numba) hold it, so this bounds what any other thread waits.

Workloads: ``default`` (the editor's first layout, paper mode), ``constrained-fine``
(constrained mode, Ts = 2 ms, 5 mm cells: about 0.6 s a plan here).

    .venv/bin/python benchmarks/bench_editor.py
    .venv/bin/python benchmarks/bench_editor.py --samples 40
"""

from __future__ import annotations

import argparse
import os
import socket
import statistics
import sys
import threading
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.editor import start_editor
from tests.viser_client import HeadlessClient

WORKLOADS = {
    "default": lambda r: None,
    "constrained-fine": lambda r: (r["settings"].update(mode="constrained", Ts=0.002),
                                   r["layout"]["cell"].update(size=0.005)),
}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(cond, timeout=60.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.0005)
    return False


class GilProbe(threading.Thread):
    """Wakes every 1 ms and records the longest gap [s] between wake-ups."""

    def __init__(self):
        super().__init__(daemon=True)
        self.longest = 0.0
        self.stop = False

    def run(self) -> None:
        last = time.perf_counter()
        while not self.stop:
            time.sleep(0.001)
            now = time.perf_counter()
            self.longest = max(self.longest, now - last)
            last = now


def measure(session, client, samples: int, during_plan: bool) -> tuple[list[float], list[float], int]:
    """Latencies [s] of typed clearances, plan times [s], and how many arrived mid-plan."""
    field = session.gui.clearance
    latencies, plans, mid = [], [], 0
    for k in range(samples):
        value = 0.001 * ((k % 2) + 1)
        if during_plan:
            session.plan_now()
            assert wait_for(lambda: session.worker.started > session.worker.finished, 10), "no plan started"
            time.sleep(0.02)
        t0 = time.perf_counter()
        client.type(field.text, f"{value:g}")
        assert wait_for(lambda v=value: session.request["layout"]["clearance"] == v, 10)
        latencies.append(time.perf_counter() - t0)
        mid += session.worker.started > session.worker.finished
        t1 = time.perf_counter()
        assert session.wait_idle(120)
        plans.append(time.perf_counter() - t1)
    return latencies, plans, mid


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=20)
    ap.add_argument("--workloads", nargs="+", default=list(WORKLOADS), choices=list(WORKLOADS))
    args = ap.parse_args()
    editor = start_editor("127.0.0.1", free_port(), None, debounce=0.05)
    client = HeadlessClient(editor.port)
    try:
        (session,) = editor.wait_for_sessions(1, 60)
        assert session.wait_idle(180), "the first plan (numba compiles on a fresh tree) did not finish"
        print(f"typed value -> session, {args.samples} samples per row (ms); plan = wall time of the plan "
              "after the value (s); GIL = longest gap of a 1 ms thread (ms)")
        header = f"{'workload':18s} {'while':8s} {'p50':>7s} {'p90':>7s} {'max':>7s} {'mid-plan':>9s} " \
                 f"{'plan s':>7s} {'GIL ms':>7s}"
        print(header)
        print("-" * len(header))
        for name in args.workloads:
            session.edit(WORKLOADS[name])
            assert session.wait_idle(180) and session.last_error is None, session.last_error
            for during in (False, True):
                probe = GilProbe()
                probe.start()
                lat, plans, mid = measure(session, client, args.samples, during)
                probe.stop = True
                probe.join()
                q = statistics.quantiles([x * 1e3 for x in lat], n=10)
                print(f"{name:18s} {'planning' if during else 'idle':8s} {statistics.median(lat) * 1e3:7.1f} "
                      f"{q[8]:7.1f} {max(lat) * 1e3:7.1f} {mid:>4d}/{len(lat):<4d} "
                      f"{statistics.median(plans):7.2f} {probe.longest * 1e3:7.1f}")
    finally:
        client.close()
        wait_for(lambda: not editor.sessions, 10)
        editor.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
