"""Constrained mode (issue 6): hard corridor, drive limits, no overshoot, psi ranges.

Every property is checked on the *actual* (nonlinear) trajectory the planner returns,
recomputed here from the result's samples, not taken from the planner's own metrics.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from planner.constrained import END_TOL_M, END_TOL_RAD, halfplanes
from planner.errors import PlannerError
from planner.plan import plan
from planner.robot import builtin_description, load_robot

TABLE1 = Path("/work/shared/data/table1-corridor.json")
PSI_TURN = Path(__file__).resolve().parents[1] / "static" / "examples" / "psi-turn.json"
TOL = 1e-9  # m


def table1() -> dict:
    if TABLE1.exists():
        return json.loads(TABLE1.read_text())
    cells = [(-0.08, 0.0), (-0.06, 0.0), (-0.04, 0.0), (-0.04, 0.02), (-0.02, 0.02), (0.0, 0.02),
             (0.0, 0.0), (0.02, 0.0), (0.04, 0.0), (0.04, 0.02)]
    segs = [{"lower": [-0.08, 0.0, 0.0], "upper": [-0.08, 0.0, 0.0]}]
    segs += [{"lower": [x, y, 0.0], "upper": [x + 0.02, y + 0.02, 0.0]} for x, y in cells]
    segs += [{"lower": [0.06, 0.04, 0.0], "upper": [0.06, 0.04, 0.0]}]
    return {"robot": "moving-slide", "segments": segs}


def psi_turn() -> dict:
    """static/examples/psi-turn.json: psi ranges 0..0.12 rad over four 20 mm cells."""
    return json.loads(PSI_TURN.read_text())


def constrained(req: dict, **settings) -> dict:
    req = copy.deepcopy(req)
    req["settings"] = {**req.get("settings", {}), "mode": "constrained", **settings}
    return req


def box_union_violation(P: np.ndarray, segments: list[dict]) -> np.ndarray:
    lo = np.array([s["lower"][:2] for s in segments])
    hi = np.array([s["upper"][:2] for s in segments])
    d = np.linalg.norm(np.maximum(np.maximum(lo[None] - P[:, None, :2], 0), P[:, None, :2] - hi[None]), axis=2)
    return d.min(axis=1)


def check_limits(res: dict, robot) -> None:
    """Forces, strokes and leg speeds of the actual trajectory within the robot's limits."""
    F = np.array(res["drives"]["force"])
    assert np.all(np.abs(F) <= robot.force_max * (1 + 1e-12)), np.abs(F).max()
    P = np.array(res["pose"])
    V = np.array(res["velocity"])
    L = robot.leg_lengths(P)
    assert np.all(L >= robot.length_min - TOL) and np.all(L <= robot.length_max + TOL)
    ldot = np.einsum("kij,kj->ki", robot.leg_jacobian_batch(P), V)
    assert np.all(np.abs(ldot) <= robot.speed_max), np.abs(ldot).max()


def end_and_overshoot(res: dict, req: dict) -> tuple[float, float]:
    segs = req["segments"]
    P = np.array(res["pose"])[:, :2]
    end = np.array(segs[-1]["lower"][:2])
    d = end - 0.5 * (np.array(segs[-2]["lower"][:2]) + np.array(segs[-2]["upper"][:2]))
    d /= np.linalg.norm(d)
    return float(np.linalg.norm(P[-1] - end)), float(max(0.0, ((P - end) @ d).max()))


@pytest.fixture(scope="module")
def table1_plans():
    req = table1()
    return req, plan(constrained(req)), plan(req)


def test_table1_constrained_stays_in_the_corridor(table1_plans):
    req, res, paper = table1_plans
    P = np.array(res["pose"])
    viol = box_union_violation(P, req["segments"])
    assert viol.max() <= TOL
    assert res["metrics"]["max_corridor_violation_m"] <= TOL
    assert res["metrics"]["contained"] is True
    assert res["metrics"]["infeasible_steps"] == 0
    # the same check fails for the paper's soft criterion: the test can tell the difference
    assert box_union_violation(np.array(paper["pose"]), req["segments"]).max() > 1e-5
    # the time-indexed range: kept everywhere except the micrometre stop box at the end point
    ti = np.array(res["corridor"]["violation_m"])
    assert ti.max() <= np.sqrt(2) * END_TOL_M + TOL
    K = res["metrics"]["steps"]
    lower, upper = np.array(res["corridor"]["lower"]), np.array(res["corridor"]["upper"])
    moving = np.any(upper[:, :2] - lower[:, :2] > 1e-9, axis=1)
    assert ti[moving].max() <= TOL and K > 0


def test_table1_constrained_limits_end_and_overshoot(table1_plans):
    req, res, _ = table1_plans
    check_limits(res, load_robot("moving-slide"))
    end_err, over = end_and_overshoot(res, req)
    assert end_err < 1e-4 and res["metrics"]["end_error_m"] < 1e-4
    assert over < 1e-4 and res["metrics"]["overshoot_m"] < 1e-4
    assert res["metrics"]["settled"]
    # at rest at the end
    assert np.linalg.norm(np.array(res["velocity"])[-1, :2]) < 1e-3


def test_overshoot_reported_in_both_modes(table1_plans):
    _, res, paper = table1_plans
    assert "overshoot_m" in res["metrics"] and "overshoot_m" in paper["metrics"]
    assert res["mode"] == "constrained" and paper["mode"] == "paper"


def test_mode_defaults():
    """Left out (or null), N, k_r and k_u take the mode's defaults; the segments keep 20
    samples unless N or samples_per_segment is given; given values win; the HTTP model does
    not fill in paper values."""
    from app.schema import PlanRequestModel, request_dict
    from planner.request import MODE_DEFAULTS, parse_request, parse_settings

    for mode in ("paper", "constrained"):
        d = MODE_DEFAULTS[mode]
        s = parse_settings({"mode": mode})
        assert (s.N, s.k_r, s.k_u, s.S) == (d["N"], d["k_r"], d["k_u"], 20)
        s = parse_settings({"mode": mode, "N": 10, "k_r": None})
        assert (s.N, s.S, s.k_r, s.k_u) == (10, 10, d["k_r"], d["k_u"])
        s = parse_settings({"mode": mode, "k_r": 2.0, "k_u": 1e-2, "samples_per_segment": 7})
        assert (s.N, s.S, s.k_r, s.k_u) == (d["N"], 7, 2.0, 1e-2)
        body = request_dict(PlanRequestModel.model_validate({**table1(), "settings": {"mode": mode}}))
        s = parse_request(body).settings
        assert (s.N, s.k_r, s.k_u, s.S) == (d["N"], d["k_r"], d["k_u"], 20)
    assert parse_settings({}).mode == "paper"


def test_constrained_defaults_spend_less_energy_than_the_paper_penalties(table1_plans):
    """The constrained defaults (lighter pull, longer horizon) against the paper mode's
    penalties in constrained mode on Table I: same corridor timing, everything kept, at least
    20 % less drive energy (the reason for the defaults, see planner.request.MODE_DEFAULTS)."""
    from planner.request import MODE_DEFAULTS

    req, res, _ = table1_plans
    heavy = plan(constrained(req, **MODE_DEFAULTS["paper"]))
    for r in (res, heavy):
        assert r["metrics"]["contained"] and r["metrics"]["settled"] and r["metrics"]["infeasible_steps"] == 0
    assert res["metrics"]["steps"] == heavy["metrics"]["steps"]
    assert res["settings"]["samples_per_segment"] == heavy["settings"]["samples_per_segment"] == 20
    assert res["metrics"]["energy"] < 0.8 * heavy["metrics"]["energy"]


def test_force_limit_active_and_kept():
    """With force_max below what the unlimited constrained plan uses, the constrained plan
    saturates the drives but never exceeds them, and still keeps the corridor."""
    req = table1()
    free = plan(constrained(req))["metrics"]["max_drive_force_n"]
    limit = round(0.85 * free, 3)
    desc = builtin_description("moving-slide")
    assert desc["legs"]["force_max"] > free  # the built-in limit does not bind on Table I
    desc["legs"] = dict(desc["legs"], force_max=limit)
    req["robot"] = desc
    res = plan(constrained(req))
    robot = load_robot(desc)
    check_limits(res, robot)
    assert res["metrics"]["max_drive_force_n"] > 0.99 * limit  # active
    assert box_union_violation(np.array(res["pose"]), req["segments"]).max() <= TOL
    assert res["metrics"]["contained"] and res["metrics"]["settled"]


def test_speed_limit_active_and_kept():
    desc = builtin_description("moving-slide")
    desc["legs"] = dict(desc["legs"], speed_max=0.12)
    req = table1()
    req["robot"] = desc
    assert plan(req)["metrics"]["max_drive_speed_m_s"] > 0.12
    res = plan(constrained(req))
    check_limits(res, load_robot(desc))
    assert res["metrics"]["max_drive_speed_m_s"] > 0.99 * 0.12
    assert res["metrics"]["contained"]


def test_too_tight_time_is_reported_infeasible():
    req = table1()
    with pytest.raises(PlannerError) as exc:
        plan(constrained(req, samples_per_segment=3))
    assert exc.value.code == "infeasible"
    res = plan(constrained(req, samples_per_segment=3, require_settled=False))
    mt = res["metrics"]
    assert mt["infeasible_steps"] > 0 and mt["constraint_slack_max_m"] > 0
    assert mt["contained"] is False


def test_too_weak_drives_reported_infeasible():
    desc = builtin_description("moving-slide")
    desc["legs"] = dict(desc["legs"], force_max=3.0)
    req = table1()
    req["robot"] = desc
    req = constrained(req, total_time_s=1.0)
    with pytest.raises(PlannerError) as exc:
        plan(req)
    assert exc.value.code == "infeasible"
    req["settings"]["require_settled"] = False
    res = plan(req)
    assert res["metrics"]["contained"] is False
    # forces stay hard even when the corridor cannot be kept
    assert np.abs(np.array(res["drives"]["force"])).max() <= 3.0 * (1 + 1e-12)


def test_psi_ranges_honoured():
    """A corridor that turns the platform: psi ranges per segment, each narrower than the
    paper's pull to the middle would need; the constrained plan keeps every sample's psi in
    its range (time-indexed) to 1e-9 rad."""
    res = plan(constrained(psi_turn()))
    P = np.array(res["pose"])
    lo, hi = np.array(res["corridor"]["lower"]), np.array(res["corridor"]["upper"])
    wide = hi[:, 2] - lo[:, 2] > 1e-9
    psi_out = np.maximum(np.maximum(lo[:, 2] - P[:, 2], 0), P[:, 2] - hi[:, 2])
    assert psi_out[wide].max() <= 1e-9
    # the end point's angle: a micrometre-radian stop box inside the last cell's angle range
    assert psi_out.max() <= END_TOL_RAD + 1e-9
    assert P[:, 2].min() >= -1e-9 and P[:, 2].max() <= 0.12 + 1e-9  # the segments' angle ranges
    assert abs(P[-1, 2] - 0.12) < 1e-4
    assert res["metrics"]["contained"]


def _layout(shape: str) -> dict:
    return {"robot": "moving-slide",
            "layout": {"bounds": {"lower": [-0.1, -0.05], "upper": [0.1, 0.08]},
                       "obstacles": [{"type": "rectangle", "lower": [-0.02, -0.05], "upper": [0.01, 0.03]}],
                       "clearance": 0.0, "cell": {"shape": shape, "size": 0.02},
                       "start": [-0.08, 0.0, 0.0], "end": [0.07, 0.0, 0.0]},
            "settings": {"mode": "constrained"}}


@pytest.mark.parametrize("shape", ["square", "triangle"])
def test_obstacle_layout_constrained(shape):
    """Around an obstacle, with square or triangular cells: every actual sample inside the
    union of the exact cells (shapely, independent of the planner), clear of the obstacle."""
    shapely = pytest.importorskip("shapely")
    pytest.importorskip("planner.segmentation")
    from planner.request import parse_request
    from planner.segmentation import corridor_from_request

    req = _layout(shape)
    robot = load_robot("moving-slide")
    segments = corridor_from_request(parse_request(req), robot).segments
    res = plan(req)
    P = np.array(res["pose"])
    cells = [shapely.Polygon(s.polygon) if s.polygon is not None else shapely.box(*s.lower[:2], *s.upper[:2])
             for s in segments if not s.is_point]
    union = shapely.union_all(cells + [shapely.Point(segments[0].centre[:2]), shapely.Point(segments[-1].centre[:2])])
    dist = shapely.distance(union, shapely.points(P[:, :2]))
    assert dist.max() <= TOL
    obstacle = shapely.box(-0.02, -0.05, 0.01, 0.03)
    assert not np.any(shapely.contains(obstacle, shapely.points(P[:, :2])))
    check_limits(res, robot)
    assert res["metrics"]["end_error_m"] < 1e-4 and res["metrics"]["overshoot_m"] < 1e-4
    assert res["metrics"]["contained"]


def test_triangle_half_planes():
    A, b = halfplanes([[0, 0], [1, 0], [0, 1]])
    assert np.allclose(np.linalg.norm(A, axis=1), 1)
    assert np.all(A @ np.array([0.2, 0.2]) < b)
    assert np.any(A @ np.array([0.6, 0.6]) > b)
    A2, b2 = halfplanes([[0, 0], [0, 1], [1, 0]])  # clockwise gives the same set
    assert np.all(A2 @ np.array([0.2, 0.2]) < b2) and np.any(A2 @ np.array([0.6, 0.6]) > b2)


def test_predictions_match_plant():
    """The one-step mismatch between the QP's prediction and the nonlinear plant stays far
    below the corridor margin (this is what makes the hard constraints hold on the plant)."""
    from planner.constrained import MARGIN_M

    res = plan(constrained(table1()))
    assert res["metrics"]["model_mismatch_max_m"] < 0.01 * MARGIN_M


def test_layout_with_end_angle_settles_in_constrained_mode():
    """Triangle cells around a round obstacle, the platform turning to 0.1 rad at the end:
    the robot stops at the end pose (an equality on psi at every end sample would leave a
    residual rotation flipping sign forever) and every sample keeps the angle range."""
    pytest.importorskip("planner.segmentation")
    req = {"robot": "moving-slide",
           "layout": {"bounds": {"lower": [-0.1, -0.05], "upper": [0.1, 0.08]},
                      "obstacles": [{"type": "circle", "center": [0.0, 0.0], "radius": 0.02}],
                      "cell": {"shape": "triangle", "size": 0.015},
                      "start": [-0.08, 0.0, 0.0], "end": [0.07, 0.0, 0.1], "psi_range": [-0.05, 0.15]},
           "settings": {"mode": "constrained"}}
    res = plan(req)
    mt = res["metrics"]
    assert mt["settled"] and mt["contained"]
    P = np.array(res["pose"])
    assert abs(P[-1, 2] - 0.1) < 1e-4 and np.linalg.norm(P[-1, :2] - [0.07, 0.0]) < 1e-4
    assert P[:, 2].min() >= -0.05 - 1e-9 and P[:, 2].max() <= 0.15 + 1e-9
    assert mt["overshoot_m"] < 1e-4
    check_limits(res, load_robot("moving-slide"))


# ---- the compiled path (planner/constrained_kernels.py) against the numpy reference ------

def _psi_corridor() -> dict:
    """Turning platform: psi ranges of non-zero width (no equality rows but at the ends)."""
    return constrained(psi_turn())


def _close(a, b, rel=1e-10) -> bool:
    a, b = np.asarray(a, float), np.asarray(b, float)
    fin = np.isfinite(b)
    if not np.array_equal(np.isfinite(a), fin):
        return False
    scale = max(float(np.abs(b[fin]).max(initial=0.0)), 1e-300)
    return bool(np.all(np.abs(a[fin] - b[fin]) <= rel * scale))


@pytest.mark.parametrize("case", ["table1", "triangle", "psi"])
def test_compiled_assembly_equals_numpy_assembly(case, monkeypatch):
    """At every 20th step the compiled QP equals the numpy reference's QP in z: prediction,
    Hessian, linear term, every row (corridor boxes, triangle half-planes, no-overshoot,
    leg speeds and strokes) and its bounds."""
    from planner import constrained as C

    make = {"table1": lambda: constrained(table1()), "triangle": lambda: _layout("triangle"), "psi": _psi_corridor}
    req = make[case]()
    orig = C.ConstrainedController.__call__
    checked = []

    def spy(self, k, x, Ad, Bd):
        if k % 20 == 0:
            qc = self.z_problem(self.build(k, x, Ad, Bd))
            monkeypatch.setattr(C.ConstrainedController, "compiled", False)
            qn = self.build(k, x, Ad, Bd)
            monkeypatch.setattr(C.ConstrainedController, "compiled", True)
            for key in ("Gx", "free", "H", "A", "bl", "bu"):
                assert _close(qc[key], qn[key]), (k, key)
            assert _close(qc["f"], qn["f"], 1e-9), k  # a difference of nearly equal terms
            assert np.array_equal(qc["kinds"], qn["kinds"]) and qc["n_hard"] == qn["n_hard"]
            checked.append("hp" if np.any(np.count_nonzero(qn["Sel"], axis=1) == 2) else "box")
        return orig(self, k, x, Ad, Bd)

    monkeypatch.setattr(C.ConstrainedController, "__call__", spy)
    plan(req)
    assert len(checked) >= 5
    if case == "triangle":
        assert "hp" in checked  # half-plane rows were compared


@pytest.mark.parametrize("q_u", [None, [1e-3, 3e-3, 5e-4, 1.5e-3]])
def test_eliminated_equalities_give_the_same_minimiser(q_u, monkeypatch):
    """Table I fixes psi = 0: one equality row per sample. The compiled path eliminates them
    (and gives DAQP only the rows near a bound); its moves equal those of DAQP on the whole
    QP in z, every row given, equalities as equalities. Unequal drive weights ``q_u`` make
    the reduced Hessian's coupling terms between moves non-zero."""
    from planner import constrained as C

    orig = C.ConstrainedController.__call__
    diffs = []

    def spy(self, k, x, Ad, Bd):
        if k % 10 == 0:
            qp = self.build(k, x, Ad, Bd)
            assert "red" in qp  # the elimination is in use
            nw = qp["red"][1]
            assert nw < self.nz
            z_red, flag_red, _ = self._solve_hard(qp)
            z_full, flag_full, _ = self._solve_hard_numpy(self.z_problem(qp))
            assert flag_red == 1 and flag_full == 1
            diffs.append(float(np.abs(z_red - z_full).max()))
        return orig(self, k, x, Ad, Bd)

    monkeypatch.setattr(C.ConstrainedController, "__call__", spy)
    plan(constrained(table1(), **({"q_u": q_u} if q_u else {})))
    assert len(diffs) >= 20
    assert max(diffs) < 1e-7  # scaled moves (force / force_max)


@pytest.mark.parametrize("case", ["table1", "psi"])
def test_compiled_plan_equals_numpy_plan(case, monkeypatch):
    """The whole plan: compiled path (equalities eliminated on Table I, the QP in z on the
    turning corridor) against the numpy reference with every row given to the solver."""
    from planner import constrained as C

    req = constrained(table1()) if case == "table1" else _psi_corridor()
    fast = plan(req)
    monkeypatch.setattr(C.ConstrainedController, "compiled", False)
    ref = plan(req)
    P, Pr = np.array(fast["pose"]), np.array(ref["pose"])
    assert P.shape == Pr.shape
    assert np.abs(P - Pr).max() < 1e-9
    assert np.abs(np.array(fast["drives"]["force"]) - np.array(ref["drives"]["force"])).max() < 1e-6
    assert fast["metrics"]["qp_refinements"] == ref["metrics"]["qp_refinements"]
