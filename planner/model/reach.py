"""Reach: whether poses and boxes of poses keep every leg within its stroke and away from
singular poses. The one implementation of the reach check, used before planning (segments,
reference poses), by the segmentation (cells) and by the editor (reachable outline).

For a fixed angle ``psi`` leg ``i``'s length at tool point ``t`` is ``|t - P_i(psi)|`` with
``P_i(psi) = A_i - Rot(psi) r0_i``, so over an axis-aligned box its extremes are exact: the
shortest at the box's point nearest ``P_i``, the longest at the farthest corner.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import PlannerError
from .kinematics import SINGULAR_TOL, legs, singularity_measure
from .robot import RobotModel

__all__ = ["pivot_points", "leg_length_range", "boxes_within_stroke", "check_pose", "check_segments"]

#: angles sampled across a segment's psi range by :func:`check_segments`
SEGMENT_ANGLES = 5


def pivot_points(model: RobotModel, psi: np.ndarray) -> np.ndarray:
    """``P_i(psi)`` for angles ``psi`` (any shape) -> (..., n, 2) [m]."""
    psi = np.asarray(psi, float)
    c, s = np.cos(psi)[..., None], np.sin(psi)[..., None]
    r0 = model.r0
    rx = c * r0[:, 0] - s * r0[:, 1]
    ry = s * r0[:, 0] + c * r0[:, 1]
    return np.stack((model.base[:, 0] - rx, model.base[:, 1] - ry), axis=-1)


def leg_length_range(model: RobotModel, lo: np.ndarray, hi: np.ndarray,
                     psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shortest and longest length of every leg over boxes ``[lo, hi]`` ((B, 2), m) at angles
    ``psi`` ((B, A), rad): ``(near, far)``, each (B, A, n) [m]. Exact."""
    P = pivot_points(model, psi)  # (B, A, n, 2)
    Px, Py = P[..., 0], P[..., 1]
    lx, ly = lo[:, None, None, 0], lo[:, None, None, 1]
    hx, hy = hi[:, None, None, 0], hi[:, None, None, 1]
    near = np.hypot(np.maximum(np.maximum(lx - Px, 0), Px - hx), np.maximum(np.maximum(ly - Py, 0), Py - hy))
    far = np.hypot(np.maximum(np.abs(Px - lx), np.abs(Px - hx)), np.maximum(np.abs(Py - ly), np.abs(Py - hy)))
    return near, far


def boxes_within_stroke(model: RobotModel, lo: np.ndarray, hi: np.ndarray,
                        psis: Sequence[float] | np.ndarray) -> np.ndarray:
    """Whether every pose in each box ``[lo, hi]`` ((C, 2), m) at every angle of ``psis``
    keeps every leg within its stroke -> (C,) bool."""
    ok = np.ones(len(lo), dtype=bool)
    for psi in psis:  # one angle at a time keeps the temporaries (C, n)
        near, far = leg_length_range(model, lo, hi, np.full((len(lo), 1), float(psi)))
        ok &= np.all((near[:, 0] >= model.length_min - 1e-12) & (far[:, 0] <= model.length_max + 1e-12), axis=1)
    return ok


def check_pose(model: RobotModel, y: np.ndarray, field_path: str = "pose") -> None:
    """Raise a :class:`PlannerError` (``unreachable`` or ``singular``, naming ``field_path``)
    if pose ``y`` has a leg outside its stroke or is singular."""
    y = np.asarray(y, dtype=float)
    length = legs(model, y)[0]
    pose = f"({y[0]:.4f} m, {y[1]:.4f} m, {y[2]:.4f} rad)"
    for i in range(model.n_legs):
        if length[i] < model.length_min[i] - 1e-12:
            raise PlannerError("unreachable", f"pose {pose} needs leg {i + 1} at {length[i]:.4f} m, "
                               f"shorter than its minimum {model.length_min[i]:.4f} m", field_path)
        if length[i] > model.length_max[i] + 1e-12:
            raise PlannerError("unreachable", f"pose {pose} needs leg {i + 1} at {length[i]:.4f} m, "
                               f"longer than its maximum {model.length_max[i]:.4f} m", field_path)
    sigma = float(singularity_measure(model, y[None])[0])
    if sigma < SINGULAR_TOL:
        raise PlannerError("singular", f"pose {pose} is singular: the legs cannot control every "
                           f"direction of motion there (smallest singular value of the leg "
                           f"Jacobian {sigma:.2e} < {SINGULAR_TOL:g})", field_path)


def check_segments(model: RobotModel, segments: Sequence) -> None:
    """Every pose a segment (``lower``, ``upper``: [x, y, psi]) allows must be reachable and
    regular. Stroke: exact over each box (:func:`leg_length_range`) at :data:`SEGMENT_ANGLES`
    angles across its psi range; singularity on a 3 x 3 grid of each box at the same
    angles. All segments at once; the first failure names ``segments[i]``."""
    lo = np.array([s.lower for s in segments])  # (S, 3)
    hi = np.array([s.upper for s in segments])
    t = np.linspace(0.0, 1.0, SEGMENT_ANGLES)
    psi = lo[:, 2:3] + (hi[:, 2:3] - lo[:, 2:3]) * t  # (S, A)
    near, far = leg_length_range(model, lo[:, :2], hi[:, :2], psi)
    short = near < model.length_min - 1e-12
    long_ = far > model.length_max + 1e-12
    for bad, which in ((short, "short"), (long_, "long")):
        if bad.any():
            si, ai, leg = np.argwhere(bad)[0]
            P = pivot_points(model, psi[si, ai])[leg]
            if which == "short":
                pose_xy, length = np.clip(P, lo[si, :2], hi[si, :2]), near[si, ai, leg]
                limit = f"shorter than its minimum {model.length_min[leg]:.4f} m"
            else:
                pose_xy = np.where(np.abs(P - lo[si, :2]) > np.abs(P - hi[si, :2]), lo[si, :2], hi[si, :2])
                length, limit = far[si, ai, leg], f"longer than its maximum {model.length_max[leg]:.4f} m"
            raise PlannerError("unreachable", f"segment {si} contains pose ({pose_xy[0]:.4f} m, {pose_xy[1]:.4f} m, "
                               f"{psi[si, ai]:.4f} rad) where leg {leg + 1} would be {length:.4f} m, {limit}",
                               f"segments[{si}]")
    g = np.linspace(0.0, 1.0, 3)
    gx, gy = np.meshgrid(g, g, indexing="ij")
    xs = lo[:, None, None, 0] + (hi - lo)[:, None, None, 0] * gx.ravel()[None, :, None]  # (S, 9, 1)
    ys = lo[:, None, None, 1] + (hi - lo)[:, None, None, 1] * gy.ravel()[None, :, None]
    poses = np.stack(np.broadcast_arrays(xs, ys, psi[:, None, :]), axis=-1)  # (S, 9, A, 3)
    sigma = singularity_measure(model, poses.reshape(-1, 3)).reshape(poses.shape[:3])
    if sigma.min() < SINGULAR_TOL:
        si, gi, ai = np.unravel_index(np.argmin(sigma), sigma.shape)
        check_pose(model, poses[si, gi, ai], f"segments[{si}]")
