"""Operations of the HTTP service: Prometheus metrics, structured JSON logs and request ids.

* **Request ids.** Every response carries ``X-Request-ID``: the client's own when it sent a
  sane one (1-128 characters of ``A-Z a-z 0-9 . _ : -``), else a new one (uuid4 hex). The id
  is in the log line of the request and in every other log line written while it is served
  (a context variable read by :class:`RequestIdFilter`).
* **Logs.** One JSON object per line on stderr (:class:`JsonFormatter`): ``ts`` (ISO-8601
  UTC), ``level``, ``logger``, ``msg`` and the record's extras; the access line of each
  request (logger ``rangeplan.access``) has ``request_id``, ``method``, ``path`` (no query
  string: it may hold a token), ``route`` (the route template), ``status``,
  ``duration_ms`` and ``client``. ``rangeplan serve`` logs this way (:func:`log_config`,
  uvicorn's own lines included); ``RANGEPLAN_ACCESS_LOG=0`` (app.settings) turns the access
  lines off.
* **Metrics.** ``GET /metrics`` in Prometheus' text format, behind the token like ``/v1``
  (:mod:`app.security`): requests by route template, method and status, their latency
  (histogram), plan durations by mode, queue depth, worker restarts and batch progress
  (table in README.md). Each app has its own registry (several apps in one process, as in
  the tests, do not share counters).

:func:`install_observability` adds all of it to an app: it wraps the whole middleware stack
(outside the error handler, so a 500 gets its request id and access line too) and adds the
route. :func:`observe_job` is the planning path's hook (one call per job).
"""

from __future__ import annotations

import contextvars
import json
import logging
import re
import time
import uuid
from datetime import UTC, datetime
from typing import Any

from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, Counter, Histogram, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily
from prometheus_client.registry import Collector

__all__ = ["JsonFormatter", "Metrics", "RequestIdFilter", "REQUEST_ID_HEADER", "current_request_id",
           "install_observability", "job_outcome", "log_config", "observe_job"]

REQUEST_ID_HEADER = "X-Request-ID"
_SANE_ID = re.compile(r"[A-Za-z0-9._:-]{1,128}")
_request_id: contextvars.ContextVar[str | None] = contextvars.ContextVar("rangeplan_request_id", default=None)
access_log = logging.getLogger("rangeplan.access")
error_log = logging.getLogger("rangeplan.error")

#: latency buckets [s]: health checks take ~1 ms, plans up to the 30 s limit
LATENCY_BUCKETS = (0.002, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0)
PLAN_BUCKETS = (0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 20.0, 30.0, 60.0)


def current_request_id() -> str | None:
    """The id of the request being served in this context (None outside a request)."""
    return _request_id.get()


def _request_id_of(headers: list[tuple[bytes, bytes]]) -> str:
    for k, v in headers:
        if k.lower() == b"x-request-id":
            try:
                given = v.decode("ascii")
            except UnicodeDecodeError:
                break
            if _SANE_ID.fullmatch(given):
                return given
            break
    return uuid.uuid4().hex


# ---------------------------------------------------------------------------------------
# logs

class RequestIdFilter(logging.Filter):
    """Adds ``request_id`` (the current request's, or None) to every record."""

    def filter(self, record: logging.LogRecord) -> bool:
        if not hasattr(record, "request_id"):
            record.request_id = _request_id.get()
        return True


_STANDARD = frozenset(vars(logging.LogRecord("", 0, "", 0, "", (), None))) | {"message", "asctime", "color_message"}


class JsonFormatter(logging.Formatter):
    """One JSON object per record: ``ts``, ``level``, ``logger``, ``msg``, the extras
    (``request_id``, ...) and ``exc`` (the traceback) when there is one."""

    def format(self, record: logging.LogRecord) -> str:
        out: dict[str, Any] = {"ts": datetime.fromtimestamp(record.created, UTC).isoformat(timespec="milliseconds")
                               .replace("+00:00", "Z"), "level": record.levelname.lower(), "logger": record.name,
                               "msg": record.getMessage()}
        for k, v in vars(record).items():
            if k not in _STANDARD and not k.startswith("_"):
                out[k] = v
        if record.exc_info:
            out["exc"] = self.formatException(record.exc_info)
        return json.dumps(out, default=str, ensure_ascii=False)


def log_config(level: str = "info") -> dict[str, Any]:
    """``logging.config.dictConfig`` settings (uvicorn's ``log_config``): every logger of
    the server (``uvicorn``, ``uvicorn.error``, ``rangeplan.*``) as JSON lines on stderr."""
    lvl = level.upper()
    handler = {"class": "logging.StreamHandler", "formatter": "json", "filters": ["request_id"],
               "stream": "ext://sys.stderr"}
    return {"version": 1, "disable_existing_loggers": False,
            "filters": {"request_id": {"()": RequestIdFilter}},
            "formatters": {"json": {"()": JsonFormatter}},
            "handlers": {"json": handler},
            "loggers": {"uvicorn": {"handlers": ["json"], "level": lvl, "propagate": False},
                        "uvicorn.error": {"level": lvl},
                        "uvicorn.access": {"handlers": [], "level": "WARNING", "propagate": False},
                        "rangeplan": {"handlers": ["json"], "level": lvl, "propagate": False}}}


# ---------------------------------------------------------------------------------------
# metrics

class _StateCollector(Collector):
    """Values read at scrape time from the app's planning pool and batch service."""

    def __init__(self, app: Any):
        self.app = app

    def collect(self):
        pool = getattr(self.app.state, "pool", None)
        in_flight = GaugeMetricFamily("rangeplan_plan_jobs_in_flight", "Jobs (plan, segment, import) accepted by the "
                                      "planning pool: running plus waiting (count)")
        queue = GaugeMetricFamily("rangeplan_plan_queue_depth", "Jobs waiting for a planning worker (count)")
        workers = GaugeMetricFamily("rangeplan_plan_workers", "Planning workers, by state (count)", labels=["state"])
        restarts = CounterMetricFamily("rangeplan_worker_restarts", "Worker processes replaced after a timeout, a "
                                       "crash or a memory error, by pool (count)", labels=["pool"])
        if pool is not None:
            stats = pool.stats()
            ready = pool.readiness()
            n = int(stats.get("in_flight", 0))
            in_flight.add_metric([], n)
            queue.add_metric([], max(0, n - int(ready["workers"])))
            workers.add_metric(["configured"], ready["workers"])
            workers.add_metric(["ready"], ready["workers_ready"])
            restarts.add_metric(["plan"], int(stats.get("replaced_workers", 0)))
        job_workers = GaugeMetricFamily("rangeplan_job_workers", "Workers that jobs (contours, plans answered 202) may "
                                        "hold at once: RANGEPLAN_JOB_WORKERS (count)")
        jobs = GaugeMetricFamily("rangeplan_jobs_in_flight", "Jobs on their share of the workers, by state: running "
                                 "(holding a slot of the share) or queued (waiting for one) (count)", labels=["state"])
        service = getattr(self.app.state, "service", None)
        if service is not None and hasattr(service, "jobs"):
            share = service.jobs()
            job_workers.add_metric([], share["workers"])
            jobs.add_metric(["running"], share["running"])
            jobs.add_metric(["queued"], share["queued"])
        waiting = GaugeMetricFamily("rangeplan_http_requests_waiting", "Requests waiting for their turn of the event "
                                    "loop (app/admission.py; RANGEPLAN_ADMISSION_QUEUE bounds them) (count)")
        admission = getattr(self.app.state, "admission", None)
        waiting.add_metric([], admission.waiting if admission is not None else 0)
        batches = getattr(self.app.state, "batches", None)
        items = GaugeMetricFamily("rangeplan_batch_items", "Items of the stored batches, by status: pending, "
                                  "running, ok, error, failed, cancelled (count)", labels=["status"])
        states = GaugeMetricFamily("rangeplan_batches", "Stored batches, by state (count)", labels=["state"])
        if batches is not None:
            restarts.add_metric(["batch"], int(batches.worker_restarts()))
            counts = batches.store.status_counts()
            for status in ("pending", "running", "ok", "error", "failed", "cancelled"):
                items.add_metric([status], counts["items"].get(status, 0))
            for state in ("queued", "running", "done", "cancelled"):
                states.add_metric([state], counts["batches"].get(state, 0))
        yield from (in_flight, queue, workers, restarts, job_workers, jobs, waiting, items, states)


class Metrics:
    """The metrics of one app (its own registry)."""

    def __init__(self, app: Any):
        self.registry = CollectorRegistry()
        r = self.registry
        self.requests = Counter("rangeplan_http_requests", "HTTP requests answered, by route template, method and "
                                "status (count)", ["route", "method", "status"], registry=r)
        self.latency = Histogram("rangeplan_http_request_duration_seconds", "Time from the request's arrival to "
                                 "the end of its response, by route template and method (s)", ["route", "method"],
                                 buckets=LATENCY_BUCKETS, registry=r)
        self.plans = Histogram("rangeplan_plan_duration_seconds", "Time a plan job spent in the planning pool "
                               "(queue, planning, serialisation), by mode and outcome (s)", ["mode", "outcome"],
                               buckets=PLAN_BUCKETS, registry=r)
        self.jobs = Counter("rangeplan_jobs", "Jobs the HTTP routes ran on the job service, by kind (plan, segment, "
                            "import, export) and outcome (ok, error, timeout, refused, crash) (count)",
                            ["kind", "outcome"], registry=r)
        r.register(_StateCollector(app))

    def text(self) -> bytes:
        return generate_latest(self.registry)


#: error codes of a job the pool did not run (the metrics' ``refused``) and of one it stopped
_REFUSED = frozenset({"too_much_work", "busy", "unavailable"})


def job_outcome(outcome: Any) -> str:
    """The metrics' outcome of a job's :mod:`app.jobs` outcome: ok, error (the input's),
    timeout, refused (not run: too much work, busy) or crash (a bug or a dead worker)."""
    if getattr(outcome, "ok", False):
        return "ok"
    code = getattr(getattr(outcome, "error", None), "code", "")
    if code == "timeout":
        return "timeout"
    if code in _REFUSED:
        return "refused"
    return "crash" if getattr(outcome, "status", 500) >= 500 else "error"


def observe_job(app: Any, job: Any, seconds: float, outcome: Any) -> None:
    """Count a job the HTTP routes ran (``job``: an :mod:`app.jobs` job; ``outcome``: its
    outcome, or a label of :func:`job_outcome`); log a crash (a 500) at error level with
    the request's id and the job's traceback."""
    label = outcome if isinstance(outcome, str) else job_outcome(outcome)
    if label == "crash":  # a 500: the server's fault, logged with the worker's traceback when it has one
        error = getattr(outcome, "error", None)
        error_log.error("job failed: %s", getattr(error, "message", outcome),
                        extra={"request_id": _request_id.get(), "job": str(getattr(job, "kind", "other")),
                               "exc": getattr(outcome, "trace", None)})
    metrics: Metrics | None = getattr(app.state, "metrics", None)
    if metrics is None:
        return
    kind = str(getattr(job, "kind", "other"))
    metrics.jobs.labels(kind, label).inc()
    if kind == "plan":
        mode = getattr(getattr(getattr(job, "request", None), "settings", None), "mode", None) or "unknown"
        metrics.plans.labels(mode, label).observe(seconds)


# ---------------------------------------------------------------------------------------
# the ASGI wrapper

def _route_of(scope: dict, status: int) -> str:
    route = scope.get("route")
    path = getattr(route, "path", None)
    if isinstance(path, str):
        return path
    if scope.get("app_root_path") or scope.get("root_path"):  # a mount (static files)
        return str(scope.get("root_path") or scope.get("app_root_path")) + "/{path}"
    return "(unmatched)" if status in (404, 405) or status < 400 else "(refused)"


_METHODS = frozenset({"GET", "HEAD", "POST", "PUT", "DELETE", "OPTIONS", "PATCH"})


class RequestContext:
    """ASGI wrapper (outermost): request id in and out, one access line and the request
    metrics per HTTP request; an exception that escaped the app's error handler (which has
    already answered 500) is logged here with the request's id instead of re-raised."""

    def __init__(self, app: Any, metrics: Metrics, access: bool = True):
        self.app, self.metrics, self.access = app, metrics, access

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        rid = _request_id_of(scope.get("headers", ()))
        token = _request_id.set(rid)
        t0 = time.perf_counter()
        status = 500
        started = False
        header = (b"x-request-id", rid.encode())

        async def send_with_id(msg):
            nonlocal status, started
            if msg["type"] == "http.response.start":
                started = True
                status = int(msg["status"])
                headers = [h for h in msg.get("headers", ()) if h[0].lower() != b"x-request-id"]
                msg = {**msg, "headers": [*headers, header]}
            await send(msg)

        try:
            await self.app(scope, receive, send_with_id)
        except Exception:
            error_log.exception("unhandled error", extra={"request_id": rid})
            if not started:  # nothing answered: the one error shape, with the id
                body = json.dumps({"error": {"code": "internal_error", "message": "internal error",
                                             "field": None}}).encode()
                await send_with_id({"type": "http.response.start", "status": 500,
                                    "headers": [(b"content-type", b"application/json"),
                                                (b"content-length", str(len(body)).encode())]})
                await send_with_id({"type": "http.response.body", "body": body})
        finally:
            elapsed = time.perf_counter() - t0
            route = _route_of(scope, status)
            method = scope.get("method", "")
            method = method if method in _METHODS else "other"  # a label of bounded cardinality
            self.metrics.requests.labels(route, method, str(status)).inc()
            self.metrics.latency.labels(route, method).observe(elapsed)
            if self.access and access_log.isEnabledFor(logging.INFO):
                client = scope.get("client")
                access_log.info("request", extra={
                    "request_id": rid, "method": scope.get("method", ""), "path": scope.get("path", ""), "route": route,
                    "status": status, "duration_ms": round(elapsed * 1e3, 3),
                    "client": f"{client[0]}:{client[1]}" if client else None})
            _request_id.reset(token)


def install_observability(app: Any, access_log: bool = True) -> Metrics:
    """Add request ids, access lines (``access_log``) and ``GET /metrics`` to a FastAPI
    ``app`` (the route is protected like ``/v1`` by :mod:`app.security`)."""
    from fastapi import Response

    metrics = Metrics(app)
    app.state.metrics = metrics
    access = access_log
    build = app.build_middleware_stack

    def build_middleware_stack():
        return RequestContext(build(), metrics, access)

    app.build_middleware_stack = build_middleware_stack

    @app.get("/metrics", include_in_schema=False)
    def prometheus_metrics() -> Response:
        """Prometheus text exposition format (README: Operations)."""
        return Response(metrics.text(), media_type=CONTENT_TYPE_LATEST)

    return metrics
