"""``python -m planner``: compile (after installing) or load the planner's kernels; while
compiling, progress and an estimate of the time left on stderr (:func:`warm_up`).
``python -m planner --background FD``: the same, as the detached background compile that
holds the lock ``FD`` (:mod:`planner.orchestrator.background`)."""

import sys

if len(sys.argv) == 3 and sys.argv[1] == "--background":
    from .orchestrator import warm_up
    from .orchestrator.background import _background_main

    _background_main(int(sys.argv[2]), warm_up)
else:
    from .orchestrator import warm_up

    print(f"planner kernels ready in {warm_up():.1f} s")
