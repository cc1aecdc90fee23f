"""The solver: one wrapper around DAQP, and the dense QP of a step (hard and slack).

DAQP (a dual active-set solver for dense QPs) was chosen by ``benchmarks/bench_qp.py`` over
OSQP, ProxSuite and Clarabel. Every DAQP call of the constrained mode goes through
:func:`solve_qp`.

Infeasibility. If the hard QP has no solution (e.g. limits too tight for the requested time),
the step is solved again with the corridor, stroke and speed rows softened by three slack
variables (corridor m, stroke m, leg speed m/s; :meth:`DenseQP.solve_slack`) with a large
quadratic + linear penalty; forces stay hard. What the controller does with the slack is
described in :mod:`planner.constraints.controller`.

Cost (issue 31 goal 6). DAQP works on the least-distance form of a QP: its setup forms
``A R^-1`` (``H = R'R``) in plain loops, 8.4 of the 9.6 ms of a call at N 49 x 5 legs, and
checks every row it holds at each iteration. On the compiled backend's Python path
(:class:`DenseQP` with :attr:`DenseQP.Rinv`) the factor is formed once a step and the rows
``A R^-1`` once for the rows of a step (BLAS ``trmm``), and DAQP is handed the least-distance
form (identity Hessian: its setup only scales the rows); the slack problem is screened
(:meth:`DenseQP.solve_slack`). The numpy reference hands DAQP every QP as it is.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["ARRIVAL_SLACK_WEIGHT", "DAQP_ITERATION_LARGE_S", "DAQP_ITERATION_S", "DAQP_LARGE_ENTRIES",
           "DAQP_SETTINGS", "RETRY_FLAGS", "RETRY_SETTINGS", "SCREEN_FIRST", "SCREEN_NEAR", "SCREEN_ROUNDS",
           "SCREEN_TOL", "SLACK_ITER_LIMIT", "SLACK_RHO1", "SLACK_RHO2", "WORK_BOUND_FLAG", "DenseQP", "QPSolution",
           "daqp_iteration_s", "daqp_iterations", "small_solve", "SMALL_SOLVE_S", "factor", "rows_ldp", "solve_qp"]

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
#: the slack problem's screened solves (:meth:`DenseQP.solve_slack`): rounds before every row
#: is held, and the violation [row units] of a row left out that makes it join (DAQP's primal
#: tolerance)
SCREEN_ROUNDS = 4
SCREEN_TOL = 1e-9
#: a side of a two-sided row is held from the start where the start is within this fraction
#: of the row's width from it, or beyond it (issue 31, users case 38: 257 of 2095 one-sided
#: rows at 0.25, one round, the same 194 iterations as with every row, at 0.4 of the time)
SCREEN_NEAR = 0.25
#: the DAQP settings of a screened slack problem's first solve: patience with the iterations
#: that do not lower the criterion (DAQP's default gives up after 10; its iterates are the
#: same until then). The rows of zero width, held whole, made the default give up and the
#: retries start again from nothing (issue 31: 146-173 iterations lost, a solve or two a step)
SCREEN_FIRST: dict = {"cycle_tol": 1000}
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
#: CPU seconds of one DAQP iteration per row it holds (bounds included) and per variable: an
#: iteration checks every row it holds against the current point (the least-distance form's
#: ``rows x variables`` product dominates). Measured: 1.1e-10 s on small problems (users case 38
#: of seed 31, 755 rows x 249 variables, in cache), up to :data:`DAQP_ITERATION_LARGE_S` on
#: large ones (the refused steps of cases 7, 16, 41, 63: 1 000-5 500 rows x 504-604 variables,
#: 1.9-3.5e-10 s, more under load); :func:`daqp_iterations` interpolates in ``rows x variables``
#: up to :data:`DAQP_LARGE_ENTRIES`
DAQP_ITERATION_S = 1.1e-10
DAQP_ITERATION_LARGE_S = 3.5e-10
DAQP_LARGE_ENTRIES = 2e6
#: DAQP's exit flag at its iteration limit
ITERATION_LIMIT_FLAG = -4
#: the fewest and the most iterations of a piece of a bounded solve (:meth:`DenseQP.solve_slack`)
BOUND_PIECE_MIN = 50
BOUND_PIECE_MAX = 1000
#: the flag of a solve that was not started or was stopped at the request's work bound
#: (:func:`daqp_iterations`), not at DAQP's own limit or verdict
WORK_BOUND_FLAG = -100


@dataclass(slots=True, eq=False)
class QPSolution:
    """A solution of the step's QP (or of a smaller one standing for it)."""

    z: np.ndarray  #: the minimiser (scaled moves; with the slacks after them in the slack problem)
    flag: int  #: DAQP's exit flag (>= 1: solved)
    iterations: int  #: DAQP iterations, summed over the solves it took
    states: np.ndarray | None = None  #: (6N,) predicted states at ``z`` where the solve formed them
    violation: float = 0.0  #: largest violation of the hard rows at ``z`` [row units], if checked
    #: DAQP's multipliers of the bounds it was given (0: not active; < 0: the lower bound), where kept
    lam: np.ndarray | None = None

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
    return QPSolution(x, int(flag), int(info["iterations"]), lam=info.get("lam"))


def daqp_iteration_s(rows: int, variables: int) -> float:
    """CPU seconds of one DAQP iteration on a QP of ``rows`` rows (the bounds on its variables
    included) and ``variables`` variables (:data:`DAQP_ITERATION_S`)."""
    entries = max(1, rows) * max(1, variables)
    share = min(1.0, entries / DAQP_LARGE_ENTRIES)
    return entries * (DAQP_ITERATION_S + (DAQP_ITERATION_LARGE_S - DAQP_ITERATION_S) * share)


#: a DAQP solve whose whole iteration limit the model prices at most this [CPU s] runs whole
#: whatever the work bound has left (:func:`small_solve`): the bound is there for the solves that
#: grow with the horizon (2-6 CPU s at N 100 x 6 legs), not for a small request's figure
#: (Table I in 0.05 s, 4 legs x N 30: the slack problem's last round, 1 159 rows x 124, is priced
#: 0.35 s for its 19 059 iterations and took 0.08 s whole; a CLI's first plan has used 0.53 s of
#: its 0.04 s bound loading the kernels when it gets there, and the solve cut into pieces did not
#: converge in 9 985 iterations). N 100 x 6 legs is priced ~10 s, N 60 x 4 legs ~0.9 s: bounded
SMALL_SOLVE_S = 0.5


def small_solve(rows: int, variables: int, iterations: int) -> bool:
    """Whether ``iterations`` DAQP iterations on a QP of ``rows`` rows and ``variables``
    variables cost at most :data:`SMALL_SOLVE_S` by the model (:func:`daqp_iteration_s`)."""
    return iterations * daqp_iteration_s(rows, variables) <= SMALL_SOLVE_S


def daqp_iterations(seconds: float, rows: int, variables: int, cap: int) -> int:
    """The DAQP iterations that ``seconds`` of work pay for on a QP of ``rows`` rows and
    ``variables`` variables (:func:`daqp_iteration_s`), at most ``cap`` (0 if nothing is left)."""
    if seconds <= 0.0:
        return 0
    return int(min(cap, seconds / daqp_iteration_s(rows, variables)))


def factor(H: np.ndarray) -> np.ndarray:
    """``R^-1`` of the Cholesky factor ``H = R'R`` (upper triangular): what
    :class:`DenseQP` needs to hand DAQP its QP in the least-distance form."""
    import scipy.linalg

    R = np.linalg.cholesky(H).T
    return scipy.linalg.solve_triangular(R, np.eye(len(R)))


def rows_ldp(A: np.ndarray, Rinv: np.ndarray) -> np.ndarray:
    """``A R^-1`` (``R^-1`` upper triangular: BLAS ``trmm``)."""
    from scipy.linalg.blas import get_blas_funcs

    (trmm,) = get_blas_funcs(("trmm",), (Rinv, A))
    return trmm(1.0, Rinv, A, side=1)


def _solve_ldp(Rinv: np.ndarray, f: np.ndarray, M: np.ndarray, upper: np.ndarray, lower: np.ndarray,
               sense: np.ndarray, start: np.ndarray | None = None, iter_limit: int | None = None,
               retry: dict | None = None) -> QPSolution:
    """``min 0.5 x'Hx + f'x`` s.t. ``lower <= (x, A x) <= upper`` (every variable bounded,
    then the rows of ``A``) handed to DAQP as the least-distance problem it solves
    internally: ``v = R x + c`` with ``H = R'R``, ``c = R^-T f``, so the criterion is
    ``|v|^2 / 2`` (a constant apart) and the rows ``(R^-1; A R^-1) v`` shifted by their value at
    ``c``. ``M = A R^-1`` is formed by the caller (BLAS, from a factor kept for the step);
    DAQP's own setup forms it in plain loops, 3-8x the time of the whole solve (issue 31: a
    step's fallback at N 49 x 5 legs spent 8.4 of its 9.6 ms a DAQP call there)."""
    c = Rinv.T @ f
    G = np.vstack((Rinv, M))
    shift = G @ c
    big = np.abs(upper) >= 1e29  # DAQP's 'no bound' stays one
    up = np.where(big, upper, upper + shift)
    big = np.abs(lower) >= 1e29
    lo = np.where(big, lower, lower + shift)
    v0 = None
    if start is not None:  # the warm start in v: R x + c
        import scipy.linalg

        v0 = scipy.linalg.solve_triangular(Rinv, start) + c
    sol = solve_qp(np.eye(len(f)), np.zeros(len(f)), G, up, lo, sense, v0, iter_limit, retry)
    return QPSolution(Rinv @ (sol.z - c), sol.flag, sol.iterations, lam=sol.lam)


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
    #: ``R^-1`` of ``H = R'R`` (:func:`factor`), or None: with it DAQP gets the least-distance
    #: form with the rows formed here by BLAS (:func:`_solve_ldp`; the compiled backend's
    #: Python path), without it the QP as it is (the numpy reference)
    Rinv: np.ndarray | None = None
    #: ``A R^-1`` with :attr:`Rinv` (every row; :func:`rows_ldp`), kept by the caller for the
    #: solves of a step with the same rows
    M: np.ndarray | None = None

    def solve_hard(self, start: np.ndarray | None = None, iter_limit: int | None = None) -> QPSolution:
        """The hard QP with every hard row given to DAQP (the numpy reference's solve);
        ``iter_limit``: DAQP's iteration limit instead of :data:`DAQP_SETTINGS`'s (a refused
        step's work bound: 0 is not solved, :data:`WORK_BOUND_FLAG`)."""
        nh = self.n_hard
        if iter_limit is not None and iter_limit <= 0:
            return QPSolution(np.zeros(len(self.f)), WORK_BOUND_FLAG, 0)
        bu = np.concatenate((self.zmax, self.upper[:nh]))
        bl = np.concatenate((-self.zmax, self.lower[:nh]))
        sense = np.zeros(len(bu), dtype=np.int32)
        sense[bu - bl <= 0] = EQUALITY
        if self.Rinv is not None:
            sol = _solve_ldp(self.Rinv, self.f, self._ldp_rows()[:nh], bu, bl, sense, start, iter_limit)
        else:
            sol = solve_qp(self.H, self.f, self.A[:nh], bu, bl, sense, start, iter_limit)
        if (iter_limit is not None and iter_limit < DAQP_SETTINGS["iter_limit"] and not sol.ok
                and sol.iterations >= iter_limit):
            sol.flag = WORK_BOUND_FLAG  # stopped by the bound, not at DAQP's own limit
        return sol

    def _ldp_rows(self) -> np.ndarray:
        """``A R^-1`` (formed once)."""
        if self.M is None:
            assert self.Rinv is not None
            self.M = rows_ldp(self.A, self.Rinv)
        return self.M

    def violation(self, z: np.ndarray) -> float:
        """Largest violation of the hard rows at ``z`` [row units] (0 if none)."""
        nh = self.n_hard
        r = self.A[:nh] @ z
        return float(np.maximum(np.maximum(self.lower[:nh] - r, r - self.upper[:nh]), 0.0).max(initial=0.0))

    def solve_slack(self, arrival: np.ndarray | None = None, iter_limit: int | None = None,
                    start: np.ndarray | None = None, left: Callable[[], float] | None = None) -> QPSolution:
        """Every row (corridor, speed and stroke) softened by four slacks ``s >= 0`` (row
        units: corridor m and rad, stroke m, leg speed m/s by :class:`RowKind`; the rows where
        ``arrival`` (a mask) is true, the arrival speed, m/s), penalised by
        ``SLACK_RHO2 |w s|^2 / 2 + SLACK_RHO1 w . s`` with ``w = (1, 1, 1,``
        :data:`ARRIVAL_SLACK_WEIGHT` ``)``; forces and force rates stay hard. The solution is
        ``(z, s)``. ``iter_limit``: DAQP's iteration limit (default :data:`SLACK_ITER_LIMIT`).

        With :attr:`Rinv` (the compiled backend's Python path) the problem is screened: a
        two-sided row enters with the side nearer to ``start`` (scaled moves; the previous
        plan's, zero without), and only where ``start`` is within :data:`SCREEN_NEAR` of its
        width from that side (a row of zero width: both sides). DAQP checks every row it holds
        at every iteration (2095 one-sided rows at N 49 x 5 legs, 194 iterations). The rows the
        solution violates join and it is solved again (:data:`SCREEN_ROUNDS`, then every row):
        a convex problem's optimum on a subset of its rows that meets every row is its optimum.
        The first solve is patient with iterations that do not lower the criterion
        (:data:`SCREEN_FIRST`). Each solve after the first starts from the working set where
        the one before ended (DAQP's sense bits, :func:`_working_set`): the rows added leave
        its multipliers dual feasible, so DAQP goes on from there instead of from no active
        row (issue 33 goal 2: users case 7 of seed 31, N 100 x 6 legs, ran four cold rounds
        and every row to the 20 000-iteration limit, 15 CPU s, and was reported without a
        solution; warm, 1 421 iterations, 0.7 s; case 16 10 530 -> 4 526 iterations, the same
        optimum).

        ``left``: a function giving the work [CPU s] it may still take (a refused step's work
        bound; None: no bound); each solve runs in pieces of iterations that what is left pays
        for (:func:`daqp_iterations`); a solve that the bound stops or leaves no iteration ends
        the problem unsolved with :data:`WORK_BOUND_FLAG` (issue 33 goal 2: at N 100 one refused
        step's slack problem took 2-6 CPU s, 3-30x its whole plan's estimate)."""
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
        Rinv = None
        Sz = S
        if self.Rinv is not None:  # least-distance form: Hs = Rs'Rs, Rs = diag(R, sqrt(rho2) w)
            Rinv = np.zeros((nz + ns, nz + ns))
            Rinv[:nz, :nz] = self.Rinv
            Rinv[nz:, nz:] = np.diag(1.0 / (w * np.sqrt(SLACK_RHO2)))
            M, S = self._ldp_rows(), S @ Rinv[nz:, nz:]
        else:
            M = self.A
        As = np.vstack((np.hstack((M, -S)), np.hstack((M, S))))
        bu = np.concatenate((self.upper, np.full(len(kinds), np.inf)))
        bl = np.concatenate((np.full(len(kinds), -np.inf), self.lower))
        keep = np.isfinite(bu) | np.isfinite(bl)
        As, bu, bl = As[keep], np.where(np.isfinite(bu), bu, 1e30)[keep], np.where(np.isfinite(bl), bl, -1e30)[keep]
        ub = np.concatenate((self.zmax, np.full(ns, 1e30), bu))
        lb = np.concatenate((-self.zmax, np.zeros(ns), bl))
        sense = np.zeros(len(ub), dtype=np.int32)
        limit = SLACK_ITER_LIMIT if iter_limit is None else iter_limit
        nb = nz + ns

        def run(held: np.ndarray | None, iterations: int, warm: np.ndarray | None = None) -> QPSolution:
            """The slack problem with the one-sided rows ``held`` (a mask; None: every row),
            solved again after a numerical failure with each of RETRY_SETTINGS. ``warm``: DAQP's
            sense bits of a working set to start from (bounds, then every one-sided row)."""
            if held is None:
                A_, u_, l_, s_ = As, ub, lb, sense
                sel = np.ones(len(ub), bool)
            else:
                sel = np.concatenate((np.ones(nb, bool), held))
                A_, u_, l_, s_ = As[held], ub[sel], lb[sel], sense[sel]
            sol = QPSolution(np.zeros(nb), -1, 0)
            for retry in ((None if Rinv is None else SCREEN_FIRST), *RETRY_SETTINGS):
                if sol.iterations and (sol.flag not in RETRY_FLAGS or sol.iterations >= iterations):
                    break
                if sol.iterations and left is not None and left() <= 0.0:
                    # no retry past the work bound (users case 42 of seed 31: a whole solve cycled
                    # for 1.7 s, twice the model, then two retries took 0.8 s more)
                    sol.flag = WORK_BOUND_FLAG
                    break
                # the slack problem always has a solution (the previous forces meet the hard rows):
                # DAQP cycled or lost its factorisation, a numerical failure; solved again
                rest = iterations - sol.iterations
                bits = s_ if warm is None or sol.iterations else warm[sel]  # a retry starts afresh
                again = (_solve_ldp(Rinv, fs, A_, u_, l_, bits, iter_limit=rest, retry=retry) if Rinv is not None
                         else solve_qp(Hs, fs, A_, u_, l_, bits, iter_limit=rest, retry=retry))
                sol = QPSolution(again.z, again.flag, sol.iterations + again.iterations, lam=again.lam)
            if sol.lam is not None:  # the working set, as sense bits over every bound and one-sided row
                lam = np.zeros(len(ub))
                lam[np.nonzero(sel)[0]] = sol.lam
                sol.lam = lam
            return sol

        def bounded(held: np.ndarray | None, iterations: int, warm: np.ndarray | None = None) -> QPSolution:
            """``run`` within the work ``left`` (measured). A solve whose whole iteration limit
            what is left pays for (:func:`daqp_iterations`) runs whole, as without a bound;
            otherwise in pieces of half of what is left pays for (at most
            :data:`BOUND_PIECE_MAX`), each from the working set where the one before stopped,
            the time measured between them (a DAQP iteration costs up to 4x the model: users
            case 0 of seed 31, 0.5 ms on 1 724 x 404); :data:`WORK_BOUND_FLAG` where the bound
            stops it. (Pieces converge more slowly than a whole solve: users case 27 did not in
            17 pieces of 1 000 where the whole solve did, so a solve the bound leaves room for is
            never cut into pieces.)"""
            rows = nb + (len(As) if held is None else int(held.sum()))
            if left is None or small_solve(rows, nb, iterations):
                return run(held, iterations, warm)
            cap = daqp_iterations(left(), rows, nb, iterations)
            if cap <= 0:
                return QPSolution(np.zeros(nb), WORK_BOUND_FLAG, 0)
            if cap >= iterations:  # the bound does not bind by the model: the solve as without it
                return run(held, iterations, warm)
            done = 0
            while True:
                rest = iterations - done
                piece = min(rest, max(BOUND_PIECE_MIN, min(cap // 2, BOUND_PIECE_MAX)))
                sol = run(held, piece, warm)
                done += sol.iterations
                sol.iterations = done
                if sol.ok or sol.flag != ITERATION_LIMIT_FLAG:
                    return sol
                # stopped at the piece's end: on from there while the bound leaves iterations (a
                # solve in pieces that reaches its own limit was cut short by them too)
                cap = daqp_iterations(left(), rows, nb, iterations - done)
                if cap <= 0 or done >= iterations or sol.lam is None:
                    sol.flag = WORK_BOUND_FLAG
                    return sol
                warm = _working_set(sol.lam)

        if Rinv is None:
            return bounded(None, limit)
        # the side of each two-sided row nearer to the start: (upper copies, lower copies) as As
        z0 = np.zeros(nz) if start is None else np.clip(start, -self.zmax, self.zmax)
        r0 = self.A @ z0
        both = np.isfinite(self.upper) & np.isfinite(self.lower)
        hi, lo = np.where(both, self.upper, 0.0), np.where(both, self.lower, 0.0)  # no inf - inf
        # a row of zero width (a fixed psi: the same hyperplane on both sides) is held whole: at
        # the optimum both its sides bind where its kind's slack is nil
        whole = both & (hi - lo <= SCREEN_TOL)
        width = np.where(both, hi - lo, np.inf)

        def near(r: np.ndarray) -> np.ndarray:
            """The one-sided rows (as ``As``) within SCREEN_NEAR of their row's width at ``r``."""
            up = np.where(both, r >= 0.5 * (hi + lo), np.isfinite(self.upper))
            near_u = ~both | (self.upper - r <= SCREEN_NEAR * width)
            near_l = ~both | (r - self.lower <= SCREEN_NEAR * width)
            return np.concatenate(((up & near_u) | whole, (~up & near_l) | whole))[keep]

        held = near(r0)
        used = 0
        warm = None
        for _ in range(SCREEN_ROUNDS):
            sol = bounded(held, limit - used, warm)
            used += sol.iterations
            if sol.flag == WORK_BOUND_FLAG:
                return QPSolution(sol.z, WORK_BOUND_FLAG, used)
            if used >= limit:
                return QPSolution(sol.z, sol.flag if sol.ok else -1, used)
            if not sol.ok:  # a numerical failure on the rows held: every row, afresh
                warm = None
                break
            z, sl = sol.z[:nz], sol.z[nz:]
            Az, Ss = self.A @ z, Sz @ sl  # the rows' values, each copy with its kind's slack
            r = np.concatenate((Az - Ss, Az + Ss))[keep]
            out = ~held & ((r > bu + SCREEN_TOL) | (r < bl - SCREEN_TOL))
            if not out.any():
                return QPSolution(sol.z, sol.flag, used)
            held |= out | near(Az)  # and the sides near the solution: fewer rounds
            warm = _working_set(sol.lam)
        sol = bounded(None, limit - used, warm)
        return QPSolution(sol.z, sol.flag, used + sol.iterations)


#: DAQP's sense bits: a bound in the working set, and at its lower side
ACTIVE, LOWER = 1, 2


def _working_set(lam: np.ndarray | None) -> np.ndarray | None:
    """DAQP's sense bits of the working set its multipliers ``lam`` name (a warm start: the
    next solve begins where this one ended, instead of from no active bound)."""
    if lam is None:
        return None
    bits = np.where(lam != 0.0, ACTIVE, 0).astype(np.int32)
    bits[lam < 0.0] |= LOWER
    return bits
