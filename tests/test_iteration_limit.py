"""The stage-wise solve's iteration limit follows the horizon's size (issue 31 goal 6): a
6-leg robot at N 100 (600 moves) arriving at rest under its force-rate limits took 400-800
active-set changes a step, and the steps over the old fixed limit of 400 went to the Python
path (DAQP's slack problem, 1-2.5 s a step: 54x the work estimate, benchmarks/README.md).
Abandoned candidates (``fastest``, the advice's checks) keep the plain limit."""

from __future__ import annotations

import numpy as np
import pytest

from planner.constraints import ConstrainedController
from planner.constraints.compiled import ITERATIONS_PER_MOVE, MAX_ITERATIONS, CompiledAssembly
from planner.corridor import range_sequence
from planner.model import load_robot
from planner.schema import parse_request
from tests.certify_support import user_case


def _controller(N: int, abandon: bool) -> ConstrainedController:
    case = user_case(np.random.default_rng([31, 142]))  # 6 legs, 49 kg, Ts 1 ms
    req = parse_request({**case, "settings": {**case["settings"], "N": N}})
    assert req.segments is not None
    model = load_robot(req.robot)
    seq = range_sequence(list(req.segments), req.settings, model.n_legs)
    return ConstrainedController(model, seq, req.settings, req.segments, abandon=abandon)


@pytest.mark.parametrize("N", [10, 100])
def test_the_limit_is_the_larger_of_the_floor_and_the_moves_and_abandoned_candidates_keep_the_floor(N):
    plain = _controller(N, abandon=False)
    assert isinstance(plain.assembly, CompiledAssembly)
    moves = N * plain.n_legs
    assert plain.assembly.max_iterations == max(MAX_ITERATIONS, ITERATIONS_PER_MOVE * moves)
    assert plain.assembly.max_iterations >= MAX_ITERATIONS
    # the step's constants hand the limit to the kernel (its 13th argument from umax on)
    assert plain.assembly.step_constants((1e-8, 3e-8), 3)[12] == plain.assembly.max_iterations
    candidate = _controller(N, abandon=True)
    assert isinstance(candidate.assembly, CompiledAssembly)
    assert candidate.assembly.max_iterations == MAX_ITERATIONS
    if N == 100:  # the case of the issue: 600 moves, 2400 changes a solve
        assert plain.assembly.max_iterations == 2400
