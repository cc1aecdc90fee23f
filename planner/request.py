"""The plan request: one JSON shape for the CLI file, the HTTP body and the editor's save file.

::

    {
      "robot": "moving-slide" | {robot description},
      "segments": [{"lower": [x, y, psi], "upper": [x, y, psi]}, ...],   # m, m, rad
      "settings": {"Ts": 0.01, "N": 20, "samples_per_segment": 20, "k_r": 1.0, "k_u": ...}
    }

Instead of ``segments`` a request may give ``reference`` (a pose per sample, the paper's
tracking criterion (12)) or ``layout`` (free-space segmentation, Section V.B). This module
parses and validates such a dict into plain dataclasses; every error names the field.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from .errors import PlannerError, invalid

#: bounds that keep one request's work finite
MAX_HORIZON = 200
MAX_SAMPLES_PER_SEGMENT = 2000
MAX_SEGMENTS = 2000
MAX_TOTAL_STEPS = 200_000

#: Defaults that depend on ``settings.mode``, applied where the request leaves the field out.
#: The constrained mode keeps the corridor by its constraints, so its range penalty only has
#: to pull the robot along: a lighter pull (k_r) and force penalty (k_u) with a longer
#: horizon use 6-75 % less drive energy on every corridor measured, all contained and
#: settled (benchmarks/README.md, issue 6; on Table I 1.14x the IPOPT optimum instead of 1.5x).
MODE_DEFAULTS = {"paper": {"N": 20, "k_r": 1.0, "k_u": 1e-3},
                 "constrained": {"N": 30, "k_r": 0.1, "k_u": 2e-4}}
#: samples each segment is held when neither samples_per_segment nor N is given [-]
DEFAULT_SAMPLES_PER_SEGMENT = 20


@dataclass
class Settings:
    """Planner settings (all SI)."""

    Ts: float = 0.01  #: sample time [s]
    N: int = 20  #: prediction horizon [samples]; default per mode (MODE_DEFAULTS)
    samples_per_segment: int | None = None  #: samples each segment is held [-]; default N if N is given, else 20
    k_r: float = 1.0  #: range penalty: Q_ra = Q_rb = k_r I [1/m, 1/rad]; default per mode
    k_u: float = 1e-3  #: drive-force penalty: Q_u = k_u I [1/N]; default per mode
    q_ra: list[float] | None = None  #: diagonal of Q_ra (x, y, psi), overrides k_r
    q_rb: list[float] | None = None  #: diagonal of Q_rb (x, y, psi), overrides k_r
    q_u: list[float] | None = None  #: diagonal of Q_u, one per drive, overrides k_u
    taper: bool = True  #: spread the range out of a start point and narrow it onto an end point (Fig. 4)
    solver: str = "riccati"  #: "riccati" (compiled loop, O(N)), "structured" (numpy, banded, O(N)) or "qr" (numpy, the paper's Householder QR)
    mode: str = "paper"  #: "paper" (the seed's soft criterion) or "constrained" (hard corridor and drive limits)
    settle_position_m: float = 1e-4  #: end-point position tolerance that counts as settled [m]
    settle_speed_m_s: float = 1e-3  #: speed below which the robot counts as stopped [m/s]
    settle_angle_rad: float = 1e-4  #: end-point angle tolerance [rad]
    settle_rate_rad_s: float = 1e-3  #: angular speed tolerance [rad/s]
    tail_max_s: float = 3.0  #: longest time the end point is held waiting for the robot to settle [s]
    plant_substeps: int = 1  #: RK4 steps of the nonlinear model per sample [-]
    require_settled: bool = True  #: raise ``not_settled`` instead of returning an unsettled plan
    speed_m_s: float | None = None  #: target mean tool speed along the corridor [m/s] (sets samples_per_segment)
    total_time_s: float | None = None  #: time the corridor's range sequence takes [s] (sets samples_per_segment)
    fastest: bool = False  #: constrained mode: shortest timing the drive limits allow (sets samples_per_segment)

    @property
    def S(self) -> int:
        return self.samples_per_segment or self.N


@dataclass
class Segment:
    lower: np.ndarray  # (3,) [m, m, rad]
    upper: np.ndarray  # (3,)
    q_ra: np.ndarray | None = None  # (3,) per-segment override
    q_rb: np.ndarray | None = None
    polygon: np.ndarray | None = None  # (k, 2) exact convex cell inside the box [m] (e.g. a triangle), CCW

    @property
    def centre(self) -> np.ndarray:
        return 0.5 * (self.lower + self.upper)

    @property
    def is_point(self) -> bool:
        return bool(np.all(self.upper - self.lower <= 1e-12))


@dataclass
class PlanRequest:
    robot: object  # name or description dict
    segments: list[Segment] | None
    reference: np.ndarray | None  # (K, 3) poses per sample (tracking criterion)
    settings: Settings
    layout: dict | None = None
    name: str | None = None
    raw: dict = field(default_factory=dict)


def _finite(value, path: str, *, lo=None, hi=None, lo_open=False, integer=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise invalid(path, f"must be a number, got {value!r}")
    if integer and (not float(value).is_integer()):
        raise invalid(path, f"must be a whole number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise invalid(path, "must be a finite number")
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise invalid(path, f"must be {'>' if lo_open else '>='} {lo:g}, got {v:g}")
    if hi is not None and v > hi:
        raise invalid(path, f"must be <= {hi:g}, got {v:g}")
    return int(v) if integer else v


def _vec(value, path: str, size: int, *, positive=False) -> np.ndarray:
    if not isinstance(value, (list, tuple)) or len(value) != size:
        raise invalid(path, f"must be a list of {size} numbers")
    return np.array([_finite(v, f"{path}[{i}]", lo=0.0 if positive else None) for i, v in enumerate(value)])


def parse_settings(raw, path: str = "settings") -> Settings:
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise invalid(path, "must be an object")
    known = Settings.__dataclass_fields__
    for key in raw:
        if key not in known:
            raise invalid(f"{path}.{key}", f"unknown setting; known settings: {', '.join(known)}")
    s = Settings()
    if "Ts" in raw:
        s.Ts = _finite(raw["Ts"], f"{path}.Ts", lo=0.0, hi=1.0, lo_open=True)
    if raw.get("N") is not None:
        s.N = _finite(raw["N"], f"{path}.N", lo=1, hi=MAX_HORIZON, integer=True)
    if raw.get("samples_per_segment") is not None:
        s.samples_per_segment = _finite(raw["samples_per_segment"], f"{path}.samples_per_segment",
                                        lo=1, hi=MAX_SAMPLES_PER_SEGMENT, integer=True)
    for key in ("k_r", "k_u"):
        if raw.get(key) is not None:
            setattr(s, key, _finite(raw[key], f"{path}.{key}", lo=0.0, hi=1e12, lo_open=True))
    for key in ("q_ra", "q_rb"):
        if raw.get(key) is not None:
            setattr(s, key, _vec(raw[key], f"{path}.{key}", 3, positive=True).tolist())
    if raw.get("q_u") is not None:
        q_u = raw["q_u"]
        if not isinstance(q_u, (list, tuple)) or not q_u:
            raise invalid(f"{path}.q_u", "must be a list with one positive number per drive")
        s.q_u = [_finite(v, f"{path}.q_u[{i}]", lo=0.0, lo_open=True) for i, v in enumerate(q_u)]
    for key in ("taper", "require_settled"):
        if key in raw:
            if not isinstance(raw[key], bool):
                raise invalid(f"{path}.{key}", "must be true or false")
            setattr(s, key, raw[key])
    if "mode" in raw:
        if raw["mode"] not in ("paper", "constrained"):
            raise invalid(f"{path}.mode", "must be 'paper' or 'constrained'")
        s.mode = raw["mode"]
    if "solver" in raw:
        if raw["solver"] not in ("riccati", "structured", "qr"):
            raise invalid(f"{path}.solver", "must be 'riccati', 'structured' or 'qr'")
        s.solver = raw["solver"]
    for key in ("settle_position_m", "settle_speed_m_s", "settle_angle_rad", "settle_rate_rad_s"):
        if key in raw:
            setattr(s, key, _finite(raw[key], f"{path}.{key}", lo=0.0, hi=1.0, lo_open=True))
    if "tail_max_s" in raw:
        s.tail_max_s = _finite(raw["tail_max_s"], f"{path}.tail_max_s", lo=0.0, hi=600.0)
    timing = [k for k in ("samples_per_segment", "speed_m_s", "total_time_s") if raw.get(k) is not None]
    if raw.get("fastest"):
        timing.append("fastest")
    if len(timing) > 1:
        raise invalid(f"{path}.{timing[1]}", f"give only one of samples_per_segment, speed_m_s, total_time_s, "
                      f"fastest; got {', '.join(timing)}")
    if raw.get("speed_m_s") is not None:
        s.speed_m_s = _finite(raw["speed_m_s"], f"{path}.speed_m_s", lo=0.0, hi=100.0, lo_open=True)
    if raw.get("total_time_s") is not None:
        s.total_time_s = _finite(raw["total_time_s"], f"{path}.total_time_s", lo=0.0, hi=3600.0, lo_open=True)
    if "fastest" in raw:
        if not isinstance(raw["fastest"], bool):
            raise invalid(f"{path}.fastest", "must be true or false")
        s.fastest = raw["fastest"]
        if s.fastest and s.mode != "constrained":
            raise invalid(f"{path}.fastest", "needs mode 'constrained' (only that mode keeps the drive limits)")
    if "plant_substeps" in raw:
        s.plant_substeps = _finite(raw["plant_substeps"], f"{path}.plant_substeps", lo=1, hi=50, integer=True)
    for key, value in MODE_DEFAULTS[s.mode].items():
        if raw.get(key) is None:
            setattr(s, key, value)
    if raw.get("samples_per_segment") is None and raw.get("N") is None:
        s.samples_per_segment = DEFAULT_SAMPLES_PER_SEGMENT
    return s


def _polygon(raw, path: str, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """A segment's exact convex cell: >= 3 finite [x, y] points [m] inside its (x, y) box."""
    if not isinstance(raw, list) or len(raw) < 3:
        raise invalid(path, "must be a list of at least 3 points [x, y] in m")
    pts = np.array([_vec(q, f"{path}[{i}]", 2) for i, q in enumerate(raw)])
    if np.any(pts < lo[:2] - 1e-9) or np.any(pts > hi[:2] + 1e-9):
        raise invalid(path, "must lie inside the segment's box [lower, upper] (x, y)")
    return pts


def parse_segments(raw, path: str = "segments") -> list[Segment]:
    if not isinstance(raw, list):
        raise invalid(path, "must be a list of segments {lower: [x, y, psi], upper: [x, y, psi]}")
    if len(raw) < 2:
        raise invalid(path, f"needs at least 2 segments (a start and an end), got {len(raw)}")
    if len(raw) > MAX_SEGMENTS:
        raise invalid(path, f"at most {MAX_SEGMENTS} segments, got {len(raw)}")
    out = []
    for i, seg in enumerate(raw):
        p = f"{path}[{i}]"
        if not isinstance(seg, dict):
            raise invalid(p, "must be an object {lower: [x, y, psi], upper: [x, y, psi]}")
        for key in seg:
            if key not in ("lower", "upper", "q_ra", "q_rb", "polygon"):
                raise invalid(f"{p}.{key}", "unknown field; a segment has lower, upper and optional q_ra, q_rb")
        lo = _vec(seg.get("lower"), f"{p}.lower", 3)
        hi = _vec(seg.get("upper"), f"{p}.upper", 3)
        bad = np.nonzero(lo > hi)[0]
        if bad.size:
            axis = "x y psi".split()[bad[0]]
            raise invalid(f"{p}.lower", f"must be <= upper ({axis}: {lo[bad[0]]:g} > {hi[bad[0]]:g})")
        q_ra = _vec(seg["q_ra"], f"{p}.q_ra", 3, positive=True) if seg.get("q_ra") is not None else None
        q_rb = _vec(seg["q_rb"], f"{p}.q_rb", 3, positive=True) if seg.get("q_rb") is not None else None
        polygon = _polygon(seg["polygon"], f"{p}.polygon", lo, hi) if seg.get("polygon") is not None else None
        out.append(Segment(lo, hi, q_ra, q_rb, polygon))
    return out


def parse_reference(raw, path: str = "reference") -> np.ndarray:
    poses = raw.get("pose") if isinstance(raw, dict) else raw
    if not isinstance(poses, list) or len(poses) < 2:
        raise invalid(path, "must be {\"pose\": [[x, y, psi], ...]} with at least 2 poses, one per sample")
    if len(poses) > MAX_TOTAL_STEPS:
        raise invalid(path, f"at most {MAX_TOTAL_STEPS} poses")
    return np.array([_vec(p, f"{path}.pose[{i}]", 3) for i, p in enumerate(poses)])


def parse_request(raw) -> PlanRequest:
    """Validate a plan request dict (the one JSON shape) into a :class:`PlanRequest`."""
    if not isinstance(raw, dict):
        raise invalid("body", "a plan request must be a JSON object")
    for key in raw:
        if key not in ("robot", "segments", "reference", "layout", "settings", "name", "start", "end", "psi_range"):
            raise invalid(key, "unknown field; a plan request has robot, segments | reference | layout, settings, name")
    given = [k for k in ("segments", "reference", "layout") if raw.get(k) is not None]
    if len(given) != 1:
        raise invalid("segments", "give exactly one of 'segments' (a corridor), 'reference' (a trajectory "
                      f"to track) or 'layout' (obstacles to segment); got {given or 'none'}")
    robot = raw.get("robot", "moving-slide")
    if not isinstance(robot, (str, dict)):
        raise invalid("robot", "must be a built-in robot name or a robot description object")
    name = raw.get("name")
    if name is not None and not isinstance(name, str):
        raise invalid("name", "must be a string")
    settings = parse_settings(raw.get("settings"))
    layout = raw.get("layout")
    if isinstance(layout, dict):  # top-level start/end/psi_range are shorthands for layout.*
        extra = {k: raw[k] for k in ("start", "end", "psi_range") if raw.get(k) is not None and layout.get(k) is None}
        if extra:
            layout = {**layout, **extra}
    segments = parse_segments(raw["segments"]) if "segments" in given else None
    reference = parse_reference(raw["reference"]) if "reference" in given else None
    if segments is not None:
        steps = len(segments) * settings.S
        if steps > MAX_TOTAL_STEPS:
            raise PlannerError("too_large", f"{len(segments)} segments x {settings.S} samples = {steps} steps "
                               f"exceeds the limit of {MAX_TOTAL_STEPS}", "settings.samples_per_segment")
    return PlanRequest(robot=robot, segments=segments, reference=reference, settings=settings,
                       layout=layout, name=name, raw=raw)


def settings_dict(s: Settings) -> dict:
    d = asdict(s)
    d["samples_per_segment"] = s.S
    return d
