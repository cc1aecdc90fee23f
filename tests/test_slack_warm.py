"""Issue 33 goal 2, issue 31 goal 6: the slack problem of a refused step, screened in rounds, each
round started from the working set where the one before ended (DAQP's sense bits, a warm
start) instead of from no active row. On the users run of seed 31 the step that refuses case 7
(6 legs, Ts 1 ms, N 100) went through four cold rounds and then every row cold, 20 000 DAQP
iterations to the limit (15 CPU s; "no solution ... even with the corridor softened"); case 16's
took 10 530 iterations. Warm, both are solved, case 16 to the same optimum."""

from __future__ import annotations

import numpy as np
import pytest

import planner.constraints.qp as qp_module
from planner import PlannerError, plan

from .certify_support import _with, user_case


class _Captured(Exception):
    pass


def _refused_slack_problem(i: int) -> tuple[qp_module.DenseQP, np.ndarray | None, np.ndarray | None]:
    """The first slack problem of users case ``i`` (seed 31): the dense QP, its arrival mask
    and its start; the plan stops there."""
    req = _with(user_case(np.random.default_rng([31, i])), mode="constrained")
    seen = []

    def spy(self, arrival=None, iter_limit=None, start=None, left=None):
        seen.append((self, arrival, start))
        raise _Captured

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(qp_module.DenseQP, "solve_slack", spy)
        with pytest.raises((_Captured, PlannerError)):
            plan(req)
    assert seen
    return seen[0]


def _rows_hold(dense: qp_module.DenseQP, arrival: np.ndarray | None, sol: qp_module.QPSolution) -> bool:
    """Every row (hard, speed and stroke) within its kind's slack at the solution, the moves
    within their bounds."""
    nz = len(dense.f)
    z, s = sol.z[:nz], sol.z[nz:]
    r = dense.A @ z
    slot = dense.kinds.copy()
    if arrival is not None:
        slot[arrival] = 3
    room = np.where(dense.kinds < 3, s[np.minimum(slot, 3)], 0.0) + 1e-6
    return bool(np.all(r <= dense.upper + room) and np.all(r >= dense.lower - room)
                and np.all(np.abs(z) <= dense.zmax + 1e-9) and np.all(s >= -1e-9))


def _cold(mp: pytest.MonkeyPatch) -> None:
    """Every round started from no active row (as before the warm start)."""
    mp.setattr(qp_module, "_working_set", lambda lam: None)


def test_case7_refused_step_is_solved_warm_where_cold_rounds_ran_to_the_limit():
    dense, arrival, start = _refused_slack_problem(7)
    warm = dense.solve_slack(arrival, None, start)
    assert warm.ok and _rows_hold(dense, arrival, warm)
    assert warm.iterations < qp_module.SLACK_ITER_LIMIT / 5
    with pytest.MonkeyPatch.context() as mp:
        _cold(mp)
        cold = dense.solve_slack(arrival, 3 * warm.iterations, start)
    # cold: not solved in 3x the iterations (nor in the whole limit: 20 000, 15-30 CPU s)
    assert not cold.ok


def test_case16_warm_rounds_reach_the_cold_optimum_in_fewer_iterations():
    """Where the cold rounds solve it too: the same moves (1e-7 of force_max) and slacks (1e-9 relative, 1e-12 m)."""
    from planner.constraints.rows import ROW_UNIT_M

    dense, arrival, start = _refused_slack_problem(16)
    warm = dense.solve_slack(arrival, None, start)
    with pytest.MonkeyPatch.context() as mp:
        _cold(mp)
        cold = dense.solve_slack(arrival, None, start)
    assert warm.ok and cold.ok and _rows_hold(dense, arrival, warm)
    nz = len(dense.f)
    assert np.abs(warm.z[:nz] - cold.z[:nz]).max() <= 1e-7
    assert np.allclose(warm.z[nz:], cold.z[nz:], rtol=1e-9, atol=1e-12 / ROW_UNIT_M)
    assert warm.iterations < cold.iterations
