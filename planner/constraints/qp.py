"""The solver: one wrapper around DAQP, and the dense QP of a step (hard and slack).

DAQP (a dual active-set solver for dense QPs) was chosen by ``benchmarks/bench_qp.py`` over
OSQP, ProxSuite and Clarabel. Every DAQP call of the constrained mode goes through
:func:`solve_qp`.

Infeasibility. If the hard QP has no solution (e.g. limits too tight for the requested time),
the step is solved again with the corridor, stroke and speed rows softened by three slack
variables (corridor m, stroke m, leg speed m/s; :meth:`DenseQP.solve_slack`) with a large
quadratic + linear penalty; forces stay hard. What the controller does with the slack is
described in :mod:`planner.constraints.controller`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ARRIVAL_SLACK_WEIGHT", "DAQP_SETTINGS", "RETRY_FLAGS", "RETRY_SETTINGS", "SLACK_ITER_LIMIT", "SLACK_RHO1",
           "SLACK_RHO2", "DenseQP",
           "QPSolution", "solve_qp"]

#: DAQP's tolerances (rows in row units: 1e-9 of a millimetre) and iteration limit
DAQP_SETTINGS = {"primal_tol": 1e-9, "dual_tol": 1e-12, "iter_limit": 2000}
#: the slack problem's iteration limit: far outside the corridor hundreds of rows are
#: violated and DAQP needs thousands of iterations (2000-9000 measured)
SLACK_ITER_LIMIT = 20000
#: DAQP exit flags of a numerical failure (cycling, a singular factorisation, an overdetermined
#: start) after which the slack problem is solved again with each of :data:`RETRY_SETTINGS`
RETRY_FLAGS = (-2, -5, -6)
#: DAQP settings tried in turn after a numerical failure of the slack problem (issue 31: at Ts
#: 2 ms the slack problems of the samples before the end point cycled; the primal tolerance of
#: 1e-7 row units, 1e-10 m, solved them in a sixth of the iterations, a larger cycle tolerance
#: in 4x; proximal regularisation, ``eps_prox``, cycled too)
RETRY_SETTINGS: tuple[dict, ...] = ({"primal_tol": 1e-7}, {"cycle_tol": 1000})
#: penalty weights of the slack variables (relative to the scaled criterion, which is O(1))
SLACK_RHO2 = 1e8
SLACK_RHO1 = 1e6
#: the arrival rows' slack (a fourth variable) costs this fraction of the others: a robot
#: displaced from the end point by an infeasible step cannot be back in the stop box and slower
#: than the arrival speed (0.1 mm/s) at once, and with the arrival rows softened like the leg
#: speeds (1 mm/s of slack costing as much as 1 mm of corridor) every move back cost ~100x
#: the corridor slack it saved over a sample: the plan stood still 0.39 mm off the end point
#: until its tail ran out (issue 20); at this weight it moves back as fast as the drives allow
ARRIVAL_SLACK_WEIGHT = 1e-3
#: sense of an equality row for DAQP
EQUALITY = 5


@dataclass(slots=True, eq=False)
class QPSolution:
    """A solution of the step's QP (or of a smaller one standing for it)."""

    z: np.ndarray  #: the minimiser (scaled moves; with the slacks after them in the slack problem)
    flag: int  #: DAQP's exit flag (>= 1: solved)
    iterations: int  #: DAQP iterations, summed over the solves it took
    states: np.ndarray | None = None  #: (6N,) predicted states at ``z`` where the solve formed them
    violation: float = 0.0  #: largest violation of the hard rows at ``z`` [row units], if checked

    @property
    def ok(self) -> bool:
        """Whether the QP was solved."""
        return self.flag >= 1


def solve_qp(H: np.ndarray, f: np.ndarray, A: np.ndarray, upper: np.ndarray, lower: np.ndarray,
             sense: np.ndarray, start: np.ndarray | None = None, iter_limit: int | None = None,
             retry: dict | None = None) -> QPSolution:
    """``min 0.5 x'Hx + f'x`` s.t. ``lower <= (x_bounds, A x) <= upper`` by DAQP with
    :data:`DAQP_SETTINGS`: the first ``len(upper) - len(A)`` entries of the bounds are simple
    bounds on ``x``, the rest bound the rows of ``A``; ``sense`` per bound (0, or
    :data:`EQUALITY`); ``start``: a primal warm start; ``iter_limit``: instead of the setting's."""
    kw = dict(DAQP_SETTINGS)
    if iter_limit is not None:
        kw["iter_limit"] = iter_limit
    if retry:
        kw.update(retry)
    if start is not None:
        kw["primal_start"] = start
    import daqp  # loaded on first use: the compiled stage-wise solve rarely falls back to it

    x, _, flag, info = daqp.solve(H, f, A, upper, lower, sense, **kw)
    return QPSolution(x, int(flag), int(info["iterations"]))


@dataclass(slots=True, eq=False)
class DenseQP:
    """The step's QP in the scaled moves ``z = u / force_max``, every row formed::

        min 0.5 z'Hz + f'z   s.t.  -zmax <= z <= zmax,  lower <= A z <= upper  (lower == upper: equality)

    The first :attr:`n_hard` rows are hard; the rest (leg strokes) enter only the slack
    problem. Rows in row units (``ROW_UNIT_M``)."""

    H: np.ndarray  #: (nz, nz) Hessian, scaled (largest diagonal entry 1)
    f: np.ndarray  #: (nz,) linear term, scaled the same way
    A: np.ndarray  #: (nrow, nz) rows
    lower: np.ndarray  #: (nrow,)
    upper: np.ndarray  #: (nrow,)
    kinds: np.ndarray  #: (nrow,) :class:`~planner.constraints.rows.RowKind`
    n_hard: int
    zmax: np.ndarray  #: (nz,) bounds of the scaled moves, ``|z| <= zmax`` (the drive forces)

    def solve_hard(self, start: np.ndarray | None = None) -> QPSolution:
        """The hard QP with every hard row given to DAQP (the numpy reference's solve)."""
        nh = self.n_hard
        bu = np.concatenate((self.zmax, self.upper[:nh]))
        bl = np.concatenate((-self.zmax, self.lower[:nh]))
        sense = np.zeros(len(bu), dtype=np.int32)
        sense[bu - bl <= 0] = EQUALITY
        return solve_qp(self.H, self.f, self.A[:nh], bu, bl, sense, start)

    def violation(self, z: np.ndarray) -> float:
        """Largest violation of the hard rows at ``z`` [row units] (0 if none)."""
        nh = self.n_hard
        r = self.A[:nh] @ z
        return float(np.maximum(np.maximum(self.lower[:nh] - r, r - self.upper[:nh]), 0.0).max(initial=0.0))

    def solve_slack(self, arrival: np.ndarray | None = None, iter_limit: int | None = None) -> QPSolution:
        """Every row (corridor, speed and stroke) softened by four slacks ``s >= 0`` (row
        units: corridor m and rad, stroke m, leg speed m/s by :class:`RowKind`; the rows where
        ``arrival`` (a mask) is true, the arrival speed, m/s), penalised by
        ``SLACK_RHO2 |w s|^2 / 2 + SLACK_RHO1 w . s`` with ``w = (1, 1, 1,``
        :data:`ARRIVAL_SLACK_WEIGHT` ``)``; forces and force rates stay hard. The solution is
        ``(z, s)``. ``iter_limit``: DAQP's iteration limit (default :data:`SLACK_ITER_LIMIT`)."""
        nz, kinds = len(self.f), self.kinds
        ns = 4
        w = np.array([1.0, 1.0, 1.0, ARRIVAL_SLACK_WEIGHT])
        Hs = np.zeros((nz + ns, nz + ns))
        Hs[:nz, :nz] = self.H
        Hs[nz:, nz:] = np.diag(w * w) * SLACK_RHO2
        fs = np.concatenate((self.f, w * SLACK_RHO1))
        S = np.zeros((len(kinds), ns))
        soft = kinds < 3  # the rate rows (kind 3) are never softened
        slot = kinds.copy()
        if arrival is not None:
            slot[arrival] = 3
        S[np.nonzero(soft)[0], slot[soft]] = 1.0
        # two one-sided rows per two-sided row: A z - s <= bu ; bl <= A z + s
        As = np.vstack((np.hstack((self.A, -S)), np.hstack((self.A, S))))
        bu = np.concatenate((self.upper, np.full(len(kinds), np.inf)))
        bl = np.concatenate((np.full(len(kinds), -np.inf), self.lower))
        keep = np.isfinite(bu) | np.isfinite(bl)
        As, bu, bl = As[keep], np.where(np.isfinite(bu), bu, 1e30)[keep], np.where(np.isfinite(bl), bl, -1e30)[keep]
        ub = np.concatenate((self.zmax, np.full(ns, 1e30), bu))
        lb = np.concatenate((-self.zmax, np.zeros(ns), bl))
        sense = np.zeros(len(ub), dtype=np.int32)
        limit = SLACK_ITER_LIMIT if iter_limit is None else iter_limit
        sol = solve_qp(Hs, fs, As, ub, lb, sense, iter_limit=limit)
        for retry in RETRY_SETTINGS:
            if sol.flag not in RETRY_FLAGS or sol.iterations >= limit:
                break
            # the slack problem always has a solution (the previous forces meet the hard rows):
            # DAQP cycled or lost its factorisation, a numerical failure; solved again
            again = solve_qp(Hs, fs, As, ub, lb, sense, iter_limit=limit - sol.iterations, retry=retry)
            sol = QPSolution(again.z, again.flag, sol.iterations + again.iterations)
        return sol
