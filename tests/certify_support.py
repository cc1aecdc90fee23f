"""An independent checker of plan results (issue 20), written from the paper and the request:
it reads the robot's description (JSON), the request and the returned arrays, and recomputes
every figure with its own plane geometry and leg kinematics. It calls none of the planner's
metric, geometry or kinematics functions (only ``planner.plan`` itself, in the harness, and the
request schema's JSON), so that a bug there cannot hide here.

What a plan must satisfy (README "The result", "Constrained mode"; paper eqs. 1-4 for the legs):

* leg ``i`` of a pose ``(x, y, psi)`` (the tool point): ``l_i = |c + R(psi) b_i - a_i|`` with the
  platform centre ``c = (x, y) - R(psi) t`` (``t`` the tool offset), ``a_i``/``b_i`` the base and
  platform pivots; its speed ``dl_i/dt = e_i . (c_dot + psi_dot R'(psi) b_i)``, ``e_i`` the unit leg;
* every mode: forces within ``force_max``, strokes within ``[length_min, length_max]``, the
  reported metrics equal to their recomputation, settled at the end point when it says so;
* constrained mode: the (x, y) of every sample inside the union of the segments (and of their
  exact cell polygons), psi inside the psi ranges of the segments holding it, the force rate
  within ``force_rate_n_s`` (default ``force_max`` / 0.05 s, from zero before the start), leg
  speeds within ``speed_max``, no overshoot past the end point along the approach direction.

One check uses the planner's own model: the integration accuracy (issue 31 goal 5). Each
sample is integrated again from the sample before under that sample's drive force, by the
model's equations of motion (eqs. 6-7, :mod:`planner.model`; the model itself is tested against
its numpy reference and the paper elsewhere) with 16 times the plant's RK4 sub-steps: every
sample within :data:`INTEGRATION_TOL_M` of it (:func:`integration_deviation`).

Errors are confirmed separately (:func:`grid_path_exists`: an independent search for a path
through the free space on a fine grid, :func:`box_leg_range`: the legs' reach over a box).
"""

from __future__ import annotations

import json
import math
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

DATA = Path(__file__).resolve().parents[1] / "planner" / "data"

#: tolerances of the checks: the corridor (the mode's 1e-9 m "contained" plus rounding of
#: the returned floats), angles, relative figures of the limits
TOL_M = 2e-9
TOL_RAD = 2e-7
TOL_REL = 1e-6
#: force-rate excess allowed (relative; issue 31 goal 6: 1e-9): the applied move of every step
#: is clipped to its force-rate limit (``ConstrainedController._clip_first_rates`` and its
#: compiled twin), so only rounding is left (4.7e-15 at most over 62 plans at Ts 1-10 ms,
#: rates of 20-3000 N/s; before the clip 1.000004 x the limit, 20.012 N/s at 20 N/s)
RATE_TOL_REL = 1e-9
#: overshoot allowed in the constrained mode [m]: a step whose QP is infeasible by less than
#: 0.8 um is solved with its rows widened by that much (README "Constrained mode")
OVERSHOOT_TOL_M = 1e-6
#: the largest distance [m] of a sample from a fine integration of the plan's own forces (issue
#: 31 goal 5: 1 um), and the reference's sub-steps per plant sub-step
INTEGRATION_TOL_M = 1e-6
INTEGRATION_REFINE = 16
#: default force rise time of the force-rate limit [s] (README: force_max per 0.05 s)
FORCE_RISE_S = 0.05
#: the settling tolerances' defaults (README)
SETTLE_POSITION_M = 1e-4
SETTLE_SPEED_M_S = 1e-3


@dataclass
class Robot:
    """The robot as its description says (SI units)."""

    base: np.ndarray  # (m, 2)
    plat: np.ndarray  # (m, 2)
    tool: np.ndarray  # (2,)
    lmin: np.ndarray  # (m,)
    lmax: np.ndarray
    fmax: np.ndarray
    vmax: np.ndarray

    @property
    def n_legs(self) -> int:
        return len(self.base)


def robot_of(desc: Any) -> Robot:
    """A robot from a built-in name or a full description (the JSON of planner/data)."""
    if desc is None:
        desc = "moving-slide"
    if isinstance(desc, str):
        desc = json.loads((DATA / f"{desc}.json").read_text())
    base = np.asarray(desc["base_pivots"], float)
    legs = desc["legs"]
    if isinstance(legs, dict):
        legs = [legs] * len(base)

    def col(k: str) -> np.ndarray:
        return np.array([float(g[k]) for g in legs])

    return Robot(base, np.asarray(desc["platform_pivots"], float), np.asarray(desc.get("tool_offset", [0, 0]), float),
                 col("length_min"), col("length_max"), col("force_max"), col("speed_max"))


def _rot(psi: np.ndarray) -> np.ndarray:
    c, s = np.cos(psi), np.sin(psi)
    return np.stack((np.stack((c, -s), -1), np.stack((s, c), -1)), -2)  # (..., 2, 2)


def legs(robot: Robot, poses: np.ndarray) -> np.ndarray:
    """Leg vectors (K, m, 2) of the poses (K, 3) [m]: base pivot -> platform pivot."""
    poses = np.atleast_2d(poses)
    R = _rot(poses[:, 2])
    centre = poses[:, :2] - R @ robot.tool
    plat = np.einsum("kij,mj->kmi", R, robot.plat)
    return centre[:, None, :] + plat - robot.base[None]


def leg_lengths(robot: Robot, poses: np.ndarray) -> np.ndarray:
    return np.linalg.norm(legs(robot, poses), axis=-1)


def leg_speeds(robot: Robot, poses: np.ndarray, vel: np.ndarray) -> np.ndarray:
    """Leg length rates (K, m) [m/s] from poses and their rates (tool point)."""
    poses, vel = np.atleast_2d(poses), np.atleast_2d(vel)
    L = legs(robot, poses)
    e = L / np.linalg.norm(L, axis=-1, keepdims=True)
    R = _rot(poses[:, 2])
    dR = np.stack((np.stack((-np.sin(poses[:, 2]), -np.cos(poses[:, 2])), -1),
                   np.stack((np.cos(poses[:, 2]), -np.sin(poses[:, 2])), -1)), -2)  # dR/dpsi
    del R
    w = vel[:, 2]
    c_dot = vel[:, :2] - w[:, None] * (dR @ robot.tool)
    p_dot = c_dot[:, None, :] + w[:, None, None] * np.einsum("kij,mj->kmi", dR, robot.plat)
    return np.sum(e * p_dot, axis=-1)


# ---------------------------------------------------------------- plane geometry


def point_box_distance(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Distances (K, S) of points (K, 2) from boxes (S, 2)."""
    d = np.maximum(np.maximum(lo[None] - p[:, None], 0.0), p[:, None] - hi[None])
    return np.hypot(d[..., 0], d[..., 1])


def point_polygon_outside(p: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """How far (K,) each point is outside a convex CCW polygon (0 inside; the largest
    half-plane excess, a lower bound of the distance that is exact near an edge)."""
    v = np.asarray(poly, float)
    e = np.roll(v, -1, axis=0) - v
    n = np.column_stack((e[:, 1], -e[:, 0])) / np.hypot(e[:, 0], e[:, 1])[:, None]  # outward for CCW
    excess = (p[:, None, :] - v[None]) @ np.zeros(2) if False else np.einsum("kvi,vi->kv", p[:, None, :] - v[None], n)
    return np.maximum(excess.max(axis=1), 0.0)


# ---------------------------------------------------------------- checking a plan


@dataclass
class Verdict:
    """What the checker found: ``problems`` empty means certified."""

    problems: list[str] = field(default_factory=list)
    figures: dict[str, float] = field(default_factory=dict)

    def fail(self, what: str) -> None:
        self.problems.append(what)

    @property
    def ok(self) -> bool:
        return not self.problems


def result_fields(result: Any, with_corridor: bool = True) -> dict:
    """What :func:`check_plan` reads of a :class:`planner.schema.PlanResult`, in the shape of
    its JSON (the settings and metrics as JSON types, the arrays as they are: a float64 array
    and its JSON list hold the same numbers). Its whole JSON, the arrays as lists and parsed
    back (``json.loads(result.model_dump_json())``, what the checker read before), took 70-80 %
    of a check's CPU time and told it nothing more (``tests/test_certify.py`` checks that both
    give the same verdict and figures)."""
    out = {"settings": result.settings.model_dump(mode="json"), "metrics": result.metrics.model_dump(mode="json"),
           "pose": result.pose, "velocity": result.velocity, "time": result.time,
           "drives": {"force": result.drives.force, "length": result.drives.length,
                      "velocity": result.drives.velocity}}
    if with_corridor:
        out["corridor"] = {"segments": None if result.corridor.segments is None else
                           [sg.model_dump(mode="json") for sg in result.corridor.segments]}
    return out


def _close(a: float, b: float, abs_tol: float, rel: float = 1e-9) -> bool:
    return abs(a - b) <= abs_tol + rel * max(abs(a), abs(b))


def check_plan(request: dict, result: Any, segments: list[dict] | None = None) -> Verdict:
    """Certify a plan result (a :class:`planner.schema.PlanResult` or its JSON dict) against
    its request (the dict sent) and the corridor it ran on (``segments``: the request's, or
    for a layout the result's ``corridor.segments``)."""
    with cpu_spent("checker: reading the result"):
        res = result if isinstance(result, dict) else result_fields(result, with_corridor=segments is None)
    v = Verdict()
    robot = robot_of(request.get("robot"))
    st = res["settings"]
    mode = st["mode"]
    Ts = float(st["Ts"])
    pose = np.asarray(res["pose"], float)
    vel = np.asarray(res["velocity"], float)
    U = np.asarray(res["drives"]["force"], float)
    K = len(pose)
    mt = res["metrics"]
    segs = segments if segments is not None else res["corridor"]["segments"]
    lo = np.array([s["lower"] for s in segs], float)
    hi = np.array([s["upper"] for s in segs], float)
    end = 0.5 * (lo[-1] + hi[-1])

    # the arrays agree with each other and with the robot
    L = leg_lengths(robot, pose)
    if not np.allclose(L, np.asarray(res["drives"]["length"], float), atol=1e-12, rtol=1e-12):
        v.fail("drives.length differs from the leg lengths of the poses")
    LV = leg_speeds(robot, pose, vel)
    if not np.allclose(LV, np.asarray(res["drives"]["velocity"], float), atol=1e-10, rtol=1e-8):
        v.fail("drives.velocity differs from the leg rates of the poses and velocities")
    if not np.allclose(np.asarray(res["time"], float), np.arange(K) * Ts, atol=1e-12, rtol=1e-12):
        v.fail("time is not k Ts")

    # limits (every mode)
    # (the paper mode is soft: its limits are reported, not guaranteed)
    ratio = float((np.abs(U) / robot.fmax).max())
    if ratio > 1.0 + TOL_REL and mode == "constrained":
        v.fail(f"drive force {ratio:.6f} x force_max")
    stroke = float(np.max(np.maximum(robot.lmin - L, 0.0) + np.maximum(L - robot.lmax, 0.0)))
    if stroke > TOL_M and mode == "constrained":
        v.fail(f"stroke exceeded by {stroke:.3g} m")
    dU = np.diff(np.vstack((np.zeros((1, U.shape[1])), U[:-1])), axis=0)
    rate = np.abs(dU).max(initial=0.0) / Ts
    speed = float(np.abs(LV).max())

    # the corridor: union of the segments' boxes (and exact polygons where given)
    xy = pose[:, :2]
    D = point_box_distance(xy, lo[:, :2], hi[:, :2])  # (K, S)
    union = float(D.min(axis=1).max())
    polys = [s.get("polygon") for s in segs]
    poly_viol = 0.0
    if any(p is not None for p in polys):
        out = np.full((K, len(segs)), np.inf)
        for j, p in enumerate(polys):
            if p is None:
                out[:, j] = D[:, j]
            else:
                out[:, j] = np.maximum(point_polygon_outside(xy, np.asarray(p, float)), D[:, j])
        poly_viol = float(out.min(axis=1).max())
    # psi within the psi ranges of the segments holding (x, y) (of the nearest if none)
    near = D <= D.min(axis=1, keepdims=True) + 1e-12
    e = np.maximum(np.maximum(lo[None, :, 2] - pose[:, None, 2], 0.0), pose[:, None, 2] - hi[None, :, 2])
    psi_viol = float(np.where(near, e, np.inf).min(axis=1).max())

    # overshoot along the approach direction (README: from the last cell's centre, or the cell
    # before where the end point is that centre), over the samples from the last cell on
    direction = approach(segs, lo, hi, end)
    over = 0.0
    if direction is not None:
        # sample k (k >= 1) is held in the range of sequence index k - 1; segment i has
        # counts[i] of them (the resolved timing of the result's settings)
        counts = st.get("segment_samples") or [int(st["samples_per_segment"])] * len(segs)
        first = int(np.sum(counts[:len(segs) - 2])) + 1
        over = float(max(0.0, ((xy[first:] - end[:2]) @ direction).max(initial=0.0)))
    end_err = float(math.hypot(*(xy[-1] - end[:2])))
    end_speed = float(math.hypot(*vel[-1, :2]))
    energy = float(np.sum(U * U) * Ts)
    path = float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))
    mine = {"duration_s": (K - 1) * Ts, "steps": K - 1, "end_error_m": end_err, "end_speed_m_s": end_speed,
            "overshoot_m": over, "max_corridor_violation_m": union, "max_corridor_violation_rad": psi_viol,
            "max_drive_force_n": float(np.abs(U).max()), "max_force_ratio": ratio, "max_force_rate_n_s": rate,
            "max_drive_speed_m_s": speed, "max_stroke_violation_m": stroke, "energy": energy,
            "path_length_m": path}
    v.figures = mine
    for k, val in mine.items():
        got = mt.get(k)
        tol = 1e-9 if k.endswith("_m") or k.endswith("_rad") else 1e-9 * max(1.0, abs(val))
        if got is None or not _close(float(got), float(val), tol, 1e-7):
            v.fail(f"metric {k}: reported {got}, recomputed {val}")
    if mt.get("settled"):
        if end_err > float(st.get("settle_position_m") or SETTLE_POSITION_M) + 1e-12:
            v.fail(f"settled but {end_err:.3g} m from the end point")
        if end_speed > float(st.get("settle_speed_m_s") or SETTLE_SPEED_M_S) + 1e-12:
            v.fail(f"settled but moving at {end_speed:.3g} m/s")
    elif st.get("require_settled", True):
        v.fail("a plan returned unsettled although require_settled")

    if mode == "constrained" and mt.get("contained"):
        if union > TOL_M or poly_viol > TOL_M:
            v.fail(f"contained but {max(union, poly_viol):.3g} m outside the corridor")
        if psi_viol > TOL_RAD:
            v.fail(f"contained but psi {psi_viol:.3g} rad outside its ranges")
        if over > OVERSHOOT_TOL_M:
            v.fail(f"overshoot {over:.3g} m past the end point")
        fr = st.get("force_rate_n_s")
        if fr != "off":
            limit = (robot.fmax / FORCE_RISE_S if fr is None
                     else np.broadcast_to(np.asarray(fr, float), robot.fmax.shape))
            worst = float((np.abs(dU) / Ts / limit).max(initial=0.0))
            if worst > 1.0 + RATE_TOL_REL:
                v.fail(f"force rate {worst:.6f} x its limit")
        sratio = float((np.abs(LV) / robot.vmax).max())
        if sratio > 1.0 + 1e-4:  # the leg-speed rows are linearised one sample ahead
            v.fail(f"leg speed {sratio:.6f} x speed_max")
    elif mode == "constrained" and st.get("require_settled", True):
        v.fail("a constrained plan returned not contained although require_settled")
    with cpu_spent("checker: fine integration"):
        dev = integration_deviation(request.get("robot"), pose, vel, U, Ts, st.get("plant_substeps"))
    v.figures["integration_deviation_m"] = dev
    if not dev <= INTEGRATION_TOL_M:
        v.fail(f"a sample {dev:.3g} m from a fine integration of the plan's forces (over {INTEGRATION_TOL_M:g} m)")
    return v


def integration_deviation(robot: Any, pose: np.ndarray, vel: np.ndarray, U: np.ndarray, Ts: float,
                          substeps: int | None) -> float:
    """The largest distance [m] in (x, y) of a sample from the sample before integrated over Ts
    under its drive force, by the planner's model (eqs. 6-7) with :data:`INTEGRATION_REFINE`
    times the plant's RK4 sub-steps (``substeps``, else what the plant chooses for the robot)."""
    from planner.model import kernels as mk
    from planner.model import load_robot
    from planner.model.plant import plant_substeps

    model = load_robot(robot if robot is not None else "moving-slide")
    n = INTEGRATION_REFINE * int(substeps or plant_substeps(model, Ts))
    X = np.ascontiguousarray(np.hstack((pose, vel)), dtype=float)
    U = np.ascontiguousarray(U, dtype=float)
    f0 = np.empty(6)
    worst = 0.0
    for k in range(len(X) - 1):
        mk.state_derivative(model.packed, X[k], U[k], f0)
        x = mk.rk4(model.packed, X[k], U[k], Ts, n, f0)
        worst = max(worst, math.hypot(x[0] - X[k + 1, 0], x[1] - X[k + 1, 1]))
    return worst


def approach(segs: list[dict], lo: np.ndarray, hi: np.ndarray, end: np.ndarray) -> np.ndarray | None:
    """The approach direction (README "The result", overshoot_m): from the centre of the last
    segment before the end point whose centre is not the end point; but where the middle of
    the segment before the last cell lies past the end point along it, from the next centres
    back (the first behind which that middle lies, else the one it lies least beyond); of the
    directions that leave the last cell's corners (its polygon's vertices) 10 um behind the end
    point, where any does."""
    entry = None
    if len(segs) >= 3:
        poly = segs[-3].get("polygon")
        entry = (np.mean(np.asarray(poly, float), axis=0) if poly is not None
                 else 0.5 * (lo[-3, :2] + hi[-3, :2])) - end[:2]
    poly = segs[-2].get("polygon") if len(segs) >= 2 else None
    corners = (np.asarray(poly, float) if poly is not None else
               np.array([[lo[-2, 0], lo[-2, 1]], [hi[-2, 0], lo[-2, 1]], [hi[-2, 0], hi[-2, 1]],
                         [lo[-2, 0], hi[-2, 1]]])) if len(segs) >= 2 else None
    dirs = []
    for j in range(len(segs) - 2, -1, -1):
        d = end[:2] - 0.5 * (lo[j, :2] + hi[j, :2])
        n = math.hypot(*d)
        if n <= 1e-9:
            continue
        d = d / n
        if entry is None:
            return d
        dirs.append(d)
    roomy = [d for d in dirs if corners is None or min(float((c - end[:2]) @ d) for c in corners) <= -1e-5]
    best, best_excess = None, np.inf
    for d in roomy or dirs:
        if entry @ d <= 0.0:
            return d
        if entry @ d < best_excess:
            best, best_excess = d, float(entry @ d)
    return best


# ---------------------------------------------------------------- confirming errors


def box_leg_range(robot: Robot, lo: np.ndarray, hi: np.ndarray, psis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shortest and longest length (m,) of each leg over the poses of the box ``lo..hi`` (x, y)
    at the angles ``psis``: the distance from a point to a box is smallest at the clamped point
    and largest at a corner."""
    mins, maxs = np.full(robot.n_legs, np.inf), np.zeros(robot.n_legs)
    for psi in np.atleast_1d(psis):
        R = _rot(np.array([psi]))[0]
        # leg vector = centre + R b - a with centre = p - R t: the pivot offset q = a - R b + R t
        q = robot.base - (R @ robot.plat.T).T + R @ robot.tool
        near = np.clip(q, lo, hi)
        mins = np.minimum(mins, np.linalg.norm(near - q, axis=1))
        corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [lo[0], hi[1]], [hi[0], hi[1]]])
        maxs = np.maximum(maxs, np.linalg.norm(corners[:, None, :] - q[None], axis=-1).max(axis=0))
    return mins, maxs


def _free_mask(layout: dict, X: np.ndarray, Y: np.ndarray, robot: Robot, psis: np.ndarray) -> np.ndarray:
    """Points of the grid (X, Y) that are in the bounds, farther than the clearance from every
    obstacle, and within the legs' stroke at every angle of ``psis``."""
    import shapely  # the geometry library, not the planner's geometry

    c = float(layout.get("clearance", 0.0))
    free = np.ones(X.shape, bool)
    pts = shapely.points(X.ravel(), Y.ravel())
    for ob in layout.get("obstacles", []):
        if ob["type"] == "rectangle":
            g = shapely.box(*ob["lower"], *ob["upper"])
        elif ob["type"] == "circle":
            g = shapely.Point(*ob["center"]).buffer(float(ob["radius"]), quad_segs=64)
        else:
            g = shapely.Polygon(ob["points"], ob.get("holes") or None)
        d = shapely.distance(g, pts).reshape(X.shape)
        free &= d > c
    for psi in psis:
        L = leg_lengths(robot, np.column_stack((X.ravel(), Y.ravel(), np.full(X.size, psi))))
        free &= np.all((L >= robot.lmin) & (L <= robot.lmax), axis=1).reshape(X.shape)
    return free


def grid_path_exists(layout: dict, robot: Robot, step: float) -> bool:
    """Whether a 4-connected chain of free grid points (spacing ``step``) joins the grid points
    nearest to the start and the end: the independent search that confirms ``no_path``
    (a chain at a fine step means a corridor of cells of about that size could exist)."""
    lo, hi = np.asarray(layout["bounds"]["lower"], float), np.asarray(layout["bounds"]["upper"], float)
    nx, ny = int(round((hi[0] - lo[0]) / step)) + 1, int(round((hi[1] - lo[1]) / step)) + 1
    X, Y = np.meshgrid(np.linspace(lo[0], hi[0], nx), np.linspace(lo[1], hi[1], ny), indexing="ij")
    s, e = np.asarray(layout["start"], float), np.asarray(layout["end"], float)
    pr = layout.get("psi_range") or [min(s[2], e[2]), max(s[2], e[2])]
    free = _free_mask(layout, X, Y, robot, np.linspace(pr[0], pr[1], 3))

    def nearest(p: np.ndarray) -> tuple[int, int]:
        return (int(np.clip(round((p[0] - lo[0]) / step), 0, nx - 1)),
                int(np.clip(round((p[1] - lo[1]) / step), 0, ny - 1)))

    a, b = nearest(s), nearest(e)
    if not (free[a] and free[b]):
        return False
    seen = np.zeros_like(free)
    seen[a] = True
    q = deque([a])
    while q:
        i, j = q.popleft()
        if (i, j) == b:
            return True
        for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            u, w = i + di, j + dj
            if 0 <= u < nx and 0 <= w < ny and free[u, w] and not seen[u, w]:
                seen[u, w] = True
                q.append((u, w))
    return False


# ---------------------------------------------------------------- random cases (hypothesis)

from hypothesis import strategies as hst  # noqa: E402

#: the workspace both robots reach comfortably around the origin, and a margin beyond it that
#: takes start and end points up to and past the reach limit [m]
_REACH = {"moving-slide": 0.09, "tri-slide": 0.08}
_BEYOND = 0.06


def _frac(draw: Any) -> float:
    return draw(hst.floats(0.0, 1.0, allow_nan=False))


@hst.composite
def obstacle(draw: Any, lo: np.ndarray, hi: np.ndarray) -> dict:
    """A rectangle, triangle, circle or square polygon with a square hole, inside ``lo..hi``."""
    kind = draw(hst.sampled_from(["rectangle", "triangle", "circle", "holed"]))
    W = hi - lo
    c = lo + W * np.array([_frac(draw), _frac(draw)])
    r = float(min(W) * (0.05 + 0.25 * _frac(draw)))
    if kind == "rectangle":
        a = float(W[0] * (0.02 + 0.4 * _frac(draw)))
        b = float(W[1] * (0.02 + 0.6 * _frac(draw)))
        # some span the whole height or width of the bounds
        if draw(hst.integers(0, 5)) == 0:
            return {"type": "rectangle", "lower": [float(c[0] - a / 2), float(lo[1])],
                    "upper": [float(c[0] + a / 2), float(hi[1])]}
        return {"type": "rectangle", "lower": [float(c[0] - a / 2), float(c[1] - b / 2)],
                "upper": [float(c[0] + a / 2), float(c[1] + b / 2)]}
    if kind == "circle":
        return {"type": "circle", "center": [float(c[0]), float(c[1])], "radius": r}
    if kind == "triangle":
        t0 = 2 * math.pi * _frac(draw)
        ang = t0 + np.array([0.0, 2.1 + _frac(draw), 4.2 + _frac(draw)])
        pts = c + r * np.column_stack((np.cos(ang), np.sin(ang)))
        return {"type": "polygon", "points": pts.tolist()}
    outer = [[c[0] - r, c[1] - r], [c[0] + r, c[1] - r], [c[0] + r, c[1] + r], [c[0] - r, c[1] + r]]
    h = r * (0.3 + 0.5 * _frac(draw))
    hole = [[c[0] - h, c[1] - h], [c[0] + h, c[1] - h], [c[0] + h, c[1] + h], [c[0] - h, c[1] + h]]
    return {"type": "polygon", "points": [[float(x), float(y)] for x, y in outer],
            "holes": [[[float(x), float(y)] for x, y in hole]]}


@hst.composite
def point_in(draw: Any, lo: np.ndarray, hi: np.ndarray, obstacles: list[dict], psi: float) -> list[float]:
    """A start or end: anywhere, near an obstacle's vertex or edge, near a corner of the bounds,
    or near the edge of the bounds (towards the reach limit), jittered by up to a few mm."""
    where = draw(hst.sampled_from(["free", "obstacle", "corner", "edge"]))
    W = hi - lo
    jit = np.array([draw(hst.floats(-0.004, 0.004)), draw(hst.floats(-0.004, 0.004))])
    if where == "obstacle" and obstacles:
        ob = obstacles[draw(hst.integers(0, len(obstacles) - 1))]
        if ob["type"] == "circle":
            a = 2 * math.pi * _frac(draw)
            p = np.asarray(ob["center"]) + (ob["radius"] + 0.004) * np.array([math.cos(a), math.sin(a)])
        else:
            pts = np.asarray(ob["points"] if ob["type"] == "polygon" else
                             [ob["lower"], [ob["upper"][0], ob["lower"][1]], ob["upper"],
                              [ob["lower"][0], ob["upper"][1]]], float)
            p = pts[draw(hst.integers(0, len(pts) - 1))]
    elif where == "corner":
        p = np.array([lo[0] if draw(hst.booleans()) else hi[0], lo[1] if draw(hst.booleans()) else hi[1]])
        jit = np.abs(jit) * np.sign(0.5 * (lo + hi) - p)
    elif where == "edge":
        p = lo + W * np.array([_frac(draw), 0.0 if draw(hst.booleans()) else 1.0])
        jit[1] = abs(jit[1]) * (1 if p[1] <= lo[1] else -1)
    else:
        p = lo + W * np.array([_frac(draw), _frac(draw)])
    p = np.clip(p + jit, lo, hi)
    return [float(p[0]), float(p[1]), float(psi)]


@hst.composite
def layout_case(draw: Any) -> dict:
    """A layout request: bounds around the reachable workspace (sometimes beyond it), 0-4
    obstacles, square or triangle cells of several sizes (or the default), a clearance."""
    robot = draw(hst.sampled_from(["moving-slide", "tri-slide"]))
    R = _REACH[robot] + (_BEYOND if draw(hst.integers(0, 4)) == 0 else 0.0)
    w = R * (0.5 + 0.5 * _frac(draw))
    h = R * (0.4 + 0.6 * _frac(draw))
    off = np.array([draw(hst.floats(-0.02, 0.02)), draw(hst.floats(-0.02, 0.02))])
    lo, hi = off - np.array([w, h]), off + np.array([w, h])
    obs = [draw(obstacle(lo, hi)) for _ in range(draw(hst.integers(0, 4)))]
    shape = draw(hst.sampled_from(["square", "triangle"]))
    size = draw(hst.sampled_from([None, 0.005, 0.01, 0.02]))
    psi = draw(hst.sampled_from([0.0, 0.0, 0.05, -0.1]))
    start = draw(point_in(lo, hi, obs, 0.0))
    end = draw(point_in(lo, hi, obs, psi))
    lay = {"bounds": {"lower": lo.tolist(), "upper": hi.tolist()}, "obstacles": obs,
           "clearance": draw(hst.sampled_from([0.0, 0.001, 0.003])), "cell": {"shape": shape, "size": size},
           "start": start, "end": end}
    return {"robot": robot, "layout": lay}


@hst.composite
def segments_case(draw: Any) -> dict:
    """A corridor of random boxes, each overlapping the one before (narrow or wide, psi ranges
    or a fixed angle), between a start point in the first box and an end point in the last (at
    a corner, on an edge or inside; one in four a point in x/y with the last box's psi range)."""
    robot = draw(hst.sampled_from(["moving-slide", "tri-slide"]))
    R = _REACH[robot]
    n = draw(hst.integers(1, 8))
    wide = draw(hst.sampled_from([0.002, 0.01, 0.03]))
    psi_w = draw(hst.sampled_from([0.0, 0.0, 0.02, 0.1]))
    p = np.array([draw(hst.floats(-R, R)), draw(hst.floats(-R, R))]) * 0.7
    pc = draw(hst.floats(-0.05, 0.05))
    # one corridor in eight has a gap (boxes or psi ranges that do not touch: an error to confirm)
    gap_at = draw(hst.integers(1, 8 * n))
    boxes = []
    for i in range(n):
        half = wide * (0.2 + _frac(draw)) * np.array([1.0 + _frac(draw), 1.0 + _frac(draw)]) / 2
        lo, hi = p - half, p + half
        boxes.append(([*lo.tolist(), pc - psi_w / 2], [*hi.tolist(), pc + psi_w / 2]))
        # the next box's centre in this box and its angle range overlapping this one: consecutive
        # boxes overlap
        p = np.clip(lo + (hi - lo) * np.array([_frac(draw), _frac(draw)]), -R, R)
        pc = float(np.clip(pc + psi_w * draw(hst.floats(-0.45, 0.45)), -0.05, 0.05))
        if i + 1 == gap_at:
            p = p + 3.0 * half
            pc += psi_w + 0.01
    def inside(b: tuple) -> list[float]:
        lo, hi = np.asarray(b[0]), np.asarray(b[1])
        return (lo + (hi - lo) * np.array([_frac(draw), _frac(draw), _frac(draw)])).tolist()

    s, e = inside(boxes[0]), inside(boxes[-1])
    e_hi = e
    # the end point at a corner or on an edge of the last box as often as inside it (issue 20: an
    # end point at a box corner with short timing left the corridor), and one in four a point in
    # x/y only, with the last box's psi range
    where = draw(hst.sampled_from(["inside", "corner", "edge"]))
    blo, bhi = boxes[-1]
    if where != "inside":
        f = [float(draw(hst.booleans())), float(draw(hst.booleans()))]
        if where == "edge":
            f[draw(hst.integers(0, 1))] = _frac(draw)
        e = [blo[0] + (bhi[0] - blo[0]) * f[0], blo[1] + (bhi[1] - blo[1]) * f[1], e[2]]
        e_hi = e
    if draw(hst.integers(0, 3)) == 0:
        e, e_hi = [e[0], e[1], blo[2]], [e[0], e[1], bhi[2]]
    segs = [{"lower": s, "upper": s}] + [{"lower": lo, "upper": hi} for lo, hi in boxes] + \
        [{"lower": e, "upper": e_hi}]
    return {"robot": robot, "segments": segs}


@hst.composite
def cases(draw: Any) -> dict:
    """A certification case: a layout or a segment corridor, with random timing settings."""
    case = draw(hst.one_of(layout_case(), segments_case()))
    settings: dict[str, Any] = {}
    timing = draw(hst.sampled_from(["default", "default", "speed", "samples"]))
    if timing == "speed":
        settings["speed_m_s"] = draw(hst.sampled_from([0.02, 0.05, 0.1]))
    elif timing == "samples":
        # down to 1-3 samples: short timing, where the end point's stop box, the arrival and
        # the no-overshoot rows meet within a sample or two
        settings["samples_per_segment"] = draw(hst.sampled_from([1, 2, 3, 5, 10, 20, 40]))
    case["settings"] = settings
    return case


def _source_free_provider():
    from hypothesis.internal.conjecture.providers import HypothesisProvider
    from hypothesis.internal.constants_ast import Constants

    class SourceFree(HypothesisProvider):
        """Hypothesis's provider without the constants it collects from the source of the
        modules loaded (it draws one now and then, ~5 % of the draws): with them a case
        depended on which modules the process had imported and on every literal in them, so
        "case 4731 of seed 22" was another corridor after any edit of the planner, or in a
        process that had not imported it yet (issue 20)."""

        @property
        def _local_constants(self):
            return Constants()

    return SourceFree


_SourceFreeProvider = _source_free_provider()


def draw_case(seed: int, i: int) -> dict:
    """Case ``i`` of the seeded list, drawn by hypothesis's own provider (its distributions,
    which favour boundary values: bounds' corners, zero widths) from a random generator seeded
    with ``(seed, i)``: the same in every run and every process, independent of the others.
    (The ``@given`` engine is not used: its generation adapts to what it saw and to time, so
    its examples differ between runs.)"""
    import random

    from hypothesis.errors import StopTest
    from hypothesis.internal.conjecture.data import ConjectureData

    for attempt in range(100):  # an overrun of the choice budget: draw again
        data = ConjectureData(random=random.Random(f"certify {seed} {i} {attempt}"), provider=_SourceFreeProvider)
        try:
            return data.draw(cases())
        except StopTest:
            continue
    raise RuntimeError(f"case {i} of seed {seed} could not be drawn")


def draw_cases(n: int, seed: int, start: int = 0) -> list[dict]:
    """Cases ``start .. start + n - 1`` of the seeded list (:func:`draw_case`)."""
    return [draw_case(seed, i) for i in range(start, start + n)]


def tiny_corridor(rng: np.random.Generator) -> dict:
    """A small segment corridor (issue 20, defect of the end point at a box corner): 2-4
    boxes of 0.5-4 mm (each starting at a corner, the middle or a random point of the one
    before), with or without a start point, the end point at a corner, on an edge or inside
    the last box, a point or (one in three) a point in x/y with the box's psi range; psi
    ranges of 0 to 0.1 rad; 1-10 samples per segment; both robots. ``rng``: a numpy generator."""
    robot = ["moving-slide", "tri-slide"][int(rng.integers(2))]
    n = int(rng.integers(2, 5))
    scale = [0.001, 0.003, 0.01][int(rng.integers(3))]
    psi_w = [0.0, 0.002, 0.01, 0.1][int(rng.integers(4))]
    p = rng.uniform(-0.02, 0.02, 2)
    pc = 0.0
    boxes = []
    for _ in range(n):
        half = scale * (0.3 + rng.random(2)) / 2
        lo, hi = p - half, p + half
        boxes.append((np.array([*lo, pc - psi_w / 2]), np.array([*hi, pc + psi_w / 2])))
        p = lo + (hi - lo) * rng.choice([0.0, 0.5, 1.0, float(rng.random())], 2)
        pc = float(pc + psi_w * rng.uniform(-0.45, 0.45))
    lo, hi = boxes[-1]
    where = int(rng.integers(3))
    if where == 0:  # a corner
        f = rng.choice([0.0, 1.0], 2)
    elif where == 1:  # an edge
        f = np.array([float(rng.choice([0.0, 1.0])), float(rng.random())])
        rng.shuffle(f)
    else:
        f = rng.random(2)
    exy = lo[:2] + (hi[:2] - lo[:2]) * f
    if rng.integers(3) == 0:  # a point in x/y with the box's psi range
        end = ([*exy, lo[2]], [*exy, hi[2]])
    else:
        q = float(lo[2] + (hi[2] - lo[2]) * [0.0, 1.0, float(rng.random())][int(rng.integers(3))])
        end = ([*exy, q], [*exy, q])
    segs = [{"lower": [float(v) for v in a], "upper": [float(v) for v in b]} for a, b in boxes]
    if rng.random() < 0.5:
        s = [*(0.5 * (boxes[0][0][:2] + boxes[0][1][:2])), float(boxes[0][0][2] + psi_w * rng.random())]
        segs.insert(0, {"lower": [float(v) for v in s], "upper": [float(v) for v in s]})
    segs.append({"lower": [float(v) for v in end[0]], "upper": [float(v) for v in end[1]]})
    return {"robot": robot, "segments": segs, "settings": {"samples_per_segment": int(rng.integers(1, 11))}}


def slow_corridor(rng: np.random.Generator) -> dict:
    """A slow corridor of millimetre boxes (issue 20, seed 22 case 4731 of the list before
    2026-11-26: the horizon spans the whole corridor, and an end point with a psi range once
    crept to its angle's middle at the arrival rate): 3-8 boxes of 0.6-3 mm, each starting
    inside the one before, psi ranges of 0 to 0.1 rad, a start point in the first box, the
    end point at a corner, on an edge or inside the last box, as a point or (one in two) a
    point in x/y with the box's psi range; timed at 0.02-0.1 m/s or at 1-5 samples per
    segment; both robots. ``rng``: a numpy generator."""
    robot = ["moving-slide", "tri-slide"][int(rng.integers(2))]
    n = int(rng.integers(3, 9))
    psi_w = [0.0, 0.02, 0.1][int(rng.integers(3))]
    p = rng.uniform(-0.03, 0.03, 2)
    pc = float(rng.uniform(-0.03, 0.03))
    boxes = []
    for _ in range(n):
        half = rng.uniform(0.0006, 0.003, 2) / 2
        lo, hi = p - half, p + half
        boxes.append((np.array([*lo, pc - psi_w / 2]), np.array([*hi, pc + psi_w / 2])))
        p = lo + (hi - lo) * rng.random(2)
        pc = float(pc + psi_w * rng.uniform(-0.45, 0.45))
    lo, hi = boxes[-1]
    f = [rng.choice([0.0, 1.0], 2), np.array([float(rng.choice([0.0, 1.0])), float(rng.random())]),
         rng.random(2)][int(rng.integers(3))]
    exy = lo[:2] + (hi[:2] - lo[:2]) * rng.permutation(f)
    if rng.random() < 0.5:
        end = ([*exy, lo[2]], [*exy, hi[2]])
    else:
        q = float(lo[2] + (hi[2] - lo[2]) * rng.random())
        end = ([*exy, q], [*exy, q])
    s = [*(boxes[0][0][:2] + (boxes[0][1][:2] - boxes[0][0][:2]) * rng.random(2)),
         float(boxes[0][0][2] + psi_w * rng.random())]
    segs = [{"lower": [float(v) for v in s], "upper": [float(v) for v in s]}]
    segs += [{"lower": [float(v) for v in a], "upper": [float(v) for v in b]} for a, b in boxes]
    segs.append({"lower": [float(v) for v in end[0]], "upper": [float(v) for v in end[1]]})
    if rng.random() < 0.7:
        settings: dict[str, Any] = {"speed_m_s": [0.02, 0.05, 0.1][int(rng.integers(3))]}
    else:
        settings = {"samples_per_segment": int(rng.integers(1, 6))}
    return {"robot": robot, "segments": segs, "settings": settings}


# ---------------------------------------------------------------- certifying one case

import collections  # noqa: E402
import contextlib  # noqa: E402
import copy  # noqa: E402
import re  # noqa: E402
import time  # noqa: E402

#: CPU seconds of this process by what it spent them on (``benchmarks/certify.py --profile``),
#: each second counted once, in the innermost category it was spent in (:func:`cpu_spent`):
#: the plan itself by outcome ("plan ok", "plan ok fastest", "plan infeasible", ...), the
#: estimates, the checker ("checker", its JSON of the result "checker: result to JSON"), the
#: confirmation of refusals ("confirmation"); the benchmark adds its own (case building,
#: calibration, retiming, the planner's advice search behind a refusal)
CPU: collections.Counter = collections.Counter()
#: the categories being timed, innermost last: [category, since, spent, {suffix: spent}]
_OPEN: list[list] = []


@contextlib.contextmanager
def cpu_spent(category: str):
    """Add the process CPU time of the block to :data:`CPU` [``category``], less the time of
    the blocks timed inside it (theirs). Yields the category's slot: setting ``slot[0]``
    inside the block names its category once known (a plan's outcome). A ``category`` that
    starts with ":" is a part of the block around it: counted as that block's category (as
    named when it ends) followed by this suffix ("plan infeasible: DAQP")."""
    now = time.process_time()
    if _OPEN:
        outer = _OPEN[-1]
        outer[2] += now - outer[1]
    slot = [category, now, 0.0, collections.Counter()]
    _OPEN.append(slot)
    try:
        yield slot
    finally:
        now = time.process_time()
        _OPEN.pop()
        spent = slot[2] + now - slot[1]
        if _OPEN and slot[0].startswith(":"):
            _OPEN[-1][3][slot[0]] += spent
        else:
            CPU[slot[0]] += spent
        for suffix, v in slot[3].items():
            CPU[f"{slot[0]}{suffix}"] += v
        if _OPEN:
            _OPEN[-1][1] = now


def cpu_category() -> str | None:
    """The innermost category being timed (None outside :func:`cpu_spent`)."""
    return _OPEN[-1][0] if _OPEN else None


#: a figure printed as zero (0, 0.0, 0.0000 ...) followed by a unit: never a cause
ZERO_FIGURE = re.compile(r"(?<!t = )(?<![\d.])0(?:\.0+)?\s*(?:mm|m|s|N|mm/s|m/s|rad|um)\b(?! \.\.)")


def _with(request: dict, **settings: Any) -> dict:
    out = copy.deepcopy(request)
    out["settings"] = {**out.get("settings", {}), **settings}
    return out


def _segments_of(request: dict, result: Any) -> list[dict]:
    if request.get("segments") is not None:
        return request["segments"]
    return [{"lower": np.asarray(s.lower).tolist(), "upper": np.asarray(s.upper).tolist(),
             "polygon": None if s.polygon is None else np.asarray(s.polygon).tolist()}
            for s in result.corridor.segments]


def confirm_error(request: dict, code: str, message: str, field_name: str | None) -> str | None:
    """None if the error is confirmed independently (or its remedy works), else what is wrong."""
    from planner import PlannerError, plan
    from planner import segment as segment_layout

    # coordinates (tuples in parentheses) are places, not causes
    if ZERO_FIGURE.search(re.sub(r"\([^()]*,[^()]*\)", "", message.split(";")[0])):
        return f"a zero figure as the cause: {message}"
    robot = robot_of(request.get("robot"))
    if code == "no_path":
        lay = request["layout"]
        m = re.search(r"cells of ([0-9.e-]+) m \(layout\.cell\.size", message)
        if m:  # the remedy must give a path
            fixed = copy.deepcopy(request)
            fixed["layout"]["cell"]["size"] = float(m.group(1))
            try:
                segment_layout(fixed)
            except PlannerError as exc:
                return f"the advised cell size {m.group(1)} m gives no path: {exc}"
            return None
        m = re.search(r"a clearance of ([0-9.e-]+) m \(layout\.clearance.*?(?: with cells of ([0-9.e-]+) m)? gives",
                      message)
        if m:
            fixed = copy.deepcopy(request)
            fixed["layout"]["clearance"] = float(m.group(1))
            if m.group(2):
                fixed["layout"]["cell"]["size"] = float(m.group(2))
            try:
                segment_layout(fixed)
            except PlannerError as exc:
                return f"the advised clearance gives no path: {exc}"
            return None
        if "give a path" in message or "gives a path" in message:
            return None  # psi_range advice: checked by the planner, not re-run here
        # no remedy: the free space itself must not join start and end on a fine grid
        W = np.asarray(lay["bounds"]["upper"], float) - np.asarray(lay["bounds"]["lower"], float)
        step = max(float(min(W)) / 400.0, 2.5e-4)
        if "no cell size can pass it" in message and grid_path_exists(lay, robot, step):
            return f"the error says no cell size can pass, but a {step:g} m grid finds a path"
        return None
    if code == "unreachable" and (field_name or "").endswith((".start", ".end")) and "needs leg" in message:
        pose = np.asarray(request["layout"][(field_name or "").rsplit(".", 1)[1]], float)
        L = leg_lengths(robot, pose[None])[0]
        if np.all((L >= robot.lmin - 1e-12) & (L <= robot.lmax + 1e-12)):
            return f"the {field_name} pose is within every leg's stroke"
        return None
    if code == "unreachable":
        m = re.search(r"segments\[(\d+)\]", field_name or "")
        if m and request.get("segments") is not None:
            s = request["segments"][int(m.group(1))]
            lo, hi = np.asarray(s["lower"], float), np.asarray(s["upper"], float)
            mins, maxs = box_leg_range(robot, lo[:2], hi[:2], np.linspace(lo[2], hi[2], 5))
            if np.all(mins >= robot.lmin - 1e-12) and np.all(maxs <= robot.lmax + 1e-12):
                return f"segment {m.group(1)} is within every leg's stroke"
        return None
    if code == "infeasible" and "do not touch" in message:
        m = re.search(r"segments\[(\d+)\] and segments\[(\d+)\] do not touch", message)
        if not m or request.get("segments") is None:
            return f"a gap named without its segments: {message}"
        a, b = (request["segments"][int(g)] for g in m.groups())
        alo, ahi = np.asarray(a["lower"], float), np.asarray(a["upper"], float)
        blo, bhi = np.asarray(b["lower"], float), np.asarray(b["upper"], float)
        apart = np.maximum(blo - ahi, alo - bhi)  # > 0: separated along that axis
        if not np.any(apart > -2.1e-6):  # the planner's gaps allow for its 1 um margins
            return f"segments {m.group(1)} and {m.group(2)} overlap, yet the error says they do not touch"
        return None
    if code == "infeasible" and re.search(r"settings\.N = \d+ with \d+x the time \([^()]*\) plans|"
                                          r"settings\.plant_substeps = \d+ plans", message):
        # (issue 31) the remedy applied as the message names it (not a list of those that "do not plan either")
        from tests.advice_support import apply_advice

        fixed = apply_advice(request, message)
        if fixed is None:
            return f"advice that names no setting to apply: {message}"
        try:
            plan(fixed)
        except PlannerError as exc:
            return f"the advised setting still fails: {exc.code}: {exc}"
        return None
    if code == "infeasible" and re.search(r"settings\.N = \d+ plans|settings\.fastest plans", message):
        fixed = copy.deepcopy(request)
        fixed.setdefault("settings", {})
        m = re.search(r"settings\.N = (\d+) plans", message)
        if m:  # a longer horizon at the same timing
            fixed["settings"]["N"] = int(m.group(1))
            if not any(fixed["settings"].get(k) not in (None, False) for k in
                       ("speed_m_s", "total_time_s", "samples_per_segment", "segment_samples", "fastest")):
                fixed["settings"]["samples_per_segment"] = int(plan_settings(request)["samples_per_segment"])
        else:
            for k in ("speed_m_s", "total_time_s", "samples_per_segment", "segment_samples"):
                fixed["settings"].pop(k, None)
            fixed["settings"]["fastest"] = True
        try:
            plan(fixed)
        except PlannerError as exc:
            return f"the advised setting still fails: {exc.code}: {exc}"
        return None
    if code == "infeasible":
        m = re.search(r"(\d+)x the time plans", message)
        if m:  # the advice must plan: every segment's samples times the factor
            factor = int(m.group(1))
            fixed = copy.deepcopy(request)
            fixed.setdefault("settings", {})
            how = re.search(r"settings\.(speed_m_s|total_time_s|samples_per_segment) = ([0-9.e+-]+)", message)
            if how:
                for k in ("speed_m_s", "total_time_s", "samples_per_segment", "segment_samples"):
                    fixed["settings"].pop(k, None)
                val = float(how.group(2))
                fixed["settings"][how.group(1)] = int(val) if how.group(1) == "samples_per_segment" else val
                size = re.search(r"layout\.cell\.size = ([0-9.e+-]+) m", message)
                if size:  # advice in samples keeps the cell size the check planned
                    fixed["layout"].setdefault("cell", {})["size"] = float(size.group(1))
            else:
                fixed["settings"]["segment_samples"] = [c * factor for c in fixed["settings"]["segment_samples"]]
            try:
                plan(fixed)
            except PlannerError as exc:
                return f"the advised {factor}x the time still fails: {exc.code}: {exc}"
        # "more time was not tried (... within the work limit)": no advice, the bounded search's
        # own account (a server's compute limit leaves it no budget)
        elif "more time" in message and not re.search(r"do(es)? not help|more time was not tried", message):
            return f"advice of more time that was not checked: {message}"
    return None


def plan_settings(request: dict) -> dict:
    """The request's settings as validated (the defaults filled in), as a dict."""
    from planner import parse_request

    return parse_request(request).settings.model_dump()


def certify_case(case: dict, modes: tuple[str, ...] = ("constrained", "paper"),
                 work_limit_s: float | None = None) -> dict:
    """Plan ``case`` in each mode, certify the answer, and time it against the estimate:
    ``{mode: {"outcome": "ok" | code, "problem": str | None, "seconds": s, "estimate": s}}``.
    ``seconds`` is the process's CPU time of the plan (robust to other load on the machine);
    ``estimate`` the work estimate the planner bounds the plan with before simulating (a
    layout's once segmented, :func:`planner.estimate_work` with its segments); ``advice`` the
    estimate's bound on checking an error's advice (``advice_seconds``). ``work_limit_s``: as
    a server with this compute limit, a request estimated over it is refused up front
    (``too_much_work``, not planned) and the plan's advice checks are bounded by it."""
    from planner import PlannerError, estimate_work, plan

    out: dict[str, dict] = {}
    for mode in modes:
        req = _with(case, mode=mode)
        fastest = " fastest" if req["settings"].get("fastest") else ""
        rec: dict[str, Any] = {"outcome": None, "problem": None}
        try:
            with cpu_spent("estimate"):
                est = estimate_work(req)
            rec["estimate"], rec["advice"] = est.seconds, est.advice_seconds
        except PlannerError as exc:
            rec.update(outcome=exc.code, estimate=None, seconds=0.0)
            out[mode] = rec
            continue
        if work_limit_s is not None and est.seconds > work_limit_s:
            rec.update(outcome="too_much_work", seconds=0.0)
            out[mode] = rec
            continue
        t0 = time.process_time()
        try:
            with cpu_spent(f"plan ok{fastest}") as slot:
                try:
                    result = plan(req, work_limit_s=work_limit_s)
                except PlannerError as exc:
                    slot[0] = f"plan {exc.code}{fastest}"
                    raise
        except PlannerError as exc:
            rec["seconds"] = time.process_time() - t0
            rec["outcome"] = exc.code
            rec["message"] = str(exc)
            if exc.code == "infeasible" and req.get("layout") is not None:
                # planned on the segmented corridor: estimated from it, as the planner does
                from planner import segment

                with cpu_spent("estimate"):
                    est = estimate_work(req, segment(req).segments)
                rec["estimate"], rec["advice"] = est.seconds, est.advice_seconds
            if mode == "constrained":
                with cpu_spent("confirmation"):
                    rec["problem"] = confirm_error(req, exc.code, exc.message, exc.field)
            out[mode] = rec
            continue
        rec["seconds"] = time.process_time() - t0
        rec["outcome"] = "ok"
        if req.get("layout") is not None:
            from planner.schema import Segment

            with cpu_spent("estimate"):
                segs = [Segment.model_validate(s) for s in _segments_of(req, result)]
                rec["estimate"] = estimate_work(req, segs).seconds
        with cpu_spent("checker"):
            verdict = check_plan(req, result, _segments_of(req, result))
        if not verdict.ok:
            rec["problem"] = "; ".join(verdict.problems[:3])
        out[mode] = rec
    return out


def user_robot(rng: np.random.Generator) -> dict:
    """A Moving-Slide-like robot of 3 to 6 legs (pivots on circles, the legs turned 0.32 rad
    off the radial direction as in the Moving Slide, 0.316 m at the home pose), its platform's
    mass x0.1 to x10, a leg friction of 5 to 2000 N s/m and (one in three) a leg-speed limit
    of 0.01 to 0.5 m/s instead of 0.5 (issue 31)."""
    n = int(rng.integers(3, 7))
    th = 2 * np.pi * np.arange(n) / n + float(rng.uniform(0, np.pi))
    base = 0.4472 * np.column_stack((np.cos(th), np.sin(th)))
    plat = 0.1414 * np.column_stack((np.cos(th + 0.32), np.sin(th + 0.32)))
    desc = json.loads((DATA / "moving-slide.json").read_text())
    desc.update(name=f"user-{n}", base_pivots=base.tolist(), platform_pivots=plat.tolist())
    desc["platform"]["mass"] = float(15.0 * 10 ** rng.uniform(-1, 1))
    desc["legs"]["friction"] = float([5.0, 50.0, 500.0, 2000.0][int(rng.integers(4))])
    if rng.random() < 1 / 3:
        desc["legs"]["speed_max"] = float(10 ** rng.uniform(-2, np.log10(0.5)))
    return desc


def _builtin_robot(rng: np.random.Generator) -> Any:
    """A built-in robot by name, or (one in three) the Moving Slide's description with a
    leg-speed limit of 0.01 to 0.5 m/s."""
    name = ["moving-slide", "tri-slide"][int(rng.integers(2))]
    if rng.random() < 1 / 3:
        desc = json.loads((DATA / f"{name}.json").read_text())
        legs = desc["legs"] if isinstance(desc["legs"], list) else [desc["legs"]]
        v = float(10 ** rng.uniform(-2, np.log10(0.5)))
        for g in legs:
            g["speed_max"] = v
        return desc
    return name


def _user_corridor(rng: np.random.Generator) -> list[dict]:
    """A start point, 1-3 boxes of 3-30 mm (or, one in four, a chain of 4-10 boxes of 5-20 mm,
    each overlapping the one before), an end point; one in three with psi ranges of 0.01-0.3
    rad (the start and end angles inside the first and last box's range)."""
    long = rng.random() < 0.25
    psi_w = float(rng.uniform(0.01, 0.3)) if rng.random() < 1 / 3 else 0.0
    pc = float(rng.uniform(-0.1, 0.1)) if psi_w else 0.0
    p = rng.uniform(-0.02, 0.02, 2)
    start = [*p, pc]
    boxes = []
    for _ in range(int(rng.integers(4, 11)) if long else int(rng.integers(1, 4))):
        size = rng.uniform(0.005, 0.02) if long else rng.uniform(0.003, 0.03)
        q = p + rng.uniform(0.3, 1.0, 2) * size * rng.choice([-1, 1], 2)
        lo, hi = np.minimum(p, q), np.maximum(p, q)
        boxes.append(([*lo, pc - psi_w / 2], [*hi, pc + psi_w / 2]))
        p = q
        pc = float(pc + psi_w * rng.uniform(-0.4, 0.4))
    lo_psi, hi_psi = boxes[-1][0][2], boxes[-1][1][2]
    end = [*p, float(lo_psi + (hi_psi - lo_psi) * rng.random())]
    segs = [{"lower": [float(v) for v in start], "upper": [float(v) for v in start]}]
    segs += [{"lower": [float(v) for v in a], "upper": [float(v) for v in b]} for a, b in boxes]
    segs.append({"lower": [float(v) for v in end], "upper": [float(v) for v in end]})
    return segs


def user_case(rng: np.random.Generator, Ts_choices: tuple[float, ...] = (0.001, 0.002, 0.005, 0.01)) -> dict:
    """Where users go (issue 31 goal 1): a robot of :func:`user_robot` or a built-in one (with
    leg-speed limits of 0.01-0.5 m/s), a corridor of :func:`_user_corridor` (short or long,
    psi ranges), Ts from ``Ts_choices`` with or without a fixed N (20-100), and every timing:
    the default, a speed of 0.001-5 m/s, a total time of 0.05-5 s, ``fastest`` (on every
    corridor shape), and force rates of 20 N/s to 3000 N/s, the default or 'off'."""
    robot: Any = user_robot(rng) if rng.random() < 0.5 else _builtin_robot(rng)
    segs = _user_corridor(rng)
    st: dict[str, Any] = {"Ts": float(Ts_choices[int(rng.integers(len(Ts_choices)))])}
    if rng.random() < 0.25:
        st["N"] = int(rng.choice([20, 30, 60, 100]))
    timing = int(rng.integers(4))
    if timing == 1:
        st["speed_m_s"] = float(10 ** rng.uniform(-3, np.log10(5.0)))
    elif timing == 2:
        st["total_time_s"] = float(10 ** rng.uniform(np.log10(0.05), np.log10(5.0)))
    elif timing == 3:
        st["fastest"] = True
    rate = int(rng.integers(4))
    if rate == 1:
        st["force_rate_n_s"] = "off"
    elif rate >= 2:
        st["force_rate_n_s"] = float(10 ** rng.uniform(np.log10(20.0), np.log10(3000.0)))
    return {"robot": robot, "segments": segs, "settings": st}


#: the remedies :func:`try_remedies` tries on a refused plan (issue 31 goal 1: is a refusal
#: needless, a setting plans that the advice does not name?)
REMEDIES = ("advice", "N x2", "fastest", "plant_substeps 8")


def try_remedies(case: dict, message: str, limit_s: float = 30.0) -> dict[str, str]:
    """Each of :data:`REMEDIES` applied to the refused request ``case`` (constrained mode):
    ``"ok"`` (planned, and the plan passes :func:`check_plan`), ``"uncertified"`` (planned, the
    checker disagrees), the error code it fails with, ``"too_much_work"`` (estimated over
    ``limit_s``, not planned, as a server with that limit), or ``"none"`` (the message names no
    setting: ``advice`` only). ``advice`` is the message's first remedy
    (:func:`tests.advice_support.apply_advice`); ``N x2`` twice the horizon the request planned
    with (at most MAX_HORIZON); ``fastest`` the request's timing replaced by ``settings.fastest``;
    ``plant_substeps 8`` eight RK4 steps a sample."""
    from planner import PlannerError, estimate_work, plan
    from planner.schema import MAX_HORIZON
    from tests.advice_support import apply_advice

    req = _with(case, mode="constrained")
    out: dict[str, str] = {}
    for name in REMEDIES:
        fixed: dict | None
        if name == "advice":
            fixed = apply_advice(req, message)
        elif name == "N x2":
            fixed = _with(req, N=min(2 * int(plan_settings(req)["N"]), MAX_HORIZON))
        elif name == "fastest":
            fixed = copy.deepcopy(req)
            for k in ("speed_m_s", "total_time_s", "samples_per_segment", "segment_samples"):
                fixed["settings"].pop(k, None)
            fixed["settings"]["fastest"] = True
        else:
            fixed = _with(req, plant_substeps=8)
        if fixed is None:
            out[name] = "none"
            continue
        try:
            if estimate_work(fixed).seconds > limit_s:
                out[name] = "too_much_work"
                continue
            result = plan(fixed, work_limit_s=limit_s)
        except PlannerError as exc:
            out[name] = exc.code
            continue
        out[name] = "ok" if check_plan(fixed, result, _segments_of(fixed, result)).ok else "uncertified"
    return out


def users_case(i: int) -> dict:
    """Case ``i`` of the users run of seed 31 (``benchmarks/certify.py --users --seed 31``), in
    the constrained mode."""
    return _with(user_case(np.random.default_rng([31, i])), mode="constrained")


def cpu_over_estimate(req: dict, table1: dict, refused: bool = False) -> float:
    """``req``'s CPU time over its work estimate at the reference machine's speed (Table I's
    CPU time now over its 20 ms there, as benchmarks/certify.py calibrates; the least of 3
    timings each). ``refused``: ``req`` is refused (``infeasible``), and its own CPU time is
    measured, up to where its advice search starts (as ``certify.py --profile`` separates "plan
    infeasible" from "advice search")."""
    import sys

    import pytest

    from planner import estimate_work, plan

    orchestrator = sys.modules["planner.orchestrator.plan"]

    class _AdviceStarts(Exception):
        pass

    def no_advice(exc, *args, **kwargs):
        raise _AdviceStarts

    def cpu(r: dict, refused: bool = False) -> float:
        best = np.inf
        for _ in range(3):
            t0 = time.process_time()
            if refused:
                with pytest.MonkeyPatch.context() as mp:
                    mp.setattr(orchestrator, "_more_time_advice", no_advice)
                    try:
                        plan(r)
                        raise AssertionError("planned, not refused")
                    except _AdviceStarts:
                        pass
            else:
                plan(r)
            best = min(best, time.process_time() - t0)
        return best

    speed = cpu(table1) / 0.020
    return cpu(req, refused) / speed / estimate_work(req).seconds

