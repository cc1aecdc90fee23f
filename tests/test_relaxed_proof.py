"""Issue 31 goal 6, issue 33 goal 2: a relaxed stretch of steps without the full hard solve's
infeasibility verdict at each step. Users case 142 of seed 31 (6 legs, 49 kg, 50 N s/m,
[point, box, point], Ts 1 ms, N 100) brakes onto its end point in 35 relaxed steps; each step
solved its hard QP to the verdict "infeasible" (263-2511 active-set changes: 28 407 of the
plan's 44 290) before the relaxed one. Now a step after a proved-infeasible one first solves
its hard QP on the rows of that proof alone (shifted by a sample; a subset of the rows that
is infeasible proves the whole QP infeasible), and only where that subset has a solution the
full hard QP (``planner.constraints.step_kernels.constrained_step``). Measured before/after:
benchmarks/README.md."""

from __future__ import annotations

import numpy as np
import pytest

import planner.constraints.compiled as compiled
from planner import plan
from planner.constraints.controller import ConstrainedController

from .certify_support import _segments_of, check_plan, users_case
from .support import TABLE1


def _plan_steps(req: dict, carry_proof: bool) -> tuple:
    """The plan of ``req`` step by step (the controller's compiled step, not the compiled loop:
    the same kernel) with the proof carried or not, and each step's (relaxed, active-set
    changes)."""
    steps: list[tuple[bool, int]] = []
    orig = compiled.CompiledAssembly.step

    def step(self, *args, **kwargs):
        out = orig(self, *args, **kwargs)
        steps.append((out.relaxed, out.iterations))
        return out

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(compiled.CompiledAssembly, "carry_proof", carry_proof)
        mp.setattr(compiled.CompiledAssembly, "step", step)
        mp.setattr(ConstrainedController, "compiled_loop", False)
        res = plan(req)
    return res, steps


def test_relaxed_stretch_plans_as_with_every_hard_qp_solved_whole():
    """Case 142 with the proof carried plans exactly as with every step's hard QP solved on all
    its rows (the same poses, forces and energy to the last bit, the same 35 relaxed steps at
    the same samples: a step is relaxed exactly when its hard QP is infeasible), certified, and
    its relaxed steps take under half the active-set changes (measured 11.4k against 29.5k)."""
    req = users_case(142)
    res, steps = _plan_steps(req, True)
    ref, ref_steps = _plan_steps(req, False)
    relaxed = [k for k, (r, _) in enumerate(steps) if r]
    assert len(relaxed) >= 10 and relaxed == [k for k, (r, _) in enumerate(ref_steps) if r]
    assert np.array_equal(np.asarray(res.pose), np.asarray(ref.pose))
    assert np.array_equal(np.asarray(res.drives.force), np.asarray(ref.drives.force))
    assert res.metrics.energy == ref.metrics.energy
    assert res.metrics.qp_relaxed_steps == ref.metrics.qp_relaxed_steps == len(relaxed)
    assert check_plan(req, res, _segments_of(req, res)).ok
    changes = sum(steps[k][1] for k in relaxed)
    changes_ref = sum(ref_steps[k][1] for k in relaxed)
    assert changes < 0.5 * changes_ref, (changes, changes_ref)


def test_steps_without_a_previous_proof_are_untouched():
    """Table I (no relaxed step) plans with the same poses and the same active-set changes at
    every step either way: the proof is carried only from a proved-infeasible step."""
    res, steps = _plan_steps(TABLE1, True)
    ref, ref_steps = _plan_steps(TABLE1, False)
    assert not any(r for r, _ in ref_steps)
    assert steps == ref_steps
    assert np.array_equal(np.asarray(res.pose), np.asarray(ref.pose))
