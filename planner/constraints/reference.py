"""The numpy reference assembly (``settings.backend = "reference"``): each step's QP in the
scaled moves ``z`` stated plainly, every hard row given to DAQP. Same interface as
:class:`~planner.constraints.compiled.CompiledAssembly`; tests check both give the same QP,
the same minimiser and the same plan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..corridor import RangeSequence
from ..model import RobotModel, kinematics
from ..model.plant import rk4_sample
from ..schema import Settings
from .composed import Constraints
from .qp import DenseQP, QPSolution
from .rows import RELAX_M, ROW_UNIT_M, RowKind, Rows, StepContext

__all__ = ["ReferenceAssembly", "ReferenceQP"]


@dataclass(slots=True, eq=False)
class ReferenceQP:
    """The QP of one step, numpy form (see :meth:`ReferenceAssembly.build`)."""

    x: np.ndarray  #: (6,) state at the step
    Ad: np.ndarray  #: (6, 6) discretised model (eq. 9)
    Bd: np.ndarray  #: (6, n_legs)
    rows: Rows
    P: np.ndarray  #: (N+1, 6, 6) ``Ad^q``
    Gx: np.ndarray  #: (6N, N m) prediction matrix in ``z`` (eq. 11)
    Gp2: np.ndarray  #: (3N, N m) its pose rows
    W: np.ndarray  #: (3N,) pose weights of the criterion
    tgt: np.ndarray  #: (3N,) their targets
    H: np.ndarray  #: (N m, N m) Hessian, scaled
    scale: float
    d: np.ndarray = field(default_factory=lambda: np.zeros(6))  #: (6,) one-step offset
    x1: np.ndarray = field(default_factory=lambda: np.zeros(6))  #: (6,) the plant's next state under its move
    free: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: (6N,) predicted states at ``z = 0``
    dense: DenseQP | None = None  #: the QP at the offset


class ReferenceAssembly:
    """The step's QP in numpy (see the module docstring)."""

    def __init__(self, model: RobotModel, seq: RangeSequence, st: Settings, constraints: Constraints):
        self.model, self.seq, self.constraints = model, seq, constraints
        self.N, self.n_legs = st.N, model.n_legs
        self.Ts, self.substeps = st.Ts, st.plant_substeps
        self.umax = constraints.forces.umax
        i, j = np.indices((self.N, self.N))
        self._lag = np.where(i >= j, i - j, self.N)

    def build(self, k: int, x: np.ndarray, Ad: np.ndarray, Bd: np.ndarray, y_nom: np.ndarray | None,
              u_prev: np.ndarray, u0: np.ndarray) -> ReferenceQP:
        """The condensed QP of step ``k`` in the scaled inputs ``z = u / force_max``::

            min 0.5 z'Hz + f'z   s.t.  |z| <= zmax,  bl <= A z <= bu  (rows with bl == bu: equal)

        Every row is a linear function ``Sel`` of the predicted states ``X = free + Gx z``
        (eq. 11) and the moves, so ``A = Sel_X Gx + Sel_z`` and the bounds are ``b0 - Sel_X
        free``; ``u_prev`` [N] are the forces of the previous sample (the rate rows); the one-step offset
        under the guessed move ``u0`` [N] (:meth:`set_offset`) changes ``free`` and sample 0's
        leg rows. The criterion (22)-(23) in ``z``: ``H = Gp2' W Gp2 + diag(du)``,
        ``f = Gp2' (W free_pose - tgt)``, both scaled so that ``H``'s largest diagonal entry is
        1. The legs are linearised at ``y_nom`` (N, 3), or at ``x``."""
        N, m, seq = self.N, self.n_legs, self.seq
        P = np.empty((N + 1, 6, 6))
        P[0] = np.eye(6)
        for q in range(1, N + 1):
            P[q] = Ad @ P[q - 1]
        blocks = np.zeros((N + 1, 6, m))
        blocks[:N] = P[:N] @ (Bd * self.umax)
        nz = N * m
        Gx = blocks[self._lag].transpose(0, 2, 1, 3).reshape(6 * N, nz)
        lo, hi, qa, qb, qu = seq.window(k, N)
        Gp2 = Gx.reshape(N, 6, nz)[:, :3].reshape(3 * N, nz)
        W = (qa * qa + qb * qb).ravel()
        H = (Gp2.T * W) @ Gp2
        H[np.diag_indices(nz)] += np.tile((qu[0] * self.umax) ** 2, N)
        scale = 1.0 / max(float(np.max(np.diag(H))), 1e-300)
        H *= scale
        if y_nom is None:
            y_nom = np.tile(x[:3], (N, 1))
        step = StepContext(np.minimum(np.arange(k, k + N), seq.K - 1), np.asarray(u_prev, float), y_nom,
                           kinematics.leg_jacobians(self.model, y_nom), kinematics.leg_lengths(self.model, y_nom))
        rows = Rows.stack([c.rows(step) for c in self.constraints.rows], [c.hard for c in self.constraints.rows])
        qp = ReferenceQP(x, Ad, Bd, rows, P, Gx, Gp2, W, (qa * qa * lo + qb * qb * hi).ravel(), H, scale)
        self.set_offset(qp, u0, rk4_sample(self.model, x, u0, self.Ts, self.substeps))
        return qp

    def set_offset(self, qp: ReferenceQP, u: np.ndarray, x1: np.ndarray) -> None:
        """The one-step offset ``d = Phi(x, u) - Ad x - Bd u`` (``x1 = Phi(x, u)``: the plant's
        next state under the move ``u`` [N]), sample 0's leg rows at the pose ``x1[:3]``, and
        the QP at them."""
        qp.x1 = x1
        qp.d = x1 - qp.Ad @ qp.x - qp.Bd @ u
        y1 = x1[:3]
        J0 = kinematics.leg_jacobians(self.model, y1)[0]
        self.constraints.leg_speed.first_sample(qp.rows, J0)
        self.constraints.stroke.first_sample(qp.rows, J0, kinematics.leg_lengths(self.model, y1)[0], y1)
        self._form(qp)

    def relax(self, qp: ReferenceQP, only: RowKind | None = None) -> None:
        """The hard rows (``only``: of that kind) widened by ``RELAX_M`` (:meth:`Rows.widen`),
        and the QP at them."""
        qp.rows.widen(RELAX_M / ROW_UNIT_M, only)
        self._form(qp)

    def _form(self, qp: ReferenceQP) -> None:
        """The QP at the offset ``qp.d`` and the rows ``qp.rows``."""
        N = self.N
        free = qp.P[1:] @ qp.x
        free += qp.P[:N] @ qp.d
        qp.free = free.ravel()
        f = (qp.Gp2.T @ (qp.W * free[:, :3].ravel() - qp.tgt)) * qp.scale
        Sel = qp.rows.selection(6 * N + qp.Gx.shape[1])
        SX, Sz = Sel[:, :6 * N], Sel[:, 6 * N:]
        sf = SX @ qp.free
        qp.dense = DenseQP(qp.H, f, SX @ qp.Gx + Sz, qp.rows.lower - sf, qp.rows.upper - sf, qp.rows.kinds,
                           qp.rows.n_hard, self.constraints.forces.bounds(N))

    def dense(self, qp: ReferenceQP) -> DenseQP:
        """Every row formed (the slack problem)."""
        assert qp.dense is not None  # set by build
        return qp.dense

    def solve(self, qp: ReferenceQP, start: np.ndarray | None, iter_limit: int | None = None) -> QPSolution:
        """The hard QP, every hard row given to DAQP, from the warm start ``start``
        (``iter_limit``: :meth:`DenseQP.solve_hard`)."""
        return self.dense(qp).solve_hard(start, iter_limit)

    def one_step_error(self, qp: ReferenceQP, u: np.ndarray) -> tuple[np.ndarray, float, float]:
        """The plant's next state under ``u`` [N] and how far it lands from the prediction
        ``Ad x + Bd u + d`` ([m], [rad])."""
        x1 = rk4_sample(self.model, qp.x, u, self.Ts, self.substeps)
        e = np.abs(x1 - (qp.Ad @ qp.x + qp.Bd @ u + qp.d))
        return x1, math.hypot(e[0], e[1]), float(e[2])

    def violation(self, qp: ReferenceQP, sol: QPSolution) -> float:
        """Largest hard-row violation of a hard solution [row units]."""
        return self.dense(qp).violation(sol.z)

    def finish(self, qp: ReferenceQP, z: np.ndarray, hard: QPSolution | None) -> tuple[np.ndarray, np.ndarray,
                                                                                         np.ndarray]:
        """The moves clipped to the force bounds, the predicted states (N, 6) and the nominal
        poses of the next step (the predicted poses shifted by one sample)."""
        z = np.clip(z, -1.0, 1.0)
        Xp = (qp.Gx @ z + qp.free).reshape(self.N, 6)
        return z, Xp, np.vstack((Xp[1:, :3], Xp[-1:, :3]))
