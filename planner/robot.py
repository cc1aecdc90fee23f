"""Robot model of a planar nRPR parallel robot (paper Section III, eqs. 1-8).

Physical coordinates (paper's ``s``), for ``n`` legs::

    s = (x_c, y_c, psi, l_1..l_n, phi_1..phi_n)

the platform centre, the platform angle, each leg's length and each leg's angle. Leg ``i``
closes the loop ``A_i + l_i e(phi_i) - (c + Rot(psi) b_i) = 0`` (eq. 2, two rows per leg,
``2n`` constraints, 3 DOF). The independent coordinates (paper's ``y``) are the pose of
the tool point ``(x, y, psi)``: the platform centre plus ``Rot(psi) * tool_offset``.

``R = ds/dy`` comes from the inverse kinematics and spans the null space of the constraint
Jacobian ``Phi_s`` (eq. 3); ``R_dot y_dot`` is the convective term of eq. (4). The leg
masses follow the usual RPR model: a cylinder turning about the base pivot ``A_i`` with its
centre of mass at a fixed distance from ``A_i``, and a rod sliding in it with its centre of
mass at a fixed distance from the platform pivot. Drive ``u_i`` [N] is the force of the
prismatic drive along leg ``i`` (positive extends the leg); the paper's ``T`` maps it onto
``l_i``, so ``R^T T`` is the transposed leg Jacobian (4 forces, 3 DOF: redundant actuation).
The robot is horizontal: no gravity in the plane; viscous friction acts on each leg's
sliding speed.

All quantities SI: m, rad, s, kg, kg m^2, N, N s/m.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import cached_property
from importlib import resources
from pathlib import Path

import numpy as np
from scipy.linalg import get_lapack_funcs

from .errors import PlannerError, invalid

E3 = np.array([0.0, 0.0, 1.0])
_gesv = get_lapack_funcs("gesv", dtype=np.float64)


def _solve(M: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve a small dense system with LAPACK gesv directly (numpy's wrapper costs 5x more
    than the solve itself at 3x3); raises on a singular matrix."""
    _, _, x, info = _gesv(M, b)
    if info != 0:
        raise np.linalg.LinAlgError("singular reduced mass matrix")
    return x

#: smallest singular value of the dimensionless leg Jacobian below which a pose is singular
SINGULAR_TOL = 1e-2


# ---------------------------------------------------------------------------------------
# robot description (JSON)
# ---------------------------------------------------------------------------------------

def _num(value, field_path: str, *, positive=False, nonneg=False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise invalid(field_path, f"must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise invalid(field_path, "must be a finite number")
    if positive and v <= 0:
        raise invalid(field_path, f"must be > 0, got {v}")
    if nonneg and v < 0:
        raise invalid(field_path, f"must be >= 0, got {v}")
    return v


def _points(value, field_path: str, count: int | None = None) -> np.ndarray:
    if not isinstance(value, (list, tuple)) or not value:
        raise invalid(field_path, "must be a non-empty list of [x, y] points in m")
    if count is not None and len(value) != count:
        raise invalid(field_path, f"must have {count} points (one per leg), got {len(value)}")
    out = []
    for i, p in enumerate(value):
        if not isinstance(p, (list, tuple)) or len(p) != 2:
            raise invalid(f"{field_path}[{i}]", "must be a point [x, y] in m")
        out.append([_num(p[0], f"{field_path}[{i}][0]"), _num(p[1], f"{field_path}[{i}][1]")])
    return np.array(out, dtype=float)


_LEG_FIELDS = ("friction", "length_min", "length_max", "force_max", "speed_max")


def _leg(value, field_path: str) -> dict:
    if not isinstance(value, dict):
        raise invalid(field_path, "must be an object describing a leg")
    out = {}
    for part in ("cylinder", "rod"):
        body = value.get(part)
        if not isinstance(body, dict):
            raise invalid(f"{field_path}.{part}", "must be an object {mass, com, inertia}")
        out[f"{part}_mass"] = _num(body.get("mass"), f"{field_path}.{part}.mass", nonneg=True)
        out[f"{part}_com"] = _num(body.get("com"), f"{field_path}.{part}.com")
        out[f"{part}_inertia"] = _num(body.get("inertia"), f"{field_path}.{part}.inertia", nonneg=True)
    out["friction"] = _num(value.get("friction", 0.0), f"{field_path}.friction", nonneg=True)
    for key in ("length_min", "length_max", "force_max", "speed_max"):
        out[key] = _num(value.get(key), f"{field_path}.{key}", positive=True)
    if out["length_min"] >= out["length_max"]:
        raise invalid(f"{field_path}.length_min", "must be smaller than length_max")
    return out


@dataclass(frozen=True, eq=False)
class Robot:
    """A planar nRPR parallel robot (description + the model of eqs. 1-8)."""

    name: str
    base: np.ndarray  # (n, 2) base pivots A_i, world frame [m]
    platform: np.ndarray  # (n, 2) platform pivots b_i, platform frame, about the platform centre [m]
    platform_mass: float  # [kg]
    platform_inertia: float  # about the platform centre [kg m^2]
    cyl_mass: np.ndarray  # (n,) [kg]
    cyl_com: np.ndarray  # (n,) distance of the cylinder's centre of mass from A_i [m]
    cyl_inertia: np.ndarray  # (n,) about its centre of mass [kg m^2]
    rod_mass: np.ndarray  # (n,) [kg]
    rod_com: np.ndarray  # (n,) distance of the rod's centre of mass from b_i [m]
    rod_inertia: np.ndarray  # (n,) [kg m^2]
    friction: np.ndarray  # (n,) viscous friction on the leg's sliding speed [N s/m]
    length_min: np.ndarray  # (n,) [m]
    length_max: np.ndarray  # (n,) [m]
    force_max: np.ndarray  # (n,) [N]
    speed_max: np.ndarray  # (n,) [m/s]
    tool: np.ndarray = field(default_factory=lambda: np.zeros(2))  # tool offset, platform frame [m]
    description: str = ""

    # ---- construction -----------------------------------------------------------------
    @classmethod
    def from_description(cls, desc: dict, field_path: str = "robot") -> "Robot":
        """Build a robot from its JSON description (see ``planner/data/moving-slide.json``)."""
        if not isinstance(desc, dict):
            raise invalid(field_path, "must be a robot name or a robot description object")
        base = _points(desc.get("base_pivots"), f"{field_path}.base_pivots")
        n = len(base)
        if n < 3:
            raise invalid(f"{field_path}.base_pivots", f"needs at least 3 legs for 3 DOF, got {n}")
        plat = _points(desc.get("platform_pivots"), f"{field_path}.platform_pivots", n)
        for pts, key in ((base, "base_pivots"), (plat, "platform_pivots")):
            gap = np.linalg.norm(pts[:, None] - pts[None], axis=-1) + np.eye(n)
            if gap.min() < 1e-6:
                i, j = np.unravel_index(np.argmin(gap), gap.shape)
                raise invalid(f"{field_path}.{key}", f"pivots {i + 1} and {j + 1} coincide; each leg needs its own pivot")
        extent = np.ptp(plat, axis=0)
        if np.linalg.matrix_rank(plat - plat.mean(axis=0), tol=1e-6) < 1 or extent.max() < 1e-6:
            raise invalid(f"{field_path}.platform_pivots", "the platform pivots must span a platform")
        pf = desc.get("platform")
        if not isinstance(pf, dict):
            raise invalid(f"{field_path}.platform", "must be an object {mass, inertia}")
        mass = _num(pf.get("mass"), f"{field_path}.platform.mass", positive=True)
        inertia = _num(pf.get("inertia"), f"{field_path}.platform.inertia", positive=True)
        legs = desc.get("legs")
        if isinstance(legs, dict):
            legs = [_leg(legs, f"{field_path}.legs")] * n
        elif isinstance(legs, list):
            if len(legs) != n:
                raise invalid(f"{field_path}.legs", f"must describe {n} legs (one per pivot), got {len(legs)}")
            legs = [_leg(leg, f"{field_path}.legs[{i}]") for i, leg in enumerate(legs)]
        else:
            raise invalid(f"{field_path}.legs", "must be one leg object (shared) or a list, one per leg")
        tool = desc.get("tool_offset", [0.0, 0.0])
        if not isinstance(tool, (list, tuple)) or len(tool) != 2:
            raise invalid(f"{field_path}.tool_offset", "must be [x, y] in m (platform frame)")
        tool = np.array([_num(tool[0], f"{field_path}.tool_offset[0]"), _num(tool[1], f"{field_path}.tool_offset[1]")])
        col = lambda key: np.array([leg[key] for leg in legs])  # noqa: E731
        name = desc.get("name", "custom")
        if not isinstance(name, str):
            raise invalid(f"{field_path}.name", "must be a string")
        return cls(
            name=name, base=base, platform=plat, platform_mass=mass, platform_inertia=inertia,
            cyl_mass=col("cylinder_mass"), cyl_com=col("cylinder_com"), cyl_inertia=col("cylinder_inertia"),
            rod_mass=col("rod_mass"), rod_com=col("rod_com"), rod_inertia=col("rod_inertia"),
            friction=col("friction"), length_min=col("length_min"), length_max=col("length_max"),
            force_max=col("force_max"), speed_max=col("speed_max"), tool=tool,
            description=str(desc.get("description", "")),
        )

    @property
    def n_legs(self) -> int:
        return len(self.base)

    @cached_property
    def _r0(self) -> np.ndarray:
        """Platform pivots relative to the tool point, platform frame (n, 2) [m]."""
        return self.platform - self.tool

    @cached_property
    def char_length(self) -> float:
        """Characteristic platform radius [m] that makes the rotation column of the leg
        Jacobian comparable with the translation columns (singularity measure)."""
        return float(max(np.max(np.linalg.norm(self._r0, axis=1)), 1e-3))

    @cached_property
    def _leg_inertia_const(self) -> np.ndarray:
        """Part of each leg's inertia about A_i that does not depend on l [kg m^2]."""
        return self.cyl_inertia + self.cyl_mass * self.cyl_com**2 + self.rod_inertia

    # ---- kinematics -------------------------------------------------------------------
    def legs(self, y: np.ndarray):
        """Inverse kinematics at pose ``y = (x, y, psi)``.

        Returns ``(l, e, r, rc)``: leg lengths (n,) [m], unit leg directions (n, 2),
        pivot positions relative to the tool point in the world frame (n, 2) [m], and the
        platform centre relative to the tool point (2,) [m].
        """
        c, s = math.cos(y[2]), math.sin(y[2])
        rot = np.array([[c, -s], [s, c]])
        r = self._r0 @ rot.T
        d = y[:2] + r - self.base
        l = np.sqrt(np.einsum("ij,ij->i", d, d))
        return l, d / l[:, None], r, -(rot @ self.tool)

    def _leg_vectors_batch(self, poses: np.ndarray):
        """For a batch of poses (k, 3): pivots relative to the tool point ``(rx, ry)`` and
        leg vectors base pivot -> platform pivot ``(dx, dy)``, each (k, n) [m]."""
        poses = np.atleast_2d(poses)
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        rx = c[:, None] * self._r0[:, 0] - s[:, None] * self._r0[:, 1]
        ry = s[:, None] * self._r0[:, 0] + c[:, None] * self._r0[:, 1]
        return rx, ry, poses[:, :1] + rx - self.base[:, 0], poses[:, 1:2] + ry - self.base[:, 1]

    def leg_lengths(self, poses: np.ndarray) -> np.ndarray:
        """Leg lengths [m] for a batch of poses (k, 3) -> (k, n)."""
        _, _, dx, dy = self._leg_vectors_batch(poses)
        return np.hypot(dx, dy)

    def leg_jacobians(self, y: np.ndarray):
        """Leg Jacobians at pose y: ``J_l`` (n, 3) with ``l_dot = J_l y_dot`` and ``J_phi``
        (n, 3) with ``phi_dot = J_phi y_dot``; these are the leg rows of ``R = ds/dy``."""
        l, e, r, rc = self.legs(y)
        cross = r[:, 0] * e[:, 1] - r[:, 1] * e[:, 0]  # r x e
        dot = np.einsum("ij,ij->i", r, e)  # r . e
        J_l = np.column_stack((e, cross))
        J_phi = np.column_stack((-e[:, 1], e[:, 0], dot)) / l[:, None]
        return l, e, r, rc, J_l, J_phi

    def R_matrix(self, y: np.ndarray) -> np.ndarray:
        """``R = ds/dy`` (eq. 4), shape (3 + 2n, 3), rows ordered as ``s``."""
        l, e, r, rc, J_l, J_phi = self.leg_jacobians(y)
        Rc = np.array([[1.0, 0.0, -rc[1]], [0.0, 1.0, rc[0]], [0.0, 0.0, 1.0]])
        return np.vstack((Rc, J_l, J_phi))

    def physical_coordinates(self, y: np.ndarray) -> np.ndarray:
        """``s(y)`` = (x_c, y_c, psi, l_1..l_n, phi_1..phi_n)."""
        l, e, r, rc = self.legs(y)
        return np.concatenate((y[:2] + rc, [y[2]], l, np.arctan2(e[:, 1], e[:, 0])))

    def constraints(self, s: np.ndarray) -> np.ndarray:
        """Loop-closure constraints ``f(s) = 0`` (eq. 2), shape (2n,)."""
        n = self.n_legs
        c, psi, l, phi = s[:2], s[2], s[3:3 + n], s[3 + n:]
        rot = np.array([[math.cos(psi), -math.sin(psi)], [math.sin(psi), math.cos(psi)]])
        lhs = self.base + l[:, None] * np.column_stack((np.cos(phi), np.sin(phi)))
        return (lhs - (c + self.platform @ rot.T)).ravel()

    def constraint_jacobian(self, s: np.ndarray) -> np.ndarray:
        """``Phi_s = df/ds`` (eq. 3), shape (2n, 3 + 2n)."""
        n = self.n_legs
        psi, l, phi = s[2], s[3:3 + n], s[3 + n:]
        c, sn = math.cos(psi), math.sin(psi)
        drot = np.array([[-sn, -c], [c, -sn]])  # d Rot / d psi
        Phi = np.zeros((2 * n, 3 + 2 * n))
        idx = np.arange(n)
        Phi[2 * idx, 0] = -1.0
        Phi[2 * idx + 1, 1] = -1.0
        Phi[:, 2] = -(self.platform @ drot.T).ravel()
        Phi[2 * idx, 3 + idx] = np.cos(phi)
        Phi[2 * idx + 1, 3 + idx] = np.sin(phi)
        Phi[2 * idx, 3 + n + idx] = -l * np.sin(phi)
        Phi[2 * idx + 1, 3 + n + idx] = l * np.cos(phi)
        return Phi

    def mass_matrix(self, s: np.ndarray) -> np.ndarray:
        """``M(s)`` of eq. (1): diagonal in these coordinates [kg, kg m^2]."""
        n = self.n_legs
        l = s[3:3 + n]
        diag = np.concatenate((
            [self.platform_mass, self.platform_mass, self.platform_inertia],
            self.rod_mass,
            self._leg_inertia_const + self.rod_mass * (l - self.rod_com) ** 2,
        ))
        return np.diag(diag)

    def forces_g(self, s: np.ndarray, s_dot: np.ndarray) -> np.ndarray:
        """``g(s, s_dot)`` of eq. (1): the legs' velocity-product terms and viscous friction [N, N m]."""
        n = self.n_legs
        l, l_dot, phi_dot = s[3:3 + n], s_dot[3:3 + n], s_dot[3 + n:]
        arm = l - self.rod_com
        g = np.zeros(3 + 2 * n)
        g[3:3 + n] = self.rod_mass * arm * phi_dot**2 - self.friction * l_dot
        g[3 + n:] = -2.0 * self.rod_mass * arm * l_dot * phi_dot
        return g

    # ---- singularity and reach ----------------------------------------------------------
    def leg_jacobian_batch(self, poses: np.ndarray) -> np.ndarray:
        """Leg Jacobians ``J_l`` for a batch of poses (k, 3) -> (k, n, 3)."""
        rx, ry, dx, dy = self._leg_vectors_batch(poses)
        l = np.hypot(dx, dy)
        ex, ey = dx / l, dy / l
        return np.stack((ex, ey, rx * ey - ry * ex), axis=-1)

    def singularity_measure_batch(self, poses: np.ndarray) -> np.ndarray:
        """:meth:`singularity_measure` for a batch of poses (k, 3) -> (k,)."""
        from .kernels import smallest_singular_values

        with np.errstate(invalid="ignore", divide="ignore"):  # a zero-length leg has no direction
            Jn = self.leg_jacobian_batch(poses) * np.array([1.0, 1.0, 1.0 / self.char_length])
        # compiled one-sided Jacobi (0 where not finite); equals the SVD's (tests/test_kernels.py)
        return smallest_singular_values(np.ascontiguousarray(Jn))

    def check_pose(self, y, field_path: str = "pose") -> None:
        """Raise a clear :class:`PlannerError` if pose ``y`` is unreachable or singular."""
        y = np.asarray(y, dtype=float)
        l, e, r, rc, J_l, J_phi = self.leg_jacobians(y)
        pose = f"({y[0]:.4f} m, {y[1]:.4f} m, {y[2]:.4f} rad)"
        for i in range(self.n_legs):
            if l[i] < self.length_min[i] - 1e-12:
                raise PlannerError("unreachable", f"pose {pose} needs leg {i + 1} at {l[i]:.4f} m, "
                                   f"shorter than its minimum {self.length_min[i]:.4f} m", field_path)
            if l[i] > self.length_max[i] + 1e-12:
                raise PlannerError("unreachable", f"pose {pose} needs leg {i + 1} at {l[i]:.4f} m, "
                                   f"longer than its maximum {self.length_max[i]:.4f} m", field_path)
        sigma = self.singularity_measure(y)
        if sigma < SINGULAR_TOL:
            raise PlannerError("singular", f"pose {pose} is singular: the legs cannot control every "
                               f"direction of motion there (smallest singular value of the leg "
                               f"Jacobian {sigma:.2e} < {SINGULAR_TOL:g})", field_path)

    def singularity_measure(self, y) -> float:
        """Smallest singular value of the dimensionless leg Jacobian ``J_l diag(1, 1, 1/L)``
        (0 at a singular pose, ~1 well inside the workspace)."""
        return float(self.singularity_measure_batch(np.asarray(y, dtype=float)[None])[0])

    # ---- dynamics ----------------------------------------------------------------------
    # Hot path: planar vectors as complex numbers (x + iy), all legs at once, so that one
    # evaluation is a few dozen small numpy operations.
    @cached_property
    def _const(self):
        n = self.n_legs
        return {
            "r0": self._r0[:, 0] + 1j * self._r0[:, 1],
            "base": self.base[:, 0] + 1j * self.base[:, 1],
            "tool": complex(self.tool[0], self.tool[1]),
            "w_r": np.concatenate((self.rod_mass, np.zeros(n))),  # weights of J_l rows in M_r
            "swap": np.concatenate((np.arange(n, 2 * n), np.arange(n))),
        }

    def _terms(self, y, v):
        """Shared pieces of eqs. (4)-(8) at state (y, v), all legs at once.

        Returns ``W = [J_l; J_phi]`` (2n, 3) (the leg rows of ``R``), ``M_r = R^T M R`` (3, 3)
        and per-leg scalars: leg length ``l``, ``r x e``, ``r . e``, ``l_dot``, ``phi_dot``,
        the leg inertia about its base pivot ``J_leg``, and the platform centre ``rc``
        relative to the tool point (complex).
        """
        k = self._const
        n = self.n_legs
        z = complex(math.cos(y[2]), math.sin(y[2]))
        r = k["r0"] * z  # pivots relative to the tool point, world frame
        d = r + complex(y[0], y[1]) - k["base"]
        l = np.abs(d)
        e = d / l
        re = r.conjugate() * e  # real: r . e, imag: r x e
        ev = e.conjugate() * complex(v[0], v[1])  # real: e . v, imag: n . v
        cross, dot = re.imag, re.real
        w = v[2]
        l_dot = ev.real + cross * w
        phi_dot = (ev.imag + dot * w) / l
        el = e / l
        W = np.empty((2 * n, 3))  # [J_l; J_phi]: rows (e, r x e) and (n, r . e) / l
        W[:n, 0] = e.real
        W[:n, 1] = e.imag
        W[:n, 2] = cross
        W[n:, 0] = -el.imag
        W[n:, 1] = el.real
        W[n:, 2] = dot / l
        arm = l - self.rod_com
        J_leg = self._leg_inertia_const + self.rod_mass * arm * arm
        wts = k["w_r"].copy()
        wts[n:] = J_leg
        M_r = (W.T * wts) @ W
        mp = self.platform_mass
        rc = -k["tool"] * z
        M_r[0, 0] += mp
        M_r[1, 1] += mp
        M_r[2, 2] += mp * abs(rc) ** 2 + self.platform_inertia
        if rc != 0:
            M_r[0, 2] -= mp * rc.imag
            M_r[2, 0] -= mp * rc.imag
            M_r[1, 2] += mp * rc.real
            M_r[2, 1] += mp * rc.real
        return W, M_r, l, cross, dot, l_dot, phi_dot, J_leg, rc

    def generalised_forces(self, y, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``R^T (g - M R_dot y_dot)`` of eqs. (5)/(6) and its pieces.

        Returns ``(M_r, h_r, J_l)``: reduced mass matrix (3, 3), reduced velocity-product and
        friction forces (3,) and the leg Jacobian (n, 3), so that ``M_r y_dd = h_r + J_l^T u``.
        In physical coordinates ``h = g - M R_dot y_dot`` has, per leg (``a`` = rod centre
        distance, ``w`` = psi_dot)::

            h_l   = -m_r a phi_dot^2 + m_r (r.e) w^2 - friction l_dot
            h_phi = 2 (J_leg / l - m_r (l - a)) l_dot phi_dot - J_leg (r x e) w^2 / l

        and ``m_p w^2 rc`` on the platform centre.
        """
        W, M_r, l, cross, dot, l_dot, phi_dot, J_leg, rc = self._terms(y, v)
        return M_r, self._h_r(W, l, cross, dot, l_dot, phi_dot, J_leg, rc, v[2]), W[:self.n_legs]

    def _h_r(self, W, l, cross, dot, l_dot, phi_dot, J_leg, rc, w, u=None):
        m_r = self.rod_mass
        h_l = m_r * (dot * w * w - self.rod_com * phi_dot * phi_dot) - self.friction * l_dot
        if u is not None:
            h_l = h_l + u
        h_phi = (2.0 * (J_leg / l - m_r * (l - self.rod_com)) * l_dot * phi_dot - J_leg * cross * (w * w) / l)
        h_r = W.T @ np.concatenate((h_l, h_phi))
        if rc != 0:
            h_r[0] += self.platform_mass * w * w * rc.real
            h_r[1] += self.platform_mass * w * w * rc.imag
        return h_r

    def acceleration(self, y, v, u) -> np.ndarray:
        """Reduced equations of motion (eq. 6):
        ``y_dd = (R^T M R)^-1 R^T (g - M R_dot y_dot) + (R^T M R)^-1 R^T T u`` [m/s^2, rad/s^2]."""
        W, M_r, l, cross, dot, l_dot, phi_dot, J_leg, rc = self._terms(y, v)
        return _solve(M_r, self._h_r(W, l, cross, dot, l_dot, phi_dot, J_leg, rc, v[2], u))

    def state_derivative(self, x, u) -> np.ndarray:
        """State-space model (eq. 7): ``x_dot = f(x) + G(x) u`` with ``x = (y, y_dot)``."""
        out = np.empty(6)
        out[:3] = x[3:]
        out[3:] = self.acceleration(x[:3], x[3:], u)
        return out

    def factorised_blocks(self, x) -> tuple[np.ndarray, np.ndarray]:
        """``A22`` (3, 3) and ``B2`` (3, n) of :meth:`factorised` (eq. 8)."""
        y, v = x[:3], x[3:]
        n = self.n_legs
        W, M_r, l, cross, dot, l_dot, phi_dot, J_leg, rc = self._terms(y, v)
        w = v[2]
        m_r = self.rod_mass
        c1 = J_leg / l - m_r * (l - self.rod_com)  # half the coefficient of l_dot phi_dot in h_phi
        # K(v) with K v = h: half-gradients of the quadratic terms, gradients of the linear ones
        a_sw = np.concatenate((-m_r * self.rod_com * phi_dot, c1 * phi_dot))  # times the other row block
        a_own = np.concatenate((-self.friction, c1 * l_dot))  # times the own row block
        K = a_sw[:, None] * W[self._const["swap"]] + a_own[:, None] * W
        K[:n, 2] += m_r * dot * w
        K[n:, 2] -= J_leg * cross * w / l
        rhs = np.empty((3, 3 + n))
        rhs[:, :3] = W.T @ K
        rhs[:, 3:] = W[:n].T
        if rc != 0:
            rhs[0, 2] += self.platform_mass * w * rc.real
            rhs[1, 2] += self.platform_mass * w * rc.imag
        sol = _solve(M_r, rhs)
        return sol[:, :3], sol[:, 3:]

    def factorised(self, x) -> tuple[np.ndarray, np.ndarray]:
        """State-dependent factorisation (eq. 8): ``x_dot = A(x) x + B(x) u``, exactly.

        ``A = [[0, I], [0, A22]]``. The free acceleration is ``Q(y, v) + L(y) v`` with ``Q``
        quadratic in ``v`` (velocity products) and ``L v`` the viscous friction. Since ``Q``
        is a quadratic form, ``(1/2) dQ/dv v = Q`` (Euler), so
        ``A22 = M_r^-1 R^T ((1/2) dh_quad/dv + dh_lin/dv)`` reproduces ``f(x)`` exactly:
        ``A(x) x == f(x)``. ``B = [[0], [M_r^-1 J_l^T]]`` is the paper's ``G(x)``.
        """
        A22, B2 = self.factorised_blocks(x)
        A = np.zeros((6, 6))
        A[:3, 3:] = np.eye(3)
        A[3:, 3:] = A22
        B = np.zeros((6, self.n_legs))
        B[3:] = B2
        return A, B

    def kinetic_energy(self, x) -> float:
        """Kinetic energy ``1/2 y_dot^T R^T M R y_dot`` [J]."""
        M_r = self._terms(x[:3], x[3:])[1]
        return 0.5 * float(x[3:] @ M_r @ x[3:])


# ---------------------------------------------------------------------------------------
# built-in robots
# ---------------------------------------------------------------------------------------

def builtin_robot_names() -> list[str]:
    return sorted(p.name[:-5] for p in resources.files("planner.data").iterdir() if p.name.endswith(".json"))


def builtin_description(name: str) -> dict:
    """The JSON description of a built-in robot by name."""
    if name not in builtin_robot_names():
        raise invalid("robot", f"unknown robot {name!r}; built-in robots: {', '.join(builtin_robot_names())}")
    return json.loads(resources.files("planner.data").joinpath(f"{name}.json").read_text())


def load_robot(spec, field_path: str = "robot") -> Robot:
    """A robot from a built-in name, a description dict or a path to a JSON file."""
    if isinstance(spec, Robot):
        return spec
    if spec is None:
        spec = "moving-slide"
    if isinstance(spec, Path):
        return Robot.from_description(json.loads(spec.read_text()), field_path)
    if isinstance(spec, str):
        return Robot.from_description(builtin_description(spec), field_path)
    return Robot.from_description(spec, field_path)
