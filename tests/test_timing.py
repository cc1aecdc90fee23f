"""Segment timing (issue 6): speed target, total time, fastest feasible timing."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from planner.errors import PlannerError
from planner.orchestrator.timing import centre_path_length, feasible
from planner.schema import PlanResult, parse_request
from tests.support import TABLE1
from tests.support import plan_json as plan


def table1() -> dict:
    return copy.deepcopy(TABLE1)


def with_settings(req: dict, **settings) -> dict:
    req = copy.deepcopy(req)
    req["settings"] = {**req.get("settings", {}), **settings}
    return req


def travel_time(res: dict, start, end) -> float:
    """Actual time [s] from the last sample at the start point to the first sample from
    which the robot stays within 0.1 mm of the end point."""
    P = np.array(res["pose"])[:, :2]
    t = np.array(res["time"])
    left = np.nonzero(np.linalg.norm(P - start, axis=1) > 1e-9)[0][0] - 1
    away = np.linalg.norm(P - end, axis=1) >= 1e-4
    arrived = np.nonzero(away)[0][-1] + 1
    return float(t[arrived] - t[left])


def test_centre_path_length_table1():
    req = parse_request(table1())
    c = np.array([s.centre[:2] for s in req.segments])
    manual = sum(np.linalg.norm(c[i + 1] - c[i]) for i in range(len(c) - 1))
    assert centre_path_length(req.segments) == pytest.approx(manual)
    assert manual > 0.2  # 9 cell steps of 20 mm plus two half-diagonals


@pytest.mark.parametrize("speed", [0.05, 0.1, 0.2])
def test_speed_target_gives_expected_travel_time(speed):
    req = table1()
    res = plan(with_settings(req, mode="constrained", speed_m_s=speed))
    segs = parse_request(req).segments
    n, Ts = len(segs), 0.01
    L = centre_path_length(segs)
    expected = L / speed
    # the sequence's moving part: (n - 2) segments of S samples
    assert res["timing"]["method"] == "speed_m_s"
    assert abs(res["timing"]["moving_time_s"] - expected) <= (n - 2) * Ts
    # the actual trajectory: leaves the start and reaches the end point that far apart
    tt = travel_time(res, segs[0].centre[:2], segs[-1].centre[:2])
    assert abs(tt - expected) <= (n - 2) * Ts + 2 * Ts
    assert res["metrics"]["contained"]


def test_total_time_sets_sequence_duration():
    req = table1()
    res = plan(with_settings(req, mode="constrained", total_time_s=1.5))
    n = len(req["segments"])
    S = res["settings"]["samples_per_segment"]
    assert abs(n * S * 0.01 - 1.5) <= n * 0.01 / 2 + 1e-12
    # the robot is at the end point (within 0.1 mm) by the end of the sequence
    P = np.array(res["pose"])[:, :2]
    k_end = n * S
    assert np.linalg.norm(P[k_end] - np.array(req["segments"][-1]["lower"][:2])) < 1e-4
    # paper mode accepts it too
    paper = plan(with_settings(req, total_time_s=1.5))
    assert paper["settings"]["samples_per_segment"] == S


def test_fastest_respects_limits_and_one_faster_does_not():
    req = table1()
    res = plan(with_settings(req, mode="constrained", fastest=True))
    mt = res["metrics"]
    S = res["settings"]["samples_per_segment"]
    assert res["timing"]["method"] == "fastest" and res["timing"]["feasible"]
    assert mt["contained"] and mt["within_limits"] and mt["settled"]
    F = np.abs(np.array(res["drives"]["force"]))
    assert F.max() <= 150.0 * (1 + 1e-12)
    assert np.abs(np.array(res["drives"]["velocity"])).max() <= 0.5
    # faster than the default timing
    assert S < 20
    # one sample per segment fewer is not feasible
    faster = plan(with_settings(req, mode="constrained", samples_per_segment=S - 1, require_settled=False))
    assert not feasible(PlanResult.model_validate(faster))


@pytest.mark.parametrize("settings, field", [
    ({"samples_per_segment": 10, "speed_m_s": 0.1}, "settings.speed_m_s"),
    ({"speed_m_s": 0.1, "total_time_s": 2.0}, "settings.total_time_s"),
    ({"mode": "constrained", "total_time_s": 2.0, "fastest": True}, "settings.fastest"),
    ({"fastest": True, "mode": "paper"}, "settings.fastest"),  # paper mode does not keep limits
    ({"speed_m_s": 0}, "settings.speed_m_s"),
    ({"total_time_s": -1}, "settings.total_time_s"),
    ({"fastest": "yes", "mode": "constrained"}, "settings.fastest"),
])
def test_bad_timing_settings_name_the_field(settings, field):
    with pytest.raises(PlannerError) as exc:
        parse_request(with_settings(table1(), **settings))
    assert exc.value.code == "invalid_input" and exc.value.field == field


def test_speed_on_reference_is_an_error():
    req = {"reference": {"pose": [[0, 0, 0], [0.001, 0, 0], [0.002, 0, 0]]}, "settings": {"speed_m_s": 0.1}}
    with pytest.raises(PlannerError) as exc:
        plan(req)
    assert exc.value.field == "settings.speed_m_s"


def test_too_slow_is_too_large():
    with pytest.raises(PlannerError) as exc:
        plan(with_settings(table1(), speed_m_s=1e-6))
    assert exc.value.code == "too_large" and exc.value.field == "settings.speed_m_s"


def test_schema_accepts_timing_fields():
    body = with_settings(table1(), mode="constrained", speed_m_s=0.1)
    d = parse_request(body).to_json_dict()  # what storage keeps, read back
    assert parse_request(d).settings.speed_m_s == 0.1


@pytest.mark.parametrize("timing", [{"speed_m_s": 0.1}, {"total_time_s": 1.5}, {}])
def test_result_settings_plan_the_same_trajectory_again(timing):
    """A result's settings are the ones the plan ran with: they validate as a request's
    settings (a client reads the result back) and, planned again, give the same trajectory;
    a speed or total time is resolved to a sample count, and timing.method keeps how."""
    req = with_settings(table1(), **timing)
    if not timing:  # a layout with no timing setting: the default tool speed
        req = {"layout": {"bounds": {"lower": [-0.08, -0.04], "upper": [0.08, 0.06]}, "obstacles": [],
                          "cell": {"shape": "square", "size": 0.02},
                          "start": [-0.06, -0.02, 0.0], "end": [0.06, 0.04, 0.0]}}
    res = plan(req)
    PlanResult.model_validate(res)  # the JSON result reads back
    assert res["timing"]["method"] == (next(iter(timing)) if timing else "speed_m_s")
    again = plan({**req, "settings": res["settings"]})
    assert again["timing"]["method"] == "samples_per_segment"
    assert again["settings"] == res["settings"]
    np.testing.assert_array_equal(np.array(again["pose"]), np.array(res["pose"]))
