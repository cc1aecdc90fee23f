"""Names and settings of the batch package that its light modules share (no planner import:
``rangeplan --help`` and the HTTP app's import stay fast)."""

from __future__ import annotations

import os

__all__ = ["SCHEDULER_ENV", "FORMAT_NAMES", "env_float", "env_int"]

#: a Dask scheduler address (``tcp://host:8786``): batches run on that cluster
SCHEDULER_ENV = "RANGEPLAN_DASK_SCHEDULER"
#: result formats (``app.batch.engine.FORMATS`` has the writers; a test keeps them equal)
FORMAT_NAMES = ("json", "csv", "none")


def env_float(name: str, default: float) -> float:
    try:
        return float(os.environ.get(name, default))
    except ValueError:
        return default


def env_int(name: str, default: int) -> int:
    return int(env_float(name, default))
