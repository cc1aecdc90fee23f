"""The constrained mode's compiled path (planner/constraints/kernels.py, dense_kernels.py,
CompiledAssembly) equals the numpy reference (ReferenceAssembly): the leg rows, every step's
QP, its minimiser and the whole plan (the stage-wise solver against DAQP:
tests/test_stagewise.py).

The step QPs are recorded from compiled plans: the controller's state at a step (state,
model, nominal poses, guessed move, warm start) is replayed through both assemblies.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from planner import plan
from planner.constraints import ConstrainedController
from planner.constraints.reference import ReferenceAssembly
from planner.model import load_robot
from tests.support import PSI_TURN, TABLE1, plan_json, with_settings

ROOT = Path(__file__).resolve().parent.parent


def _layout_triangles() -> dict:
    return {"robot": "moving-slide",
            "layout": {"bounds": {"lower": [-0.1, -0.05], "upper": [0.1, 0.08]},
                       "obstacles": [{"type": "rectangle", "lower": [-0.02, -0.05], "upper": [0.01, 0.03]}],
                       "clearance": 0.0, "cell": {"shape": "triangle", "size": 0.02},
                       "start": [-0.08, 0.0, 0.0], "end": [0.07, 0.0, 0.0]},
            "settings": {"mode": "constrained"}}


CASES = {"table1": lambda: with_settings(TABLE1, mode="constrained"),  # psi = 0: equalities eliminated
         "psi": lambda: with_settings(PSI_TURN, mode="constrained"),  # psi ranges: the QP in z
         "triangle": _layout_triangles}  # half-plane rows


@dataclass
class Step:
    """The controller's state at step ``k`` of a compiled plan."""

    controller: ConstrainedController
    k: int
    x: np.ndarray
    Ad: np.ndarray
    Bd: np.ndarray
    y_nom: np.ndarray | None
    u_prev: np.ndarray
    u0: np.ndarray
    start: np.ndarray | None


def record_steps(req: dict, every: int) -> list[Step]:
    """Every ``every``-th step of the compiled plan of ``req``."""
    steps: list[Step] = []
    orig = ConstrainedController.__call__

    def spy(self, k, x, Ad, Bd):
        if k % every == 0:
            y_nom = None if self.y_nom is None else self.y_nom.copy()
            steps.append(Step(self, k, x.copy(), Ad.copy(), Bd.copy(), y_nom, self.u_prev.copy(), self.guess(),
                              self.warm_start()))
        return orig(self, k, x, Ad, Bd)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(ConstrainedController, "__call__", spy)
        mp.setattr(ConstrainedController, "compiled_loop", False)  # every step through __call__
        plan(req)
    return steps


@pytest.fixture(scope="module")
def recorded():
    cache: dict[str, list[Step]] = {}

    def get(case: str) -> list[Step]:
        if case not in cache:
            cache[case] = record_steps(CASES[case](), 10)
        return cache[case]

    return get


def both(step: Step):
    """The step's QP from the compiled and from the reference assembly, offsets set."""
    c = step.controller
    assert c.st.backend == "compiled"
    ref = ReferenceAssembly(c.model, c.criterion, c.st, c.constraints)
    out = []
    for asm in (c.assembly, ref):
        out.append((asm, asm.build(step.k, step.x, step.Ad, step.Bd, step.y_nom, step.u_prev, step.u0)))
    return out


def _close(a, b, rel=1e-10) -> bool:
    a, b = np.asarray(a, float), np.asarray(b, float)
    fin = np.isfinite(b)
    if not np.array_equal(np.isfinite(a), fin):
        return False
    scale = max(float(np.abs(b[fin]).max(initial=0.0)), 1e-300)
    return bool(np.all(np.abs(a[fin] - b[fin]) <= rel * scale))


def robots():
    ms = load_robot("moving-slide")
    desc = json.loads((ROOT / "planner" / "data" / "moving-slide.json").read_text())
    desc["tool_offset"] = [0.012, -0.007]  # pivots relative to the tool point differ from the platform's
    return [ms, load_robot("tri-slide"), load_robot(desc)]


@pytest.mark.parametrize("case", ["table1", "triangle", "psi"])
def test_compiled_assembly_equals_numpy_assembly(case, recorded):
    """At every 20th step the compiled QP equals the numpy reference's QP in z: rows
    (corridor boxes, triangle half-planes, no-overshoot, leg speeds and strokes, each
    constraint's kernel against its numpy rows), prediction, Hessian, linear term, the
    matrix of every row and its bounds."""
    checked = []
    for step in recorded(case)[::2]:
        (casm, qc), (rasm, qn) = both(step)
        rc, rn = qc.rows, qn.rows
        assert np.array_equal(rc.col, rn.col) and np.array_equal(rc.kinds, rn.kinds)
        assert (rc.n_hard, rc.speed0, rc.stroke0) == (rn.n_hard, rn.speed0, rn.stroke0)
        for a, b in ((rc.val, rn.val), (rc.lower, rn.lower), (rc.upper, rn.upper)):
            assert _close(a, b, 1e-12), step.k
        dc, dn = casm.dense(qc), rasm.dense(qn)
        assert _close(qc.full.Gx, qn.Gx), step.k
        assert _close(qc.full.free, qn.free), step.k
        for key in ("H", "A", "lower", "upper"):
            assert _close(getattr(dc, key), getattr(dn, key)), (step.k, key)
        assert _close(dc.f, dn.f, 1e-9), step.k  # a difference of nearly equal terms
        assert np.array_equal(dc.kinds, dn.kinds) and dc.n_hard == dn.n_hard
        nx = qn.Gx.shape[0]
        two = np.count_nonzero(rn.selection(nx + qn.Gx.shape[1])[:, :nx], axis=1) == 2
        checked.append("hp" if np.any(two) else "box")
    assert len(checked) >= 5
    if case == "triangle":
        assert "hp" in checked  # half-plane rows were compared


@pytest.mark.parametrize("case", ["table1", "triangle", "psi"])
def test_backends_give_the_same_minimiser(case, recorded):
    """Every 10th step's QP on the Python path of both backends (the compiled assembly's dense
    QP and the numpy assembly's, every hard row given to DAQP): the same moves."""
    diffs = []
    for step in recorded(case):
        (casm, qc), (rasm, qn) = both(step)
        zc, zn = casm.solve(qc, step.start), rasm.solve(qn, step.start)
        assert zc.ok and zn.ok
        diffs.append(float(np.abs(zc.z - zn.z).max()))
    assert len(diffs) >= 10
    assert max(diffs) < 1e-8  # scaled moves (force / force_max)


@pytest.mark.parametrize("case", ["table1", "psi"])
def test_compiled_plan_equals_numpy_plan(case):
    """The whole plan: the compiled path (one compiled call per step, the stage-wise solver;
    equalities eliminated on Table I, none on the turning corridor) against the numpy
    reference (every row given to DAQP)."""
    req = CASES[case]()
    fast = plan_json(req)
    ref = plan_json(with_settings(req, backend="reference"))
    P, Pr = np.array(fast["pose"]), np.array(ref["pose"])
    assert P.shape == Pr.shape
    assert np.abs(P - Pr).max() < 1e-9
    assert np.abs(np.array(fast["drives"]["force"]) - np.array(ref["drives"]["force"])).max() < 1e-6
    assert fast["metrics"]["qp_refinements"] == ref["metrics"]["qp_refinements"]
