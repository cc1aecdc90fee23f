"""What users install (issue 30): the wheel and sdist sizes, the image's size and its start-up.

    python benchmarks/bench_install.py [--image localhost/rangeplan:test] [--rounds 5]

- ``wheel``, ``sdist``: ``python -m build --no-isolation`` of this tree [kB];
- ``image``: the image's size, its base's (``.container-base``, as container/build.sh wrote
  it) and the difference, rangeplan's own layers [MB];
- ``/ready``: seconds from ``podman run -d --read-only --tmpfs /tmp --user UID:0`` (a random
  uid, as Kubernetes runs it) to the first 200 of ``/ready``, and to the first plan of Table I,
  over ``--rounds`` containers (median, min, max).

Needs root and podman (``make container-test`` installs it and builds the image).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.test_smoke import AUTH, TABLE1, ImageTarget  # noqa: E402  one way to run the image


def dist_sizes() -> dict[str, float]:
    with tempfile.TemporaryDirectory() as out:
        subprocess.run([sys.executable, "-m", "build", "--no-isolation", "--outdir", out, str(ROOT)], check=True,
                       capture_output=True)
        return {p.suffix if p.suffix == ".whl" else ".tar.gz": p.stat().st_size / 1e3 for p in Path(out).iterdir()}


def image_sizes(target: ImageTarget) -> tuple[float, float, str]:
    base_file = ROOT / ".container-base"
    base = base_file.read_text().strip() if base_file.exists() else "python:3.11-slim"
    size = int(target.engine("image", "inspect", "--format", "{{.Size}}", target.image, check=True).stdout)
    base_size = int(target.engine("image", "inspect", "--format", "{{.Size}}", base, check=True).stdout)
    return size / 1e6, base_size / 1e6, base


def start_up(target: ImageTarget) -> tuple[float, float]:
    """(s to /ready 200, s to the first plan's answer) of one new container."""
    with tempfile.TemporaryDirectory() as data, target.serve(Path(data)) as srv:
        while True:
            try:
                if httpx.get(f"{srv.url}/ready", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            if time.monotonic() - srv.started > 120:
                raise RuntimeError("not ready in 120 s")
            time.sleep(0.02)
        ready = time.monotonic() - srv.started
        r = httpx.post(f"{srv.url}/v1/plan", json=TABLE1, headers=AUTH, timeout=120)
        r.raise_for_status()
        return ready, time.monotonic() - srv.started


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--image", default="localhost/rangeplan:test")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    sizes = dist_sizes()
    print("| artifact | size |\n|---|---:|")
    print(f"| wheel | {sizes['.whl']:.0f} kB |\n| sdist | {sizes['.tar.gz']:.0f} kB |")
    target = ImageTarget(args.image)
    total, base_mb, base = image_sizes(target)
    print(f"| image | {total:.0f} MB |\n| its base ({base}) | {base_mb:.0f} MB |\n"
          f"| rangeplan's own layers | {total - base_mb:.1f} MB |")
    runs = [start_up(target) for _ in range(args.rounds)]
    print(f"\n| {args.rounds} containers, --read-only --user {target.user} | median | min | max |\n"
          "|---|---:|---:|---:|")
    for name, values in (("run -> /ready 200 [s]", [r[0] for r in runs]),
                         ("run -> first plan of Table I [s]", [r[1] for r in runs])):
        print(f"| {name} | {statistics.median(values):.2f} | {min(values):.2f} | {max(values):.2f} |")


if __name__ == "__main__":
    main()
