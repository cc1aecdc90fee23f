"""``python -m planner``: compile (after installing) or load the planner's kernels; while
compiling, progress and an estimate of the time left on stderr (:func:`warm_up`)."""

from .orchestrator import warm_up

print(f"planner kernels ready in {warm_up():.1f} s")
