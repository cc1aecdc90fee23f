"""Planning off the event loop: a small pool of worker processes with a per-job time limit.

Planning is CPU-bound Python + small numpy (the GIL is held most of the time), so threads
give no parallelism; worker processes do, and a process that runs past the time limit can
be killed and replaced without disturbing the other jobs (a thread cannot be stopped).

Each worker owns one end of a pipe, imports the planner once, then serves jobs. A job is
a plain dict (``kind``: ``"plan"``, ``"segment"`` or ``"import"``); the worker runs the planner, serialises
the result to JSON itself, stores plans in the SQLite store itself (WAL, multi-process safe)
and sends back ready-to-send bytes, so the server process only moves bytes.

The pool is used from threads (``run`` blocks); the API calls it through a thread pool.
``mode="thread"`` runs jobs in the calling thread instead (no parallelism under the GIL, no
way to stop a runaway job; kept to measure the difference, see benchmarks/bench_http.py).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import json  # noqa: E402
import math  # noqa: E402
import queue  # noqa: E402
import socket  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
from itertools import chain  # noqa: E402
from multiprocessing.connection import Connection  # noqa: E402

import orjson  # noqa: E402


class JobTimeout(Exception):
    """The job ran longer than the pool's time limit (its worker was replaced)."""


class PoolBusy(Exception):
    """Too many jobs waiting for a worker."""


class WorkerCrashed(Exception):
    """The worker process died while running the job."""


# ---------------------------------------------------------------------------------------
# the job itself (runs in the worker process, or in a thread in "thread" mode)

_stores: dict = {}


def _store(path):
    if path is None:
        return None
    st = _stores.get(path)
    if st is None:
        from app.storage import Store
        st = _stores[path] = Store(path)
    return st


def _check_finite(obj, path="result"):
    """json.dumps(allow_nan=False) says only *that* a value is not finite; say where."""
    if isinstance(obj, float):
        if not math.isfinite(obj):
            return path
    elif isinstance(obj, dict):
        for k, v in obj.items():
            p = _check_finite(v, f"{path}.{k}")
            if p:
                return p
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            p = _check_finite(v, f"{path}[{i}]")
            if p:
                return p
    return None


def _all_finite(obj) -> bool:
    """Quick test that ``obj`` holds no NaN or infinity (the JSON encoder would write them as
    null): each flat list of numbers, and each list of such rows, is summed in C, and a NaN
    or infinity makes the sum non-finite. May answer False for finite numbers whose sum
    overflows; :func:`_check_finite` then decides. ~20x cheaper than walking every float."""
    if isinstance(obj, float):
        return math.isfinite(obj)
    if isinstance(obj, dict):
        return all(map(_all_finite, obj.values()))
    if isinstance(obj, (list, tuple)):
        try:
            return math.isfinite(sum(obj))
        except TypeError:  # not a flat list of numbers
            pass
        except OverflowError:  # an int too large for a float
            return all(map(_all_finite, obj))
        try:  # rows of numbers, e.g. a pose per sample
            # (a row that is a dict sums its keys, not its values; but a dict with number
            # keys is not orjson's to encode: _dumps then checks with the stdlib encoder)
            return math.isfinite(sum(chain.from_iterable(obj)))
        except (TypeError, OverflowError):
            return all(map(_all_finite, obj))
    return True


# orjson writes a Table I result (~145 kB, ~8000 floats) in ~0.3 ms against ~4.5 ms for the
# stdlib encoder; the numbers are the same (shortest round-trip form; only the exponent
# spelling differs: 1e-7 vs 1e-07). Anything orjson would encode differently from the stdlib
# (dataclasses, datetimes, subclasses of dict/str/int, non-str keys, huge ints) makes it
# raise TypeError, and the stdlib encodes that result as before.
_ORJSON_OPT = (orjson.OPT_PASSTHROUGH_DATACLASS | orjson.OPT_PASSTHROUGH_DATETIME
               | orjson.OPT_PASSTHROUGH_SUBCLASS)


def _float_subclass(obj):
    if isinstance(obj, float):  # e.g. numpy.float64: the same number as a float
        return float(obj)
    raise TypeError


def _dumps(result: dict) -> bytes:
    """``result`` as compact UTF-8 JSON; a NaN or infinity anywhere is a ``diverged``
    PlannerError naming where it is."""
    if _all_finite(result):
        try:
            return orjson.dumps(result, default=_float_subclass, option=_ORJSON_OPT)
        except TypeError:
            pass
    try:
        return json.dumps(result, allow_nan=False, separators=(",", ":")).encode()
    except ValueError:
        from planner.errors import PlannerError
        raise PlannerError("diverged", f"the planner produced a non-finite number at {_check_finite(result)}; "
                           "try a smaller sample time or larger k_u", "settings") from None


def run_job(job: dict) -> tuple:
    """Run one job; returns ``("ok", payload: bytes, meta: dict)`` or
    ``("error", PlannerError.to_dict())``. ``job["request"]`` is a validated
    :class:`planner.schema.PlanRequest`."""
    from planner.errors import PlannerError

    try:
        if job["kind"] == "plan":
            from app.storage import new_id
            from planner import plan, to_csv

            req = job["request"]
            result = plan(req)
            plan_id = new_id() if job.get("store") else None
            result.plan_id = plan_id
            data = result.to_json()
            store = _store(job.get("store"))
            if plan_id and store is not None:
                store.save_plan_json(data.decode(), req.to_json_dict(), job.get("corridor_id"),
                                     id=plan_id)
            fmt = job.get("format")
            if fmt == "csv":
                payload = to_csv(result).encode()
            elif fmt in ("gcode", "joints", "dxf"):
                from planner.exchange import export
                payload = export(result, fmt, layout=req.layout, forces=bool(job.get("forces")),
                                 source=job.get("source")).encode()
            else:
                payload = data
            return ("ok", payload, {"plan_id": plan_id})
        if job["kind"] == "import":
            from planner.exchange import import_drawing

            res = import_drawing(job["data"], job["options"], filename=job.get("filename"),
                                 content_type=job.get("content_type"))
            return ("ok", _dumps(res.to_json_dict()), {})
        if job["kind"] == "segment":
            from planner import segment

            return ("ok", _dumps(segment(job["request"]).to_dict()), {})
        if job["kind"] == "sleep":  # for tests of the time limit
            time.sleep(float(job["seconds"]))
            return ("ok", b"{}", {})
        raise ValueError(f"unknown job kind {job['kind']!r}")
    except PlannerError as exc:
        return ("error", exc.to_dict())
    except ArithmeticError as exc:  # numpy LinAlgError is a ValueError; see below
        return ("error", _degenerate(exc, job))
    except ValueError as exc:
        import numpy as np
        if isinstance(exc, np.linalg.LinAlgError):
            # singular or non-finite model matrices: a degenerate robot description or pose
            # the planner's own checks let through; the input's fault, not the server's
            return ("error", _degenerate(exc, job))
        raise


def _degenerate(exc: Exception, job: dict) -> dict:
    custom = not isinstance(getattr(job.get("request"), "robot", None), str)
    return {"code": "singular", "field": "robot" if custom else None,
            "message": f"the robot model is degenerate here ({type(exc).__name__}: {exc}); check that the "
                       "robot's pivots are distinct, its legs have positive length, masses and inertias "
                       "are positive, and the corridor avoids singular poses"}


def _worker_main(conn) -> None:
    # import the planner and load its compiled kernels before the first job, not during it
    import app.storage  # noqa: F401  (imported before the first job, not during it)
    import planner
    try:
        planner.warm_up()  # ~0.3 s from numba's on-disk cache; the first plan paid it before
    except Exception:
        pass
    try:
        conn.send("ready")  # the job clock starts only after this
    except (OSError, ValueError):
        return
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError, KeyboardInterrupt):
            return
        if job is None:
            return
        try:
            out = run_job(job)
        except MemoryError:
            out = ("crash", "the planner ran out of memory")
        except Exception as exc:  # a planner bug: report it, keep serving
            out = ("crash", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=8)}")
        try:
            conn.send(out)
        except (OSError, ValueError):
            return


# ---------------------------------------------------------------------------------------
# the pool (runs in the server process)

STARTUP_TIMEOUT_S = 120.0


class _Worker:
    """A worker process started as ``python -m app.workers FD`` (a fresh interpreter that
    never re-imports the server's ``__main__``), talking over a socket pair."""

    def __init__(self):
        parent, child = socket.socketpair()
        try:
            self.proc = subprocess.Popen([sys.executable, "-m", "app.workers", str(child.fileno())],
                                         pass_fds=(child.fileno(),), stdin=subprocess.DEVNULL,
                                         close_fds=True)
        finally:
            child.close()
        self.conn = Connection(parent.detach())
        self.ready = False

    def call(self, job: dict, timeout: float):
        try:
            if not self.ready:  # interpreter start and imports do not count against the job
                if not self.conn.poll(STARTUP_TIMEOUT_S) or self.conn.recv() != "ready":
                    raise WorkerCrashed("worker did not start")
                self.ready = True
            self.conn.send(job)
            if not self.conn.poll(timeout):
                raise JobTimeout
            return self.conn.recv()
        except (EOFError, OSError) as exc:
            raise WorkerCrashed(f"worker exited with status {self.proc.poll()} ({exc})") from None

    def alive(self) -> bool:
        return self.proc.poll() is None

    def kill(self) -> None:
        try:
            self.proc.kill()
            self.proc.wait(5)
        except (OSError, subprocess.TimeoutExpired):
            pass
        finally:
            self.conn.close()

    def stop(self) -> None:
        try:
            self.conn.send(None)
        except (OSError, ValueError):
            pass
        try:
            self.proc.wait(2)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(2)
        self.conn.close()


class PlanPool:
    """``workers`` planning processes (``mode="process"``) or inline execution
    (``mode="thread"``); ``timeout_s`` bounds each job's compute time; at most ``max_queue``
    jobs wait for a worker (more: :class:`PoolBusy`)."""

    def __init__(self, workers: int | None = None, timeout_s: float = 30.0, max_queue: int = 64,
                 mode: str = "process"):
        if mode not in ("process", "thread"):
            raise ValueError("mode must be 'process' or 'thread'")
        self.mode = mode
        self.n = max(1, int(workers or os.cpu_count() or 1))
        self.timeout_s = float(timeout_s)
        self.max_queue = int(max_queue)
        self._lock = threading.Lock()
        self._inflight = 0
        self._idle: queue.Queue = queue.Queue()
        self._workers: list[_Worker] = []
        self._closed = False
        self.replaced = 0
        if mode == "process":
            for _ in range(self.n):
                w = _Worker()
                self._workers.append(w)
                self._idle.put(w)
        else:
            self._sem = threading.Semaphore(self.n)

    @property
    def capacity(self) -> int:
        """Jobs accepted at once (running + waiting)."""
        return self.n + self.max_queue

    def stats(self) -> dict:
        return {"mode": self.mode, "workers": self.n, "in_flight": self._inflight,
                "timeout_s": self.timeout_s, "replaced_workers": self.replaced}

    def run(self, job: dict):
        """Run a job (blocking); returns what :func:`run_job` returns (or ``("crash", text)``
        for an unexpected exception in the planner), or raises :class:`JobTimeout`,
        :class:`PoolBusy` or :class:`WorkerCrashed` (the process died)."""
        with self._lock:
            if self._closed:
                raise PoolBusy("the server is shutting down")
            if self._inflight >= self.capacity:
                raise PoolBusy(f"{self._inflight} jobs in progress")
            self._inflight += 1
        try:
            if self.mode == "thread":
                with self._sem:
                    t0 = time.perf_counter()
                    try:
                        out = run_job(job)
                    except Exception as exc:
                        out = ("crash", f"{type(exc).__name__}: {exc}")
                    if time.perf_counter() - t0 > self.timeout_s:
                        raise JobTimeout  # cannot stop a thread: only report it afterwards
                    return out
            w = self._idle.get()
            replacement = w
            try:
                if not w.alive():
                    w.kill()
                    replacement = w = self._replace(w)
                return w.call(job, self.timeout_s)  # ("ok", ...), ("error", ...) or ("crash", text)
            except (JobTimeout, WorkerCrashed, OSError) as exc:
                w.kill()
                replacement = self._replace(w)
                if isinstance(exc, OSError):
                    raise WorkerCrashed(str(exc)) from None
                raise
            finally:
                self._idle.put(replacement)
        finally:
            with self._lock:
                self._inflight -= 1

    def _replace(self, old: _Worker) -> _Worker:
        new = _Worker()
        with self._lock:
            self.replaced += 1
            self._workers = [new if w is old else w for w in self._workers]
        return new

    def close(self) -> None:
        with self._lock:
            self._closed = True
            workers, self._workers = self._workers, []
        for w in workers:
            w.stop()


if __name__ == "__main__":
    _worker_main(Connection(int(sys.argv[1])))
