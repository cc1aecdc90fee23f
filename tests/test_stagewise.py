"""The stage-wise solver of the constrained mode (planner/constraints/stagewise.py, its
compiled twin in stagewise_kernels.py and dual_kernels.py): on step QPs recorded from
plans, the compiled twin equals the numpy reference, and both give DAQP's minimiser on the
same QP stated densely (every row, equalities as equalities). DAQP stays the reference.
"""

from __future__ import annotations

import numpy as np
import pytest

from planner.constraints import stagewise as sw
from planner.constraints.compiled import RELAX_M
from planner.constraints.dual_kernels import dual_solve
from planner.constraints.rows import ROW_UNIT_M
from planner.constraints.stagewise_kernels import stage_setup, substitute
from planner.constraints.step_kernels import prediction_violation
from tests.support import TABLE1, with_settings
from tests.test_constraints_kernels import CASES, record_steps


@pytest.fixture(scope="module")
def recorded():
    cache: dict[str, list] = {}

    def get(case: str) -> list:
        if case not in cache:
            cache[case] = record_steps(CASES[case](), 6)
        return cache[case]

    return get


def _qp(step):
    asm = step.controller.assembly
    return asm, asm.build(step.k, step.x, step.Ad, step.Bd, step.y_nom, step.u_prev, step.u0)


def compiled_solve(asm, qp, warm=None):
    """The compiled stage-wise solve of a step's QP: ``(status, Y, iterations)``."""
    R = qp.rows
    ok, ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu = stage_setup(
        qp.Ad, qp.Bd, asm.umax, asm.du, qp.W, R.col, R.val, R.lower, R.upper, R.n_hard)
    assert ok
    N, m = len(qp.W) // 3, len(asm.umax)
    Y = np.empty(6 * N + N * m)
    V, Lm = np.empty((N * m + 1, 6 * N + N * m)), np.empty((N * m + 1, N * m + 1))
    status, it, _, _ = dual_solve(ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu, asm.du, qp.x, qp.d, qp.tgt,
                                  R.col, R.val, R.lower, R.upper, asm.zmax, R.n_hard, sw.SOLVE_TOL, sw.DEPENDENT_TOL,
                                  sw.WARM_TOL, 2000, np.zeros(0) if warm is None else warm, V, Lm, Y)
    return status, Y, it


@pytest.mark.parametrize("case", ["table1", "psi", "triangle"])
def test_same_minimiser_as_daqp_on_recorded_step_qps(case, recorded):
    """Every 6th step's QP of a plan (Table I: psi fixed, equalities eliminated; the turning
    corridor: psi ranges; triangle cells: half-plane rows): the stage-wise solver's moves, the
    compiled twin's and the numpy reference's, equal DAQP's on the dense QP to 1e-8 (scaled
    moves force / force_max), and meet every row to the solver's tolerance."""
    diffs, twins, active = [], [], []
    for step in recorded(case):
        asm, qp = _qp(step)
        daqp = asm.dense(qp).solve_hard()
        assert daqp.ok, step.k
        status, Y, _ = compiled_solve(asm, qp)
        assert status == sw.SOLVED, step.k
        N = len(qp.W) // 3
        sp = sw.stage_problem(qp.Ad, qp.Bd, asm.umax, asm.du, qp.W, qp.rows)
        assert sp is not None
        ref = sw.dual_solve(sp, qp.rows, asm.zmax, qp.x, qp.d, qp.tgt)
        assert ref.status == sw.SOLVED and ref.violation <= sw.SOLVE_TOL
        diffs.append(float(np.abs(Y[6 * N:] - daqp.z).max()))
        twins.append(float(np.abs(Y - ref.Y).max()))
        active.append(len(ref.active))
        # the states are the prediction of the moves (eq. 11 with the one-step offset)
        X = asm.full(qp).predict(Y[6 * N:])
        assert np.abs(X - Y[:6 * N]).max() < 1e-9
    assert len(diffs) >= 8
    assert max(diffs) < 1e-8
    assert max(twins) < 1e-9  # compiled twin and numpy reference: the same arithmetic
    assert max(active) > 0  # some steps had active rows


def test_unconstrained_minimiser_is_the_riccati_substitution(recorded):
    """The solver's first point, one backward and one forward Riccati pass, is the dense QP's
    unconstrained minimiser ``-H^-1 f`` (on steps without equalities, which the stage-wise
    problem eliminates)."""
    checked = 0
    for step in recorded("psi"):
        asm, qp = _qp(step)
        sp = sw.stage_problem(qp.Ad, qp.Bd, asm.umax, asm.du, qp.W, qp.rows)
        assert sp is not None
        if sp.ecnt.any():
            continue
        checked += 1
        dense = asm.dense(qp)
        z_dense = np.linalg.solve(dense.H, -dense.f)
        c, k0, q, r = sw.affine_terms(sp, qp.x, qp.d, qp.tgt)
        Y = sw.substitute(sp, q, r, c, k0, qp.x)
        N = len(qp.W) // 3
        assert np.abs(Y[6 * N:] - z_dense).max() < 1e-9
        R = qp.rows
        _, ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu = stage_setup(
            qp.Ad, qp.Bd, asm.umax, asm.du, qp.W, R.col, R.val, R.lower, R.upper, R.n_hard)
        Yc = np.empty_like(Y)
        substitute(A, B, P, K, C, L, Z, ecnt, q, r, c, k0, qp.x, N - 1, True, Yc)
        assert np.abs(Yc - Y).max() < 1e-12
    assert checked >= 3


@pytest.mark.parametrize("case", ["table1", "triangle"])
def test_warm_start_gives_the_same_minimiser_in_fewer_changes(case, recorded):
    """Warm-started from the previous step's solution shifted by one sample, the solve ends
    on the same minimiser as from the unconstrained one (compiled twin and numpy reference
    alike). On Table I's arrival (steps 150-199, up to ~10 rows active) it takes fewer
    active-set changes in total: the shifted solution's active rows mostly stay active. (On
    the triangle corridor, where few rows are active, rows that only touch a bound there can
    cost a few more.)"""
    steps = record_steps(CASES[case](), 1)[150:200]
    cold_it = warm_it = 0
    prev = None
    for step in steps:
        asm, qp = _qp(step)
        status, Y, it = compiled_solve(asm, qp)
        assert status == sw.SOLVED
        if prev is not None:
            N, m = len(qp.W) // 3, len(asm.umax)
            warm = sw.shifted(prev, N, m)
            status_w, Yw, it_w = compiled_solve(asm, qp, warm)
            assert status_w == sw.SOLVED
            assert np.abs(Yw - Y).max() < 1e-8
            sp = sw.stage_problem(qp.Ad, qp.Bd, asm.umax, asm.du, qp.W, qp.rows)
            assert sp is not None
            ref = sw.dual_solve(sp, qp.rows, asm.zmax, qp.x, qp.d, qp.tgt, warm)
            assert np.abs(ref.Y - Yw).max() < 1e-9 and ref.iterations == it_w
            cold_it += it
            warm_it += it_w
        prev = Y
    if case == "table1":
        assert warm_it < 0.5 * cold_it


def test_infeasible_qp_is_reported():
    """A step whose rows contradict each other (the first sample's x pinned to two different
    values by a box and a half-plane) is reported infeasible, not solved."""
    step = record_steps(with_settings(TABLE1, mode="constrained"), 100)[1]
    asm, qp = _qp(step)
    R = qp.rows
    j = 0  # first horizon sample's x box row (rows sorted by axis, then sample)
    assert R.col[j, 0] == 0 and R.col[j, 1] < 0
    x0 = R.lower[j]
    R.lower[j], R.upper[j] = x0 + 1.0, x0 + 1.0 + 1e-3  # x in [x0 + 1 mm, ...]
    R.lower[j + 1] = R.upper[j + 1] = R.lower[j + 1]  # keep y
    hp = np.nonzero((R.col[:, 0] == 0) & (R.col[:, 1] == 1))[0]
    if hp.size == 0:  # no half-plane row on sample 0: contradict the box with its own upper bound
        R.upper[j] = x0
    else:
        R.upper[hp[0]] = -1e9
    status, _, _ = compiled_solve(asm, qp)
    assert status != sw.SOLVED
    assert not asm.dense(qp).solve_hard().ok  # DAQP agrees


def test_relaxation_stays_inside_the_margin():
    """The tolerance a step may be solved with (rows widened) leaves at least a fifth of the
    corridor margin (0.2 um, far more than the one-step mismatch of ~1e-9 m), so the actual
    robot stays inside the unshrunk corridor."""
    from planner.constraints import MARGIN_M
    assert RELAX_M <= 0.8 * MARGIN_M
    assert RELAX_M / ROW_UNIT_M > sw.SOLVE_TOL


@pytest.mark.parametrize("q_u", [None, [1e-3, 3e-3, 5e-4, 1.5e-3]])
def test_eliminated_equalities_give_the_same_minimiser(q_u):
    """Table I fixes psi = 0: one equality row per sample, which the stage-wise problem
    eliminates (``z_s = L_s x_s + Z_s w_s + k0_s``); its moves equal DAQP's on the QP in z with
    the equalities as equalities, and meet them. Unequal drive weights ``q_u`` make the
    eliminated problem's cross terms between the inputs and the states non-zero."""
    req = with_settings(TABLE1, mode="constrained", **({"q_u": q_u} if q_u else {}))
    diffs = []
    for step in record_steps(req, 10):
        asm, qp = _qp(step)
        sp = sw.stage_problem(qp.Ad, qp.Bd, asm.umax, asm.du, qp.W, qp.rows)
        assert sp is not None and sp.ecnt.sum() > 0  # the elimination is in use
        status, Y, _ = compiled_solve(asm, qp)
        daqp = asm.dense(qp).solve_hard()
        assert status == sw.SOLVED and daqp.ok
        N = len(qp.W) // 3
        diffs.append(float(np.abs(Y[6 * N:] - daqp.z).max()))
        assert np.abs(Y[2:6 * N:6] - 0.0).max() < 1e-12  # psi = 0 at every predicted sample
    assert len(diffs) >= 20
    assert max(diffs) < 1e-8  # scaled moves (force / force_max)


@pytest.mark.parametrize("case", ["table1", "psi", "triangle"])
def test_prediction_violation_is_the_dense_qps(case, recorded):
    """``step_kernels.prediction_violation`` (the acceptance test of a stage-wise solution)
    equals the dense QP's largest violation of its hard rows (``X = free + Gx z``, every row,
    equalities included) and of the force bounds, at moves that are not a solution."""
    rng = np.random.default_rng(3)
    for step in recorded(case)[:4]:
        asm, qp = _qp(step)
        dense = asm.dense(qp)
        N, m = len(qp.W) // 3, len(asm.umax)
        for scale in (1e-6, 1e-2, 1.2):
            z = rng.uniform(-scale, scale, N * m)
            Y = np.concatenate((rng.normal(size=6 * N), z))  # its own states are not read
            want = max(dense.violation(z), float(np.max(np.abs(z) - asm.zmax)), 0.0)
            R = qp.rows
            got = prediction_violation(qp.Ad, qp.Bd * asm.umax, qp.x, qp.d, R.col, R.val, R.lower, R.upper, asm.zmax,
                                       R.n_hard, Y)
            assert got == pytest.approx(want, rel=1e-9, abs=1e-12)
