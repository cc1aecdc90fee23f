"""``rangeplan serve``: the HTTP API (uvicorn) and, alongside it, the browser editor.

The API binds 127.0.0.1:8000 by default (``--host``/``--port`` or ``RANGEPLAN_HOST`` /
``RANGEPLAN_PORT``); the editor listens on ``--editor-port`` (``RANGEPLAN_EDITOR_PORT``, 8080).
Both share the SQLite store in ``RANGEPLAN_DATA_DIR`` (default: a per-user data directory).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import sys  # noqa: E402


def _log(msg: str) -> None:
    print(f"rangeplan: {msg}", file=sys.stderr, flush=True)


class _StopSignal(Exception):
    """SIGTERM (e.g. ``docker stop``) as an exception, so the editor is stopped too."""

    def __init__(self, previous=None):
        super().__init__("terminated")
        self.previous = previous

    @classmethod
    def install(cls) -> _StopSignal:
        import signal
        import threading

        if threading.current_thread() is not threading.main_thread():
            return cls()

        def handler(sig, frame):
            raise cls()
        return cls(signal.signal(signal.SIGTERM, handler))

    def restore(self) -> None:
        if self.previous is not None:
            import signal
            signal.signal(signal.SIGTERM, self.previous)


def serve(host: str = "127.0.0.1", port: int = 8000, editor_port: int = 8080, editor: bool = True) -> int:
    """Run the API until interrupted (and the editor, when ``editor`` and available).
    Returns the process exit status."""
    import uvicorn

    from app.api import create_app
    from app.storage import Store, default_data_dir

    store = Store(default_data_dir())
    _log(f"data: {store.path}")
    handle = None
    if editor:
        try:
            from app.editor import start_editor
        except ImportError as exc:
            _log(f"editor unavailable ({exc}); serving the API only")
        else:
            try:
                handle = start_editor(host, editor_port, store)
                _log(f"editor: http://{host}:{editor_port}")
            except OSError as exc:
                _log(f"editor could not start on {host}:{editor_port} ({exc}); serving the API only")
                handle = None
    app = create_app(store, editor_port=editor_port if handle is not None else None)
    _log(f"API: http://{host}:{port} (OpenAPI at /docs)")
    stop_signal = _StopSignal.install()
    try:
        config = uvicorn.Config(app, host=host, port=port, log_level=os.environ.get("RANGEPLAN_LOG_LEVEL", "info"),
                                access_log=os.environ.get("RANGEPLAN_ACCESS_LOG", "1") != "0")
        server = uvicorn.Server(config)
        server.run()
        # uvicorn returns (does not raise) when it cannot bind
        return 0 if server.started else 1
    except (KeyboardInterrupt, _StopSignal):
        # uvicorn shut down gracefully, then re-raised the signal: a requested stop is a success
        return 0
    finally:
        stop_signal.restore()
        if handle is not None:
            try:
                handle.stop()
            except Exception as exc:  # the editor's shutdown must not hide the API's exit status
                _log(f"editor shutdown: {exc}")
