"""``python -m planner``: compile (after installing) or load the planner's kernels."""

from .orchestrator import warm_up

print(f"planner kernels ready in {warm_up():.1f} s")
