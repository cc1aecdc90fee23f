"""The orchestrator: one :func:`plan` composing the layers below, the receding-horizon
simulation, the result builder and the timing search."""

from .plan import plan, plan_timed, segment, warm_up
from .result import build_result, limit_metrics, rates_within, to_csv
from .simulate import PaperController, Simulation, simulate
from .timing import feasible, resolve_timing, timing_info
from .work import WorkEstimate, estimate_work

__all__ = ["plan", "plan_timed", "segment", "warm_up", "build_result", "limit_metrics", "rates_within", "to_csv",
           "PaperController", "Simulation", "simulate",
           "feasible", "resolve_timing", "timing_info", "WorkEstimate", "estimate_work"]
