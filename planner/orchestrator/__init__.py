"""The orchestrator: one :func:`plan` composing the layers below, the receding-horizon
simulation, the result builder and the timing search."""

from .plan import plan, segment, warm_up
from .result import build_result, to_csv
from .simulate import PaperController, Simulation, simulate
from .timing import resolve_timing, timing_info
from .work import WorkEstimate, estimate_work

__all__ = ["plan", "segment", "warm_up", "build_result", "to_csv", "PaperController", "Simulation", "simulate",
           "resolve_timing", "timing_info", "WorkEstimate", "estimate_work"]
