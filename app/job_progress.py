"""Progress of a job while it runs (issue 35): the one rule of the time left
(:func:`time_left`, for ``GET /v1/jobs/{id}`` and the CLI's progress line), the one rule of
when to come back (:func:`retry_after`: a job's ``Retry-After`` from its time left and the work
queued ahead of it, :func:`job_wait`; a busy answer's from when the first slot frees,
:func:`first_free`), the callback a worker's job writes its progress to the store with
(:func:`job_progress`), and the one of a job run in this thread (:func:`progress_here`). No
web framework or editor import."""

from __future__ import annotations

import contextlib
import contextvars
import math
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Protocol

__all__ = ["JOIN_SHARE", "PROGRESS_EVERY_S", "RETRY_MAX_S", "RETRY_MIN_S", "ProgressStore", "first_free", "here",
           "job_progress", "job_wait", "progress_here", "retry_after", "row_left", "time_left", "with_estimate"]


class ProgressStore(Protocol):
    """What a job's progress is written to (:class:`app.storage.Store`'s ``jobs`` table)."""

    def job_started(self, id: str, total: int | None, estimate_s: float | None) -> None: ...

    def job_progress(self, id: str, done: int, total: int | None = None) -> None: ...


#: the time after a contour's last pass (joining the passes, the contour section, storing the
#: plan) as a share of the passes' own time: 0.25-0.32 measured on 4-40 passes
#: (benchmarks/bench_jobs.py); counted in :func:`time_left` as that many passes per pass
JOIN_SHARE = 0.3


def time_left(done: int, total: int | None, started: float | None, updated: float | None, now: float,
              estimate_s: float | None) -> float | None:
    """Estimated time left of a job [s], the one rule of ``GET /v1/jobs/{id}`` and of the CLI's
    progress line: once a unit is done, the time per unit measured up to the last unit done
    (``updated``), for the units left and the join after them (:data:`JOIN_SHARE`), less the
    time since that unit (not below a tenth of a unit's time: a unit that takes longer than
    the mean is still running, and a running job never says 0 s left); before, the work
    estimate less the time run (not below a tenth of it); ``None`` without either."""
    if done > 0 and total and started is not None:
        updated = now if updated is None else updated
        per_unit = (updated - started) / done
        return max(per_unit * (total - done + JOIN_SHARE * total) - (now - updated), 0.1 * per_unit)
    if estimate_s is not None:
        return max(estimate_s - max(0.0, now - (now if started is None else started)), 0.1 * estimate_s)
    return None


#: the range of a ``Retry-After`` [s]: at least a second (HTTP's unit), at most a minute (a client
#: polling a job that overruns its estimate, or waiting for a slot, hears again within a minute)
RETRY_MIN_S = 1
RETRY_MAX_S = 60


def retry_after(seconds: float | None) -> int:
    """A ``Retry-After`` [s] for an expected wait of ``seconds``: rounded up, within
    [:data:`RETRY_MIN_S`, :data:`RETRY_MAX_S`]; the least when the wait is unknown."""
    if seconds is None or not math.isfinite(seconds):
        return RETRY_MIN_S
    return int(min(RETRY_MAX_S, max(RETRY_MIN_S, math.ceil(seconds))))


def row_left(row: dict, now: float) -> float | None:
    """:func:`time_left` of a job's row (the store's ``jobs`` columns); None when unknown."""
    return time_left(int(row["done"]), row["total"], row["started"], row["updated"], now, row["estimate_s"])


def job_wait(rows: list[dict], job_id: str, workers: int, now: float) -> float | None:
    """When the job ``job_id`` is expected to end [s from ``now``], from the unfinished jobs'
    rows in the order they were queued (``rows``): a running job's time left (:func:`row_left`);
    a queued one's own estimate plus the work ahead of it (the running jobs' time left and the
    queued ones' estimates before it) shared by the ``workers`` of the jobs' share. None when
    the job is not among the rows; an unknown time counts 0 (a contour whose worker has not
    read its program yet)."""
    ahead = 0.0
    for row in rows:
        left = row_left(row, now) or 0.0
        if row["id"] == job_id:
            return left if row["state"] == "running" else ahead / max(1, int(workers)) + left
        ahead += left
    return None


def first_free(rows: list[dict], now: float, others: Sequence[float] = ()) -> float | None:
    """When the first slot of a busy server is expected to free [s from ``now``]: the least time
    left of the running jobs (``rows``, the store's unfinished jobs) and of ``others`` (the time
    left of the synchronous requests on a worker); None when none is known."""
    lefts = [left for row in rows if row["state"] == "running" and (left := row_left(row, now)) is not None]
    lefts += [max(0.0, float(s)) for s in others]
    return min(lefts, default=None)


#: a progress callback ``(done, total, estimate_s)`` of a job run in this thread (the CLI's
#: progress line: :func:`progress_here`); a worker's jobs report through the store instead
_HERE: contextvars.ContextVar[Callable[[int, int, float | None], None] | None] = contextvars.ContextVar(
    "rangeplan_progress_here", default=None)


@contextlib.contextmanager
def progress_here(callback: Callable[[int, int, float | None], None]) -> Iterator[None]:
    """Jobs run in this thread meanwhile (:class:`app.executors.InProcessExecutor`) report their
    progress to ``callback(done, total, estimate_s)``: a contour its cut passes, with its work
    estimate."""
    token = _HERE.set(callback)
    try:
        yield
    finally:
        _HERE.reset(token)


def with_estimate(callback: Callable[[int, int, float | None], None], estimate_s: float) -> Callable[[int, int], None]:
    return lambda done, total: callback(done, total, estimate_s)


#: the least time between two progress writes of a job [s] (the first and the last are always
#: written): a program of 2000 passes writes ~4 rows a second, not 2000
PROGRESS_EVERY_S = 0.25


def job_progress(store: ProgressStore | None, job_id: str, estimate_s: float | None = None):
    """The progress callback ``(done, total)`` of the HTTP job ``job_id``: its first call marks
    the job running with ``total`` and the work estimate ``estimate_s``, later ones write the
    units done to the store's ``jobs`` row, at most every :data:`PROGRESS_EVERY_S` but always
    the last (``done == total``). The worker's SQLite store carries progress across the process
    boundary (and to a Dask worker sharing the data directory): no pipe message, and any
    server process reading the store answers ``GET /v1/jobs/{id}``."""
    st = store
    state = {"started": False, "at": 0.0}

    def report(done: int, total: int) -> None:
        if st is None:
            return
        now = time.monotonic()
        if not state["started"]:
            st.job_started(job_id, total, estimate_s)
            state["started"], state["at"] = True, now
            return
        if done >= total or now - state["at"] >= PROGRESS_EVERY_S:
            st.job_progress(job_id, done, total)
            state["at"] = now

    return report


def here() -> Callable[[int, int, float | None], None] | None:
    """The callback of :func:`progress_here` in effect in this thread, if any."""
    return _HERE.get()
