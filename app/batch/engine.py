"""The batch engine's one function: plan one request wherever it runs and return a compact,
picklable outcome (plain types and the result's bytes in the requested format).

:func:`plan_item` is what every engine runs: the calling process (``inline``), a local
process pool (``local``) or a Dask worker (``dask``). It validates the request (a plan request, or a
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

Workers import this module once and load the compiled kernels once
(:func:`warm_worker`: a process pool's initializer, or the Dask worker plugin in
:mod:`app.batch.cluster`); nothing is imported or compiled per item.
"""

from __future__ import annotations

import os
import time
from typing import Any

import orjson

from app.executors import WORKER, run_bounded, warm_worker, where
from app.formats import OUTPUT_FORMATS
from app.jobs import ContourJob, Failed, PlanJob, failed
from planner import PlannerError
from planner.schema import ContourRequest, PlanRequest, error_details

__all__ = ["FORMATS", "STAGING_PREFIX", "plan_item", "request_kind", "plan_chunk", "unpack_chunk", "warm_worker",
           "where"]

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
              timeout_s: float | None = None) -> dict[str, Any]:
    """Plan one request (JSON text, a dict, a :class:`PlanRequest` or, for a G-code program, a
    :class:`ContourRequest`: :func:`request_kind`) and return ``{"status": "ok" | "error",
    "kind": "plan" | "contour", "name", "payload": bytes | None, "summary": {...} | None,
    "error": {code, message, field} | None, "wall_ms", **where()}``. ``payload`` is the result
    in ``fmt`` (:data:`FORMATS`; a contour item's is the result of ``POST /v1/contour``, with
    its ``contour`` section). ``timeout_s`` bounds the planning time (code ``timeout``), and,
    as for ``POST /v1/plan`` and ``POST /v1/contour``, a request whose work estimate exceeds it
    is not planned (code ``too_much_work``; a contour item's is estimated once its program is
    read)."""
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
        outcome = run_bounded(job, timeout_s, WORKER["memory_mb"])
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


def plan_chunk(requests: list, fmt: str = "json", timeout_s: float | None = None,
               stage: str | None = None) -> dict[str, Any]:
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
        oc = plan_item(r, fmt, timeout_s)
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
