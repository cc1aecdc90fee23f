"""The planner's configuration from the environment (issue 34 goal 5): the only module of
``planner/`` that reads ``os.environ``, once per process (:func:`config`), into an immutable
:class:`PlannerConfig`; and the one place that sets the BLAS thread counts before numpy loads
(:func:`single_threaded_blas`, called first by the CLI, the server and the planning workers).
Standard library only (``import planner`` stays light).

The planner follows four variables, all about where its compiled kernels are kept
(:mod:`planner._jit`): numba's ``NUMBA_CACHE_DIR``, ``RANGEPLAN_KERNEL_CACHE``, the XDG
``XDG_CACHE_HOME`` and ``HOME``. The service's settings object (``app/settings.py``) names the
same variables (a test keeps both readings equal) and is the one table users read; the planner
cannot import ``app/``, so it reads them here itself.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

__all__ = ["BLAS_THREAD_VARS", "ENV_VARS", "PlannerConfig", "config", "read_config", "single_threaded_blas"]

#: the environment variables the planner reads (each a field of :class:`PlannerConfig`)
ENV_VARS = ("NUMBA_CACHE_DIR", "RANGEPLAN_KERNEL_CACHE", "XDG_CACHE_HOME", "HOME")


class PlannerConfig(NamedTuple):
    """Where the planner keeps its compiled kernels (:func:`planner._jit.chosen_kernel_cache`).

    ``numba_cache_dir``: ``NUMBA_CACHE_DIR`` (kernels in ``<it>/rangeplan-<key>``);
    ``kernel_cache``: ``RANGEPLAN_KERNEL_CACHE`` (kernels in ``<it>/<key>``); ``cache_home``:
    ``XDG_CACHE_HOME``, else ``<home>/.cache`` (kernels in ``<it>/rangeplan/kernels/<key>``,
    the default); ``home``: ``HOME``, else the user's home from the password database (the
    private cache, ``<home>/.cache/rangeplan/kernels/<key>``). An empty variable is unset.
    Immutable (a named tuple: ``dataclasses`` would cost ``rangeplan --help`` ~8 ms of imports)."""

    numba_cache_dir: Path | None
    kernel_cache: Path | None
    cache_home: Path
    home: Path


def read_config(environ: Mapping[str, str]) -> PlannerConfig:
    """The configuration of the variables in ``environ`` (the process's, or a given mapping)."""

    def path(name: str) -> Path | None:
        value = environ.get(name, "")
        return Path(value) if value else None

    home = path("HOME") or Path(os.path.expanduser("~"))
    return PlannerConfig(numba_cache_dir=path("NUMBA_CACHE_DIR"), kernel_cache=path("RANGEPLAN_KERNEL_CACHE"),
                         cache_home=path("XDG_CACHE_HOME") or home / ".cache", home=home)


@lru_cache(maxsize=1)
def config() -> PlannerConfig:
    """This process's configuration: the environment read once, on first use."""
    return read_config(os.environ)


#: the thread counts of the BLAS libraries numpy may load
BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def single_threaded_blas() -> None:
    """One BLAS thread unless the environment says otherwise: the planner's matrices are small
    and dense, where a single thread is much faster. Must run before numpy loads (the CLI,
    the server and the planning workers call it first)."""
    for var in BLAS_THREAD_VARS:
        os.environ.setdefault(var, "1")
