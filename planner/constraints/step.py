"""The QP of one step, compiled form: typed data around the kernels of
:mod:`planner.constraints.dense_kernels`.

The QP of a step, in the scaled moves ``z = u / force_max`` (N m) over the horizon::

    min 0.5 z'Hz + f'z   s.t.  -1 <= z <= 1,  lower <= Sel Y <= upper,  Y = (X, z),  X = free + Gx z

(:class:`FullQP`: the prediction ``Gx`` of eq. 11, the criterion (22)-(23) in ``z`` as
``H, f``, the rows of :class:`~planner.constraints.rows.Rows` on the states and moves). The
controller solves it by the stage-wise dual active-set method
(:mod:`planner.constraints.stagewise`, compiled in :mod:`planner.constraints.step_kernels`);
this dense form, every row given to DAQP, is its fallback (a step the stage-wise solve does
not finish) and the slack problem's (:meth:`~planner.constraints.qp.DenseQP.solve_slack`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import dense_kernels as ck
from .qp import DenseQP, QPSolution, factor, rows_ldp
from .rows import Rows

__all__ = ["FullQP", "StepQP"]


@dataclass(slots=True, eq=False)
class FullQP:
    """The step's QP in ``z`` (module docstring), compiled: the parts that depend on the
    model only, and those that depend on the one-step offset ``d`` (:meth:`set_free`)."""

    P: np.ndarray  #: (N+1, 6, 6) ``Ad^q``
    Gx: np.ndarray  #: (6N, N m) prediction matrix in ``z`` (eq. 11)
    H: np.ndarray  #: (N m, N m) Hessian, scaled (largest diagonal entry 1)
    scale: float  #: that scale
    free: np.ndarray  #: (6N,) predicted states at ``z = 0``
    f: np.ndarray  #: (N m,) linear term, scaled
    lower: np.ndarray  #: (nrow,) row bounds minus ``Sel free``
    upper: np.ndarray
    #: ``R^-1`` of ``H = R'R`` (:func:`~planner.constraints.qp.factor`), formed on the first
    #: DAQP solve and kept for the step's others (the relaxed solves, the refinements, the
    #: slack problem): DAQP gets the least-distance form (:class:`DenseQP`)
    Rinv: np.ndarray | None = None
    #: the last rows formed (``A``) and ``A R^-1``: a relaxed solve changes only the bounds
    rows_ldp: tuple[np.ndarray, np.ndarray] | None = None

    @classmethod
    def form(cls, Ad: np.ndarray, Bd: np.ndarray, umax: np.ndarray, du: np.ndarray, x: np.ndarray, d: np.ndarray,
             W: np.ndarray, tgt: np.ndarray, rows: Rows) -> FullQP:
        """Prediction and Hessian (``kernels.prediction``, ``kernels.hessian``) of the model
        ``Ad, Bd``, force limits ``umax`` [N], move weights ``du`` (N m,) and pose weights
        ``W`` (3N,), and the parts at the offset ``d`` (:meth:`set_free`)."""
        N, nz = len(W) // 3, len(du)
        P, Gx, H = np.empty((N + 1, 6, 6)), np.empty((6 * N, nz)), np.empty((nz, nz))
        ck.prediction(Ad, Bd, umax, P, Gx)
        scale = ck.hessian(Ad, Bd, umax, W, du, H)
        free, f, lower, upper = ck.free_parts(P, x, d, Gx, W, tgt, rows.col, rows.val, rows.lower, rows.upper)
        return cls(P, Gx, H, scale, free, f * scale, lower, upper)

    def set_free(self, x: np.ndarray, d: np.ndarray, W: np.ndarray, tgt: np.ndarray, rows: Rows) -> None:
        """The parts at the free response ``free = P[1:] x + P[:N] d`` (``kernels.free_parts``)."""
        self.free, f, self.lower, self.upper = ck.free_parts(self.P, x, d, self.Gx, W, tgt, rows.col, rows.val,
                                                             rows.lower, rows.upper)
        self.f = f * self.scale

    def predict(self, z: np.ndarray) -> np.ndarray:
        """The predicted states ``X = free + Gx z`` (6N,)."""
        X = np.empty(self.Gx.shape[0])
        ck.predict(self.Gx, self.free, z, X)
        return X

    def dense(self, rows: Rows, zmax: np.ndarray) -> DenseQP:
        """Every row formed: ``A = Sel_X Gx + Sel_z`` (``kernels.constraint_matrix``); the
        moves' bounds ``|z| <= zmax``."""
        A = np.empty((rows.n_rows, self.Gx.shape[1]))
        ck.constraint_matrix(rows.col, rows.val, self.Gx, A)
        if self.Rinv is None:
            self.Rinv = factor(self.H)
        if self.rows_ldp is None or not np.array_equal(self.rows_ldp[0], A):
            self.rows_ldp = (A, rows_ldp(A, self.Rinv))
        return DenseQP(self.H, self.f, A, self.lower, self.upper, rows.kinds, rows.n_hard, zmax, self.Rinv,
                       self.rows_ldp[1])

    def solve(self, rows: Rows, zmax: np.ndarray, start: np.ndarray | None,
              iter_limit: int | None = None) -> QPSolution:
        """The hard QP, every hard row given to DAQP, from the warm start ``start``; the
        predicted states at its solution in ``states``, its largest row violation in
        ``violation``. ``iter_limit``: :meth:`DenseQP.solve_hard`."""
        dense = self.dense(rows, zmax)
        sol = dense.solve_hard(start, iter_limit)
        if sol.ok:
            sol.states = self.predict(sol.z)
            sol.violation = dense.violation(sol.z)
        return sol


@dataclass(slots=True, eq=False)
class StepQP:
    """The QP of one step, compiled form: the model and rows of the step at the one-step
    offset, and the QP in ``z`` (formed on first use)."""

    x: np.ndarray  #: (6,) state at the step
    Ad: np.ndarray  #: (6, 6) discretised model (eq. 9)
    Bd: np.ndarray  #: (6, n_legs)
    W: np.ndarray  #: (3N,) pose weights of the criterion
    tgt: np.ndarray  #: (3N,) their targets
    rows: Rows
    d: np.ndarray  #: (6,) one-step offset (see the controller)
    x1: np.ndarray  #: (6,) the plant's next state under the move of ``d``
    full: FullQP | None = None
