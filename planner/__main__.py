"""``python -m planner``: compile (after installing) or load the planner's kernels, with
progress and an estimate of the time left on stderr while compiling."""

from .orchestrator import warm_up
from .orchestrator.compiling import compile_progress

with compile_progress():
    seconds = warm_up()
print(f"planner kernels ready in {seconds:.1f} s")
