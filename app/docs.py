"""The API documentation pages, offline: Swagger UI at ``/docs`` and ReDoc at ``/redoc`` with
their scripts, styles and icon served by this server from the ``fastapi-offline`` package
(MIT; it ships Swagger UI, Apache-2.0, and ReDoc, MIT), not from a CDN, so the pages work on
a machine without internet (issue 15). A Content-Security-Policy keeps the browser from
loading anything from elsewhere; Swagger UI's online validator badge is off.

FastAPI's own ``/docs`` and ``/redoc`` (CDN assets) are turned off by creating the app with
``docs_url=None, redoc_url=None``; :func:`install_docs` adds these instead.
"""

from __future__ import annotations

from pathlib import Path

import fastapi_offline
from fastapi import FastAPI, Request
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html, get_swagger_ui_oauth2_redirect_html
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

__all__ = ["ASSETS_DIR", "ASSETS_URL", "CSP", "install_docs"]

#: the package's folder of Swagger UI and ReDoc assets
ASSETS_DIR = Path(fastapi_offline.__file__).resolve().parent / "static"
#: where this server serves them
ASSETS_URL = "/docs-assets"
#: nothing from another origin; the pages' own inline start-up script and styles; ReDoc's
#: search runs in a worker made from a blob
CSP = ("default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
       "img-src 'self' data:; worker-src 'self' blob:; connect-src 'self'; frame-ancestors 'self'")


def _page(html: HTMLResponse) -> HTMLResponse:
    html.headers["Content-Security-Policy"] = CSP
    return html


def install_docs(app: FastAPI, docs_url: str = "/docs", redoc_url: str = "/redoc") -> None:
    """Serve the documentation pages and their assets (call before a catch-all mount at "/")."""
    openapi_url = app.openapi_url or "/openapi.json"
    redirect_url = app.swagger_ui_oauth2_redirect_url or "/docs/oauth2-redirect"
    app.mount(ASSETS_URL, StaticFiles(directory=ASSETS_DIR), name="docs-assets")

    @app.get(docs_url, include_in_schema=False)
    async def swagger_ui(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "")
        return _page(get_swagger_ui_html(
            openapi_url=f"{root}{openapi_url}", title=f"{app.title} - Swagger UI",
            oauth2_redirect_url=f"{root}{redirect_url}",
            swagger_js_url=f"{root}{ASSETS_URL}/swagger-ui-bundle.js",
            swagger_css_url=f"{root}{ASSETS_URL}/swagger-ui.css",
            swagger_favicon_url=f"{root}{ASSETS_URL}/favicon.png",
            swagger_ui_parameters={"validatorUrl": None, "persistAuthorization": False,
                                   **(app.swagger_ui_parameters or {})}))

    @app.get(redirect_url, include_in_schema=False)
    async def swagger_ui_redirect() -> HTMLResponse:
        return _page(get_swagger_ui_oauth2_redirect_html())

    @app.get(redoc_url, include_in_schema=False)
    async def redoc(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "")
        return _page(get_redoc_html(openapi_url=f"{root}{openapi_url}", title=f"{app.title} - ReDoc",
                                    redoc_js_url=f"{root}{ASSETS_URL}/redoc.standalone.js",
                                    redoc_favicon_url=f"{root}{ASSETS_URL}/favicon.png", with_google_fonts=False))
