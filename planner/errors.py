"""Errors the planner raises on bad input or an impossible plan.

Every error carries a stable machine-readable ``code`` (for HTTP clients), a plain
``message`` and, where the cause is one field of the request, the ``field`` path
(e.g. ``"segments[3].lower"``) so a user can find what to fix.
"""

from __future__ import annotations


class PlannerError(ValueError):
    """A request the planner cannot turn into a plan.

    Codes: ``invalid_input`` (a field is malformed), ``unreachable`` (a pose outside the
    legs' stroke), ``singular`` (a pose where the drives lose control of a direction),
    ``not_settled`` (the robot did not settle at the end point within the tail),
    ``no_path`` (segmentation found no corridor), ``too_large`` (a bound on work was hit),
    ``infeasible`` (constrained mode could not meet its hard constraints).
    """

    def __init__(self, code: str, message: str, field: str | None = None):
        self.code = code
        self.message = message
        self.field = field
        super().__init__(f"{field}: {message}" if field else message)

    def to_dict(self) -> dict:
        return {"code": self.code, "message": self.message, "field": self.field}


def invalid(field: str, message: str) -> PlannerError:
    return PlannerError("invalid_input", message, field)


def over_the_limit(limit_s: float, time_limit_s: float | None = None) -> str:
    """The one wording of the work a server admits, for a ``too_much_work`` refusal: ``limit_s``
    [s] of estimated work, admitted under the time limit ``time_limit_s`` [s] where that is
    larger (the estimate's margin: a run may take that much longer than its estimate)."""
    if time_limit_s is not None and time_limit_s > limit_s:
        return (f"the {limit_s:.3g} s of estimated work this server admits under its time limit of {time_limit_s:g} s "
                f"(a run may take up to {time_limit_s / limit_s:.2g}x its estimate)")
    return f"the {limit_s:.3g} s of work this server admits"
