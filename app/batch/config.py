"""Names the batch package's light modules share (no planner import: ``rangeplan --help``
and the HTTP app's import stay fast). Settings are :class:`app.settings.Settings`."""

from __future__ import annotations

__all__ = ["SCHEDULER_ENV", "FORMAT_NAMES"]

#: a Dask scheduler address (``tcp://host:8786``): batches run on that cluster
SCHEDULER_ENV = "RANGEPLAN_DASK_SCHEDULER"
#: result formats (``app.batch.engine.FORMATS`` has the writers; a test keeps them equal)
FORMAT_NAMES = ("json", "csv", "none")
