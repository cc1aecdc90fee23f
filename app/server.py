"""``rangeplan serve``: the HTTP API (uvicorn) and, alongside it, the browser editor.

The API binds 127.0.0.1:8000 by default (``--host``/``--port`` or ``RANGEPLAN_HOST`` /
``RANGEPLAN_PORT``); the editor listens on ``--editor-port`` (``RANGEPLAN_EDITOR_PORT``, 8080).
Both share the SQLite store in ``RANGEPLAN_DATA_DIR`` (default: a per-user data directory),
the planning pool (the editor plans on the API's workers) and the access rules of
:mod:`app.security`. It refuses to start (exit status 2) with a bad security setting, or
bound to a non-loopback address without a token unless ``allow_unauthenticated``; and
(exit status 1) when either port is taken.
"""

from __future__ import annotations

from planner._config import single_threaded_blas

single_threaded_blas()  # before numpy loads

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


def serve(host: str = "127.0.0.1", port: int = 8000, editor_port: int = 8080, editor: bool = True,
          allow_unauthenticated: bool = False) -> int:
    """Run the API until interrupted (and the editor, when ``editor`` and available).
    Returns the process exit status."""
    from app.kernel_cache import seed_kernel_cache
    from app.security import AccessPolicy, ConfigError, is_loopback

    try:
        policy = AccessPolicy.from_env(bind_host=host)
    except ConfigError as exc:
        _log(f"error: {exc}")
        return 2
    if not policy.auth_required and not is_loopback(host):
        if not allow_unauthenticated:
            _log(f"error: refusing to serve on {host} (reachable from other machines) without a token: set "
                 "RANGEPLAN_API_TOKEN or RANGEPLAN_API_TOKEN_FILE, or pass --allow-unauthenticated")
            return 2
        _log(f"warning: serving on {host} without a token (--allow-unauthenticated): anyone who can reach this "
             "port can read, change and delete every corridor")
    seeded = seed_kernel_cache()  # before the planner is imported (numba resolves its cache at import)
    if seeded:
        _log(seeded)

    from app.api import create_app
    from app.service import JobService
    from app.settings import SettingsError, settings
    from app.storage import Store, default_data_dir

    try:
        cfg = settings()
    except SettingsError as exc:
        _log(f"error: {exc}")
        return 2
    store = Store(default_data_dir())
    _log(f"data: {store.path}")
    _log(f"access: {'token required' if policy.auth_required else 'no token'}; hosts "
         f"{', '.join(sorted(policy.allowed_hosts))}; CORS {', '.join(policy.cors_origins) or 'off'}")
    # one job service for the API and the editor: the same workers, estimate, limits, errors
    service = JobService.start(cfg.workers, cfg.plan_timeout_s, cfg.max_queue, mode=cfg.executor,
                               memory_mb=cfg.worker_memory_mb, export_timeout_s=cfg.export_timeout_s,
                               start=cfg.worker_start, reference_while_compiling=True, job_workers=cfg.job_workers)
    _log(f"workers: {service.workers} ({cfg.executor}); jobs may hold {min(service.job_workers, service.workers)} of "
         "them at once (RANGEPLAN_JOB_WORKERS), "
         + ("the others are kept for synchronous requests" if service.job_workers < service.workers else
            "so a synchronous request that finds every worker on a job is answered 503 busy"))
    if service.kernels is not None and (running := service.kernels.running()) is not None:
        _log(f"kernels: {running.note()}" if running.failed is not None else
             f"kernels: not compiled yet: compiling them in the background, {running.ready_in()} (pid {running.pid}, "
             f"log {running.log}); plans run on the numpy reference meanwhile (same trajectories, ~100x slower)")
    handle = None
    try:
        if editor:
            try:
                from app.editor import start_editor, start_guarded, use_service
            except ImportError as exc:
                _log(f"editor unavailable ({exc}); serving the API only")
            else:
                use_service(service)  # the editor plans on the API's workers, under the same limits
                handle = start_guarded(policy, lambda: start_editor(host, editor_port, store))
                if editor_port and handle.port != editor_port:
                    _log(f"error: the editor port {editor_port} is taken; choose another with --editor-port "
                         "(RANGEPLAN_EDITOR_PORT) or run without the editor (--no-editor)")
                    return 1
                _log(f"editor: http://{host}:{handle.port}")
        app = create_app(store, editor_port=handle.port if handle is not None else None, access=policy,
                         service=service)
        _log(f"API: http://{host}:{port} (OpenAPI at /docs)")
        return _run_api(app, host, port, cfg.log_level, cfg.access_log, cfg.keep_alive_s)
    finally:
        if handle is not None:
            try:
                handle.stop()
            except Exception as exc:  # the editor's shutdown must not hide the API's exit status
                _log(f"editor shutdown: {exc}")
            from app.editor import use_service
            use_service(None)
        service.close()


def _run_api(app, host: str, port: int, log_level: str = "info", access_log: bool = True,
             keep_alive_s: float = 65.0) -> int:
    import uvicorn

    stop_signal = _StopSignal.install()
    try:
        from app.observability import log_config

        # JSON lines (app.observability); the access lines are the app's own, with request ids
        # (``access_log``: RANGEPLAN_ACCESS_LOG), not uvicorn's
        # an idle connection outlives the clients' keep-alive expiry (httpx 5 s = uvicorn's default):
        # with equal timeouts a client may send on a connection the server is just closing (ReadError)
        config = uvicorn.Config(app, host=host, port=port, log_level=log_level, access_log=False,
                                log_config=log_config(log_level),
                                # uvicorn annotates int but passes the seconds to loop.call_later: a float works
                                timeout_keep_alive=keep_alive_s)  # pyright: ignore[reportArgumentType]
        server = uvicorn.Server(config)
        server.run()
        # uvicorn returns (does not raise) when it cannot bind
        return 0 if server.started else 1
    except (KeyboardInterrupt, _StopSignal):
        # uvicorn shut down gracefully, then re-raised the signal: a requested stop is a success
        return 0
    finally:
        stop_signal.restore()
