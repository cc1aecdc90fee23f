"""Memory of the server process while clients download a large stored plan, side by side
across checkouts (``--root``): issue 21's goal that 4 concurrent CSV exports of a stored ~60 MB
plan grow the server process by at most 300 MB, and issue 33's that downloads in every
format (``--format json csv ...``) grow it by at most its bounded buffers (4 JSON downloads:
<= 50 MB) with ``/ready`` answering within 1 s.

The plan is planned once by this checkout's planner (Table I's cells back and forth,
``--samples`` per segment, paper mode; cached in the temporary directory) and stored, as
``POST /v1/plan`` stores it, in a fresh SQLite store per checkout and format. Each checkout's
own ``rangeplan serve --no-editor`` then runs on a free 127.0.0.1 port over its store (its
``.venv``, else this interpreter with the checkout on ``PYTHONPATH``: e.g. an older revision
unpacked by ``git archive``), and ``--exports`` clients fetch ``GET /v1/plans/{id}?format=FMT``
at once, each body streamed to nowhere and its length checked. A thread samples the server
process's RSS (the server only, not its workers) every 10 ms and ``/ready`` every 100 ms.
Printed per checkout and format: the stored plan's size, the downloads' wall time, the
server's RSS before, its peak and growth during the downloads, and what it still holds
after; ``/ready``'s slowest answer during the downloads.

    .venv/bin/python benchmarks/bench_service.py --root /path/to/main --root . --format json --format csv
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import psutil

HERE = Path(__file__).resolve().parent.parent
TABLE1 = json.loads((HERE / "app" / "static" / "examples" / "table1.json").read_text())


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def big_request(samples: int) -> dict:
    mid = TABLE1["segments"][1:-1]
    body = (mid + mid[::-1]) * 5
    return {"segments": [TABLE1["segments"][0], *body[:98], TABLE1["segments"][-1]],
            "settings": {"mode": "paper", "samples_per_segment": samples}}


def stored_plan(samples: int, cache: Path) -> tuple[str, dict]:
    """The big plan's result JSON (planned once, cached) and its request."""
    req = big_request(samples)
    path = cache / f"rangeplan-bench-plan-{samples}.json"
    if not path.is_file():
        sys.path.insert(0, str(HERE))
        from planner import plan

        t0 = time.perf_counter()
        path.write_bytes(plan(req).to_json())
        print(f"# planned the stored plan ({samples} samples per segment) in {time.perf_counter() - t0:.1f} s",
              flush=True)
    return path.read_text(), req


def start(root: Path, data_dir: str, workers: int) -> tuple[subprocess.Popen, str]:
    port = free_port()
    env = {**os.environ, "RANGEPLAN_DATA_DIR": data_dir, "RANGEPLAN_WORKERS": str(workers),
           "RANGEPLAN_ACCESS_LOG": "0", "RANGEPLAN_LOG_LEVEL": "warning", "RANGEPLAN_MAX_PLAN_BYTES": str(1 << 30),
           "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    venv = root / ".venv" / "bin" / "python"
    env["PYTHONPATH"] = str(root)
    proc = subprocess.Popen([str(venv if venv.exists() else sys.executable), "-m", "app.cli", "serve", "--no-editor",
                             "--port", str(port)], env=env, cwd=root, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline:
        try:
            if httpx.get(url + "/ready", timeout=2).status_code == 200:
                return proc, url
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    stop(proc)
    raise RuntimeError(f"the server of {root} did not get ready")


def stop(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def measure(root: Path, text: str, request: dict, exports: int, fmt: str, workers: int) -> dict:
    with tempfile.TemporaryDirectory(prefix="rangeplan-bench-") as data:
        sys.path.insert(0, str(HERE))
        from app.storage import Store

        st = Store(data, max_plan_bytes=1 << 30)
        plan_id = st.save_plan_json(text, request)
        st.close()
        assert plan_id, "the plan was not stored"
        proc, url = start(root, data, workers)
        try:
            server = psutil.Process(proc.pid)
            time.sleep(1.0)
            before = server.memory_info().rss
            peak = [before]
            ready_max = [0.0]
            done = threading.Event()

            def sample_rss() -> None:
                while not done.is_set():
                    peak[0] = max(peak[0], server.memory_info().rss)
                    time.sleep(0.01)

            def sample_ready() -> None:
                with httpx.Client(base_url=url, timeout=60) as c:
                    while not done.is_set():
                        t0 = time.perf_counter()
                        try:
                            c.get("/ready")
                        except httpx.HTTPError:  # counted as the time it took to fail
                            pass
                        ready_max[0] = max(ready_max[0], time.perf_counter() - t0)
                        time.sleep(0.1)

            sizes: list[int | str] = [0] * exports

            def export(i: int) -> None:
                n = 0
                try:
                    with httpx.stream("GET", f"{url}/v1/plans/{plan_id}", params={"format": fmt}, timeout=300) as r:
                        for chunk in r.iter_bytes(1 << 20):
                            n += len(chunk)
                        sizes[i] = n if r.status_code == 200 else f"HTTP {r.status_code}"
                except httpx.HTTPError as exc:
                    sizes[i] = type(exc).__name__

            samplers = [threading.Thread(target=sample_rss), threading.Thread(target=sample_ready)]
            for t in samplers:
                t.start()
            t0 = time.perf_counter()
            clients = [threading.Thread(target=export, args=(i,)) for i in range(exports)]
            for t in clients:
                t.start()
            for t in clients:
                t.join()
            wall = time.perf_counter() - t0
            done.set()
            for t in samplers:
                t.join()
            time.sleep(1.0)
            after = server.memory_info().rss
        finally:
            stop(proc)
    ok = all(isinstance(s, int) and s > 0 and s == sizes[0] for s in sizes)
    return {"root": str(root), "format": fmt, "plan_mb": len(text) / 1e6,
            "export_mb": sizes[0] / 1e6 if ok else float("nan"),
            "wall_s": wall, "before_mb": before / 1e6, "peak_mb": peak[0] / 1e6, "growth_mb": (peak[0] - before) / 1e6,
            "after_mb": after / 1e6, "ready_max_s": ready_max[0], "ok": ok, "sizes": sizes}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", action="append", type=Path, help="checkout with a .venv (repeat; default: this one)")
    ap.add_argument("--exports", type=int, default=4, help="concurrent exports")
    ap.add_argument("--format", action="append", help="download format (repeat; default: csv)")
    ap.add_argument("--samples", type=int, default=1200, help="samples per segment of the stored plan (1200: ~60 MB)")
    ap.add_argument("--workers", type=int, default=2, help="planning workers of each server")
    args = ap.parse_args()
    roots = [r.resolve() for r in (args.root or [HERE])]
    text, request = stored_plan(args.samples, Path(tempfile.gettempdir()))
    print(f"# {os.cpu_count()} CPUs; load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"{'checkout':40s} {'format':>6s} {'plan MB':>8s} {'export MB':>9s} {'wall s':>7s} {'RSS before':>10s} "
          f"{'peak':>8s} {'growth':>8s} {'after':>8s} {'/ready max s':>12s} ok")
    for fmt in args.format or ["csv"]:
        for root in roots:
            r = measure(root, text, request, args.exports, fmt, args.workers)
            print(f"{r['root'][-40:]:40s} {r['format']:>6s} {r['plan_mb']:8.1f} {r['export_mb']:9.1f} "
                  f"{r['wall_s']:7.1f} {r['before_mb']:10.0f} {r['peak_mb']:8.0f} {r['growth_mb']:8.0f} "
                  f"{r['after_mb']:8.0f} {r['ready_max_s']:12.2f} {'yes' if r['ok'] else r['sizes']}", flush=True)
    print(f"# load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
