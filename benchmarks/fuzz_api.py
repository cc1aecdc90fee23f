"""The full schemathesis run of the API (issue 15): every check, all phases with the
stateful links, ``--max-examples`` per operation (default 1000), against a real server with
the token on, two workers and a 3 s compute limit (tests/fuzz/runner.py; the quick profile
of ``make test`` is the same run with 100). Prints the requests each operation received and
the outcome; the figures are in benchmarks/README.md.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/fuzz_api.py [--max-examples 1000] [--seed 1]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.fuzz.runner import run


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--max-examples", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    r = run(max_examples=args.max_examples, seed=args.seed)
    print(f"schemathesis --checks all, --max-examples {args.max_examples}, seed {args.seed}: "
          f"{r.generated} test cases in {r.seconds:.0f} s ({r.stateful_cases} in stateful scenarios, "
          f"{r.top_ups} operations topped up)\n")
    print("| operation | requests received |")
    print("|---|---:|")
    for op, n in sorted(r.per_operation.items(), key=lambda kv: kv[0].split(" ", 1)[::-1]):
        if n > 1:
            print(f"| `{op}` | {n} |")
    others = sum(n for n in r.per_operation.values() if n == 1)
    print(f"| other methods on these paths (405 checks) | {others} |")
    print(f"\nfailures: {len(r.failures)}, run errors: {len(r.errors)}, server 5xx answers: {r.server_errors}, "
          f"tracebacks in the server log: {r.server_tracebacks}, server exit status after SIGTERM: {r.server_exit}")
    if r.failures or r.errors:
        print(r.output)
    return 0 if r.exit_code == 0 and not r.server_errors else 1


if __name__ == "__main__":
    sys.exit(main())
