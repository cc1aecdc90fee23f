"""Progress and an estimate while numba compiles the planner's kernels (issue 24).

The first plan after installing compiles the kernels (numba, ``cache=True``): a minute or
more on a small machine. :func:`compile_progress` watches numba's ``numba:compile`` events
(fired only when a kernel really compiles, never when it loads from the on-disk cache) and
writes to ``stream`` what is going on: at the first compile a line saying so, then every
``interval`` seconds the kernels compiled so far, the time taken and an estimate of the time
left. Nothing is written when every kernel loads from the cache.

The estimate: :data:`COMPILE_COST` holds each kernel's own compile time (callees excluded) as
measured by ``benchmarks/bench_start.py --profile-compile`` on a quiet 2-core machine; the
kernels still to compile are those whose on-disk cache index holds no entry for this source
(numba keys it by the source file's content); the time left is their cost scaled by how fast
the done ones went on this machine (so a busy machine is accounted for after a few kernels).
"""

from __future__ import annotations

import importlib
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, TextIO

from numba.core import event
from numba.extending import is_jitted

from .. import _jit
from ..constraints import registry as _registry

__all__ = ["compile_progress", "kernel_dispatchers", "pending_kernels", "COMPILE_COST", "KERNEL_MODULES"]

#: the modules holding the compiled kernels (numba dispatchers) other than the constraint
#: registry's
_BASE_MODULES = ("planner.model.kernels", "planner.horizon.kernels", "planner.corridor.kernels",
                 "planner.constraints.dense_kernels", "planner.constraints.stagewise_kernels",
                 "planner.constraints.dual_kernels", "planner.constraints.step_kernels",
                 "planner.orchestrator.kernels")
#: the modules holding the compiled kernels: those above, the registry's fused assembly and the
#: modules of the registry's row kernels (:data:`planner.constraints.registry.SECTIONS`)
KERNEL_MODULES = tuple(dict.fromkeys((*_BASE_MODULES, _registry.__name__,
                                      *(k.py_func.__module__ for s in _registry.SECTIONS for k in (s.count, s.fill)))))

#: each kernel's own compile time [CPU s] (callees excluded, numba's own overloads spread over
#: the kernels), measured by ``python benchmarks/bench_start.py --profile-compile`` (a full
#: warm-up with an empty cache: 164 CPU s, 2026-11-25); only ratios matter to the estimate.
#: The row constraints' count and fill kernels: their registry sections'
#: (:func:`planner.constraints.registry.compile_costs`)
COMPILE_COST: dict[str, float] = {
    "simulate_constrained": 24.2, "constrained_step": 20.33, "dual_solve_active": 19.38, "simulate_paper": 13.47,
    "stage_setup": 11.77, "substitute_many": 7.64, "substitute": 6.37, "riccati": 6.18, "zoh": 4.47, "_terms": 4.29,
    "hessian": 4.05, "_drop": 3.13, "assemble": 3.11, "model_step": 2.82, "union_distances": 2.49,
    "free_parts": 2.39, "affine": 1.98, "_expm": 1.82, "_on_working_set": 1.73, "build_grid": 1.62,
    "_eliminate": 1.6, "factorised_blocks": 1.52, "prediction": 1.5, "_polygon_distance": 1.36, "rk4": 1.19,
    "acceleration": 0.89, "first_legs": 0.82, "_most_violated": 0.78, "_chol3_solve": 0.7,
    "predict": 0.65, "_matrix_row_into": 0.61, "plant_step": 0.54, "state_derivative": 0.53,
    "finish": 0.49, "leg_rows": 0.43, "constraint_matrix": 0.4, "offset": 0.36, "_row_value": 0.35,
    "blocks_derivative": 0.32, **_registry.compile_costs(),
}
_DEFAULT_COST = 0.5  # a kernel not in the table


def kernel_dispatchers() -> dict[str, Any]:
    """Every compiled kernel of the planner by ``module.name`` (imports the kernel modules)."""
    found: dict[str, Any] = {}
    for name in KERNEL_MODULES:
        module = importlib.import_module(name)
        for attr, value in vars(module).items():
            if is_jitted(value) and value.__module__ == name:
                found[f"{name.rsplit('.', 1)[-1]}.{attr}"] = value
    return found


def _cached(dispatcher: Any) -> bool | None:
    """Whether numba's on-disk cache holds compiled code of this kernel's current source
    (None: cannot tell): :func:`planner._jit.cached` (its index file, numba's layout)."""
    try:
        return _jit.cached(dispatcher)
    except Exception:
        return None


def _inlined(dispatcher: Any) -> bool:
    """A kernel inlined into its callers (``inline="always"``): compiled within them, never cached itself."""
    return getattr(dispatcher, "targetoptions", {}).get("inline") == "always"


def pending_kernels() -> list[str]:
    """The kernels (``module.name``) that would compile, not load, on first use (the inlined
    ones, compiled within their callers, are not counted)."""
    return [name for name, d in kernel_dispatchers().items() if not _inlined(d) and _cached(d) is False]


def _cost(qualname: str) -> float:
    return COMPILE_COST.get(qualname, _DEFAULT_COST)


class _Progress(event.Listener):
    """The ``numba:compile`` listener; the kernels still to compile are looked up at the
    first compile (nothing is read while every kernel loads from the cache)."""

    def __init__(self, stream: TextIO, interval: float) -> None:
        self.stream, self.interval = stream, interval
        self.pending: set[str] = set()
        self.total = 0.0
        self.lock = threading.Lock()
        self.t0: float | None = None
        self.done: set[str] = set()
        self.done_cost = 0.0
        self.t_last: float | None = None
        self.stop = threading.Event()
        self.thread: threading.Thread | None = None
        self.tty = bool(getattr(stream, "isatty", lambda: False)())

    def on_start(self, ev: Any) -> None:
        with self.lock:
            if self.t0 is None:
                self.t0 = time.perf_counter()
                self.pending = {name.rsplit(".", 1)[-1] for name in pending_kernels()}
                self.total = sum(_cost(n) for n in self.pending)
                n = len(self.pending) or "the"
                self._write(f"compiling {n} kernels of the planner (numba; {_jit.kernel_cache().later()})"
                            f"{self._eta_text()}", final=True)
                self.thread = threading.Thread(target=self._tick, name="rangeplan-compile-progress", daemon=True)
                self.thread.start()

    def on_end(self, ev: Any) -> None:
        name = ev.data["dispatcher"].py_func.__name__
        with self.lock:
            if name not in self.done:
                self.done.add(name)
                if name in self.pending:
                    self.done_cost += _cost(name)
                    self.t_last = time.perf_counter()

    def _eta(self) -> float | None:
        """Seconds left: the cost of the kernels still to compile at this machine's speed (measured
        over the kernels done, once a little of the work is done; the table's own before), less
        the time spent since the last kernel finished (a countdown while a big one compiles)."""
        if not self.pending:
            return None
        now = time.perf_counter()
        left = max(self.total - self.done_cost, 0.0)
        if left == 0.0:
            return 0.0
        t0 = self.t0 if self.t0 is not None else now
        last = self.t_last if self.t_last is not None else t0
        speed = (last - t0) / self.done_cost if self.done_cost >= 0.03 * self.total else 1.0
        return max(left * speed - (now - last), 1.0)

    def _eta_text(self) -> str:
        eta = self._eta()
        return "" if eta is None else f", about {eta:.0f} s left"

    def line(self) -> str:
        elapsed = time.perf_counter() - (self.t0 or time.perf_counter())
        of = f" of {len(self.pending)}" if self.pending else ""
        return f"compiling kernels: {len(self.done & self.pending) if self.pending else len(self.done)}{of} done, " \
               f"{elapsed:.0f} s{self._eta_text()}"

    def _write(self, text: str, final: bool = False) -> None:
        if self.tty:
            self.stream.write("\r\033[K" + text + ("\n" if final else ""))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def _tick(self) -> None:
        while not self.stop.wait(self.interval):
            with self.lock:
                self._write(self.line())

    def close(self) -> None:
        self.stop.set()
        if self.thread is not None:
            self.thread.join()
            elapsed = time.perf_counter() - (self.t0 or time.perf_counter())
            n = len(self.done & self.pending) if self.pending else len(self.done)
            kept = _jit.kernel_cache().lasting
            self._write(f"compiled {n} kernels in {elapsed:.0f} s "
                        f"({'cached for the next runs' if kept else 'for this process only'})", final=True)


@contextmanager
def compile_progress(stream: TextIO | None = None, interval: float | None = None) -> Iterator[None]:
    """Within the block, report on ``stream`` (default ``sys.stderr``) any compiling of
    the planner's kernels: a line when it starts, progress with an estimate of the time
    left every ``interval`` seconds (1 s on a terminal, 10 s otherwise), a line at the end."""
    global _active
    if _active:  # nested (warm_up within the CLI's block): the outer one reports
        yield
        return
    out = sys.stderr if stream is None else stream
    tty = bool(getattr(out, "isatty", lambda: False)())
    progress = _Progress(out, interval if interval is not None else (1.0 if tty else 10.0))
    event.register("numba:compile", progress)
    _active = True
    try:
        yield
    finally:
        _active = False
        event.unregister("numba:compile", progress)
        progress.close()


_active = False  # a compile_progress block is open (numba compiles under one global lock)
