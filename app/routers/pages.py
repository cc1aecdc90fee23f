"""The landing page (``app/static/``, shipped in the wheel: its files as routes of their own, the examples under
``/examples``), or a redirect to ``/docs`` when there is none."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, FastAPI
from fastapi.responses import FileResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles

__all__ = ["STATIC_DIR", "install_pages"]

#: the landing page and its examples, package data of ``app`` (``RANGEPLAN_STATIC_DIR`` overrides)
STATIC_DIR = Path(__file__).resolve().parent.parent / "static"


def _serve_file(path: Path):
    return lambda: FileResponse(path)


def install_pages(app: FastAPI, static_dir: Path | None = None) -> None:
    """The landing page's files as routes (no catch-all mount at "/": it answered every
    unknown method and path, preflights included, with 405) and the examples at /examples."""
    static_dir = static_dir or STATIC_DIR
    router = APIRouter(include_in_schema=False)
    if (static_dir / "index.html").is_file():
        for f in sorted(static_dir.iterdir()):
            if f.is_file():
                router.add_api_route("/" if f.name == "index.html" else f"/{f.name}", _serve_file(f),
                                     methods=["GET"])
        app.include_router(router)
        if (static_dir / "examples").is_dir():
            app.mount("/examples", StaticFiles(directory=static_dir / "examples"), name="examples")
    else:
        router.add_api_route("/", lambda: RedirectResponse("/docs"), methods=["GET"])
        app.include_router(router)
