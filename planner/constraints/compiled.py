"""The compiled assembly (``settings.backend = "compiled"``): each step in one compiled call
(:func:`planner.constraints.step_kernels.constrained_step`: the rows by the registry's fused
assembly of the kernels of :mod:`planner.constraints.kernels`, the QP solved by the stage-wise dual active-set method of
:mod:`planner.constraints.stagewise`), and the same step on the Python path (the dense QP,
every row given to DAQP: :mod:`planner.constraints.step`) where that call does not finish
it. Same interface as :class:`~planner.constraints.reference.ReferenceAssembly`, the numpy
reference; the controller picks one of the two at construction.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..corridor import RangeSequence
from ..model import RobotModel
from ..schema import Settings
from . import kernels as ck
from .composed import Constraints
from .qp import DenseQP, QPSolution
from .registry import SECTIONS
from .registry import assemble as fused_assemble
from .rows import RELAX_M, ROW_UNIT_M, RowKind, Rows
from .stagewise import DEPENDENT_TOL, SOLVE_TOL, WARM_TOL
from .step import FullQP, StepQP
from .step_kernels import PROOF_FIELDS, constrained_step

__all__ = ["ITERATIONS_PER_MOVE", "KERNEL_SECTIONS", "MAX_ITERATIONS", "RELAX_M", "AssemblyInputs", "CompiledAssembly",
           "StepOutcome"]

#: most active-set changes of one stage-wise solve before the step goes to DAQP: this many, or
#: :data:`ITERATIONS_PER_MOVE` per scaled move of the horizon (``N n_legs``) where that is more
MAX_ITERATIONS = 400
#: (issue 31: a 6-leg robot at N 100, 600 moves, arriving at rest under its force-rate limits
#: took 400-800 active-set changes a step; at 400 the last 22 steps before the end point and 3
#: earlier ones went to the Python path, 1.2-2.5 s each on DAQP's slack problem, 54-76x the
#: work estimate; with this all 600 steps are solved compiled, 3.7x less CPU)
ITERATIONS_PER_MOVE = 4

#: the row constraints the fused ``registry.assemble`` takes, in its (the row) order: the registry's
KERNEL_SECTIONS = tuple(s.row_class for s in SECTIONS)


@dataclass(frozen=True, eq=False)
class AssemblyInputs:
    """What the fused ``registry.assemble`` reads that does not change during a plan."""

    N: int  #: horizon [samples]
    K: int  #: samples of the range sequence
    lower: np.ndarray  #: (K + N, 3) ``r_a`` per sample, the last repeated N times (as ``RangeSequence.window``)
    upper: np.ndarray  #: (K + N, 3) ``r_b``
    qa: np.ndarray  #: (K + N, 3) diagonals of ``Q_ra``
    qb: np.ndarray  #: (K + N, 3) diagonals of ``Q_rb``
    r0: np.ndarray  #: (n_legs, 2) platform pivots relative to the tool point [m]
    base: np.ndarray  #: (n_legs, 2) base pivots [m]
    lmin: np.ndarray  #: (n_legs,) shortest leg lengths [m] (sample 0's stroke rows, ``kernels.first_legs``)
    lmax: np.ndarray  #: (n_legs,) longest
    sections: tuple  #: the row constraints' ``kernel_args`` as plain tuples, in row order

    @classmethod
    def of(cls, model: RobotModel, seq: RangeSequence, N: int, constraints: Constraints) -> AssemblyInputs:
        """The inputs of a plan: its range sequence, the legs and the row constraints (one of
        each of :data:`KERNEL_SECTIONS`, in that order)."""
        if tuple(type(c) for c in constraints.rows) != KERNEL_SECTIONS:
            raise TypeError("the compiled assembly fuses the rows of "
                            f"{', '.join(c.__name__ for c in KERNEL_SECTIONS)}, in this order")
        args = tuple(c.kernel_args for c in constraints.rows)
        for s, a in zip(SECTIONS, args):
            if type(a) is not s.args:
                raise TypeError(f"{s.row_class.__name__}.kernel_args gives {type(a).__name__}, not {s.args.__name__}")
        sections = tuple(tuple(a) for a in args)  # plain: they unbox fastest (registry.typed_sections)

        def pad(a: np.ndarray) -> np.ndarray:
            return np.ascontiguousarray(np.concatenate((a, np.repeat(a[-1:], N, axis=0))), dtype=float)

        return cls(N, seq.K, pad(seq.lower), pad(seq.upper), pad(seq.qa), pad(seq.qb),
                   np.ascontiguousarray(model.r0, dtype=float), np.ascontiguousarray(model.base, dtype=float),
                   constraints.stroke.lmin, constraints.stroke.lmax, sections)

    @property
    def kernel_inputs(self) -> tuple:
        """The constant inputs of the compiled step (``step_kernels.constrained_step``'s
        ``inputs``): ``K``, the padded range sequence, the legs, their strokes and the
        sections' tuples."""
        return (self.K, self.lower, self.upper, self.qa, self.qb, self.r0, self.base, self.lmin, self.lmax,
                self.sections)

    def assemble(self, k: int, x: np.ndarray, y_prev: np.ndarray,
                 u_prev: np.ndarray) -> tuple[np.ndarray, np.ndarray, Rows]:
        """The criterion's weights and targets (3N,) and the rows of step ``k`` at state ``x``,
        the legs linearised at ``y_prev`` (N, 3) (or at ``x``: ``y_prev`` empty), the forces
        applied over the previous sample ``u_prev`` [N]."""
        W, tgt, col, val, lower, upper, kinds, n_hard, speed0, stroke0 = fused_assemble(
            k, self.N, x, y_prev, u_prev, ROW_UNIT_M, self.K, self.lower, self.upper, self.qa, self.qb, self.r0,
            self.base, self.sections)
        return W, tgt, Rows(col, val, lower, upper, kinds, int(n_hard), int(speed0), int(stroke0))


@dataclass(slots=True, eq=False)
class StepOutcome:
    """A step done by :meth:`CompiledAssembly.step`."""

    status: int  #: 1 solved; otherwise the step is to be done on the Python path
    Y: np.ndarray  #: (6N + N m,) the solution ``(X, z)`` as solved
    z: np.ndarray  #: (N m,) scaled moves, clipped to the force bounds
    X: np.ndarray  #: (N, 6) predicted states
    y_nom: np.ndarray  #: (N, 3) nominal poses of the next step
    iterations: int  #: active-set changes
    refinements: int  #: re-solves at a refined offset
    violation: float  #: largest row violation at the solution [row units]
    relaxed: bool  #: solved with the rows widened by RELAX_M


class CompiledAssembly:
    """The step's QP by the compiled kernels (see the module docstring)."""

    #: solve a step after a proved-infeasible one first on the rows of that proof
    #: (``step_kernels.constrained_step``); off: every step's hard QP on all its rows (the
    #: same plans: ``tests/test_relaxed_proof.py`` compares them)
    carry_proof: ClassVar[bool] = True

    def __init__(self, model: RobotModel, seq: RangeSequence, st: Settings, constraints: Constraints):
        self.N = st.N
        self.Ts, self.substeps = st.Ts, st.plant_substeps
        self.packed = model.packed
        self.umax = constraints.forces.umax
        #: the bounds of the scaled moves (1, and 1 - FORCE_RECOURSE after the first move)
        self.zmax = constraints.forces.bounds(self.N)
        #: move weight per drive ``(q_u force_max)^2``, and per move of the horizon
        self.du = np.ascontiguousarray((np.asarray(seq.qu, float) * self.umax) ** 2)
        self.du_moves = np.tile(self.du, self.N)
        self.inputs = AssemblyInputs.of(model, seq, self.N, constraints)
        self._legs = (self.inputs.r0, self.inputs.base, self.inputs.lmin, self.inputs.lmax)
        self._no_poses = np.zeros((0, 3))
        self._no_warm = np.zeros(0)
        self._kernel_inputs = self.inputs.kernel_inputs
        nz = self.N * model.n_legs
        #: the stage-wise solve's iteration limit (:data:`MAX_ITERATIONS`, :data:`ITERATIONS_PER_MOVE`)
        self.max_iterations = max(MAX_ITERATIONS, ITERATIONS_PER_MOVE * nz)
        #: the dual method's work space: a response per active row, and the Cholesky factor
        self._V = np.empty((nz + 1, 6 * self.N + nz))
        self._Lm = np.empty((nz + 1, nz + 1))
        #: the rows that proved the last step's hard QP infeasible, for the next step
        #: (``step_kernels.record_proof``: a count, then PROOF_FIELDS integers per row of the
        #: active set and the violated row; empty where :attr:`carry_proof` is off)
        self.proof = np.zeros(1 + PROOF_FIELDS * (nz + 2) if self.carry_proof else 0, np.int64)

    def step_constants(self, refine_tol: tuple[float, float], refine_max: int) -> tuple:
        """The arguments of :func:`~planner.constraints.step_kernels.constrained_step` from
        ``umax`` on (the same for every step of a plan)."""
        return (self.umax, self.zmax, self.du, ROW_UNIT_M, self.N, refine_tol[0], refine_tol[1], refine_max, SOLVE_TOL,
                DEPENDENT_TOL, WARM_TOL, RELAX_M / ROW_UNIT_M, self.max_iterations, self._V, self._Lm, self.proof,
                self._kernel_inputs)

    def step(self, k: int, x: np.ndarray, Ad: np.ndarray, Bd: np.ndarray, y_nom: np.ndarray | None,
             u_prev: np.ndarray, u0: np.ndarray, warm: np.ndarray | None, refine_tol: tuple[float, float],
             refine_max: int) -> StepOutcome:
        """Step ``k`` in one compiled call (module docstring): rows at the nominal poses
        ``y_nom`` (or at ``x``) and after the forces ``u_prev`` [N] of the previous sample,
        warm-started from ``warm`` (the previous solution shifted, or None), offset under the
        guessed move ``u0`` [N], refined while the plant lands farther than ``refine_tol``
        (m, rad) from the prediction."""
        out = constrained_step(k, np.ascontiguousarray(x, dtype=float), Ad, Bd,
                               y_nom if y_nom is not None else self._no_poses, u_prev,
                               np.ascontiguousarray(u0, dtype=float), warm if warm is not None else self._no_warm,
                               self.packed, self.Ts, self.substeps, *self.step_constants(refine_tol, refine_max))
        status, Y, z, X, y_next, iterations, refinements, worst, relaxed = out
        return StepOutcome(int(status), Y, z, X, y_next, int(iterations), int(refinements), float(worst),
                           bool(relaxed))

    def build(self, k: int, x: np.ndarray, Ad: np.ndarray, Bd: np.ndarray, y_nom: np.ndarray | None,
              u_prev: np.ndarray, u0: np.ndarray) -> StepQP:
        """The QP of step ``k`` at state ``x`` and model ``Ad, Bd``: the rows and criterion
        (legs linearised at ``y_nom``, or at ``x``), the one-step offset under the guessed move
        ``u0`` [N] (:meth:`set_offset`)."""
        x = np.ascontiguousarray(x, dtype=float)
        W, tgt, rows = self.inputs.assemble(k, x, y_nom if y_nom is not None else self._no_poses, u_prev)
        x1 = ck.plant_step(self.packed, x, np.ascontiguousarray(u0, dtype=float), self.Ts, self.substeps)
        d = ck.offset(x1, x, u0, Ad, Bd)
        rows.relinearise_first_legs(x1, *self._legs)
        return StepQP(x, Ad, Bd, W, tgt, rows, d, x1)

    def set_offset(self, qp: StepQP, u: np.ndarray, x1: np.ndarray) -> None:
        """The one-step offset ``d = Phi(x, u) - Ad x - Bd u`` (``x1 = Phi(x, u)``: the plant's
        next state under the move ``u`` [N]), sample 0's leg rows at ``x1``, and the parts of
        the QP that depend on them."""
        qp.x1 = x1
        qp.d = ck.offset(x1, qp.x, u, qp.Ad, qp.Bd)
        qp.rows.relinearise_first_legs(x1, *self._legs)
        if qp.full is not None:
            qp.full.set_free(qp.x, qp.d, qp.W, qp.tgt, qp.rows)

    def relax(self, qp: StepQP, only: RowKind | None = None) -> None:
        """The hard rows (``only``: of that kind) widened by :data:`RELAX_M`
        (:meth:`Rows.widen`), and the QP at them."""
        qp.rows.widen(RELAX_M / ROW_UNIT_M, only)
        if qp.full is not None:
            qp.full.set_free(qp.x, qp.d, qp.W, qp.tgt, qp.rows)

    def full(self, qp: StepQP) -> FullQP:
        """The QP in ``z``, formed on first use."""
        if qp.full is None:
            qp.full = FullQP.form(qp.Ad, qp.Bd, self.umax, self.du_moves, qp.x, qp.d, qp.W, qp.tgt, qp.rows)
        return qp.full

    def solve(self, qp: StepQP, start: np.ndarray | None, iter_limit: int | None = None) -> QPSolution:
        """The hard QP from the warm start ``start`` (scaled moves), every row given to DAQP
        (the Python path of a step; ``iter_limit``: :meth:`DenseQP.solve_hard`)."""
        return self.full(qp).solve(qp.rows, self.zmax, start, iter_limit)

    def one_step_error(self, qp: StepQP, u: np.ndarray) -> tuple[np.ndarray, float, float]:
        """The plant's next state under ``u`` [N] and how far it lands from the prediction
        ``Ad x + Bd u + d`` ([m], [rad])."""
        return ck.one_step_error(self.packed, qp.x, u, qp.Ad, qp.Bd, qp.d, self.Ts, self.substeps)

    def dense(self, qp: StepQP) -> DenseQP:
        """Every row formed (the slack problem)."""
        return self.full(qp).dense(qp.rows, self.zmax)

    def violation(self, qp: StepQP, sol: QPSolution) -> float:
        """Largest hard-row violation of a hard solution [row units] (checked by the solve)."""
        return sol.violation

    def finish(self, qp: StepQP, z: np.ndarray, hard: QPSolution | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The moves ``z`` clipped to the force bounds, the predicted states (N, 6) and the
        nominal poses of the next step."""
        X = self.full(qp).predict(np.clip(z, -1.0, 1.0))
        return ck.finish(z, X)
