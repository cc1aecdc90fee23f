"""The plan loop end to end (paper mode): Table I, a 3RPR robot, tracking, errors."""

import copy

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from planner.corridor import range_sequence
from planner.errors import PlannerError
from planner.model import dynamics, kinematics, load_robot
from planner.schema import parse_request
from tests.support import TABLE1, robot_description
from tests.support import plan_json as plan


def table1(**settings):
    """Table I in the paper mode (the default mode is the constrained one since issue 17)."""
    req = copy.deepcopy(TABLE1)
    req["settings"] = {"mode": "paper", **settings}
    return req


@pytest.fixture(scope="module")
def t1():
    return plan(table1())


def test_table1_starts_at_start_and_ends_at_end(t1):
    pose = np.array(t1["pose"])
    assert np.allclose(pose[0], [-0.08, 0.0, 0.0], atol=0)
    assert np.linalg.norm(pose[-1, :2] - [0.06, 0.04]) < 1e-4
    assert t1["metrics"]["end_error_m"] < 1e-4
    assert t1["metrics"]["settled"]
    assert np.hypot(*t1["velocity"][-1][:2]) < 1e-3
    # the robot actually travelled the corridor: it passed near every square segment
    segs = list(TABLE1["segments"])
    for s in segs[1:-1]:
        lo, hi = np.array(s["lower"][:2]), np.array(s["upper"][:2])
        d = np.linalg.norm(np.maximum(np.maximum(lo - pose[:, :2], 0), pose[:, :2] - hi), axis=1)
        assert d.min() < 0.005


def test_table1_outputs_are_finite_and_consistent(t1):
    n = len(t1["time"])
    for key in ("pose", "velocity", "acceleration"):
        arr = np.array(t1[key])
        assert arr.shape == (n, 3) and np.all(np.isfinite(arr))
    for key in ("length", "velocity", "force"):
        arr = np.array(t1["drives"][key])
        assert arr.shape == (n, 4) and np.all(np.isfinite(arr))
    assert np.allclose(np.diff(t1["time"]), 0.01)
    force = np.array(t1["drives"]["force"])
    assert t1["metrics"]["max_drive_force_n"] == pytest.approx(np.abs(force).max())
    assert t1["metrics"]["energy"] == pytest.approx(np.sum(force**2) * 0.01)
    assert t1["metrics"]["steps"] == n - 1
    assert t1["metrics"]["duration_s"] == pytest.approx(t1["time"][-1])
    # velocity and acceleration integrate to the pose: within a sample the force is constant,
    # so pose[k+1] = pose[k] + Ts v[k] + Ts^2/2 a[k] + O(Ts^3 jerk)
    pose, vel, acc = np.array(t1["pose"]), np.array(t1["velocity"]), np.array(t1["acceleration"])
    pred = pose[:-1] + 0.01 * vel[:-1] + 0.5 * 0.01**2 * acc[:-1]
    step = np.abs(np.diff(pose, axis=0)).max()
    assert np.abs(pred - pose[1:]).max() < 1e-3 * step
    # drive lengths are the inverse kinematics of the pose
    robot = load_robot("moving-slide")
    assert np.allclose(kinematics.leg_lengths(robot, pose), t1["drives"]["length"], atol=1e-12)


def test_table1_output_and_physics_agree(t1):
    """pose[k+1] is what the nonlinear model gives from sample k under force[k]."""
    robot = load_robot("moving-slide")
    X = np.hstack((t1["pose"], t1["velocity"]))
    U = np.array(t1["drives"]["force"])
    acc = np.array(t1["acceleration"])
    for k in range(0, len(X) - 1, 17):
        sol = solve_ivp(lambda t, x, u=U[k]: dynamics.state_derivative(robot, x, u), (0, 0.01), X[k],
                        method="DOP853", rtol=1e-12, atol=1e-14)
        assert np.abs(sol.y[:3, -1] - X[k + 1, :3]).max() < 1e-9
        assert np.abs(sol.y[3:, -1] - X[k + 1, 3:]).max() < 1e-7
        assert np.allclose(acc[k], dynamics.acceleration(robot, X[k, :3], X[k, 3:], U[k]), rtol=1e-9, atol=1e-9)


def test_table1_paper_mode_is_soft_and_reports_it(t1):
    m = t1["metrics"]
    corridor = np.array(t1["corridor"]["violation_m"])
    assert m["time_indexed_violation_m"] == pytest.approx(corridor.max())
    assert 0 <= m["max_corridor_violation_m"] <= m["time_indexed_violation_m"]
    assert m["overshoot_m"] >= 0
    assert m["max_drive_force_n"] < 150.0


def test_qr_and_structured_plans_agree():
    a = plan(table1(solver="qr", N=10, k_u=2e-4))
    b = plan(table1(solver="structured", N=10, k_u=2e-4))
    assert len(a["time"]) == len(b["time"])
    assert np.abs(np.array(a["pose"]) - np.array(b["pose"])).max() < 1e-9
    assert np.abs(np.array(a["drives"]["force"]) - np.array(b["drives"]["force"])).max() < 1e-6


def test_three_leg_robot_plans_through_a_corridor():
    req = {"robot": "tri-slide", "segments": [
        {"lower": [-0.04, -0.02, 0.0], "upper": [-0.04, -0.02, 0.0]},
        {"lower": [-0.04, -0.02, 0.0], "upper": [-0.02, 0.0, 0.0]},
        {"lower": [-0.02, -0.02, 0.0], "upper": [0.0, 0.0, 0.0]},
        {"lower": [0.0, -0.02, 0.0], "upper": [0.02, 0.0, 0.0]},
        {"lower": [0.02, 0.0, 0.0], "upper": [0.02, 0.0, 0.0]},
    ]}
    r = plan(req)
    assert np.array(r["drives"]["force"]).shape[1] == 3
    assert r["metrics"]["end_error_m"] < 1e-4
    assert np.allclose(r["pose"][0], [-0.04, -0.02, 0.0])


def test_tracking_criterion_follows_a_reference():
    t = np.arange(0, 1.5, 0.01)
    s = np.clip(t / 1.0, 0, 1)
    s = s * s * (3 - 2 * s)  # smooth step
    ref = np.column_stack((-0.03 + 0.06 * s, 0.02 * s, 0.05 * s))
    r = plan({"reference": {"pose": ref.tolist()}, "settings": {"k_u": 1e-4}})
    assert r["criterion"] == "tracking"
    pose = np.array(r["pose"])
    assert np.abs(pose[:len(ref)] - ref[:len(pose)]).max() < 2e-3
    assert r["metrics"]["end_error_m"] < 1e-4


def test_orientation_range_moves_psi():
    req = table1()
    for seg in req["segments"][6:]:
        seg["lower"][2] = seg["upper"][2] = 0.1
    r = plan(req)
    assert abs(r["pose"][-1][2] - 0.1) < 1e-4


def test_range_sequence_holds_each_segment_and_tapers():
    req = parse_request(table1(N=5))
    seq = range_sequence(req.segments, req.settings, 4)
    assert seq.K == 12 * 5
    assert np.allclose(seq.lower[:5], [-0.08, 0, 0]) and np.allclose(seq.upper[:5], [-0.08, 0, 0])
    # segment 2 spreads out of the start point and reaches the full square at its last sample
    assert np.allclose(seq.upper[9], [-0.06, 0.02, 0]) and np.allclose(seq.upper[5], [-0.076, 0.004, 0])
    # segment 11 narrows onto the end point, segment 12 holds it
    assert np.allclose(seq.lower[54], [0.06, 0.04, 0]) and np.allclose(seq.upper[59], [0.06, 0.04, 0])
    lo, hi, *_ = seq.window(58, 5)
    assert np.allclose(lo, [0.06, 0.04, 0]) and np.allclose(hi, [0.06, 0.04, 0])


A, B = [-0.013, -0.0075, 0.0], [-0.010, -0.0075, 0.0]
MOVE = [{"lower": A, "upper": A}, {"lower": [-0.015, -0.0095, 0.0], "upper": [-0.008, -0.0055, 0.0]},
        {"lower": B, "upper": B}]


@pytest.mark.parametrize("S", [1, 2, 5, 8])
def test_a_single_segment_between_two_points_spreads_then_narrows(S):
    """Between two points the range spreads out of the start over the first half of its samples
    (always containing the start: a robot at rest there may stay) and narrows onto the end over
    the second half (always containing the end): spreading and narrowing at once pulled it off
    the start from the first sample, which a robot whose forces rise at a bounded rate cannot
    follow at a fine sample time."""
    req = parse_request({"segments": MOVE, "settings": {"segment_samples": [1, S, 1]}})
    seq = range_sequence(req.segments, req.settings, 4)
    lo, hi = seq.lower[1:1 + S], seq.upper[1:1 + S]
    spread, before = (S + 1) // 2, S // 2  # samples of the spreading; samples before the narrowing

    def inside(p, k):
        return np.all(lo[k] <= np.add(p, 1e-15)) and np.all(np.subtract(p, 1e-15) <= hi[k])

    assert all(inside(A, k) for k in range(before))
    assert all(inside(B, k) for k in range(spread - 1, S))
    assert np.allclose(lo[-1], B) and np.allclose(hi[-1], B)  # the last sample is at the end
    if S % 2 == 0:  # the full box between the halves
        assert np.allclose(lo[before - 1], MOVE[1]["lower"]) and np.allclose(hi[before - 1], MOVE[1]["upper"])
    if S > 2:  # the first sample: a range about the start, a fraction of the box
        assert inside(A, 0) and np.all((hi[0] - lo[0])[:2] < np.subtract(MOVE[1]["upper"], MOVE[1]["lower"])[:2])


def test_a_short_move_at_a_fine_sample_time_with_the_force_rate_limit():
    """A 3 mm move from rest to rest at Ts = 1 ms with the default force-rate limit plans (it
    found no timing at all, and took 1.7 s at 2 ms) and, with a horizon of 0.1 s, in about the
    time it takes at 10 ms."""
    coarse = plan({"segments": MOVE, "settings": {"Ts": 0.01, "fastest": True}})
    fine = plan({"segments": MOVE, "settings": {"Ts": 0.001, "N": 100, "fastest": True}})
    assert fine["metrics"]["contained"] and fine["metrics"]["within_limits"]
    assert fine["time"][-1] <= 1.2 * coarse["time"][-1]
    plain = plan({"segments": MOVE, "settings": {"Ts": 0.001, "fastest": True}})
    assert plain["metrics"]["contained"] and plain["metrics"]["within_limits"]


@pytest.mark.parametrize("mutate, code, field", [
    (lambda r: r["segments"][3].update(lower=[0.1, 0, 0]), "invalid_input", "segments[3].lower"),
    (lambda r: r.update(segments=r["segments"][:1]), "invalid_input", "segments"),
    (lambda r: r["settings"].update(Ts=0), "invalid_input", "settings.Ts"),
    (lambda r: r["settings"].update(N=10_000), "invalid_input", "settings.N"),
    (lambda r: r["settings"].update(k_u=float("nan")), "invalid_input", "settings.k_u"),
    (lambda r: r["settings"].update(bogus=1), "invalid_input", "settings.bogus"),
    (lambda r: r["segments"][5].update(upper=[0.4, 0.04, 0]), "unreachable", "segments[5]"),
    (lambda r: r.update(robot="no-such-robot"), "invalid_input", "robot"),
    (lambda r: r.update(segments=r["segments"] * 9, settings={"samples_per_segment": 2000}), "too_large",
     "settings.samples_per_segment"),
])
def test_bad_requests_name_the_field(mutate, code, field):
    req = table1()
    mutate(req)
    with pytest.raises(PlannerError) as err:
        plan(req)
    assert err.value.code == code
    assert err.value.field == field
    assert err.value.message


def test_singular_robot_is_rejected_before_planning():
    req = table1()
    desc = load_robot("moving-slide")
    d = copy.deepcopy(robot_description("moving-slide"))
    d["base_pivots"] = [[-0.3, -0.3], [0.3, -0.3], [0.3, 0.3], [-0.3, 0.3]]
    req["robot"] = d
    req["segments"] = [{"lower": [0, 0, 0], "upper": [0, 0, 0]}, {"lower": [0, 0, 0], "upper": [0.02, 0.02, 0]},
                       {"lower": [0.02, 0.02, 0], "upper": [0.02, 0.02, 0]}]
    with pytest.raises(PlannerError) as err:
        plan(req)
    assert err.value.code == "singular" and err.value.field == "segments[0]"
    assert desc.n_legs == 4


def test_unsettled_plan_is_reported_not_hidden():
    req = table1(tail_max_s=0.0, samples_per_segment=3)
    with pytest.raises(PlannerError) as err:
        plan(req)
    assert err.value.code == "not_settled" and "end error" in err.value.message
    req["settings"]["require_settled"] = False
    r = plan(req)
    assert r["metrics"]["settled"] is False and r["metrics"]["end_error_m"] > 1e-4
