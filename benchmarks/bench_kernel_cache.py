"""The first plan of an installation whose kernels another installation compiled (issue 34
goal 5: numba's public cache, keyed on content-addressed copies of the kernel modules).

    python benchmarks/bench_kernel_cache.py --base-tree /work/main [--rounds 5] \\
        [--cache-base DIR] [--cache-head DIR]

For the base tree and this tree (head), each with its own kernel cache (``RANGEPLAN_KERNEL_CACHE``:
``--cache-base``/``--cache-head``, default new temporary directories) filled first by the
tree's own checkout (``python -m planner``: compiles what is missing, not timed), then for
each installation of that tree:

- ``checkout``: the tree itself (``PYTHONPATH``);
- ``worktree``: ``git worktree add --detach`` of the tree's HEAD at another path (another
  checkout: other paths, other file mtimes);
- ``wheel``: the tree's wheel (``pip wheel --no-deps --no-build-isolation``) installed with
  ``--no-deps`` into a fresh venv whose other packages come from this interpreter's
  site-packages (a ``.pth``);

a new process that imports the planner and plans Table I (constrained): seconds from its first
line to the plan (wall, and the process's CPU then), the kernels it compiled (numba's cache
misses) and loaded (hits); then the warm plan of Table I in that process (median of 20) [ms].
Medians over ``--rounds`` processes, base and head interleaved; the last column head/base.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TABLE1 = ROOT / "app" / "static" / "examples" / "table1.json"

CHILD = f"""
import json, resource, sys, time
t0 = time.perf_counter()
import planner
from planner.orchestrator import compiling
req = json.load(open({str(TABLE1)!r}))
planner.plan(req)
first = time.perf_counter() - t0
ru = resource.getrusage(resource.RUSAGE_SELF)
cpu = ru.ru_utime + ru.ru_stime
ks = compiling.kernel_dispatchers().values()
hits = sum(sum(d.stats.cache_hits.values()) for d in ks)
misses = sum(sum(d.stats.cache_misses.values()) for d in ks)
warm = []
for _ in range(20):
    t = time.perf_counter()
    planner.plan(req)
    warm.append(time.perf_counter() - t)
warm.sort()
print(json.dumps({{"first_s": first, "cpu_s": cpu, "hits": hits, "misses": misses, "warm_ms": 1e3 * warm[10],
                  "planner": planner.__file__}}))
"""


def run(python: str, path: str | None, cache: Path, cwd: Path) -> dict:
    env = {"PATH": "/usr/bin:/bin", "HOME": os.environ.get("HOME", "/root"), "RANGEPLAN_KERNEL_CACHE": str(cache),
           "OPENBLAS_NUM_THREADS": "1", "PYTHONDONTWRITEBYTECODE": "1"}
    if path:
        env["PYTHONPATH"] = path
    out = subprocess.run([python, "-c", CHILD], env=env, cwd=cwd, capture_output=True, text=True, timeout=1800)
    if out.returncode:
        raise RuntimeError(out.stderr)
    return json.loads(out.stdout.strip().splitlines()[-1])


def installations(tree: Path, tmp: Path) -> dict[str, tuple[str, str | None, Path]]:
    """name -> (python, PYTHONPATH, the planner package it must import)."""
    wt = tmp / "worktree"
    subprocess.run(["git", "-C", str(tree), "worktree", "add", "--detach", str(wt), "HEAD"], check=True,
                   capture_output=True)
    dist, venv = tmp / "dist", tmp / "venv"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation", "-w",
                    str(dist), str(wt)], check=True, capture_output=True)
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    subprocess.run([str(venv / "bin" / "pip"), "install", "--quiet", "--no-deps", "--no-index",
                    *map(str, dist.glob("*.whl"))], check=True)
    site = Path(subprocess.run([str(venv / "bin" / "python"), "-c", "import sysconfig; print(sysconfig.get_paths()"
                                "['purelib'])"], check=True, capture_output=True, text=True).stdout.strip())
    (site / "zz_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")  # after the wheel's own
    return {"checkout": (sys.executable, str(tree), tree / "planner"),
            "worktree": (sys.executable, str(wt), wt / "planner"),
            "wheel": (str(venv / "bin" / "python"), None, site / "planner")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base-tree", type=Path, required=True)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--cache-base", type=Path)
    ap.add_argument("--cache-head", type=Path)
    args = ap.parse_args()
    trees = {"base": args.base_tree.resolve(), "head": ROOT}
    with tempfile.TemporaryDirectory(prefix="bench-kernel-cache-") as t:
        tmp = Path(t)
        caches = {"base": args.cache_base or tmp / "cache-base", "head": args.cache_head or tmp / "cache-head"}
        setups = {}
        try:
            for side, tree in trees.items():
                (tmp / side).mkdir()
                setups[side] = installations(tree, tmp / side)
                python, path, _ = setups[side]["checkout"]
                subprocess.run([python, "-m", "planner"], cwd=tmp, check=True, capture_output=True,
                               env={"PATH": "/usr/bin:/bin", "HOME": os.environ.get("HOME", "/root"),
                                    "PYTHONPATH": str(path), "RANGEPLAN_KERNEL_CACHE": str(caches[side]),
                                    "OPENBLAS_NUM_THREADS": "1"})
            got: dict[tuple[str, str], list[dict]] = {}
            for _ in range(args.rounds):
                for name in ("checkout", "worktree", "wheel"):
                    for side in trees:
                        python, path, package = setups[side][name]
                        r = run(python, path, caches[side], tmp)
                        assert Path(r["planner"]).parent == package, (r["planner"], package)
                        got.setdefault((name, side), []).append(r)
        finally:
            for side, tree in trees.items():
                subprocess.run(["git", "-C", str(tree), "worktree", "remove", "--force", str(tmp / side / "worktree")],
                               capture_output=True)
    print(f"load average {os.getloadavg()[0]:.1f}, {args.rounds} rounds, medians")
    print("| installation | metric | base | head | head/base |")
    print("|---|---|---|---|---|")
    for name in ("checkout", "worktree", "wheel"):
        for metric, unit in (("first_s", "import + first plan, wall s"), ("cpu_s", "CPU s then"),
                             ("misses", "kernels compiled"), ("hits", "kernels loaded"),
                             ("warm_ms", "warm plan, ms")):
            b, h = (statistics.median(r[metric] for r in got[(name, s)]) for s in ("base", "head"))
            ratio = f"{h / b:.2f}" if b else "-"
            print(f"| {name} | {unit} | {b:.3g} | {h:.3g} | {ratio} |")
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
