"""The receding-horizon plan loop (paper Sections IV-V): a fast simulation of the robot
under range-space predictive control.

At every sample ``k``: factorise the model at the current state (eq. 8), discretise it
(eq. 9), read the next ``N`` ranges, minimise the criterion (eqs. 22-23), apply the first
move ``u(k)`` to the *nonlinear* model (eq. 6) integrated over one sample (RK4), and repeat.
After the corridor's last sample the end point is held until the robot has settled.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from . import kernels
from .discretisation import zoh_factorised
from .errors import PlannerError, invalid
from .ranges import RangeSequence, range_sequence, reference_sequence
from .request import PlanRequest, parse_request
from .robot import SINGULAR_TOL, Robot, load_robot
from .solver import SOLVERS
from .trajectory import build_result

C_POSE = np.eye(3, 6)


def rk4_sample(robot: Robot, x: np.ndarray, u: np.ndarray, Ts: float, substeps: int,
               f0: np.ndarray | None = None) -> np.ndarray:
    """The plant: the nonlinear model (eq. 6/7) under a constant drive force ``u`` over one
    sample, by ``substeps`` classical Runge-Kutta steps. ``f0`` may pass ``x_dot`` at ``x``."""
    h = Ts / substeps
    f = robot.state_derivative
    for i in range(substeps):
        k1 = f0 if (i == 0 and f0 is not None) else f(x, u)
        k2 = f(x + 0.5 * h * k1, u)
        k3 = f(x + 0.5 * h * k2, u)
        k4 = f(x + h * k3, u)
        x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x


def check_segments(robot: Robot, segments) -> None:
    """Every pose a segment allows must be reachable (within the legs' stroke) and regular.

    For a fixed angle a leg's length is the distance from the tool point to the point
    ``A_i - r_i(psi)``, so its extremes over a segment's box are exact (nearest point and
    farthest corner); the angle range is sampled (5 angles). Singularity is checked on a
    3 x 3 grid of each box at the same angles. All segments at once.
    """
    lo = np.array([s.lower for s in segments])  # (S, 3)
    hi = np.array([s.upper for s in segments])
    t = np.linspace(0.0, 1.0, 5)
    psi = lo[:, 2:3] + (hi[:, 2:3] - lo[:, 2:3]) * t  # (S, 5)
    c, s = np.cos(psi), np.sin(psi)
    r0 = robot._r0
    rx = c[..., None] * r0[:, 0] - s[..., None] * r0[:, 1]  # (S, 5, n)
    ry = s[..., None] * r0[:, 0] + c[..., None] * r0[:, 1]
    Px, Py = robot.base[:, 0] - rx, robot.base[:, 1] - ry
    lx, ly = lo[:, None, None, 0], lo[:, None, None, 1]
    hx, hy = hi[:, None, None, 0], hi[:, None, None, 1]
    near = np.hypot(np.maximum(np.maximum(lx - Px, 0), Px - hx), np.maximum(np.maximum(ly - Py, 0), Py - hy))
    far = np.hypot(np.maximum(np.abs(Px - lx), np.abs(Px - hx)), np.maximum(np.abs(Py - ly), np.abs(Py - hy)))
    short = near < robot.length_min - 1e-12
    long_ = far > robot.length_max + 1e-12
    for bad, which in ((short, "short"), (long_, "long")):
        if bad.any():
            si, ai, leg = np.argwhere(bad)[0]
            P = np.array([Px[si, ai, leg], Py[si, ai, leg]])
            if which == "short":
                pose_xy, length = np.clip(P, lo[si, :2], hi[si, :2]), near[si, ai, leg]
                limit = f"shorter than its minimum {robot.length_min[leg]:.4f} m"
            else:
                pose_xy = np.where(np.abs(P - lo[si, :2]) > np.abs(P - hi[si, :2]), lo[si, :2], hi[si, :2])
                length, limit = far[si, ai, leg], f"longer than its maximum {robot.length_max[leg]:.4f} m"
            raise PlannerError("unreachable", f"segment {si} contains pose ({pose_xy[0]:.4f} m, {pose_xy[1]:.4f} m, "
                               f"{psi[si, ai]:.4f} rad) where leg {leg + 1} would be {length:.4f} m, {limit}",
                               f"segments[{si}]")
    g = np.linspace(0.0, 1.0, 3)
    gx, gy = np.meshgrid(g, g, indexing="ij")
    xs = lo[:, None, None, 0] + (hi - lo)[:, None, None, 0] * gx.ravel()[None, :, None]  # (S, 9, 1)
    ys = lo[:, None, None, 1] + (hi - lo)[:, None, None, 1] * gy.ravel()[None, :, None]
    poses = np.stack(np.broadcast_arrays(xs, ys, psi[:, None, :]), axis=-1)  # (S, 9, 5, 3)
    sigma = robot.singularity_measure_batch(poses.reshape(-1, 3)).reshape(poses.shape[:3])
    if sigma.min() < SINGULAR_TOL:
        si, gi, ai = np.unravel_index(np.argmin(sigma), sigma.shape)
        robot.check_pose(poses[si, gi, ai], f"segments[{si}]")


def _settled(x, end, st) -> bool:
    return (math.hypot(x[0] - end[0], x[1] - end[1]) < st.settle_position_m
            and abs(x[2] - end[2]) < st.settle_angle_rad
            and math.hypot(x[3], x[4]) < st.settle_speed_m_s
            and abs(x[5]) < st.settle_rate_rad_s)


class PaperController:
    """The paper's controller: minimise the range-space criterion (22)-(23) over the
    horizon, unconstrained, and return the first move ``u(k)``."""

    def __init__(self, robot: Robot, seq: RangeSequence, st, segments=None):
        self.seq, self.N = seq, st.N
        self.solver = SOLVERS[st.solver]

    def __call__(self, k: int, x: np.ndarray, Ad: np.ndarray, Bd: np.ndarray) -> np.ndarray:
        lo, hi, qa, qb, qu = self.seq.window(k, self.N)
        return self.solver(Ad, Bd, C_POSE, x, qa, qb, qu, lo, hi)[0]

    def report(self) -> dict:
        """Extra metrics of this controller (none for the paper's)."""
        return {}


def make_controller(robot: Robot, seq: RangeSequence, st, segments=None):
    if st.mode == "constrained":
        from .constrained import ConstrainedController
        return ConstrainedController(robot, seq, st, segments)
    return PaperController(robot, seq, st, segments)


#: solvers whose loop runs on the numpy reference implementation of every stage
REFERENCE_SOLVERS = ("structured", "qr")


def _diverged(k: int, Ts: float) -> PlannerError:
    return PlannerError("diverged", f"the simulated robot diverged at t = {(k + 1) * Ts:.3f} s; "
                        "try a smaller sample time or larger k_u", "settings")


def _singular(t: float, x: np.ndarray) -> PlannerError:
    return PlannerError("singular", f"the robot model is degenerate at t = {t:.3f} s, pose ({x[0]:.4f} m, "
                        f"{x[1]:.4f} m, {x[2]:.4f} rad): its reduced mass matrix or the horizon problem is "
                        "singular; check the robot's masses and inertias and keep the corridor away from "
                        "singular poses", "robot")


def simulate_compiled(robot: Robot, seq: RangeSequence, st) -> dict:
    """The paper-mode loop of :func:`simulate` with the Riccati solver, run whole in
    :func:`planner.kernels.simulate_paper` (same steps, same stopping rule)."""
    N, Ts = st.N, st.Ts
    max_steps = seq.K + int(math.ceil(st.tail_max_s / Ts))
    pad = lambda a: np.ascontiguousarray(np.concatenate((a, np.repeat(a[-1:], N, axis=0))))  # noqa: E731
    settle = np.array([st.settle_position_m, st.settle_angle_rad, st.settle_speed_m_s, st.settle_rate_rad_s])
    x0 = np.concatenate((seq.start, np.zeros(3)))
    X, U, ACC, steps, settled, status = kernels.simulate_paper(
        robot_kernel_array(robot), x0, pad(seq.lower), pad(seq.upper), pad(seq.qa), pad(seq.qb),
        np.ascontiguousarray(seq.qu, dtype=float), seq.K, N, Ts, st.plant_substeps, max_steps,
        np.asarray(seq.end, dtype=float), settle)
    if status == kernels.DIVERGED:
        raise _diverged(max(steps - 1, 0), Ts)
    if status == kernels.SINGULAR:
        raise _singular(steps * Ts, X[steps])
    return {"X": X, "U": U, "ACC": ACC, "steps": steps, "settled": bool(settled)}


def robot_kernel_array(robot: Robot) -> np.ndarray:
    """The robot packed for :mod:`planner.kernels` (cached on the robot)."""
    rb = robot.__dict__.get("_kernel_array")
    if rb is None:
        rb = kernels.robot_array(robot)
        object.__setattr__(robot, "_kernel_array", rb)
    return rb


def simulate(robot: Robot, seq: RangeSequence, st, controller=None) -> dict:
    """Run the receding-horizon loop; returns the sampled states, inputs and leg data.

    With the default Riccati solver the paper's loop runs compiled
    (:func:`simulate_compiled`) and other controllers (constrained mode) get the compiled
    model, hold and plant per step; the ``structured`` and ``qr`` solvers run every stage on
    the numpy reference implementation."""
    controller = controller or PaperController(robot, seq, st)
    reference = st.solver in REFERENCE_SOLVERS
    if type(controller) is PaperController and not reference:
        return simulate_compiled(robot, seq, st)
    N, Ts, m = st.N, st.Ts, robot.n_legs
    max_steps = seq.K + int(math.ceil(st.tail_max_s / Ts))
    X = np.empty((max_steps + 1, 6))
    U = np.zeros((max_steps + 1, m))
    ACC = np.empty((max_steps + 1, 3))
    x = np.concatenate((seq.start, np.zeros(3)))
    X[0] = x
    settled_at = None
    k = 0
    rb = robot_kernel_array(robot)
    for k in range(max_steps):
        if reference:
            A22, B2 = robot.factorised_blocks(x)  # eq. (8)
            Ad, Bd = zoh_factorised(A22, B2, Ts)  # eq. (9)
        else:
            A22, B2, Ad, Bd, ok = kernels.model_step(rb, x, Ts)  # eqs. (8)-(9), compiled
            if not ok:
                raise _singular(k * Ts, x)
        u = controller(k, x, Ad, Bd)
        xdot = np.concatenate((x[3:], A22 @ x[3:] + B2 @ u))  # == f(x) + G(x) u exactly (eq. 8)
        U[k] = u
        ACC[k] = xdot[3:]
        if reference:
            x = rk4_sample(robot, x, u, Ts, st.plant_substeps, xdot)
        else:
            x = kernels.rk4(rb, x, np.ascontiguousarray(u, dtype=float), Ts, st.plant_substeps, xdot)
        X[k + 1] = x
        if not np.all(np.isfinite(x)) or abs(x[0]) + abs(x[1]) > 1e3:
            raise _diverged(k, Ts)
        if k + 1 >= seq.K and _settled(x, seq.end, st):
            settled_at = k + 1
            break
    steps = k + 1
    ACC[steps] = robot.acceleration(X[steps, :3], X[steps, 3:], U[steps])
    return {"X": X[:steps + 1], "U": U[:steps + 1], "ACC": ACC[:steps + 1], "steps": steps,
            "settled": settled_at is not None}


def plan(request, *, robot: Robot | None = None, segments=None) -> dict:
    """Plan a trajectory for a request (dict in the one JSON shape, or a parsed
    :class:`PlanRequest`). Returns the result dict (see :mod:`planner.trajectory`)."""
    t0 = time.perf_counter()
    req = request if isinstance(request, PlanRequest) else parse_request(request)
    st = req.settings
    robot = robot or load_robot(req.robot)
    m = robot.n_legs
    if st.q_u is not None and len(st.q_u) != m:
        raise invalid("settings.q_u", f"must have one entry per drive ({m}), got {len(st.q_u)}")
    if segments is None:
        segments = req.segments
    if segments is None and req.layout is not None:
        from .segmentation import corridor_from_request
        segments = corridor_from_request(req, robot).segments
    if segments is not None:
        check_segments(robot, segments)
        if st.fastest:  # issue 6: search the shortest feasible timing (runs plan() per candidate)
            from .timing import fastest_plan
            return fastest_plan(req, robot, segments, t0)
    from .timing import resolve_timing, timing_info
    st = resolve_timing(st, segments)  # speed_m_s / total_time_s -> samples_per_segment
    if st is not req.settings:
        req = dataclasses.replace(req, settings=st)
    if segments is not None:
        seq = range_sequence(segments, st, m)
    else:
        for i, pose in enumerate(req.reference):
            robot.check_pose(pose, f"reference.pose[{i}]")
        seq = reference_sequence(req.reference, st, m)
    robot.check_pose(seq.start, "segments[0]" if segments is not None else "reference.pose[0]")
    controller = make_controller(robot, seq, st, segments)
    sim = simulate(robot, seq, st, controller)
    result = build_result(robot, req, seq, segments, sim, time.perf_counter() - t0)
    result["mode"] = st.mode
    result["metrics"].update(controller.report())
    result["timing"] = timing_info(st, segments)
    if st.mode == "constrained":  # containment judged on the actual trajectory; may raise infeasible
        from .constrained import finalize
        finalize(result, st, segments)
    result["metrics"]["compute_ms"] = (time.perf_counter() - t0) * 1e3  # everything, result arrays included
    if not sim["settled"] and st.require_settled:
        mt = result["metrics"]
        raise PlannerError("not_settled", f"the robot did not settle at the end point within "
                           f"{st.tail_max_s:g} s after the corridor (end error {mt['end_error_m'] * 1e3:.3f} mm, "
                           f"speed {mt['end_speed_m_s'] * 1e3:.3f} mm/s); lengthen settings.tail_max_s, "
                           "add samples per segment or raise k_r", "settings.tail_max_s")
    return result


def warm_up() -> float:
    """Compile (first run after installing) or load (afterwards, from the on-disk cache) the
    compiled kernels by planning a short corridor in both modes; returns the seconds taken.
    Servers call it before taking jobs, ``make`` after installing."""
    t0 = time.perf_counter()
    segments = [{"lower": [0.0, 0.0, 0.0], "upper": [0.0, 0.0, 0.0]},
                {"lower": [0.0, 0.0, 0.0], "upper": [0.01, 0.01, 0.0]},
                {"lower": [0.01, 0.01, 0.0], "upper": [0.01, 0.01, 0.0]}]
    for mode in ("paper", "constrained"):
        plan({"robot": "moving-slide", "segments": segments,
              "settings": {"mode": mode, "N": 5, "require_settled": False, "tail_max_s": 0.05}})
    return time.perf_counter() - t0


if __name__ == "__main__":
    print(f"planner kernels ready in {warm_up():.1f} s")
