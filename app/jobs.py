"""What a planning job does (in a worker process, or inline in "thread" mode): the planner
called on a validated request, the result serialised to JSON (and stored) there, so that
the server process only moves bytes. Jobs are plain dicts with a ``kind``: ``"plan"``,
``"segment"``, ``"editor"`` (segmentation and plan for the editor) or ``"sleep"`` (tests).
"""

from __future__ import annotations

import json
import math
import time
from itertools import chain

import orjson

from app.failures import degenerate

__all__ = ["run_job"]

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
            if plan_id and store is not None and store.save_plan_json(
                    data.decode(), req.to_json_dict(), job.get("corridor_id"), id=plan_id) is None:
                plan_id = result.plan_id = None  # too large to keep (storage quotas): sent, not stored
                data = result.to_json()
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
        if job["kind"] == "contour":  # a G-code program (app/contour_api.py)
            return _contour(job)
        if job["kind"] == "import":
            from planner.exchange import import_drawing

            res = import_drawing(job["data"], job["options"], filename=job.get("filename"),
                                 content_type=job.get("content_type"))
            return ("ok", _dumps(res.to_json_dict()), {})
        if job["kind"] == "segment":
            from planner import segment

            return ("ok", _dumps(segment(job["request"]).to_dict()), {})
        if job["kind"] == "editor":
            return ("ok", _editor_plan(job["request"]), {})
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


def _contour(job: dict) -> tuple:
    """Contour a G-code program (:func:`planner.contour.plan_contour`): stored like a plan."""
    from app.storage import new_id
    from planner import to_csv
    from planner.contour import plan_contour
    from planner.exchange import export

    req = job["request"]
    result = plan_contour(req)
    plan_id = new_id() if job.get("store") else None
    result.plan_id = plan_id
    data = result.to_json()
    store = _store(job.get("store"))
    if plan_id and store is not None and store.save_plan_json(
            data.decode(), req.model_dump(mode="json"), None, id=plan_id) is None:
        plan_id = result.plan_id = None
        data = result.to_json()
    fmt = job.get("format")
    if fmt == "csv":
        payload = to_csv(result).encode()
    elif fmt in ("gcode", "joints", "dxf"):
        payload = export(result, fmt, forces=bool(job.get("forces")), source=job.get("source")).encode()
    else:
        payload = data
    return ("ok", payload, {"plan_id": plan_id})


def _editor_plan(req) -> bytes:
    """The editor's re-plan: the segmentation of a layout (kept when the plan then fails)
    and the plan, as JSON ``{"segmentation", "result", "error"}`` (each may be null)."""
    from planner import PlannerError, plan, segment

    seg = None
    try:
        segments = None
        if req.layout is not None:
            seg = segment(req)
            segments = seg.segments
        result = plan(req, segments=segments).to_json_dict()
        return _dumps({"segmentation": seg.to_dict() if seg else None, "result": result, "error": None})
    except PlannerError as exc:
        return _dumps({"segmentation": seg.to_dict() if seg else None, "result": None, "error": exc.to_dict()})


def _degenerate(exc: Exception, job: dict) -> dict:
    return degenerate(exc, custom_robot=not isinstance(getattr(job.get("request"), "robot", None), str))
