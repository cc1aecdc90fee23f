"""The batch engine's one function: plan one request wherever it runs and return a compact,
picklable outcome (plain types and the result's bytes in the requested format); and the typed
job a batch submits to an executor, :class:`BatchChunkJob` (a chunk of items).

:func:`plan_item` is what every engine runs, inside a :class:`BatchChunkJob` submitted to the
service's executors (:class:`app.executors.JobExecutor`): the calling process (``inline``), a
local pool of planning processes (``local``, :class:`app.workers.PlanPool`) or a Dask worker
(``dask``, :class:`app.cluster.DaskExecutor`). It validates the request (a plan request, or a
contour request: a G-code program, :func:`request_kind`) and runs it as the service's typed job
(:class:`app.jobs.PlanJob` or :class:`app.jobs.ContourJob`) through
:func:`app.executors.run_bounded` (the same work estimate, time limit and error mapping as the
HTTP API's workers): with a time limit or a memory cap the item runs in a planning process of
the worker (a child of it, killed at the limit: the worker itself lives on). It never raises
for a request's fault: a planner error comes back as ``{"status": "error", "error": {code,
message, field}}``, like the HTTP API's 422 body. :func:`plan_chunk` plans several requests in
one task (fewer round trips to a pool or a scheduler per plan; each item still has its own time
limit and outcome) and, where the worker sees the caller's output directory, writes each
result there itself so that only a summary travels back (the task-attempt files of an output
committer: written under a temporary name, renamed into place by the caller).

Workers load the compiled kernels once (a pool's worker when it starts, a Dask worker by the
plugin of :mod:`app.cluster`) and import this module with their first chunk; nothing is
imported or compiled per item.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Any, ClassVar

import orjson

from app.executors import run_bounded, where
from app.formats import OUTPUT_FORMATS
from app.jobs import ContourJob, Done, Failed, PlanJob, failed
from planner import PlannerError
from planner.schema import ContourRequest, PlanRequest, error_details

__all__ = ["BatchChunkJob", "FORMATS", "STAGING_PREFIX", "chunk_outcomes", "plan_chunk", "plan_item", "request_kind",
           "unpack_chunk", "where"]

#: output formats: file extension and the function writing a result's bytes (``none``: the
#: summary only, no result file; what a million-corridor study keeps, see docs/batch-scale.md)
FORMATS: dict[str, tuple[str | None, Any]] = {
    **{k: (OUTPUT_FORMATS[k].extension, OUTPUT_FORMATS[k].writer) for k in ("json", "csv")},
    "none": (None, None),
}

def request_kind(request: str | bytes | dict | PlanRequest | ContourRequest) -> str:
    """``"contour"`` for a contour request (a G-code program: an object with ``program``, the
    body of ``POST /v1/contour``), else ``"plan"`` (the body of ``POST /v1/plan``). Text is
    parsed only when it names ``"program"`` at all."""
    if isinstance(request, ContourRequest):
        return "contour"
    if isinstance(request, dict):
        return "contour" if "program" in request else "plan"
    if isinstance(request, (str, bytes)):
        raw = request.encode("utf-8", "surrogateescape") if isinstance(request, str) else request
        if b'"program"' in raw:
            try:
                obj = orjson.loads(raw)
            except orjson.JSONDecodeError:
                return "plan"
            return "contour" if isinstance(obj, dict) and "program" in obj else "plan"
    return "plan"


def _job(request: str | bytes | dict | PlanRequest | ContourRequest, fmt: str) -> PlanJob | ContourJob:
    """The typed job of one item (validated here: an invalid request raises ValidationError)."""
    if isinstance(request, PlanRequest):
        return PlanJob(request, fmt)
    if isinstance(request, ContourRequest):
        return ContourJob(request, fmt)
    model = ContourRequest if request_kind(request) == "contour" else PlanRequest
    req = model.model_validate(request) if isinstance(request, dict) else model.model_validate_json(request)
    return ContourJob(req, fmt) if isinstance(req, ContourRequest) else PlanJob(req, fmt)


def plan_item(request: str | bytes | dict | PlanRequest | ContourRequest, fmt: str = "json",
              timeout_s: float | None = None, memory_mb: int | None = None,
              engine: str | None = None) -> dict[str, Any]:
    """Plan one request (JSON text, a dict, a :class:`PlanRequest` or, for a G-code program, a
    :class:`ContourRequest`: :func:`request_kind`) and return ``{"status": "ok" | "error",
    "kind": "plan" | "contour", "name", "payload": bytes | None, "summary": {...} | None,
    "error": {code, message, field} | None, "wall_ms", **where()}``. ``payload`` is the result
    in ``fmt`` (:data:`FORMATS`; a contour item's is the result of ``POST /v1/contour``, with
    its ``contour`` section). ``timeout_s`` bounds the planning time (code ``timeout``), and,
    as for ``POST /v1/plan`` and ``POST /v1/contour``, a request whose work estimate exceeds it
    is not planned (code ``too_much_work``; a contour item's is estimated once its program is
    read); ``memory_mb`` caps the planning process the item then runs in (``too_much_memory``).
    ``engine`` names where it ran (``local``, ``inline``) unless it ran on a Dask worker."""
    from pydantic import ValidationError

    t0 = time.perf_counter()
    out: dict[str, Any] = {"status": "error", "kind": "plan", "name": None, "payload": None, "summary": None,
                           "error": None}
    try:
        if fmt not in FORMATS:
            raise PlannerError("invalid_input", f"unknown format {fmt!r}; one of {', '.join(FORMATS)}", "format")
        out["kind"] = request_kind(request)
        job = _job(request, fmt)
        out["name"] = job.request.name
        outcome = run_bounded(job, timeout_s, memory_mb)
    except PlannerError as exc:
        outcome = failed(exc.to_dict())
    except ValidationError as exc:
        details = error_details(exc.errors())
        first = details[0] if details else {"code": "invalid_input", "field": None, "message": "invalid input"}
        msg = first["message"].replace("body is not valid JSON", "not valid JSON", 1)
        outcome = failed({"code": first["code"], "message": msg, "field": first["field"]})
    if isinstance(outcome, Failed):
        out["error"] = outcome.error.to_dict()
    else:
        out.update(status="ok", payload=outcome.payload, summary=outcome.summary)
    out["wall_ms"] = (time.perf_counter() - t0) * 1e3
    out.update(where())
    if engine and out["engine"] != "dask":
        out["engine"] = engine
    return out


#: name prefix of the staging directory a run makes in its output directory (one per run:
#: ``<prefix><random token>``); workers write results there, the caller renames them into place
STAGING_PREFIX = ".rangeplan-staging-"

_STAGE_SEEN: dict[str, bool] = {}


def _stage_visible(stage: str) -> bool:
    """Whether this process sees the staging directory ``stage`` (cached per directory). Its
    name holds a random token, so a worker on another host that has a directory of the same
    path but not the same (shared) filesystem does not find it and sends results back."""
    seen = _STAGE_SEEN.get(stage)
    if seen is None:
        if len(_STAGE_SEEN) > 64:
            _STAGE_SEEN.clear()
        seen = _STAGE_SEEN[stage] = os.path.isdir(stage)
    return seen


def _stage_write(stage: str, payload: bytes) -> str | None:
    """Write ``payload`` to a new file in ``stage``; its name, or None if it cannot be written
    (the directory is gone, the disk is full: the result then travels back instead). A file
    cut short by a dying worker stays under this temporary name, never the result's."""
    name = f"{os.getpid()}-{os.urandom(8).hex()}.part"
    path = os.path.join(stage, name)
    try:
        with open(path, "wb") as f:
            f.write(payload)
    except OSError:
        _STAGE_SEEN[stage] = False
        try:
            os.unlink(path)
        except OSError:
            pass
        return None
    return name


def plan_chunk(requests: list | tuple, fmt: str = "json", timeout_s: float | None = None,
               stage: str | None = None, memory_mb: int | None = None, engine: str | None = None) -> dict[str, Any]:
    """:func:`plan_item` for each request, in order (one task for several small plans),
    packed for the trip back: ``{"outcomes": [...], "blob": bytes}``.

    ``stage``: a directory the caller made for this run (see :data:`STAGING_PREFIX`). If this
    process sees it, each result is written there as it is planned and only its file name
    (``staged``) and ``bytes`` travel back: the caller renames the file into place, so the
    result never crosses a pipe or the network and a half-written file never has its final
    name. Otherwise (no ``stage``, or a Dask worker without the shared directory) the
    results travel: each outcome's payload is replaced by its ``size`` in the one ``blob``
    (a Dask transfer of one 6 MB buffer costs about half the CPU of forty 145 kB ones);
    :func:`unpack_chunk` restores the payloads."""
    staging = stage is not None and _stage_visible(stage)
    outcomes = []
    parts = []
    for r in requests:
        oc = plan_item(r, fmt, timeout_s, memory_mb, engine)
        payload = oc.pop("payload")
        oc["size"] = None
        if payload is not None:
            name = _stage_write(stage, payload) if staging and stage is not None else None
            if name is not None:
                oc["staged"], oc["bytes"] = name, len(payload)
            else:
                oc["size"] = len(payload)
                parts.append(payload)
        outcomes.append(oc)
    return {"outcomes": outcomes, "blob": b"".join(parts)}


@dataclass(frozen=True)
class BatchChunkJob:
    """A chunk of a batch's items as one typed job (:class:`app.jobs.ChunkJob`): what the batch
    runner submits to an executor (:meth:`app.executors.JobExecutor.submit`; one round trip to
    a pool's worker or a Dask scheduler for several ~5 ms plans, as :mod:`app.batch.runner` sizes
    the chunks). Its :meth:`run` is
    :func:`plan_chunk`: each item the service's typed job under its own bounds (``timeout_s``:
    its work estimate and time limit, ``memory_mb``: its memory cap), in a planning process of
    the process the chunk runs in, killed at the item's limit; ``stage``: the run's staging
    directory; ``engine``: the name each outcome reports. The :class:`~app.jobs.Done` it
    answers: ``summary["outcomes"]`` (:func:`plan_chunk`'s, one per item, in order) and
    ``payload``, the results not written to ``stage`` back to back (:func:`unpack_chunk`)."""

    requests: tuple
    format: str = "json"
    timeout_s: float | None = None
    memory_mb: int | None = None
    stage: str | None = None
    engine: str | None = None
    kind: ClassVar[str] = "batch"

    def run(self) -> Done:
        packed = plan_chunk(self.requests, self.format, self.timeout_s, self.stage, self.memory_mb, self.engine)
        return Done(packed["blob"], summary={"outcomes": packed["outcomes"]})


def chunk_outcomes(done: Done) -> list[dict[str, Any]]:
    """The item outcomes of a :class:`BatchChunkJob`'s :class:`~app.jobs.Done` (:func:`unpack_chunk`)."""
    return unpack_chunk({"outcomes": (done.summary or {})["outcomes"], "blob": done.payload or b""})


def unpack_chunk(packed: dict[str, Any]) -> list[dict[str, Any]]:
    """The outcomes of :func:`plan_chunk` with their ``payload`` again (views of the blob;
    None for a result written to the staging directory: its outcome has ``staged``)."""
    view = memoryview(packed["blob"])
    at = 0
    out = []
    for oc in packed["outcomes"]:
        size = oc.pop("size", None)
        oc["payload"] = None if size is None else view[at:at + size]
        at += size or 0
        out.append(oc)
    return out
