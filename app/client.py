"""A typed Python client of the rangeplan HTTP API (httpx), for integrators.

    from app.client import Client

    with Client("http://127.0.0.1:8000") as rp:
        drawing = rp.import_drawing("part.dxf", scale=0.1, start=[-0.07, 0, 0], end=[0.07, 0, 0])
        result = rp.plan({"layout": drawing.layout})            # a planner.schema.PlanResult
        Path("part.ngc").write_text(rp.export(result.plan_id, "gcode"))

Requests and results are the planner's own pydantic models (:mod:`planner.schema`), so
what the client sends is validated exactly as the server validates it. Every error the
service answers (4xx, 5xx) is raised as :class:`RangeplanError` with its ``code``,
``message``, ``field`` and HTTP ``status``; so are transport failures (code
``unavailable``). A server with a token (``RANGEPLAN_API_TOKEN``) needs it on every call:
``Client(url, token=...)``, by default the ``RANGEPLAN_API_TOKEN`` of the environment.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

import httpx
from pydantic import ValidationError

from app.formats import ExportFormatName
from app.settings import client_token
from planner.schema import (
    PARTIAL_LAYOUT,
    ContourRequest,
    CorridorRecord,
    ImportResult,
    PlanRequest,
    PlanResult,
    planner_error,
)

__all__ = ["Client", "RangeplanError"]

Request = PlanRequest | Mapping[str, Any]
#: ``csv`` and the machine formats (:data:`app.formats.OUTPUT_FORMATS`)
ExportFormat = ExportFormatName
_DRAWING_TYPES = {".dxf": "application/dxf", ".svg": "image/svg+xml"}


class RangeplanError(Exception):
    """An error answer of the service (or a transport failure: code ``unavailable``)."""

    def __init__(self, code: str, message: str, field: str | None = None, status: int | None = None):
        self.code, self.message, self.field, self.status = code, message, field, status
        super().__init__(f"{code}: {field + ': ' if field else ''}{message}")


def _body(request: Request) -> dict[str, Any]:
    """The request as JSON, validated here as the server would (a RangeplanError names the field)."""
    if isinstance(request, PlanRequest):
        return request.to_json_dict()
    try:
        return PlanRequest.model_validate(dict(request)).to_json_dict()
    except ValidationError as exc:
        e = planner_error(exc)
        raise RangeplanError(e.code, e.message, e.field) from None


class Client:
    """The rangeplan service at ``base_url`` (``timeout`` in s per call). ``token``: the
    server's token, sent as ``Authorization: Bearer`` (default: ``$RANGEPLAN_API_TOKEN``;
    none for a server without one)."""

    def __init__(self, base_url: str = "http://127.0.0.1:8000", *, token: str | None = None, timeout: float = 120.0,
                 transport: httpx.BaseTransport | None = None):
        # the client's own environment (it may run on another machine than the service)
        token = token if token is not None else client_token()
        headers = {"Authorization": f"Bearer {token}"} if token else None
        self._http = httpx.Client(base_url=base_url, timeout=timeout, transport=transport, headers=headers)

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ transport
    def _call(self, method: str, url: str, **kwargs: Any) -> httpx.Response:
        try:
            r = self._http.request(method, url, **kwargs)
        except httpx.HTTPError as exc:
            raise RangeplanError("unavailable", f"{type(exc).__name__}: {exc}") from None
        if r.status_code >= 400:
            try:
                err = r.json()["error"]
                raise RangeplanError(err.get("code", "http_error"), err.get("message", r.text), err.get("field"),
                                     r.status_code)
            except (ValueError, KeyError, TypeError):
                raise RangeplanError("http_error", r.text[:500], None, r.status_code) from None
        return r

    def _plan_result(self, r: httpx.Response) -> PlanResult:
        """The plan of a planning call's answer: the body (200), or, for a long request the
        service answered ``202 Accepted`` as a job, the stored plan once the job at
        ``Location`` is done (polled as its ``Retry-After`` says); a failed job raises its error."""
        if r.status_code != 202:
            return PlanResult.model_validate_json(r.content)
        url = r.headers["Location"]
        while True:
            time.sleep(float(r.headers.get("Retry-After", "1")))
            r = self._call("GET", url)
            job = r.json()
            if job["state"] == "done":
                return self.fetch_plan(job["plan_id"])
            if job["state"] == "failed":
                e = job["error"] or {}
                raise RangeplanError(e.get("code", "internal_error"), e.get("message", "the job failed"),
                                     e.get("field"))

    # ------------------------------------------------------------------ planning
    def plan(self, request: Request) -> PlanResult:
        """Plan a request (``segments``, ``reference`` or ``layout``); the result carries
        its ``plan_id`` for :meth:`fetch_plan` and :meth:`export`. A long one the service runs
        as a job (202) is followed to its end."""
        return self._plan_result(self._call("POST", "/v1/plan", json=_body(request)))

    def plan_corridor(self, corridor_id: str) -> PlanResult:
        """Plan a saved corridor."""
        return PlanResult.model_validate_json(self._call("POST", f"/v1/corridors/{corridor_id}/plan").content)

    def fetch_plan(self, plan_id: str) -> PlanResult:
        """A stored plan result."""
        return PlanResult.model_validate_json(self._call("GET", f"/v1/plans/{plan_id}").content)

    def export(self, plan_id: str, format: ExportFormat, *, forces: bool = False) -> str:
        """A stored plan in an output format of :data:`app.formats.OUTPUT_FORMATS` other than
        JSON: ``csv``, ``gcode`` (LinuxCNC), ``joints`` (leg lengths for halstreamer;
        ``forces`` adds the drive forces), ``dxf`` (path, corridor, obstacles), ..."""
        params: dict[str, Any] = {"format": format}
        if forces:
            params["forces"] = "true"
        return self._call("GET", f"/v1/plans/{plan_id}", params=params).text

    def contour(self, program: str | Path, *, origin: tuple[float, float] | list[float] = (0.0, 0.0),
                tolerance_m: float | None = None, feed: Literal["program", "fastest"] = "program",
                cut_below_m: float = 0.0, robot: Any = "moving-slide", settings: dict[str, Any] | None = None,
                name: str | None = None) -> PlanResult:
        """Contour a G-code program (its text, or a path to a .ngc file): ``POST /v1/contour``.
        ``origin``: program zero in the robot frame [m]; ``tolerance_m`` [m] (default the
        program's G64 P, else 0.05 mm); ``feed``: ``program`` or ``fastest``. The result has its
        ``contour`` section and a ``plan_id`` for :meth:`export`."""
        text = program.read_text() if isinstance(program, Path) else program
        try:
            body = ContourRequest.model_validate({
                "program": text, "origin": list(origin), "tolerance_m": tolerance_m, "feed": feed,
                "cut_below_m": cut_below_m, "robot": robot, "settings": settings or {}, "name": name})
        except ValidationError as exc:
            e = planner_error(exc)
            raise RangeplanError(e.code, e.message, e.field) from None
        r = self._call("POST", "/v1/contour", json=body.model_dump(mode="json", exclude_none=True))
        return self._plan_result(r)  # a long program: a job (202), followed to its end

    # ------------------------------------------------------------------ drawings
    def import_drawing(self, drawing: str | Path | bytes, *, format: Literal["dxf", "svg"] | None = None,
                       **options: Any) -> ImportResult:
        """A DXF or SVG drawing (a path, or its bytes with ``format``) as a layout and a
        report; ``options`` are :class:`planner.schema.ImportOptions` (units, layers,
        offset [m], rotation [rad], scale, join_tolerance [m], flatten_tolerance [m],
        margin [m], bounds_layer, start, end)."""
        if isinstance(drawing, bytes):
            data, suffix = drawing, f".{format}" if format else ""
        else:
            path = Path(drawing)
            data, suffix = path.read_bytes(), f".{format}" if format else path.suffix.lower()
        content_type = _DRAWING_TYPES.get(suffix)
        if content_type is None:
            raise RangeplanError("invalid_input", "say whether the drawing is DXF or SVG (a .dxf or .svg file, or "
                                 "format='dxf' | 'svg')", "format")
        params: list[tuple[str, str]] = []
        for key, value in options.items():
            if value is None:
                continue
            values = value if isinstance(value, (list, tuple)) else [value]
            params.extend((key, str(v)) for v in values)
        r = self._call("POST", "/v1/import", content=data, params=params, headers={"Content-Type": content_type})
        return ImportResult.model_validate_json(r.content, context=PARTIAL_LAYOUT)

    # ------------------------------------------------------------------ corridors
    def save(self, request: Request, corridor_id: str | None = None) -> CorridorRecord:
        """Save a request as a new corridor, or over ``corridor_id``."""
        body = _body(request)
        if corridor_id is None:
            r = self._call("POST", "/v1/corridors", json=body)
        else:
            r = self._call("PUT", f"/v1/corridors/{corridor_id}", json=body)
        return CorridorRecord.model_validate_json(r.content)

    def list(self) -> list[dict[str, Any]]:
        """Summaries ``{id, name, created, updated, bytes}`` of all saved corridors, oldest
        first, read page by page (``fetch`` gives one with its request)."""
        out: list[dict[str, Any]] = []
        cursor: str | None = None
        while True:
            params: dict[str, Any] = {"limit": 200, **({"cursor": cursor} if cursor else {})}
            page = self._call("GET", "/v1/corridors", params=params).json()
            out += page["items"]
            cursor = page.get("next_cursor")
            if not cursor:
                return out

    def fetch(self, corridor_id: str) -> CorridorRecord:
        """One saved corridor."""
        return CorridorRecord.model_validate_json(self._call("GET", f"/v1/corridors/{corridor_id}").content)

    def delete(self, corridor_id: str) -> None:
        """Delete a saved corridor."""
        self._call("DELETE", f"/v1/corridors/{corridor_id}")
