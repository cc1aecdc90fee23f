"""Issue 31 goal 6, issue 33 goal 2: the Python path of a step (a step the compiled stage-wise
solve does not finish: DAQP on the hard QP, then the slack problem) at a fraction of its cost.
Users case 38 of seed 31 (5 legs, 72 kg, 500 N s/m, [point, box, point], Ts 10 ms, 1674 N/s)
takes it at 3 steps near the end point; each cost 0.1 s (14 DAQP calls, 0.25 s of the plan's
0.33 s, against an estimate of 0.052 s), most of it in DAQP's setup (``A R^-1`` in plain
loops) and in its checks of every one of 2095 one-sided rows of the slack problem at each
iteration. Measured before/after: benchmarks/README.md."""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest

import planner.constraints.qp as qp_module
from planner import plan
from planner.constraints.step import FullQP

from .certify_support import _segments_of, check_plan, users_case


def _plain_dense(self, rows, zmax):
    """FullQP.dense as before: every row formed, no factor (DAQP gets the QP as it is)."""
    from planner.constraints import dense_kernels as ck

    A = np.empty((rows.n_rows, self.Gx.shape[1]))
    ck.constraint_matrix(rows.col, rows.val, self.Gx, A)
    return qp_module.DenseQP(self.H, self.f, A, self.lower, self.upper, rows.kinds, rows.n_hard, zmax)


def _fallback_qps(req: dict) -> list[tuple[qp_module.DenseQP, np.ndarray | None, np.ndarray | None]]:
    """The dense QPs of the plan's Python-path steps given to the slack problem, each with its
    arrival rows' mask and the start it was given (the previous plan's moves)."""
    seen: list[tuple[qp_module.DenseQP, np.ndarray | None, np.ndarray | None]] = []
    orig = qp_module.DenseQP.solve_slack

    def spy(self, arrival=None, iter_limit=None, start=None, left=None):
        seen.append((self, arrival, start))
        return orig(self, arrival, iter_limit, start)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(qp_module.DenseQP, "solve_slack", spy)
        plan(req)
    return seen


def test_least_distance_form_and_screened_slack_problem_give_daqp_plain_answers():
    """On the step QPs of case 38 that needed the slack problem: the hard QP handed to DAQP in
    the least-distance form (rows ``A R^-1`` formed by BLAS) and the slack problem screened
    (a side of each row near the previous plan, the rest checked at the solution) have the
    solutions of the plain forms: the same verdict, moves within 1e-7 of force_max, the same
    slacks to 1e-12 m; the screened problem holds fewer than a third of the rows and every row
    holds at its solution."""
    qps = _fallback_qps(users_case(38))
    assert len(qps) >= 2
    for dense, arrival, start in qps:
        assert dense.Rinv is not None and dense.M is not None
        plain = qp_module.DenseQP(dense.H, dense.f, dense.A, dense.lower, dense.upper, dense.kinds, dense.n_hard,
                                  dense.zmax)
        # the factor: H = R'R
        R = np.linalg.inv(dense.Rinv)
        assert np.allclose(R.T @ R, dense.H, atol=1e-12)
        hard, hard0 = dense.solve_hard(), plain.solve_hard()
        assert hard.ok == hard0.ok
        rows: list[int] = []
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(qp_module, "solve_qp", _counting(rows))
            screened = dense.solve_slack(arrival, None, start)
        slack0 = plain.solve_slack(arrival)
        assert screened.ok and slack0.ok
        nz = len(dense.f)
        assert np.abs(screened.z[:nz] - slack0.z[:nz]).max() <= 1e-7
        assert np.abs(screened.z[nz:] - slack0.z[nz:]).max() * qp_module_row_unit() <= 1e-12
        one_sided = 2 * int(np.sum(np.isfinite(dense.upper) & np.isfinite(dense.lower)))
        assert max(rows) < one_sided / 3, (rows, one_sided)
        # every row (the hard ones and the strokes) within its kind's slack at the solution
        z, s = screened.z[:nz], screened.z[nz:]
        r = dense.A @ z
        soft = dense.kinds < 3
        slot = dense.kinds.copy()
        if arrival is not None:
            slot[arrival] = 3
        room = np.where(soft, s[np.minimum(slot, 3)], 0.0) + 1e-6
        assert np.all(r <= dense.upper + room) and np.all(r >= dense.lower - room)


def _counting(rows: list[int]):
    """``solve_qp`` that records the rows of each problem it is given."""
    orig = qp_module.solve_qp

    def count(H, f, A, *args, **kwargs):
        rows.append(A.shape[0])
        return orig(H, f, A, *args, **kwargs)

    return count


def qp_module_row_unit() -> float:
    from planner.constraints.rows import ROW_UNIT_M

    return ROW_UNIT_M


def test_case38_plans_as_with_the_plain_forms_and_asks_daqp_once_a_step():
    """Case 38 plans, certified, as with DAQP given every QP as it is and every row of the
    slack problem (poses within 1e-9 m / rad, forces within 1e-6 N); a step the compiled solve
    proved infeasible (widened by RELAX_M, at the guessed offset) is not solved again on the
    hard rows as given nor as widened: one hard DAQP solve a fallback step (the speed rows
    widened once more), three before."""
    req = users_case(38)
    calls: list[int] = []
    orig = qp_module.DenseQP.solve_hard

    def count(self, *args, **kwargs):
        calls.append(1)
        return orig(self, *args, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(qp_module.DenseQP, "solve_hard", count)
        res = plan(req)
    m = res.metrics
    assert m.qp_fallbacks is not None and m.qp_fallbacks >= 1 and m.infeasible_steps == 0
    assert len(calls) == m.qp_fallbacks, (len(calls), m.qp_fallbacks)
    assert check_plan(req, res, _segments_of(req, res)).ok
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(FullQP, "dense", _plain_dense)
        # the plain forms cost more than the refused-step work bound lets a plan take past 1.3x
        # its estimate (the plan is already there): the comparison is of answers, without it
        mp.setattr(sys.modules["planner.orchestrator.plan"], "REFUSAL_WORK", math.inf)
        ref = plan(req)
    assert ref.metrics.qp_fallbacks == m.qp_fallbacks and ref.metrics.qp_relaxed_steps == m.qp_relaxed_steps
    assert np.abs(np.asarray(res.pose) - np.asarray(ref.pose)).max() <= 1e-9
    assert np.abs(np.asarray(res.drives.force) - np.asarray(ref.drives.force)).max() <= 1e-6
    assert res.metrics.energy == pytest.approx(ref.metrics.energy, rel=1e-9)
