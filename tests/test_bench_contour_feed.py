"""``benchmarks/bench_contour_feed.py --lag``: the plan's lag behind the peer at the same path
position (issue 35, branch fixedsamples), on a plan made from the peer's own motion: held at
its start for one sample and then exactly the peer's, the lag is one sample, all of it in the
first sample, and the pass's time over the peer's is that sample."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parent.parent / "benchmarks" / "bench_contour_feed.py"


def _bench():
    if "bench_contour_feed" not in sys.modules:
        spec = importlib.util.spec_from_file_location("bench_contour_feed", BENCH)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules["bench_contour_feed"] = module
    return sys.modules["bench_contour_feed"]


def _peer(L: float, T: float):
    """A straight pass of length ``L`` from rest to rest in ``T`` (a triangular speed), as the
    peer's cache holds it: per element its times and speeds."""
    t = np.linspace(0.0, T, 401)
    vmax = 2 * L / T
    v = np.where(t <= T / 2, vmax * t / (T / 2), vmax * (T - t) / (T / 2))
    s = np.where(t <= T / 2, vmax * t * t / T, L - vmax * (T - t) ** 2 / T)
    return {"t": [t], "v": [v], "time": T}, (t, s)


@pytest.mark.parametrize("held", [0, 1, 3])
def test_the_lag_is_the_samples_held_at_the_start(held):
    bench = _bench()
    L, Ts, n = 0.01, 0.01, 40
    T = n * Ts
    peer, (tp, sp) = _peer(L, T)
    j = np.arange(n + held + 1)
    s = np.interp(np.maximum(j - held, 0) * Ts, tp, sp)
    pose = np.column_stack((np.concatenate(([0.0], s)), np.zeros(len(s) + 1)))  # a rest sample before the pass
    cutting = np.concatenate(([False, False], np.ones(len(s) - 1, bool)))
    res = SimpleNamespace(pose=pose, settings=SimpleNamespace(Ts=Ts),
                          contour=SimpleNamespace(cutting=cutting.tolist(), passes=[None]))
    els = [SimpleNamespace(length_m=L)]
    row = bench.lag_rows("line", 0, els, peer, res, 0)[0]
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert int(cells[2]) == n + held and float(cells[3]) == pytest.approx(n)
    phases = [float(c.split(":")[1]) for c in cells[4:9]]
    assert float(cells[9]) == pytest.approx(held, abs=0.02)  # the time over the peer's, in samples
    assert sum(phases) == pytest.approx(held, abs=0.02)
    # the held samples are the first sample's lag (one) and the speeding up's (the rest)
    assert phases[0] == pytest.approx(min(held, 1), abs=0.02)
    assert phases[2] == pytest.approx(0.0, abs=0.02) and phases[3] == pytest.approx(0.0, abs=0.02)
