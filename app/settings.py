"""The service's one settings object: every ``RANGEPLAN_*`` environment variable (and the
variables of other programs the service follows: ``XDG_DATA_HOME``, ``XDG_CACHE_HOME``,
numba's ``NUMBA_CACHE_DIR``, glibc's ``MALLOC_TRIM_THRESHOLD_``), its CLI flag where there is
one, its default and its meaning, in one table (:class:`Settings`).

Read with :func:`settings` (the environment at the time of the call, or a given mapping; a
value that does not parse is a :class:`SettingsError` naming the variable and the cause,
never a silent default). This module is the only one of ``app/`` that reads the environment
for configuration (a test checks it). The planner's own variables (where its compiled
kernels are kept: ``RANGEPLAN_KERNEL_CACHE``, ``NUMBA_CACHE_DIR``, ``XDG_CACHE_HOME``) are
read by ``planner/_config.py``, as the planner cannot import ``app/``: their fields here are
their documentation, and a test keeps both readings equal. The typed client's token is
:func:`client_token`. The manual's configuration table is :func:`settings_table` (a test
keeps them equal; ``python -m app.settings`` prints it). No web framework, planner or editor
import.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, JsonValue, ValidationError

__all__ = ["Settings", "SettingsError", "client_token", "env_name", "settings", "settings_table"]

MiB = 1024 * 1024


def _cpus() -> int:
    return os.cpu_count() or 1


def _half_cpus() -> int:
    return max(1, _cpus() // 2)


def _f(default: Any = None, description: str = "", *, cli: str | None = None, default_text: str | None = None,
       factory=None, **kw: Any) -> Any:
    """A setting: its default (or ``factory``), description, CLI flag and the default as the
    table shows it."""
    extra: dict[str, JsonValue] = {"cli": cli, "default_text": default_text}
    if factory is not None:
        return Field(default_factory=factory, description=description, json_schema_extra=extra, **kw)
    return Field(default, description=description, json_schema_extra=extra, **kw)


class Settings(BaseModel):
    """Configuration of ``rangeplan serve``, the HTTP API, its workers, storage, batches, the
    editor and the command line: each field is the environment variable ``RANGEPLAN_<FIELD>``
    (read by :func:`settings`; a plain pydantic model: pydantic-settings' sources import
    asyncio and more, ~0.1 s of every ``rangeplan plan``, for what is one loop over the
    environment here)."""

    model_config = ConfigDict(extra="ignore", frozen=True)

    # -- serving
    host: str = _f("127.0.0.1", "Address the API binds (a non-loopback address needs a token)", cli="serve --host")
    port: int = _f(8000, "TCP port of the API", cli="serve --port", ge=0, le=65535)
    editor_port: int = _f(8080, "TCP port of the browser editor", cli="serve --editor-port", ge=0, le=65535)
    log_level: str = _f("info", "Log level of the server's JSON log lines (critical, error, warning, info, debug, "
                        "trace)")
    keep_alive_s: float = _f(65.0, "Seconds an idle HTTP connection is kept open; longer than clients' own idle "
                             "expiry (httpx 5 s, proxies 60 s), so no client reuses a connection the server is "
                             "closing", gt=0)
    access_log: bool = _f(True, "One JSON log line per request, with its request id (0: off)")
    static_dir: Path | None = _f(None, "Landing page directory (index.html, examples/)",
                                 default_text="the package's app/static/")
    # -- planning
    workers: int = _f(None, "Planning worker processes", factory=_cpus, default_text="CPU count", ge=1)
    executor: Literal["process", "thread", "dask"] = _f("process", "Where plans run: worker processes, threads of "
                                                        "the server process (no parallelism, no stopping; for "
                                                        "measurements), or the Dask cluster at "
                                                        "RANGEPLAN_DASK_SCHEDULER (dask)")
    plan_timeout_s: float = _f(30.0, "Compute limit of one plan, import or batch item [s]; work estimated above 1/1.5 "
                               "of it is refused before it starts (a run may take up to 1.5x its estimate)",
                               cli="batch --timeout (default there: none)", gt=0)
    export_timeout_s: float = _f(120.0, "Time limit of writing a stored plan in an export format (GET /v1/plans/{id}?"
                                 "format=) [s]; at least RANGEPLAN_PLAN_TIMEOUT_S", gt=0)
    worker_memory_mb: int = _f(2048, "Address-space limit of each planning process [MiB] (0: none)", ge=0)
    worker_start: Literal["forkserver", "exec"] = _f("forkserver", "How a planning process starts: forked from one "
                                                     "that loaded the planner once (ready in ~0.1 s), or a fresh "
                                                     "interpreter loading it (1-6 s each)")
    async_after_s: float = _f(10.0, "A contour or plan whose work estimate is over this [s] is answered 202 Accepted "
                              "as a job (GET /v1/jobs/{id}); a request's Prefer: respond-async asks for a job at any "
                              "estimate, Prefer: wait=N sets N for that request", gt=0)
    job_timeout_s: float = _f(600.0, "Compute limit of a contour, and of a plan run as a job [s]; work estimated above "
                              "1/1.5 of it is refused before it starts; at least RANGEPLAN_PLAN_TIMEOUT_S", gt=0)
    job_workers: int | None = _f(None, "Planning workers that jobs (contours, and plans answered 202 Accepted) may "
                                 "hold at once; the others are kept for synchronous requests (plans, imports, "
                                 "the editor), which a free worker serves before any waiting job. More jobs wait "
                                 "their turn (state queued). At RANGEPLAN_WORKERS or more, jobs may hold every "
                                 "worker, and a synchronous request that finds them all on jobs is answered 503 busy "
                                 "at once", default_text="RANGEPLAN_WORKERS - 1 (at least 1)", ge=1)
    max_jobs: int = _f(100, "Jobs kept (the oldest finished are dropped; with this many unfinished the API answers "
                       "503 busy)", ge=1)
    job_max_age_s: float = _f(86400.0, "Seconds a finished job is kept", gt=0)
    max_queue: int = _f(64, "Jobs waiting for a worker beyond which the API answers 503 busy", ge=0)
    admission_queue: int = _f(1024, "Requests waiting for the event loop (it starts one new request a turn, so that "
                              "/health and /ready answer at once under any burst) beyond which the API answers "
                              "503 busy", ge=1)
    max_body_bytes: int = _f(2 * MiB, "Largest request body [bytes] (413 above)", default_text="2 MiB", gt=0)
    # -- storage
    data_dir: Path | None = _f(None, "Directory of the SQLite store",
                               default_text="$XDG_DATA_HOME/rangeplan or ~/.local/share/rangeplan")
    max_plans: int = _f(1000, "Stored plans kept (the oldest are dropped)", ge=1)
    max_corridor_bytes: int = _f(1 * MiB, "Largest corridor request JSON [bytes] (413 above)", default_text="1 MiB",
                                 gt=0)
    max_plan_bytes: int = _f(64 * MiB, "Largest plan result stored [bytes] (larger ones are answered, not stored)",
                             default_text="64 MiB", gt=0)
    max_store_bytes: int = _f(1024 * MiB, "Corridors and plans together [bytes] (507 when corridors fill it)",
                              default_text="1 GiB", gt=0)
    # -- access
    api_token: str | None = _f(None, "Bearer token every request needs (none: no token)")
    api_token_file: Path | None = _f(None, "File holding the token (instead of RANGEPLAN_API_TOKEN)")
    allowed_hosts: str = _f("", "Host names the server answers to besides loopback (comma-separated)")
    cors_origins: str = _f("", "Origins allowed cross-origin requests (comma-separated scheme://host[:port], or *)")
    # -- batches
    batch_workers: int = _f(None, "Worker processes of the service's batches", factory=_half_cpus,
                            default_text="half the CPU count", ge=1)
    max_batches: int = _f(100, "Finished batches kept", ge=1)
    max_batch_items: int = _f(10_000, "Items of one batch", ge=1)
    max_batch_queue: int = _f(100_000, "Items of all queued batches", ge=1)
    dask_scheduler: str | None = _f(None, "Dask scheduler address (tcp://host:8786): batches run on that cluster "
                                    "(and the service's plans with RANGEPLAN_EXECUTOR=dask)",
                                    cli="batch --scheduler")
    dask_malloc: str = _f("relax", "glibc malloc tuning of Dask workers (relax | keep)")
    # -- kernels
    kernel_seed: Path | None = _f(None, "Compiled-kernel cache copied into NUMBA_CACHE_DIR before the planner loads")
    kernel_cache: Path | None = _f(None, "Directory of the planner's compiled-kernel caches (one per kernel source "
                                   "version, <dir>/<key>, shared by every checkout and install of that source; read "
                                   "by the planner itself, planner/_config.py)",
                                   default_text="$XDG_CACHE_HOME/rangeplan/kernels or ~/.cache/rangeplan/kernels")
    # -- other programs' variables the service follows (named as they are, no prefix)
    numba_cache_dir: Path | None = _f(None, "numba's compiled-kernel cache directory (numba's own variable; the "
                                      "kernel seed is copied there)", validation_alias="NUMBA_CACHE_DIR",
                                      default_text="unset (the planner picks its cache)")
    xdg_cache_home: Path | None = _f(None, "Base directory of user caches (the XDG variable); the kernel cache "
                                     "defaults to its rangeplan/kernels/", validation_alias="XDG_CACHE_HOME",
                                     default_text="~/.cache")
    xdg_data_home: Path | None = _f(None, "Base directory of user data (the XDG variable); the store defaults to "
                                    "its rangeplan/", validation_alias="XDG_DATA_HOME",
                                    default_text="~/.local/share")
    malloc_trim_threshold: int | None = _f(None, "glibc's trim threshold [bytes] (glibc's own variable; Dask's nanny "
                                           "sets 65536 in its workers, which rangeplan relaxes unless "
                                           "RANGEPLAN_DASK_MALLOC=keep)", validation_alias="MALLOC_TRIM_THRESHOLD_")


def env_name(field: str) -> str:
    """The environment variable of a :class:`Settings` field: ``RANGEPLAN_<FIELD>``, or the
    other program's own name (``XDG_DATA_HOME``, ``NUMBA_CACHE_DIR``)."""
    alias = Settings.model_fields[field].validation_alias
    return alias if isinstance(alias, str) else f"RANGEPLAN_{field.upper()}"


_BY_ENV = {env_name(f): f for f in Settings.model_fields}


class SettingsError(ValueError):
    """An environment variable whose value does not parse (its name and the cause)."""


def settings(environ: Mapping[str, str] | None = None) -> Settings:
    """The settings of the current environment (or of the variables in ``environ``: a
    policy or a path computed for another environment, tests); raises
    :class:`SettingsError` for a value that does not parse."""
    if environ is None:  # the process environment: names in any case (as pydantic-settings read them)
        given = {name.upper(): v for name, v in os.environ.items()}
    else:
        given = dict(environ)
    values: dict[str, Any] = {str(Settings.model_fields[f].validation_alias or f): v for name, v in given.items()
                              if (f := _BY_ENV.get(name)) is not None and v != ""}  # empty: the default
    try:
        return Settings.model_validate(values)
    except ValidationError as exc:
        e = exc.errors()[0]
        loc = str(e["loc"][0]) if e.get("loc") else ""
        name = env_name(loc) if loc in Settings.model_fields else loc if loc in _BY_ENV else "RANGEPLAN_*"
        raise SettingsError(f"{name}: {e['msg']} (got {e.get('input')!r})") from None


def client_token(environ: Mapping[str, str] | None = None) -> str | None:
    """The token the typed client (:class:`app.client.Client`) sends by default:
    ``RANGEPLAN_API_TOKEN`` of the client's own environment, read alone (the client may run
    where the server's other variables are unset or mean something else); None when unset."""
    env = os.environ if environ is None else environ
    return env.get("RANGEPLAN_API_TOKEN") or None


def settings_table() -> str:
    """The configuration table of the README (Markdown): variable, CLI flag, default, meaning."""
    rows = ["| environment | CLI flag | default | meaning |", "|---|---|---|---|"]
    for name, f in Settings.model_fields.items():
        extra: dict[str, Any] = f.json_schema_extra if isinstance(f.json_schema_extra, dict) else {}
        default = extra.get("default_text")
        if default is None:
            d = f.default
            default = "none" if d is None else ("1" if d is True else "0" if d is False else str(d))
        cli = f"`{extra['cli']}`" if extra.get("cli") else ""
        rows.append(f"| `{env_name(name)}` | {cli} | {default} | {f.description} |")
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    print(settings_table(), end="")
