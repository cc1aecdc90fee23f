"""Constraint rows: what every constraint object gives, and the rows of one step.

Every constraint of the QP except the drive-force bounds is a *row*: a linear function of
the predicted states ``X`` (6N: pose and velocity of samples 1..N) and the scaled moves ``z``
(N m) between two bounds,

    lower[r] <= sum_k val[r, k] Y[col[r, k]] <= upper[r]      (at most 3 entries per row),

with ``Y = (X, z)`` (an index below ``6N`` is a state, from ``6N`` on a move), i.e. a sparse
selection ``Sel`` of the states and moves. With the prediction ``X = free + Gx z`` (eq. 11 in
the scaled moves ``z``) a row becomes ``lower - Sel_X free <= (Sel_X Gx + Sel_z) z <= upper -
Sel_X free``. Rows are scaled so that one unit is :data:`ROW_UNIT_M` of its unit (m of pose,
m/s of leg speed, m of stroke, rad of angle), which keeps the solver's tolerances
meaningful in every kind; the force-rate rows are in the scaled moves' unit (``force_max``),
like the force bounds, so that their coefficients are 1 (in newtons they were 1e4 times the
other rows' and the slack problem's DAQP solve failed on it).

A constraint object (:class:`RowConstraint`) is made for a plan (:meth:`RowConstraint.of`),
gives its :class:`RowBlock` for a step from a :class:`StepContext` (its numpy reference), and
the typed tuple of arrays its compiled twin in :mod:`planner.constraints.kernels` reads
(:attr:`RowConstraint.kernel_args`). The row constraints of the constrained mode, in row
order, are the one list of :mod:`planner.constraints.registry`; the rows of a step
(:class:`Rows`) are the blocks of all of them in that order.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import numpy as np

from ..corridor import RangeSequence
from ..model import RobotModel
from ..schema import Segment, Settings
from . import kernels as ck

__all__ = ["RELAX_M", "ROW_UNIT_M", "RowBlock", "RowConstraint", "RowKind", "Rows", "StepContext"]

#: rows are scaled so that 1 unit = this many metres before the solver sees them
ROW_UNIT_M = 1e-3
#: a QP found infeasible is solved again with its rows widened by this [m, m/s, rad; of force_max
#: for the force rates] (both backends):
#: inside the corridor margin (MARGIN_M, MARGIN_RAD: 0.2 um is left, 200 times the one-step
#: mismatch), so the actual corridor is still kept; the leg-speed margin is 5e-6 m/s
#: (the applied move is clipped back to its force-rate rows as given: issue 31)
RELAX_M = 8e-7


class RowKind(IntEnum):
    """What a row bounds; the index of the slack variable that softens it in the slack
    problem."""

    CORRIDOR = ck.KIND_CORRIDOR  #: a pose coordinate or a half-plane [m, rad]
    STROKE = ck.KIND_STROKE  #: a leg length [m]
    SPEED = ck.KIND_SPEED  #: a leg speed, or the tool's speed on arrival [m/s, rad/s]
    RATE = ck.KIND_RATE  #: a drive force's change over one sample [N]; never softened


@dataclass(slots=True, eq=False)
class StepContext:
    """What a constraint needs to give its rows of one step (``N`` samples, ``n_legs`` legs)."""

    idx: np.ndarray  #: (N,) sequence index of each sample (``min(k + j, K - 1)``)
    u_prev: np.ndarray  #: (n_legs,) the drive forces applied over the previous sample [N]
    y_nom: np.ndarray  #: (N, 3) nominal poses of the leg linearisation [m, m, rad]
    J: np.ndarray  #: (N, n_legs, 3) leg Jacobians ``J_l`` at ``y_nom``
    L: np.ndarray  #: (N, n_legs) leg lengths at ``y_nom`` [m]


@dataclass(slots=True, eq=False)
class RowBlock:
    """One constraint's rows (in metres, not yet in row units)."""

    col: np.ndarray  #: (r, c) state indices, ``c`` <= 3
    val: np.ndarray  #: (r, c) coefficients
    lower: np.ndarray  #: (r,) lower bounds (``-inf``: none)
    upper: np.ndarray  #: (r,) upper bounds
    kind: RowKind
    legs: bool = False  #: rows of the legs (speed, stroke), one per sample and leg: sample 0's are relinearised
    unit: float = ROW_UNIT_M  #: what one row unit is (the force-rate rows: in the moves' own unit, 1)


@dataclass(slots=True, eq=False)
class Rows:
    """The rows of one step (row units): ``lower <= Sel X <= upper`` with ``Sel`` given
    sparse by ``col``/``val``. The first :attr:`n_hard` rows are hard; the rest (the leg
    strokes) enter only the slack problem."""

    col: np.ndarray  #: (nrow, 3) int64 state indices, -1 where unused
    val: np.ndarray  #: (nrow, 3) coefficients, divided by ROW_UNIT_M
    lower: np.ndarray  #: (nrow,) ``b0l``
    upper: np.ndarray  #: (nrow,) ``b0u``
    kinds: np.ndarray  #: (nrow,) int64 :class:`RowKind`
    n_hard: int  #: rows given to the hard QP
    speed0: int  #: first leg-speed row (sample 0's)
    stroke0: int  #: first stroke row (sample 0's)

    @classmethod
    def stack(cls, blocks: Sequence[RowBlock], hard: Sequence[bool]) -> Rows:
        """The rows of the blocks in order, in row units; ``hard[i]``: block ``i`` is hard
        (the hard blocks come first)."""
        assert list(hard) == sorted(hard, reverse=True), "hard rows first"
        n = [len(b.lower) for b in blocks]
        starts = np.concatenate(([0], np.cumsum(n)[:-1])).astype(int)
        col = np.full((sum(n), 3), -1, np.int64)
        val = np.zeros((sum(n), 3))
        for b, r, nb in zip(blocks, starts, n):
            col[r:r + nb, :b.col.shape[1]] = b.col
            val[r:r + nb, :b.col.shape[1]] = b.val
        kinds = np.concatenate([np.full(nb, int(b.kind), np.int64) for b, nb in zip(blocks, n)])

        def first(kind: RowKind) -> int:  # the first leg row of that kind (sample 0's), -1 if none
            return next((int(r) for b, r in zip(blocks, starts) if b.kind == kind and b.legs), -1)

        unit = np.concatenate([np.full(nb, b.unit) for b, nb in zip(blocks, n)])
        return cls(col, val / unit[:, None], np.concatenate([b.lower for b in blocks]) / unit,
                   np.concatenate([b.upper for b in blocks]) / unit, kinds,
                   sum(nb for nb, h in zip(n, hard) if h), first(RowKind.SPEED), first(RowKind.STROKE))

    @property
    def n_rows(self) -> int:
        """Number of rows, hard and slack-only."""
        return len(self.lower)

    def selection(self, n_entries: int) -> np.ndarray:
        """The dense selection ``Sel`` (nrow, 6N + N m) of the states and moves (the numpy
        reference's form)."""
        Sel = np.zeros((self.n_rows, n_entries))
        r, k = np.nonzero(self.col >= 0)
        Sel[r, self.col[r, k]] = self.val[r, k]
        return Sel

    def widen(self, relax: float, only: RowKind | None = None) -> None:
        """Every hard row that is not an equality widened by ``relax`` on both sides (row
        units; ``relax * ROW_UNIT_M`` of force_max for the force-rate rows, which are in the
        scaled moves), in place: the relaxation of an infeasible step (the compiled twin is in
        ``step_kernels.constrained_step``, where the equalities are eliminated). ``only``:
        the rows of that kind alone."""
        nh = self.n_hard
        r = np.where(self.kinds[:nh] == RowKind.RATE, relax * ROW_UNIT_M, relax)
        r[self.lower[:nh] >= self.upper[:nh]] = 0.0
        if only is not None:
            r[self.kinds[:nh] != only] = 0.0
        self.lower[:nh] -= r
        self.upper[:nh] += r

    def relinearise_first_legs(self, x1: np.ndarray, r0: np.ndarray, base: np.ndarray, lmin: np.ndarray,
                               lmax: np.ndarray) -> None:
        """Sample 0's leg-speed and stroke rows at the pose ``x1[:3]`` (``kernels.first_legs``;
        the numpy twins: :meth:`LegSpeedConstraint.first_sample`,
        :meth:`LegStrokeConstraint.first_sample`)."""
        ck.first_legs(x1, r0, base, lmin, lmax, ROW_UNIT_M, self.speed0, self.stroke0, self.val, self.lower,
                      self.upper)


class RowConstraint(ABC):
    """A constraint that gives rows on the predicted states (see the module docstring)."""

    #: what its rows bound (the slack that softens them)
    kind: RowKind
    #: hard (the hard QP) or only in the slack problem
    hard: bool = True

    @classmethod
    @abstractmethod
    def of(cls, model: RobotModel, seq: RangeSequence, segments: Sequence[Segment] | None,
           st: Settings) -> RowConstraint:
        """The constraint of a plan (the robot, its range sequence, its segments if known and
        its settings); one with no rows where the plan does not ask for it."""

    @abstractmethod
    def rows(self, step: StepContext) -> RowBlock:
        """Its rows of one step, numpy (the reference of its compiled twin)."""

    @property
    @abstractmethod
    def kernel_args(self) -> NamedTuple:
        """The typed tuple its count and fill kernels read (its section of the fused
        ``assemble``, :mod:`planner.constraints.registry`)."""
