"""Planning off the event loop: a small pool of worker processes with a per-job time limit.

Planning is CPU-bound Python + small numpy (the GIL is held most of the time), so threads
give no parallelism; worker processes do, and a process that runs past the time limit can
be killed and replaced without disturbing the other jobs (a thread cannot be stopped).

Each worker owns one end of a pipe, imports the planner once, then serves jobs. A job is
one of :data:`app.jobs.Job` (plan, segment, import, editor, export, ...); the worker runs it
(:func:`app.jobs.run_job`), serialises the result to JSON itself, stores plans in the SQLite
store itself (WAL, multi-process safe) and sends back a typed outcome with ready-to-send
bytes (or the spool file of an export), so the server process only moves bytes.

The pool is used from threads (``run`` blocks) by :class:`app.service.JobService`, which
the API and the editor submit jobs to: the service checks the work estimate and maps the
pool's exceptions (:class:`JobTimeout`, :class:`PoolBusy`, :class:`WorkerCrashed`) to error
outcomes. ``mode="thread"`` runs jobs in the calling thread instead (no parallelism under
the GIL, no way to stop a runaway job; kept to measure the difference, see
benchmarks/bench_http.py, and for an editor run without a server).

Bounds on each job (issue 15), the same for the API and the editor:

* before a job is queued, the planner's work estimate (:func:`planner.estimate_work`) is
  compared with the time limit (by the service): ``too_much_work`` in microseconds instead
  of a worker held until the limit;
* the time limit itself (:class:`JobTimeout`; the worker is killed and replaced);
* an address-space limit per worker process (``memory_mb``, ``RLIMIT_AS``): a job that needs
  more fails with ``too_much_memory`` and the worker is replaced.

Workers run at a lower CPU priority (``nice`` 5) than the server, so that health checks and
storage requests are answered while every worker plans. A worker is *ready* once it has
imported the planner and loaded (or compiled) the kernels by planning tiny corridors
(:meth:`PlanPool.ready`; the server's ``/ready``).
"""

from __future__ import annotations

from planner._config import single_threaded_blas

single_threaded_blas()  # before numpy loads

import os  # noqa: E402
import socket  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from collections.abc import Iterator  # noqa: E402
from concurrent.futures import Future, ThreadPoolExecutor  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from multiprocessing.connection import Connection  # noqa: E402
from typing import Any  # noqa: E402

from app.failures import limit_memory, out_of_memory  # noqa: E402
from app.jobs import Failed, Job, Outcome, run_job  # noqa: E402
from app.worker_process import WORKER_NICE, load_planner  # noqa: E402  (the worker template's too)


class JobTimeout(Exception):
    """The job ran longer than the pool's time limit (its worker was replaced)."""


class PoolBusy(Exception):
    """Too many jobs waiting for a worker."""


class JobsHoldEveryWorker(PoolBusy):
    """A synchronous request found every worker running a background job (a contour or a plan
    answered 202, which may run up to the job limit): refused at once rather than queued behind
    one (only when the jobs' share is every worker, ``RANGEPLAN_JOB_WORKERS`` >= the workers)."""


class WorkerCrashed(Exception):
    """The worker process died while running the job."""


class JobKilledWorkers(WorkerCrashed):
    """The job was run again after its process died, and died there too, until the executor
    gave up on it (a Dask scheduler's ``KilledWorker``): the job itself is the likely cause."""


class WorkerOutOfMemory(WorkerCrashed):
    """The worker process was ended by a failed allocation (an abort, as Rust code such as
    the JSON encoder does, or the kernel's OOM killer) while it had a memory limit."""


#: default address-space limit of a worker process [MiB] (the interpreter with the planner
#: loaded takes ~0.5 GiB of it; the largest plan within the request bounds peaked at 0.8 GiB)
DEFAULT_MEMORY_MB = 2048


def _worker_main(conn, memory_mb: int | None = None, parent: int | None = None, pdeathsig: bool = False,
                 nice: int = WORKER_NICE) -> None:
    """A worker started as a fresh interpreter (``start="exec"``), ``nice`` below its parent. It
    ignores Ctrl-C, which reaches the whole process group: its parent decides what stops (a
    batch worker's planning process killed by the terminal's SIGINT would report its item as a
    dead worker's)."""
    import signal

    if parent is not None:  # end with the server, even a kill -9 of it (app.lifeline)
        from app.lifeline import exit_with_parent

        exit_with_parent(parent, thread_bound=pdeathsig)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        os.nice(nice)
    except OSError:
        pass
    _serve(conn, memory_mb, load_planner())


def _forked_worker(conn, memory_mb: int | None = None, nice: int = WORKER_NICE) -> None:
    """A worker forked by multiprocessing's fork server (``start="forkserver"``), which has
    already loaded the planner (:mod:`app.worker_template`): ready at once. It ends with the
    fork server (the kernel's parent-death signal and the watch thread of
    :mod:`app.lifeline`), which ends with the server (its pipe to the server closes)."""
    from app import worker_template
    from app.lifeline import exit_with_parent

    # the fork server's pid (the template was imported there); if this process imported it
    # itself (a fork server started with other preloads), its parent is the fork server
    template = worker_template.PID if worker_template.PID != os.getpid() else os.getppid()
    exit_with_parent(template, thread_bound=True)  # the fork server forks from its only thread
    if nice > WORKER_NICE:  # the template already runs WORKER_NICE below the server
        try:
            os.nice(nice - WORKER_NICE)
        except OSError:
            pass
    _serve(conn, memory_mb, worker_template.STATUS)


def _serve(conn, memory_mb: int | None, status: tuple[str, str | None]) -> None:
    """Report ``status`` to the pool, then run jobs until told to stop."""
    try:
        conn.send(status)  # the job clock starts only after this
    except (OSError, ValueError):
        return
    if status[0] != "ready":
        return
    limit_memory(memory_mb)  # after the warm-up: the limit bounds what a job may add
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError, KeyboardInterrupt):
            return
        if job is None:
            return
        out = run_job(job, memory_mb)
        # the heap may be fragmented or half-built after a memory error: start afresh
        ran_out = isinstance(out, Failed) and out.error.code == "too_much_memory"
        try:
            conn.send(out)
        except (OSError, ValueError):
            return
        if ran_out:
            return


# ---------------------------------------------------------------------------------------
# the pool (runs in the server process)

STARTUP_TIMEOUT_S = 120.0


#: how the pool starts a worker process (:class:`PlanPool`'s ``start``)
START_METHODS = ("forkserver", "exec")


def default_start() -> str:
    """``"forkserver"`` where multiprocessing has a fork server (Linux, macOS), else ``"exec"``."""
    import multiprocessing

    return "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "exec"


class _Exec:
    """A ``subprocess.Popen`` seen through the part of ``multiprocessing.Process`` that
    :class:`_Worker` uses (``pid``, ``exitcode``, ``is_alive``, ``join``, ``kill``), so that
    both start methods are handled by one code path."""

    def __init__(self, proc: subprocess.Popen):
        self.proc = proc
        self.pid: int | None = proc.pid

    @property
    def exitcode(self) -> int | None:
        return self.proc.poll()

    def is_alive(self) -> bool:
        return self.proc.poll() is None

    def join(self, timeout: float | None = None) -> None:
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            pass

    def kill(self) -> None:
        self.proc.kill()


class _Worker:
    """One planning process and the server's end of its pipe. A thread starts it and waits
    for its first message (ready, or failed with a reason). Two ways to start it:

    * ``"forkserver"``: forked by multiprocessing's fork server, a process started once per
      server that imported the planner and loaded its kernels (:mod:`app.worker_template`):
      ready in milliseconds; the first one waits for the fork server's own warm-up. Its
      workers see the environment the server had when the fork server started (its first
      pool), not a later change of the environment (one fork server per server process);
    * ``"exec"``: ``python -m app.workers FD MEMORY_MB PARENT_PID PDEATHSIG``, a fresh
      interpreter that never re-imports the server's ``__main__`` and loads the planner
      itself (1-3 s), over a socket pair.
    """

    def __init__(self, memory_mb: int | None = None, start: str = "exec", nice: int = WORKER_NICE):
        self.started = threading.Event()  #: the worker reported (ready or failed)
        self.ready = False
        self.failure: str | None = None
        self._lock = threading.Lock()
        self._killed = False
        #: a ``multiprocessing.Process`` (forkserver; its ``pid`` is None until the fork server
        #: has started it) or an :class:`_Exec`
        self.process: Any = None
        if start == "forkserver":
            import multiprocessing

            ctx = multiprocessing.get_context("forkserver")
            ctx.set_forkserver_preload(["app.worker_template"])  # before the fork server starts
            self.conn, child = ctx.Pipe(duplex=True)
            self.process = ctx.Process(target=_forked_worker, args=(child, memory_mb, nice), daemon=True,
                                       name="rangeplan-worker")
            threading.Thread(target=self._start_forked, args=(child,), name="rangeplan-worker-start",
                             daemon=True).start()
            return
        parent, child_sock = socket.socketpair()
        try:
            # the parent's pid, and whether this thread lives as long as the server (the kernel's
            # parent-death signal is tied to it; app.lifeline)
            bound = int(threading.current_thread() is threading.main_thread())
            self.process = _Exec(subprocess.Popen([sys.executable, "-m", "app.workers", str(child_sock.fileno()),
                                                   str(int(memory_mb or 0)), str(os.getpid()), str(bound),
                                                   str(int(nice))],
                                                  pass_fds=(child_sock.fileno(),), stdin=subprocess.DEVNULL,
                                                  close_fds=True))
        finally:
            child_sock.close()
        self.conn = Connection(parent.detach())
        threading.Thread(target=self._wait_ready, name="rangeplan-worker-start", daemon=True).start()

    def _start_forked(self, child: Connection) -> None:
        # blocks until the fork server has loaded the planner (the first worker: the whole warm-up)
        try:
            with self._lock:
                if self._killed:
                    raise OSError("stopped before it started")
            self.process.start()
        except Exception as exc:
            self.failure = f"the planning process could not start ({type(exc).__name__}: {exc})"
            self.started.set()
            return
        finally:
            child.close()
        with self._lock:
            killed = self._killed
        if killed:  # kill() came while the fork server was starting
            self._end_process()
            self.failure = "stopped before it started"
            self.started.set()
            return
        self._wait_ready()

    def _wait_ready(self) -> None:
        try:
            if not self.conn.poll(STARTUP_TIMEOUT_S):
                self.failure = f"did not load the planner within {STARTUP_TIMEOUT_S:g} s"
            else:
                status, reason = self.conn.recv()
                self.ready, self.failure = status == "ready", reason
        except (EOFError, OSError, ValueError, TypeError) as exc:
            self.failure = f"exited while starting ({type(exc).__name__}; status {self.poll()})"
        finally:
            self.started.set()

    def call(self, job: Job, timeout: float | None) -> Outcome:
        try:
            # interpreter start and imports do not count against the job
            if not self.started.wait(STARTUP_TIMEOUT_S + 1) or not self.ready:
                raise WorkerCrashed(f"the planning process could not start: {self.failure or 'no answer'}")
            self.conn.send(job)
            if not self.conn.poll(timeout):
                raise JobTimeout
            return self.conn.recv()
        except (EOFError, OSError) as exc:
            raise WorkerCrashed(f"worker exited with status {self.poll()} ({exc})") from None

    @property
    def pid(self) -> int | None:
        """The planning process's id (None while a forked one is not started yet)."""
        return self.process.pid

    def poll(self) -> int | None:
        """The exit status (negative: the signal), None while it runs or has not started."""
        return None if self.process.pid is None else self.process.exitcode

    def alive(self) -> bool:
        if self.process.pid is None:  # the fork server is still loading the planner
            return not self.started.is_set()
        return self.process.is_alive()

    def exit_status(self, timeout: float = 2.0) -> int | None:
        """Wait up to ``timeout`` s for the process to end; its exit status (None: still running)."""
        if self.process.pid is None:
            return None
        self.process.join(timeout)
        return self.process.exitcode

    def _end_process(self) -> None:
        with self._lock:
            self._killed = True
            if self.process.pid is None:
                return  # not started: _start_forked ends it once started
        try:
            self.process.kill()
            self.process.join(5)
        except (OSError, ValueError):
            pass

    def _close_conn(self) -> None:
        """Close the pipe once: :meth:`stop` (the pool closing) and :meth:`kill` (the job's
        thread after its worker died) may both come; a second ``close`` would close the fd
        number again, by then maybe another file's (it failed with EBADF in a test's teardown)."""
        with self._lock:
            if not self.conn.closed:
                self.conn.close()

    def kill(self) -> None:
        try:
            self._end_process()
        finally:
            self._close_conn()

    def stop(self) -> None:
        try:
            self.conn.send(None)
        except (OSError, ValueError):
            pass
        if self.exit_status(2) is None:
            self._end_process()
        self._close_conn()


#: exit statuses of a worker ended by a failed allocation: SIGABRT (Rust's allocation error
#: handler, e.g. orjson growing its buffer) and SIGKILL (the kernel's OOM killer)
_ALLOCATION_FAILURE = (-6, -9)


class Admission:
    """The bounded queue of an executor (:class:`PlanPool`, :class:`app.cluster.DaskExecutor`):
    at most :attr:`capacity` jobs in flight, more are :class:`PoolBusy`, and none once closed.
    The executor sets ``_lock``, ``_inflight``, ``_closed`` and ``jobs_run``."""

    _lock: threading.Lock
    _inflight: int
    _closed: bool
    jobs_run: int

    @property
    def capacity(self) -> int:
        raise NotImplementedError

    def _admit(self) -> None:
        """One more job in flight (:class:`PoolBusy` when full or shutting down). The capacity
        is read before the lock is taken: a cluster's asks its scheduler, on the client's event
        loop, whose thread releases finished jobs (:meth:`_release`) under the same lock."""
        capacity = self.capacity
        with self._lock:
            if self._closed:
                raise PoolBusy("the server is shutting down")
            if self._inflight >= capacity:
                raise PoolBusy(f"{self._inflight} jobs in progress")
            self._inflight += 1
            self.jobs_run += 1

    def _release(self, *_: Any) -> None:
        """One job fewer in flight (also a future's done callback)."""
        with self._lock:
            self._inflight -= 1

    @contextmanager
    def _admitted(self) -> Iterator[None]:
        """One job in flight while the block runs."""
        self._admit()
        try:
            yield
        finally:
            self._release()


class PlanPool(Admission):
    """``workers`` planning processes (``mode="process"``) or inline execution
    (``mode="thread"``); ``timeout_s`` bounds each job's compute time (and, through the work
    estimate, what is accepted); at most ``max_queue`` jobs wait for a worker (more:
    :class:`PoolBusy`); ``memory_mb`` is each worker's address-space limit [MiB] (0: none);
    ``start`` how a worker process starts (:data:`START_METHODS`; default :func:`default_start`):
    forked from a process that has loaded the planner, or a fresh interpreter; ``nice``: the
    workers' CPU priority below this process (default :data:`WORKER_NICE`; a batch's pool
    runs lower, yielding to the interactive one).

    Two kinds of caller (issue 33): synchronous requests, and *background* jobs
    (``run(..., background=True)``: a contour or a plan answered 202, which may run up to the
    job limit). A free worker goes to a waiting synchronous request first; a background job
    takes one only when no synchronous request waits; and a synchronous request that finds
    every worker running a background job is refused at once (:class:`JobsHoldEveryWorker`)
    instead of waiting behind one. How many background jobs run at once is the caller's
    bound (:class:`app.service.JobService`'s job share)."""

    def __init__(self, workers: int | None = None, timeout_s: float = 30.0, max_queue: int = 64,
                 mode: str = "process", memory_mb: int | None = DEFAULT_MEMORY_MB, start: str | None = None,
                 nice: int = WORKER_NICE):
        if mode not in ("process", "thread"):
            raise ValueError("mode must be 'process' or 'thread'")
        self.start = start or default_start()
        if self.start not in START_METHODS:
            raise ValueError(f"start must be one of {', '.join(START_METHODS)}")
        self.mode = mode
        self.n = max(1, int(workers or os.cpu_count() or 1))
        self.timeout_s = float(timeout_s)
        self.max_queue = int(max_queue)
        self.memory_mb = int(memory_mb or 0)
        self.nice = int(nice)
        self._threads: ThreadPoolExecutor | None = None  # the callers of submit()
        self._thread_ready: bool | None = None  # thread mode: warm-up done (True) / failed (False)
        self._lock = threading.Lock()
        self._inflight = 0
        self.jobs_run = 0  #: jobs handed to a worker (or run inline)
        self._free: list[_Worker] = []  # idle workers (process mode), under _free_cond
        self._free_cond = threading.Condition(threading.Lock())
        self.sync_waiting = 0  #: synchronous callers waiting for a worker now (they go first)
        self.background_running = 0  #: background jobs on a worker now
        self.background_waiting = 0  #: background jobs waiting for a worker now
        self._renewing = False  # renew() waits for the running background jobs: no new one starts
        self._workers: list[_Worker] = []
        self._closed = False
        self.replaced = 0
        self.renewed = 0  #: times every worker was renewed (:meth:`renew`)
        self._renew_lock = threading.Lock()
        if mode == "process":
            for _ in range(self.n):
                w = _Worker(self.memory_mb, self.start, self.nice)
                self._workers.append(w)
                self._free.append(w)
        else:
            self._sem = threading.Semaphore(self.n)
            threading.Thread(target=self._warm_up_inline, name="rangeplan-warm-up", daemon=True).start()

    @property
    def capacity(self) -> int:
        """Jobs accepted at once (running + waiting)."""
        return self.n + self.max_queue

    def _warm_up_inline(self) -> None:
        try:
            load = load_planner()
            if load[0] != "ready":
                raise RuntimeError(load[1])
            self._thread_ready = True
        except Exception:
            self._thread_ready = False

    def stats(self) -> dict:
        return {"mode": self.mode, "workers": self.n, "in_flight": self._inflight,
                "sync_waiting": self.sync_waiting, "background_running": self.background_running,
                "background_waiting": self.background_waiting,
                "timeout_s": self.timeout_s, "replaced_workers": self.replaced, "memory_mb": self.memory_mb}

    def _take(self, background: bool, refuse: bool = True) -> _Worker:
        """An idle worker, once there is one: synchronous callers first, a background job only
        when none waits (``refuse``: :class:`JobsHoldEveryWorker` for a synchronous caller
        finding every worker on a background job)."""
        with self._free_cond:
            if background:
                self.background_waiting += 1
                try:
                    while not self._free or self.sync_waiting or self._renewing:
                        self._free_cond.wait()
                finally:
                    self.background_waiting -= 1
                self.background_running += 1
                return self._free.pop(0)
            if refuse and not self._free and self.background_running >= self.n:
                raise JobsHoldEveryWorker(f"every planning worker ({self.n}) is running a job")
            self.sync_waiting += 1
            try:
                while not self._free:
                    self._free_cond.wait()
            finally:
                self.sync_waiting -= 1
                self._free_cond.notify_all()  # a background job may go now
            return self._free.pop(0)

    def _give_back(self, w: _Worker, background: bool) -> None:
        with self._free_cond:
            if background:
                self.background_running -= 1
            self._free.append(w)
            self._free_cond.notify_all()

    def readiness(self) -> dict:
        """``{"ready", "workers_ready", "workers", "failures"}``: ready when at least one
        worker has loaded the planner's kernels and none is known to be unable to plan."""
        if self.mode == "thread":
            ok = bool(self._thread_ready)
            return {"ready": ok and not self._closed, "workers_ready": self.n if ok else 0, "workers": self.n,
                    "failures": ["the planner's warm-up failed"] if self._thread_ready is False else []}
        with self._lock:
            workers = list(self._workers)
        ready = [w for w in workers if w.ready and w.alive()]
        failures = sorted({w.failure for w in workers if w.failure})
        return {"ready": bool(ready) and not failures and not self._closed, "workers_ready": len(ready),
                "workers": self.n, "failures": failures}

    def run(self, job: Job, timeout_s: float | None = None, background: bool = False) -> Outcome:
        """Run a job (blocking); returns its outcome (:func:`app.jobs.run_job`), or raises
        :class:`JobTimeout`, :class:`PoolBusy` or :class:`WorkerCrashed` (the process died).
        ``timeout_s`` overrides the pool's time limit for this job (0: none); ``background``:
        a job that yields a free worker to waiting synchronous requests (the class docstring).
        The work estimate is the caller's (:class:`app.service.JobService`,
        :func:`app.executors.run_bounded`)."""
        limit = self.timeout_s if timeout_s is None else float(timeout_s)
        with self._admitted():
            if self.mode == "thread":
                with self._sem:
                    t0 = time.perf_counter()
                    out = run_job(job)
                    if 0 < limit < time.perf_counter() - t0:
                        raise JobTimeout  # cannot stop a thread: only report it afterwards
                    return out
            w = self._take(background)
            replacement = w
            try:
                if not w.alive():
                    w.kill()
                    replacement = w = self._replace(w)
                out = w.call(job, limit if limit > 0 else None)
                if isinstance(out, Failed) and out.error.code == "too_much_memory":
                    w.exit_status()  # it exits after a memory error (or is killed): replace it now
                    w.kill()
                    replacement = self._replace(w)
                return out
            except (JobTimeout, WorkerCrashed, OSError) as exc:
                status = w.exit_status() if not isinstance(exc, JobTimeout) else None
                w.kill()
                replacement = self._replace(w)
                if self.memory_mb and status in _ALLOCATION_FAILURE:
                    raise WorkerOutOfMemory(out_of_memory(self.memory_mb, job.kind)["message"]) from None
                if isinstance(exc, OSError):
                    raise WorkerCrashed(str(exc)) from None
                raise
            finally:
                self._give_back(replacement, background)

    def renew(self) -> None:
        """Replace every worker by a new one (after the background compile of the kernels: the
        new ones load the compiled kernels, issue 24). Waits for each worker's running job;
        jobs that come meanwhile wait for a new worker. It first waits for the running
        background jobs without holding a worker (none starts meanwhile), so that synchronous
        requests are served until then, and then takes each worker as it is free (a synchronous
        request waits at most for the synchronous work under way). With ``start="forkserver"`` the fork
        server (:mod:`app.worker_template`, which loaded the planner before the kernels were
        compiled) is stopped and started again. Thread mode: nothing to do (the next plans
        load the compiled kernels in this process)."""
        if self.mode != "process":
            return
        with self._renew_lock:
            with self._free_cond:
                self._renewing = True
                while self.background_running:
                    self._free_cond.wait()
            try:
                old = [self._take(False, refuse=False) for _ in range(self.n)]  # each free, in turn
            finally:
                with self._free_cond:
                    self._renewing = False
            for w in old:
                w.stop()
            if self.start == "forkserver":
                from multiprocessing import forkserver

                stop = getattr(forkserver._forkserver, "_stop", None)  # CPython's own (its tests use it)
                if stop is not None:
                    stop()
            new = [_Worker(self.memory_mb, self.start, self.nice) for _ in range(self.n)]
            with self._lock:
                self._workers = new
                self.renewed += 1
            for w in new:
                self._give_back(w, False)

    def submit(self, job: Job, timeout_s: float | None = None) -> Future:
        """:meth:`run` without blocking: a future of the outcome (its exception one of
        :meth:`run`'s). At most one job per worker is sent at once; the others wait here, and
        :meth:`Future.cancel` withdraws a job that has not been sent yet."""
        with self._lock:
            if self._closed:  # as run() answers then, without starting threads again
                refused: Future = Future()
                refused.set_exception(PoolBusy("the server is shutting down"))
                return refused
            if self._threads is None:
                self._threads = ThreadPoolExecutor(self.n, thread_name_prefix="rangeplan-pool-submit")
            threads = self._threads
        return threads.submit(self.run, job, timeout_s)

    def _replace(self, old: _Worker) -> _Worker:
        if self._closed:  # closing: the dead one stays dead
            return old
        new = _Worker(self.memory_mb, self.start, self.nice)
        with self._lock:
            self.replaced += 1
            self._workers = [new if w is old else w for w in self._workers]
        return new

    def close(self, cancel: bool = False) -> None:
        """Stop the workers: each after its job (``cancel``: at once, their jobs are lost, the
        jobs not sent yet cancelled)."""
        with self._lock:
            self._closed = True
            workers, self._workers = self._workers, []
            threads, self._threads = self._threads, None
        if threads is not None:
            threads.shutdown(wait=False, cancel_futures=True)
        for w in workers:
            if cancel:
                w.kill()
            else:
                w.stop()


if __name__ == "__main__":
    _worker_main(Connection(int(sys.argv[1])), int(sys.argv[2]) if len(sys.argv) > 2 else None,
                 int(sys.argv[3]) if len(sys.argv) > 3 else None, len(sys.argv) > 4 and sys.argv[4] == "1",
                 int(sys.argv[5]) if len(sys.argv) > 5 else WORKER_NICE)
