"""Trajectory output: the result JSON, its metrics, and CSV.

Result (SI units, one row per sample ``k = 0..K``, ``time[k] = k Ts``)::

    time [s], pose [[x, y, psi]] [m, m, rad], velocity [m/s, m/s, rad/s],
    acceleration [m/s^2, m/s^2, rad/s^2] (the model's, under the force applied at that sample),
    drives: {length [m], velocity [m/s], force [N]} (one column per leg),
    corridor: {lower, upper} (the per-sample range used) and violation_m per sample,
    metrics: see :func:`metrics`.

``drives.force[k]`` is applied from sample ``k`` to ``k+1`` (zero-order hold); the last row
holds zero force (the plan ends, the robot is at rest). ``pose[k+1]`` is what the nonlinear
model gives from ``pose[k]``, ``velocity[k]`` under ``force[k]``.
"""

from __future__ import annotations

import csv
import io

import numpy as np

from .request import settings_dict


def _box_distance(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Euclidean distance of points ``p`` (..., d) outside boxes ``[lo, hi]`` (0 inside)."""
    return np.linalg.norm(np.maximum(np.maximum(lo - p, 0.0), p - hi), axis=-1)


def corridor_violation(poses: np.ndarray, segments) -> np.ndarray:
    """Distance [m] of each pose's (x, y) outside the union of the segments.

    The same numbers as ``_box_distance(poses[:, None, :2], lo, hi).min(axis=1)`` (the norm
    is the same sum of squares; the square root, being monotone, is taken after the minimum),
    ~3x faster on a (samples x segments) grid."""
    lo = np.array([s.lower[:2] for s in segments])
    hi = np.array([s.upper[:2] for s in segments])
    px, py = poses[:, 0:1], poses[:, 1:2]
    dx = np.maximum(np.maximum(lo[:, 0] - px, 0.0), px - hi[:, 0])
    dy = np.maximum(np.maximum(lo[:, 1] - py, 0.0), py - hi[:, 1])
    return np.sqrt((dx * dx + dy * dy).min(axis=1))


def overshoot(poses: np.ndarray, segments, end: np.ndarray, first_sample: int) -> float:
    """How far [m] the robot passes the end point along its final approach direction
    (from the centre of the segment before the end segment to the end point), over the
    samples from ``first_sample`` on. 0 when it never passes it."""
    if segments is None or len(segments) < 2:
        d = end[:2] - poses[max(first_sample - 1, 0), :2]
    else:
        d = end[:2] - segments[-2].centre[:2]
    norm = np.linalg.norm(d)
    if norm < 1e-12:
        return 0.0
    past = (poses[first_sample:, :2] - end[:2]) @ (d / norm)
    return float(max(0.0, past.max(initial=0.0)))


def build_result(robot, req, seq, segments, sim, compute_s: float) -> dict:
    st = req.settings
    X, U, ACC, steps = sim["X"], sim["U"], sim["ACC"], sim["steps"]
    Ts = st.Ts
    K = steps + 1
    t = np.arange(K) * Ts
    poses, vel = X[:, :3], X[:, 3:]
    lengths = robot.leg_lengths(poses)
    leg_vel = np.einsum("kij,kj->ki", robot.leg_jacobian_batch(poses), vel)
    # per-sample ranges used by the criterion (sample 0: the start point)
    idx = np.minimum(np.arange(K) - 1, seq.K - 1)
    lower = seq.lower[idx].copy()
    upper = seq.upper[idx].copy()
    lower[0] = upper[0] = seq.start
    ti_violation = _box_distance(poses[:, :2], lower[:, :2], upper[:, :2])
    if segments is not None:
        union_violation = corridor_violation(poses, segments)
        psi_lo = min(s.lower[2] for s in segments)
        psi_hi = max(s.upper[2] for s in segments)
        psi_violation = float(np.max(np.maximum(np.maximum(psi_lo - poses[:, 2], 0), poses[:, 2] - psi_hi)))
        first = max((len(segments) - 2) * st.S, 0)
    else:
        union_violation = ti_violation
        psi_violation = float(np.max(np.abs(poses[:, 2] - np.concatenate(([seq.start[2]], seq.upper[idx[1:], 2])))))
        first = max(seq.K - st.N, 0)
    end_err = float(np.hypot(*(poses[-1, :2] - seq.end[:2])))
    stroke = float(np.max(np.maximum(np.maximum(robot.length_min - lengths, 0), lengths - robot.length_max)))
    sing = robot.singularity_measure_batch(poses)
    metrics = {
        "duration_s": float(t[-1]),
        "steps": int(steps),
        "settled": bool(sim["settled"]),
        "end_error_m": end_err,
        "end_error_rad": float(abs(poses[-1, 2] - seq.end[2])),
        "end_speed_m_s": float(np.hypot(vel[-1, 0], vel[-1, 1])),
        "overshoot_m": overshoot(poses, segments, seq.end, first),
        "max_corridor_violation_m": float(union_violation.max()),
        "max_corridor_violation_rad": psi_violation,
        "time_indexed_violation_m": float(ti_violation.max()),
        "max_drive_force_n": float(np.abs(U).max()),
        "force_limit_n": float(robot.force_max.min()),
        "max_force_ratio": float((np.abs(U) / robot.force_max).max()),
        "max_drive_speed_m_s": float(np.abs(leg_vel).max()),
        "max_speed_ratio": float((np.abs(leg_vel) / robot.speed_max).max()),
        "max_stroke_violation_m": stroke,
        "min_singularity_measure": float(sing.min()),
        "energy": float(np.sum(U * U) * Ts),
        "path_length_m": float(np.sum(np.hypot(*np.diff(poses[:, :2], axis=0).T))),
        "compute_ms": compute_s * 1e3,
    }
    return {
        "name": req.name,
        "robot": robot.name,
        "mode": "paper",
        "criterion": "range-space" if segments is not None else "tracking",
        "settings": settings_dict(st),
        "units": {"time": "s", "pose": ["m", "m", "rad"], "velocity": ["m/s", "m/s", "rad/s"],
                  "acceleration": ["m/s^2", "m/s^2", "rad/s^2"], "drives.length": "m",
                  "drives.velocity": "m/s", "drives.force": "N", "energy": "N^2 s"},
        "time": t.tolist(),
        "pose": poses.tolist(),
        "velocity": vel.tolist(),
        "acceleration": ACC.tolist(),
        "drives": {"length": lengths.tolist(), "velocity": leg_vel.tolist(), "force": U.tolist()},
        "corridor": {"lower": lower.tolist(), "upper": upper.tolist(), "violation_m": ti_violation.tolist(),
                     "segments": None if segments is None else
                     [{"lower": s.lower.tolist(), "upper": s.upper.tolist()} for s in segments]},
        "metrics": metrics,
    }


def csv_columns(n_legs: int) -> list[str]:
    cols = ["time_s", "x_m", "y_m", "psi_rad", "vx_m_s", "vy_m_s", "psi_dot_rad_s",
            "ax_m_s2", "ay_m_s2", "psi_ddot_rad_s2"]
    cols += [f"leg{i + 1}_length_m" for i in range(n_legs)]
    cols += [f"leg{i + 1}_velocity_m_s" for i in range(n_legs)]
    cols += [f"leg{i + 1}_force_n" for i in range(n_legs)]
    cols += ["range_lower_x_m", "range_lower_y_m", "range_lower_psi_rad",
             "range_upper_x_m", "range_upper_y_m", "range_upper_psi_rad", "range_violation_m"]
    return cols


def to_csv(result: dict) -> str:
    """One row per sample, a header naming each column with its unit."""
    d = result["drives"]
    n = len(d["force"][0])
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(csv_columns(n))
    c = result["corridor"]
    for k, t in enumerate(result["time"]):
        w.writerow([repr(t), *map(repr, result["pose"][k]), *map(repr, result["velocity"][k]),
                    *map(repr, result["acceleration"][k]), *map(repr, d["length"][k]),
                    *map(repr, d["velocity"][k]), *map(repr, d["force"][k]),
                    *map(repr, c["lower"][k]), *map(repr, c["upper"][k]), repr(c["violation_m"][k])])
    return buf.getvalue()
