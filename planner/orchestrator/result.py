"""The plan result, built in one place (:func:`build_result`) from a simulation: the
per-sample arrays, every metric computed from the returned trajectory, the controller's
figures and the timing; and its CSV form (:func:`to_csv`).

Shapes and units are documented on :class:`planner.schema.PlanResult`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..constraints import CONTAIN_TOL_M, CONTAIN_TOL_RAD, force_rate
from ..corridor import RangeSequence
from ..corridor.geometry import APPROACH_MIN_M, approach_direction, box_distance, corridor_distances
from ..errors import PlannerError
from ..model import RobotModel, kinematics
from ..schema import UNITS, CorridorSamples, CorridorSegment, Drives, Metrics, PlanResult, Segment, Settings, Timing
from .simulate import Simulation

__all__ = ["build_result", "limit_metrics", "overshoot", "rates_within", "to_csv", "csv_columns"]


def overshoot(poses: np.ndarray, direction: np.ndarray | None, end: np.ndarray, first_sample: int) -> float:
    """How far [m] the robot passes the end point along the approach ``direction`` (unit,
    (2,); :func:`planner.corridor.geometry.approach_direction`), over the samples from
    ``first_sample`` on. 0 when it never passes it (or there is no direction)."""
    if direction is None:
        return 0.0
    past = (poses[first_sample:, :2] - end[:2]) @ direction
    return float(max(0.0, past.max(initial=0.0)))


def _trajectory_direction(poses: np.ndarray, end: np.ndarray, first_sample: int) -> np.ndarray | None:
    """For a tracked reference (no segments): from the pose at ``first_sample - 1`` to the end."""
    d = end[:2] - poses[max(first_sample - 1, 0), :2]
    n = float(np.hypot(d[0], d[1]))
    return d / n if n > APPROACH_MIN_M else None


def _check_finite(**arrays: np.ndarray) -> None:
    for name, a in arrays.items():
        if not np.all(np.isfinite(a)):
            raise PlannerError("diverged", f"the planner produced a non-finite number in {name}; try a smaller "
                               "sample time or larger k_u", "settings")


#: relative tolerance of the drive-force rates in ``within_limits`` (the rounding of the
#: forces' differences; the applied moves are clipped to their rate rows, issue 31)
RATE_TOL_REL = 1e-9

#: relative tolerance of the tool speed in ``within_limits`` (``settings.tool_speed_max_m_s``;
#: the rows hold a polygon inside the speed circle, so the plan keeps below it)
TOOL_SPEED_TOL_REL = 1e-9


def rates_within(robot: RobotModel, st: Settings, dU: np.ndarray) -> bool:
    """Whether the drive-force steps ``dU`` [N] (a sample each) keep the force-rate limit of
    ``st`` (to the relative tolerance :data:`RATE_TOL_REL`; no limit: true)."""
    rate = force_rate(robot, st)  # per drive [N/s], None: no limit
    return rate is None or bool(np.all(np.abs(dU) <= rate * st.Ts * (1.0 + RATE_TOL_REL)))


def limit_metrics(robot: RobotModel, st: Settings, velocity: np.ndarray, lengths: np.ndarray, leg_velocity: np.ndarray,
                  force: np.ndarray, start_force: np.ndarray | None = None) -> dict:
    """The drive-limit metrics of a sampled plan (the one implementation: a plan's result,
    :func:`build_result`, and a contour's joined parts, :func:`planner.contour.join.join_parts`):
    the largest drive force, force rate, leg speed, stroke violation and tool speed, and in the
    constrained mode ``within_limits``. ``force`` (K, n_legs): the forces held from each sample
    to the next, the last row the plan's end (not a force applied); the rates are the steps of
    the forces applied, the first from ``start_force`` (zero if None: the robot at rest)."""
    K = len(force)
    before = np.zeros((1, force.shape[1])) if start_force is None else np.asarray(start_force, float).reshape(1, -1)
    # drive-force rates: the force steps at each sample (from the forces before the start) over Ts;
    # the last row is the zero of the plan's end, not a force applied
    dU = np.diff(np.vstack((before, force[:-1])), axis=0) if K > 1 else np.zeros((0, force.shape[1]))
    stroke = float(np.max(np.maximum(np.maximum(robot.length_min - lengths, 0), lengths - robot.length_max)))
    out = {
        "max_drive_force_n": float(np.abs(force).max()),
        "max_force_rate_n_s": float(np.abs(dU).max(initial=0.0) / st.Ts),
        "force_limit_n": float(robot.force_max.min()),
        "max_force_ratio": float((np.abs(force) / robot.force_max).max()),
        "max_drive_speed_m_s": float(np.abs(leg_velocity).max()),
        "max_speed_ratio": float((np.abs(leg_velocity) / robot.speed_max).max()),
        "max_stroke_violation_m": stroke,
        "max_tool_speed_m_s": float(np.hypot(velocity[:, 0], velocity[:, 1]).max()),
    }
    if st.mode == "constrained":
        rate_ok = rates_within(robot, st, dU)
        tool_ok = (st.tool_speed_max_m_s is None
                   or out["max_tool_speed_m_s"] <= st.tool_speed_max_m_s * (1.0 + TOOL_SPEED_TOL_REL))
        out["within_limits"] = bool(out["max_force_ratio"] <= 1.0 + 1e-12 and out["max_speed_ratio"] <= 1.0
                                    and stroke <= CONTAIN_TOL_M and rate_ok and tool_ok)
    return out


def build_result(robot: RobotModel, name: str | None, st: Settings, seq: RangeSequence,
                 segments: Sequence[Segment] | None, sim: Simulation, controller_report: dict,
                 timing: Timing, start_force: np.ndarray | None = None) -> PlanResult:
    """The result of one simulated plan. ``compute_ms`` is left 0 for the caller to set.
    ``start_force``: the forces held before the first sample (:func:`limit_metrics`)."""
    X, U, ACC, steps = sim.X, sim.U, sim.ACC, sim.steps
    _check_finite(pose=X, force=U, acceleration=ACC)
    K = steps + 1
    t = np.arange(K) * st.Ts
    poses, vel = X[:, :3], X[:, 3:]
    lengths = kinematics.leg_lengths(robot, poses)
    leg_vel = np.einsum("kij,kj->ki", kinematics.leg_jacobians(robot, poses), vel)
    # per-sample ranges used by the criterion (sample 0: the start point); every figure below
    # is O(1) per sample: each sample knows its range and its segment
    idx = np.minimum(np.arange(K) - 1, seq.K - 1)
    lower = seq.lower[idx].copy()
    upper = seq.upper[idx].copy()
    lower[0] = upper[0] = seq.start
    ti_violation = box_distance(poses[:, :2], lower[:, :2], upper[:, :2])
    ti_violation_rad = np.maximum(np.maximum(lower[:, 2] - poses[:, 2], 0.0), poses[:, 2] - upper[:, 2])
    poly_violation = None
    if segments is not None:
        segment_of = seq.segment[np.maximum(idx, 0)]
        segment_of[0] = 0
        dist = corridor_distances(poses, segment_of, segments)
        union_violation, psi_violation, poly_violation = dist.xy, dist.psi, dist.polygon
        n = len(segments)
        first = int(np.argmax(seq.segment >= n - 2)) + 1 if n >= 2 else 0  # the last cell's samples on
        direction = approach_direction(segments)
    else:
        union_violation, psi_violation = ti_violation, ti_violation_rad
        first = max(seq.K - st.N, 0)
        direction = _trajectory_direction(poses, seq.end, first)
    limits = limit_metrics(robot, st, vel, lengths, leg_vel, U, start_force)
    metrics = {
        "duration_s": float(t[-1]),
        "steps": int(steps),
        "settled": bool(sim.settled),
        "end_error_m": float(np.hypot(*(poses[-1, :2] - seq.end[:2]))),
        "end_error_rad": float(abs(poses[-1, 2] - seq.end[2])),
        "end_speed_m_s": float(np.hypot(vel[-1, 0], vel[-1, 1])),
        "overshoot_m": overshoot(poses, direction, seq.end, first),
        "max_corridor_violation_m": float(union_violation.max()),
        "max_corridor_violation_rad": float(psi_violation.max()),
        "time_indexed_violation_m": float(ti_violation.max()),
        "time_indexed_violation_rad": float(ti_violation_rad.max()),
        **{k: v for k, v in limits.items() if k != "within_limits"},
        "min_singularity_measure": float(kinematics.singularity_measure(robot, poses).min()),
        "energy": float(np.sum(U * U) * st.Ts),
        "path_length_m": float(np.sum(np.hypot(*np.diff(poses[:, :2], axis=0).T))),
        "compute_ms": 0.0,
        **controller_report,
    }
    if st.mode == "constrained":  # containment judged on the actual (nonlinear) trajectory
        union = metrics["max_corridor_violation_m"]
        if poly_violation is not None:
            pv = float(poly_violation.max())
            metrics["max_polygon_violation_m"] = pv
            union = max(union, pv)
        metrics["contained"] = bool(metrics.get("infeasible_steps", 0) == 0 and union <= CONTAIN_TOL_M
                                    and metrics["max_corridor_violation_rad"] <= CONTAIN_TOL_RAD)
        metrics["within_limits"] = limits["within_limits"]
    corridor = CorridorSamples.model_construct(
        lower=lower, upper=upper, violation_m=ti_violation,
        segments=None if segments is None else
        [CorridorSegment.model_construct(lower=s.lower, upper=s.upper, polygon=s.polygon) for s in segments])
    return PlanResult.model_construct(
        plan_id=None, name=name, robot=robot.name, mode=st.mode,
        criterion="range-space" if segments is not None else "tracking",
        settings=st, units=UNITS, time=t, pose=poses, velocity=vel, acceleration=ACC,
        drives=Drives.model_construct(length=lengths, velocity=leg_vel, force=U),
        corridor=corridor, metrics=Metrics.model_construct(**{**dict.fromkeys(Metrics.model_fields), **metrics}),
        timing=timing)


def csv_columns(n_legs: int) -> list[str]:
    """The CSV header: each column named with its unit."""
    cols = ["time_s", "x_m", "y_m", "psi_rad", "vx_m_s", "vy_m_s", "psi_dot_rad_s",
            "ax_m_s2", "ay_m_s2", "psi_ddot_rad_s2"]
    cols += [f"leg{i + 1}_length_m" for i in range(n_legs)]
    cols += [f"leg{i + 1}_velocity_m_s" for i in range(n_legs)]
    cols += [f"leg{i + 1}_force_n" for i in range(n_legs)]
    cols += ["range_lower_x_m", "range_lower_y_m", "range_lower_psi_rad",
             "range_upper_x_m", "range_upper_y_m", "range_upper_psi_rad", "range_violation_m"]
    return cols


def to_csv(result: PlanResult, header: Sequence[str] = ()) -> str:
    """One row per sample, a header naming each column with its unit; ``header`` lines come
    first as ``# `` comment lines (the editor's design, plan id, request hash). Numbers are
    written as Python's shortest round-trip ``repr`` (what ``csv.writer`` wrote before; no
    value needs quoting), joined in C: ~3x faster than the csv module for a large plan; a
    negative zero is written as ``0.0``."""
    d, c = result.drives, result.corridor
    table = np.column_stack((result.time, result.pose, result.velocity, result.acceleration, d.length, d.velocity,
                             d.force, c.lower, c.upper, c.violation_m)) + 0.0  # + 0.0: never "-0.0"
    lines = ["# " + " ".join(str(line).splitlines()) for line in header]
    lines.append(",".join(csv_columns(np.asarray(d.force).shape[1])))
    lines += [",".join(map(repr, row)) for row in table.tolist()]
    lines.append("")
    return "\n".join(lines)
