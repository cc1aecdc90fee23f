"""The constrained mode (beyond the paper): the range-space criterion with hard corridor,
drive-force, leg-speed, stroke and no-overshoot constraints, solved every sample as a
quadratic program (DAQP)."""

from .controller import CONTAIN_TOL_M, END_TOL_M, END_TOL_RAD, MARGIN_M, ConstrainedController, PoseSets

__all__ = ["ConstrainedController", "PoseSets", "CONTAIN_TOL_M", "END_TOL_M", "END_TOL_RAD", "MARGIN_M"]
