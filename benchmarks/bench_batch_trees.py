"""Batch throughput of two source trees side by side (a change against its base), in one run.

For each mode and round, every engine runs once per tree, the trees interleaved (so a change
in the machine's load hits both alike), each run a fresh child process of that tree's own
``benchmarks/bench_batch.py --child`` (workers started and warmed, not timed; then
``app.batch.cli.run_batch`` over the same JSON Lines file of Table I variants, writing one
JSON result per item and summary.csv). Prints, per mode and engine, the median over rounds of
each tree's wall time and plans/s, the median of each round's ratio (second tree against the
first) of plans/s and of all processes' CPU per plan, and checks that both trees' results
have the same total energy.

    PYTHONPATH=. OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/bench_batch_trees.py \\
        /path/to/base /path/to/change --rounds 3 --items 1000
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
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_batch import corridors  # noqa: E402


def run(tree: Path, engine: str, workers: int, jsonl: Path, warm: Path) -> dict:
    out = Path(tempfile.mkdtemp(prefix="bench-trees-"))
    try:
        env = {**os.environ, "PYTHONPATH": str(tree), "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
        p = subprocess.run([sys.executable, str(tree / "benchmarks" / "bench_batch.py"), "--child", engine,
                            "--workers", str(workers), "--jsonl", str(jsonl), "--warm", str(warm), "--out", str(out)],
                           capture_output=True, text=True, env=env, timeout=7200, cwd=tree)
        if p.returncode != 0:
            raise RuntimeError(f"{tree} {engine}: {p.stderr[-2000:]}")
        return json.loads(p.stdout.strip().splitlines()[-1])
    finally:
        shutil.rmtree(out, ignore_errors=True)


def _cpu(r: dict) -> float:
    """All processes' CPU per plan [ms] (the main process, its workers; Dask's scheduler runs in the main one)."""
    return r["main_cpu_ms"] + r["worker_cpu_ms"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("trees", nargs=2, type=Path, help="the base tree, then the changed one")
    ap.add_argument("--items", type=int, default=1000)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--modes", nargs="+", default=["paper", "constrained"])
    ap.add_argument("--engines", nargs="+", default=["1 process", "local pool", "dask"])
    args = ap.parse_args()
    trees = [t.resolve() for t in args.trees]
    tmp = Path(tempfile.mkdtemp(prefix="bench-trees-in-"))
    print(f"# {os.cpu_count()} CPUs; load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    t_start = time.time()
    res: dict[tuple[str, str], list[list[dict]]] = {}
    try:
        for mode in args.modes:
            jsonl, warm = tmp / f"{mode}.jsonl", tmp / f"{mode}-warm.jsonl"
            jsonl.write_text("".join(json.dumps(r) + "\n" for r in corridors(args.items, mode)))
            warm.write_text("".join(json.dumps(r) + "\n" for r in corridors(4 * args.workers, mode)))
            for rnd in range(args.rounds):
                for engine in args.engines:
                    order = trees if rnd % 2 == 0 else trees[::-1]  # alternate which tree goes first
                    got = {t: run(t, engine, args.workers, jsonl, warm) for t in order}
                    res.setdefault((mode, engine), []).append([got[t] for t in trees])
                    a, b = (got[t] for t in trees)
                    print(f"# {mode} round {rnd + 1} {engine}: {args.items / a['wall_s']:.1f} -> "
                          f"{args.items / b['wall_s']:.1f} plans/s, all CPU per plan {_cpu(a):.2f} -> "
                          f"{_cpu(b):.2f} ms (main {a['main_cpu_ms']:.2f} -> {b['main_cpu_ms']:.2f}), "
                          f"load {os.getloadavg()[0]:.2f}", flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"# load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}; "
          f"{(time.time() - t_start) / 60:.1f} min")
    print(f"\n{args.items} corridors per run, {args.workers} workers, median over {args.rounds} interleaved rounds; "
          f"A = {trees[0]}, B = {trees[1]}\n")
    print("| mode | engine | A wall [s] | B wall [s] | A plans/s | B plans/s | B/A plans/s | B/A all CPU per plan "
          "| ok / failed (A, B) |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---|")
    for (mode, engine), rounds in res.items():
        for a, b in rounds:
            assert abs(a["energy_sum"] - b["energy_sum"]) <= 1e-9 * max(1.0, abs(a["energy_sum"])), (a, b)
        wa = statistics.median(a["wall_s"] for a, _ in rounds)
        wb = statistics.median(b["wall_s"] for _, b in rounds)
        speed = statistics.median(a["wall_s"] / b["wall_s"] for a, b in rounds)
        cpu_ratio = statistics.median(_cpu(b) / _cpu(a) for a, b in rounds)
        a0, b0 = rounds[0]
        print(f"| {mode} | {engine} | {wa:.2f} | {wb:.2f} | {args.items / wa:.1f} | {args.items / wb:.1f} | "
              f"{speed:.3f} | {cpu_ratio:.3f} | {a0['ok']}/{a0['failed']}, {b0['ok']}/{b0['failed']} |")


if __name__ == "__main__":
    main()
