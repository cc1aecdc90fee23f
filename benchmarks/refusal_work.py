"""A refused plan's own work against its estimate (issue 33 goal 2, issue 31 goal 6), from the
``--resume`` files of ``benchmarks/certify.py --profile`` runs: per file, the refusals whose own
CPU ("plan infeasible" and its DAQP calls, before the advice search) is over 1.5x their work
estimate, as measured (CPU s / estimate s) and at the reference machine's speed (also over the
run's calibrated speed, Table I's CPU over its 20 ms there), the largest, the run's CPU, and the
largest refusals.

    .venv/bin/python benchmarks/refusal_work.py before.jsonl after.jsonl [--largest 8]
"""

from __future__ import annotations

import argparse
import json


def own_cpu(record: dict) -> float:
    """The refused plan's own CPU [s]: its plan and its DAQP calls, before the advice search."""
    cpu = record["cpu"]
    return cpu.get("plan infeasible", 0.0) + cpu.get("plan infeasible: DAQP", 0.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="+")
    ap.add_argument("--largest", type=int, default=8)
    args = ap.parse_args()
    print("| run | cases | refusals | over 1.5x (CPU / estimate) | over 1.5x (at reference speed) | largest (case) "
          "| refusals' own CPU s | CPU s | CPU s / case |")
    print("|---|---|---|---|---|---|---|---|---|")
    largest = {}
    for path in args.files:
        records = {}
        for line in open(path):
            r = json.loads(line)
            records[r["index"]] = r  # a case recorded twice: the last
        refused = [r for r in records.values() if r["modes"]["constrained"]["outcome"] == "infeasible"]
        raw = [(own_cpu(r) / r["modes"]["constrained"]["estimate"], r["index"]) for r in refused]
        ref = [(own_cpu(r) / r["modes"]["constrained"]["speed"] / r["modes"]["constrained"]["estimate"], r["index"],
                own_cpu(r), r["modes"]["constrained"]["estimate"]) for r in refused]
        total = sum(r["cpu_s"] for r in records.values())
        top = max(ref)
        print(f"| {path} | {len(records)} | {len(refused)} | {sum(v > 1.5 for v, _ in raw)} | "
              f"{sum(v > 1.5 for v, *_ in ref)} | {top[0]:.2f} ({top[1]}) | {sum(own_cpu(r) for r in refused):.1f} | "
              f"{total:.1f} | {total / len(records):.2f} |")
        largest[path] = sorted(ref, reverse=True)[:args.largest]
    for path, rows in largest.items():
        print(f"\n{path}: the largest refusals (own CPU / estimate at reference speed)\n")
        print("| case | own CPU s | estimate s | ratio |")
        print("|---|---|---|---|")
        for v, i, cpu, est in rows:
            print(f"| {i} | {cpu:.2f} | {est:.3f} | {v:.2f} |")


if __name__ == "__main__":
    main()
