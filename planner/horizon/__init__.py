"""The horizon problem (paper Section IV): predictions (eqs. 10-11) and the unconstrained
minimisation of the range-space criterion (eqs. 12-23) by three solvers with the same
minimiser: the paper's Householder QR, a banded KKT solve and a Riccati recursion
(compiled twin in :mod:`~planner.horizon.kernels`)."""

from .prediction import prediction_matrices
from .solvers import SOLVERS, solve_qr, solve_riccati, solve_structured, square_root_solve, stacked_system

__all__ = ["prediction_matrices", "SOLVERS", "solve_qr", "solve_riccati", "solve_structured", "square_root_solve",
           "stacked_system"]
