"""The QP of one step, compiled form: typed data around the kernels of
:mod:`planner.constraints.kernels`, with the screened solves.

The QP of a step, in the scaled moves ``z = u / force_max`` (N m) over the horizon::

    min 0.5 z'Hz + f'z   s.t.  -1 <= z <= 1,  lower <= Sel X <= upper,  X = free + Gx z

(:class:`FullQP`: the prediction ``Gx`` of eq. 11, the criterion (22)-(23) in ``z`` as
``H, f``, the rows of :class:`~planner.constraints.rows.Rows`). Two reformulations shrink
what DAQP is given without changing the minimiser:

* **equalities eliminated** (:class:`ReducedQP`): a point range (psi = 0 along Table I: one
  equality per sample) is an equality row, which costs DAQP about as much as the rest of the
  solve together. Where a sample has equalities, its move is parametrised on the null space
  of their one-step effect, ``z_i = Z_i w_i + K_i (c_i - C_i Y_i)``
  (``kernels.reduce_setup``); the QP in ``w`` has fewer variables and no equalities, its
  force bounds become rows. Used wherever a step has equalities that can be eliminated,
  the QP in ``z`` elsewhere;
* **rows screened**: DAQP gets only the rows within :data:`SCREEN_ROWS` of a bound at the
  warm start (and forces within :data:`SCREEN_FORCE` of ``force_max``); at its solution every
  row is checked, and a violated one is added and the QP solved again (1 of 240 steps on
  Table I). A solution of fewer rows that meets all rows solves the whole QP (the same unique
  minimiser), so this changes only the time. The rows given stay given for the step's
  refinements.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import kernels as ck
from .qp import DenseQP, QPSolution, solve_qp
from .rows import Rows

__all__ = ["SCREEN_FORCE", "SCREEN_ROWS", "SCREEN_TOL", "FullQP", "ReducedQP", "StepQP"]

#: the solver gets only the rows within this of a bound (row units: mm, mm of stroke, mm/s of
#: leg speed, by row kind: corridor, stroke, speed) at the warm start's prediction, and the
#: equalities; rows violated at its solution by more than SCREEN_TOL are added and it re-solves
SCREEN_ROWS = (1.0, 1.0, 50.0)
SCREEN_TOL = 1e-9
#: with the equalities eliminated the force bounds are rows too: given to the solver where
#: the warm start's force is within this fraction of force_max of the bound
SCREEN_FORCE = 0.2
_SCREEN = np.array(SCREEN_ROWS, float)  # by RowKind


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
    keep: np.ndarray | None = None  #: (n_hard,) the rows given to DAQP (screening), once screened

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

    def dense(self, rows: Rows) -> DenseQP:
        """Every row formed: ``A = Sel Gx`` (``kernels.constraint_matrix``)."""
        A = np.empty((rows.n_rows, self.Gx.shape[1]))
        ck.constraint_matrix(rows.col, rows.val, self.Gx, A)
        return DenseQP(self.H, self.f, A, self.lower, self.upper, rows.kinds, rows.n_hard)

    def solve(self, rows: Rows, start: np.ndarray | None) -> QPSolution:
        """The hard QP, screened and checked (module docstring), from the warm start
        ``start`` (scaled moves, or None)."""
        X = np.empty(self.Gx.shape[0])
        keep = self.keep
        if keep is None:  # rows near a bound at the warm start's prediction
            ck.predict(self.Gx, self.free, start if start is not None else np.zeros(self.Gx.shape[1]), X)
            keep = self.keep = rows.screen(X, _SCREEN)
        iterations = 0
        while True:
            A, bu, bl, sense = ck.solver_problem(keep, rows.col, rows.val, self.Gx, self.lower, self.upper)
            sol = solve_qp(self.H, self.f, A, bu, bl, sense, start)
            iterations += sol.iterations
            if not sol.ok:  # fewer rows infeasible: the whole QP is too
                break
            ck.predict(self.Gx, self.free, sol.z, X)
            worst, added = rows.check(X, keep, SCREEN_TOL)
            if added == 0:
                sol.states, sol.violation = X, worst
                break
            start = sol.z
        sol.iterations = iterations
        return sol


@dataclass(slots=True, eq=False)
class ReducedQP:
    """The step's QP with its equalities eliminated (module docstring; ``kernels.reduce_setup``
    explains the parametrisation): variables ``w`` (``n_w``), moves ``z_i = Z_i w_i + K_i
    (c_i - C_i Y_i)``, states ``X = X_free + G w``. The fields from :attr:`z_free` on depend on
    the one-step offset (:meth:`set_free`)."""

    n_w: int  #: number of variables
    offsets: np.ndarray  #: (N+1,) first variable of sample i's ``w_i``
    eq_count: np.ndarray  #: (N,) number of equalities of sample i
    eq_axis: np.ndarray  #: (N, 3) the pose coordinates they fix
    eq_value: np.ndarray  #: (N, 3) and their values [m, rad]
    K: np.ndarray  #: (N, m, 3) ``(C_i Bu)^+``
    Z: np.ndarray  #: (N, m, m) null-space basis of ``C_i Bu`` (first columns used)
    A_closed: np.ndarray  #: (N, 6, 6) closed-loop transition ``Ad + Bu L_i``
    L: np.ndarray  #: (N, m, 6) ``-K_i C_i Ad``
    G: np.ndarray  #: (6N, n_w) closed-loop prediction
    H: np.ndarray  #: (n_w, n_w) Hessian, scaled
    scale: float  #: that scale
    eliminated: np.ndarray  #: (nrow,) rows replaced by the parametrisation
    Bu: np.ndarray  #: (6, m) ``Bd diag(umax)``
    z_free: np.ndarray  #: (N m,) moves at ``w = 0``
    X_free: np.ndarray  #: (6N,) states at ``w = 0``
    f: np.ndarray  #: (n_w,) linear term, scaled
    lower: np.ndarray  #: (nrow,) row bounds minus ``Sel X_free``
    upper: np.ndarray
    keep: np.ndarray | None = None  #: (n_hard,) rows given to DAQP, once screened
    keep_force: np.ndarray | None = None  #: (N m,) force bounds given to DAQP (as rows), once screened

    @classmethod
    def setup(cls, Ad: np.ndarray, Bd: np.ndarray, umax: np.ndarray, du: np.ndarray, x: np.ndarray, d: np.ndarray,
              W: np.ndarray, tgt: np.ndarray, rows: Rows) -> ReducedQP | None:
        """The reduced QP of the rows' equalities (``du``: move weight per drive) at the
        offset ``d``, or None where there is none or one cannot be eliminated (then the QP in
        ``z`` is solved)."""
        N = len(W) // 3
        (ok, n_w, offsets, eq_count, eq_axis, eq_value, K, Z, A_closed, L, G, H, scale, eliminated,
         Bu) = ck.reduce_setup(Ad, Bd, umax, W, du, rows.col, rows.val, rows.lower, rows.upper, rows.n_hard, N)
        if not ok:
            return None
        z_free, X_free, f, lower, upper = ck.reduce_free(x, d, Ad, Bu, eq_count, eq_axis, eq_value, K, Z, A_closed, L,
                                                         G, offsets, W, tgt, du, scale, rows.col, rows.val,
                                                         rows.lower, rows.upper)
        return cls(int(n_w), offsets, eq_count, eq_axis, eq_value, K, Z, A_closed, L, G, H, scale, eliminated, Bu,
                   z_free, X_free, f, lower, upper)

    def set_free(self, x: np.ndarray, d: np.ndarray, Ad: np.ndarray, W: np.ndarray, tgt: np.ndarray, du: np.ndarray,
                 rows: Rows) -> None:
        """The parts at the offset ``d`` (``kernels.reduce_free``)."""
        self.z_free, self.X_free, self.f, self.lower, self.upper = ck.reduce_free(
            x, d, Ad, self.Bu, self.eq_count, self.eq_axis, self.eq_value, self.K, self.Z, self.A_closed, self.L,
            self.G, self.offsets, W, tgt, du, self.scale, rows.col, rows.val, rows.lower, rows.upper)

    def forward(self, x: np.ndarray, d: np.ndarray, Ad: np.ndarray, w: np.ndarray, z: np.ndarray,
                X: np.ndarray) -> None:
        """Moves ``z`` and states ``X`` at ``w``, into the given arrays (``kernels.reduce_forward``)."""
        ck.reduce_forward(x, d, Ad, self.Bu, self.eq_count, self.eq_axis, self.eq_value, self.K, self.Z, self.offsets,
                          w, z, X)

    def solve(self, x: np.ndarray, d: np.ndarray, Ad: np.ndarray, rows: Rows, start: np.ndarray | None) -> QPSolution:
        """The reduced QP, screened and checked as :meth:`FullQP.solve`, every row and force
        bound checked at the solution. Returns the moves ``z`` (not ``w``)."""
        m = self.Bu.shape[1]
        nz, nx, nh = len(self.eq_count) * m, 6 * len(self.eq_count), rows.n_hard
        ws = ck.reduce_start(start, self.Z, self.offsets, m) if start is not None else None
        keep, keep_force = self.keep, self.keep_force
        if keep is None or keep_force is None:  # rows near a bound at the warm start
            if ws is not None:
                z, X = np.empty(nz), np.empty(nx)
                self.forward(x, d, Ad, ws, z, X)
            else:
                z, X = self.z_free, self.X_free
            keep, keep_force = self.keep, self.keep_force = np.zeros(nh, bool), np.zeros(nz, bool)
            ck.reduce_screen(rows.col, rows.val, rows.lower, rows.upper, rows.kinds, nh, self.eliminated, X, z,
                             _SCREEN, SCREEN_FORCE, keep, keep_force)
        z, X = np.empty(nz), np.empty(nx)
        iterations = 0
        while True:
            A, bu, bl, sense = ck.reduce_problem(keep, keep_force, rows.col, rows.val, self.G, self.offsets, self.L,
                                                 self.Z, self.eq_count, self.z_free, self.lower, self.upper, m)
            sol = solve_qp(self.H, self.f, A, bu, bl, sense, ws)
            iterations += sol.iterations
            if not sol.ok:  # fewer rows infeasible: the whole QP is too
                return QPSolution(np.zeros(nz), sol.flag, iterations)
            self.forward(x, d, Ad, sol.z, z, X)
            worst, added = ck.reduce_check(rows.col, rows.val, rows.lower, rows.upper, nh, self.eliminated, X, z,
                                           keep, keep_force, SCREEN_TOL)
            if added == 0:
                return QPSolution(z, sol.flag, iterations, X, worst)
            ws = sol.z


@dataclass(slots=True, eq=False)
class StepQP:
    """The QP of one step, compiled form: the model and rows of the step at the one-step
    offset, the reduced QP where the equalities are eliminated, the QP in ``z`` where needed
    (formed on first use)."""

    x: np.ndarray  #: (6,) state at the step
    Ad: np.ndarray  #: (6, 6) discretised model (eq. 9)
    Bd: np.ndarray  #: (6, n_legs)
    W: np.ndarray  #: (3N,) pose weights of the criterion
    tgt: np.ndarray  #: (3N,) their targets
    rows: Rows
    d: np.ndarray  #: (6,) one-step offset (see the controller)
    x1: np.ndarray  #: (6,) the plant's next state under the move of ``d``
    reduced: ReducedQP | None
    full: FullQP | None = None
