"""The plan request: one JSON shape for the CLI file, the HTTP body, the editor's save file
and storage. These models are its only definition and its only validator.

::

    {
      "name": "seed Table I",
      "robot": "moving-slide" | {robot description},
      "segments": [{"lower": [x, y, psi], "upper": [x, y, psi]}, ...],   # m, m, rad
      "settings": {"Ts": 0.01, "N": 20, "samples_per_segment": 20, "k_r": 1.0, "k_u": 0.001, ...}
    }

Instead of ``segments`` a request may give ``reference`` (a pose per sample: the paper's
tracking criterion (12)) or ``layout`` (obstacles to segment: Section V.B). A request that
validates can be planned as far as its numbers go; what needs the robot's reach or the
dynamics (unreachable poses, no path, infeasible limits) is found by the planner.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    ConfigDict,
    Discriminator,
    Field,
    StrictBool,
    Tag,
    ValidationError,
    field_validator,
    model_validator,
)

from ..errors import PlannerError
from ._types import Coordinate, Count, Finite, Penalty3, PointPair, Pose3, PoseTriple, Strict, array_of, fail
from .errors import planner_error
from .layout import Layout
from .limits import (
    DEFAULT_FORCE_RISE_S,
    DEFAULT_HORIZON_BRAKES,
    DEFAULT_HORIZON_MAX,
    DEFAULT_HORIZON_RAMPS,
    DEFAULT_LAYOUT_SPEED_M_S,
    DEFAULT_MODE,
    DEFAULT_ROBOT,
    DEFAULT_SAMPLES_PER_SEGMENT,
    DEFAULT_SEGMENT_S,
    MAX_HORIZON,
    MAX_PENALTY,
    MAX_PENALTY_RATIO,
    MAX_SAMPLES_PER_SEGMENT,
    MAX_SEGMENTS,
    MAX_TOTAL_STEPS,
    MIN_SPEED,
    MIN_TS,
    MODE_DEFAULTS,
)
from .robot import RobotDescription, builtin_description, builtin_robot_names

__all__ = ["PlanRequest", "Reference", "Segment", "Settings", "parse_request", "TIMING_FIELDS", "EXAMPLE_REQUEST",
           "default_horizon", "default_samples_per_segment"]

#: the settings that choose the timing of a corridor; at most one per request
TIMING_FIELDS = ("samples_per_segment", "segment_samples", "speed_m_s", "total_time_s", "fastest")
_MODE_FIELDS = ("N", "k_r", "k_u", "samples_per_segment")
#: the default of a setting the mode decides: replaced by a number in :meth:`Settings._resolve`
#: (typed ``Any`` so that the field keeps its number type for the code that reads it)
MODE_DECIDES: Any = None


def default_horizon(Ts: float, robot: RobotDescription, force_rate: Any) -> int:
    """The constrained mode's default horizon ``N`` [samples]: ``N Ts`` covers
    :data:`~planner.schema.limits.DEFAULT_HORIZON_RAMPS` force ramps (``force_max / force_rate``
    of the slowest drive; none with ``force_rate`` "off") and
    :data:`~planner.schema.limits.DEFAULT_HORIZON_BRAKES` braking times (a drive's ``speed_max``
    at the acceleration of the robot's whole mass under the sum of the drives' ``force_max``),
    at least the mode's 30 samples and at most
    :data:`~planner.schema.limits.DEFAULT_HORIZON_MAX`. The Moving Slide: 0.25 s, so 30 samples at
    Ts 10 ms (as before), 51 at 5 ms, 100 at 2 and 1 ms."""
    legs = robot.leg_list()
    fmax = np.array([g.force_max for g in legs], float)
    if isinstance(force_rate, str):
        ramp = 0.0
    elif force_rate is None:
        ramp = DEFAULT_FORCE_RISE_S
    else:  # one rate or one per drive; another count (named by the request's own check, or
        # Settings sized for the default robot while the request's has other legs): the
        # slowest ramp any drive could have
        rates = np.asarray(force_rate, float).ravel()
        ramp = float(np.max(fmax / rates) if rates.size in (1, fmax.size) else fmax.max() / rates.min())
    mass = robot.platform.mass + sum(g.cylinder.mass + g.rod.mass for g in legs)
    brake = max(g.speed_max for g in legs) * mass / float(fmax.sum())
    horizon_s = DEFAULT_HORIZON_RAMPS * ramp + DEFAULT_HORIZON_BRAKES * brake
    low = int(MODE_DEFAULTS["constrained"]["N"])
    return int(min(max(low, math.ceil(horizon_s / Ts - 1e-9)), DEFAULT_HORIZON_MAX, MAX_HORIZON))


def default_samples_per_segment(Ts: float, mode: str) -> int:
    """Samples a segment is held when neither ``samples_per_segment`` nor ``N`` is given:
    :data:`~planner.schema.limits.DEFAULT_SAMPLES_PER_SEGMENT` in paper mode; in constrained
    mode :data:`~planner.schema.limits.DEFAULT_SEGMENT_S` of time, at least that many."""
    if mode != "constrained":
        return DEFAULT_SAMPLES_PER_SEGMENT
    return int(min(max(DEFAULT_SAMPLES_PER_SEGMENT, round(DEFAULT_SEGMENT_S / Ts)), MAX_SAMPLES_PER_SEGMENT))


#: a convex cell's vertices [[x, y], ...] in m
CellVertices = Annotated[np.ndarray, array_of(list[PointPair], min_length=3)]
#: one pose per sample [[x, y, psi], ...]
Poses = Annotated[np.ndarray, array_of(list[PoseTriple], min_length=2, max_length=MAX_TOTAL_STEPS)]
#: one positive number per drive, at most MAX_PENALTY
PerDrive = Annotated[np.ndarray, array_of(list[Annotated[float, Field(allow_inf_nan=False, strict=True,
                                                                         le=MAX_PENALTY)]],
                                          min_length=1)]


class Segment(Strict):
    """One range of the corridor (paper Section V.B): ``r_a = lower``, ``r_b = upper``."""

    lower: Pose3 = Field(description="Lower range limit r_a = [x_a, y_a, psi_a] (m, m, rad)")
    upper: Pose3 = Field(description="Upper range limit r_b = [x_b, y_b, psi_b] (m, m, rad)")
    q_ra: Penalty3 | None = Field(None, description="Diagonal of Q_ra for this segment's samples (1/m, 1/m, 1/rad), "
                              ">= 0")
    q_rb: Penalty3 | None = Field(None, description="Diagonal of Q_rb for this segment's samples (1/m, 1/m, 1/rad), "
                              ">= 0")
    polygon: CellVertices | None = Field(None, description="Exact convex cell (e.g. a triangle) inside "
                                    "the box, vertices [[x, y], ...] in m; used by the constrained mode")

    @model_validator(mode="after")
    def _box(self) -> Segment:
        bad = np.nonzero(self.lower > self.upper)[0]
        if bad.size:
            i = int(bad[0])
            raise fail(f"must be <= upper ({'x y psi'.split()[i]}: {self.lower[i]:g} > {self.upper[i]:g})", "lower")
        if self.polygon is not None and (np.any(self.polygon < self.lower[:2] - 1e-9)
                                         or np.any(self.polygon > self.upper[:2] + 1e-9)):
            raise fail("must lie inside the segment's box [lower, upper] (x, y)", "polygon")
        return self

    @property
    def centre(self) -> np.ndarray:
        """The middle of the range [m, m, rad]."""
        return 0.5 * (self.lower + self.upper)

    @property
    def is_point(self) -> bool:
        """A range of zero size (a start or end point). (On the three numbers as Python
        floats: numpy's per-call cost made this a tenth of a small plan's fixed cost.)"""
        lo, hi = self.lower, self.upper
        return bool(hi[0] - lo[0] <= 1e-12 and hi[1] - lo[1] <= 1e-12 and hi[2] - lo[2] <= 1e-12)

    @property
    def is_xy_point(self) -> bool:
        """A range of zero size in x and y (a point, possibly with a psi range: an end point
        at which the robot may settle at any angle of that range)."""
        lo, hi = self.lower, self.upper
        return bool(hi[0] - lo[0] <= 1e-12 and hi[1] - lo[1] <= 1e-12)


class Reference(Strict):
    """A trajectory to track (the paper's criterion (12)): one pose per sample."""

    pose: Poses = Field(
        description="Desired pose per sample, [x, y, psi] in m, m, rad; the first is the start")


class Settings(Strict):
    """Planner settings (SI units). ``N``, ``k_r``, ``k_u`` and ``samples_per_segment`` left out
    (or null) take the mode's defaults; after validation they always hold numbers."""

    Ts: Finite = Field(0.01, ge=MIN_TS, le=1.0, description="Sample time in s")
    N: Count = Field(MODE_DECIDES, ge=1, le=MAX_HORIZON, description="Prediction horizon in samples; default "
                   f"{MODE_DEFAULTS['paper']['N']:g} in paper mode; in constrained mode one that covers "
                   f"{DEFAULT_HORIZON_RAMPS:g} force ramps and {DEFAULT_HORIZON_BRAKES:g} braking times of the robot, "
                   f"at least {MODE_DEFAULTS['constrained']['N']:g} and at most {DEFAULT_HORIZON_MAX} samples "
                   "(30 for the moving-slide at Ts 0.01 s, 100 at Ts 0.002 s)")
    samples_per_segment: Count = Field(MODE_DECIDES, ge=1, le=MAX_SAMPLES_PER_SEGMENT,
                                     description="Samples each segment is held (count); default N if N is given, "
                                     f"else {DEFAULT_SAMPLES_PER_SEGMENT} (constrained mode: {DEFAULT_SEGMENT_S:g} s "
                                     f"of samples, at least {DEFAULT_SAMPLES_PER_SEGMENT})")
    segment_samples: Annotated[list[Annotated[int, Field(ge=1, le=MAX_SAMPLES_PER_SEGMENT)]],
                               Field(min_length=2, max_length=MAX_SEGMENTS)] | None = Field(
        None, description="Samples each segment is held, one count per segment (a corridor's own timing, e.g. the "
        "one fastest found); instead of samples_per_segment, which it overrides")
    k_r: Finite = Field(MODE_DECIDES, gt=0, le=MAX_PENALTY,
                        description="Range penalty: Q_ra = Q_rb = k_r I (1/m, 1/rad); "
                        f"default {MODE_DEFAULTS['paper']['k_r']:g} in paper mode, "
                        f"{MODE_DEFAULTS['constrained']['k_r']:g} in constrained mode")
    k_u: Finite = Field(MODE_DECIDES, gt=0, le=MAX_PENALTY,
                        description="Drive-force penalty: Q_u = k_u I (1/N); default "
                        f"{MODE_DEFAULTS['paper']['k_u']:g} in paper mode, "
                        f"{MODE_DEFAULTS['constrained']['k_u']:g} in constrained mode")
    q_ra: Penalty3 | None = Field(None, description="Diagonal of Q_ra (1/m, 1/m, 1/rad), >= 0; overrides k_r")
    q_rb: Penalty3 | None = Field(None, description="Diagonal of Q_rb (1/m, 1/m, 1/rad), >= 0; overrides k_r")
    q_u: PerDrive | None = Field(None, description="Diagonal of Q_u, one positive number per "
                                   "drive (1/N); overrides k_u")
    taper: StrictBool = Field(True, description="Spread the range out of the start point and narrow it onto the end "
                              "point")
    mode: Literal["paper", "constrained"] = Field(
        DEFAULT_MODE, description="'constrained' (default): the range criterion with hard corridor, drive limits and "
        "no overshoot; 'paper': the seed's method, the paper's soft range criterion (nothing keeps the robot inside)")
    solver: Literal["riccati", "structured", "qr"] = Field(
        "riccati", description="How the paper mode's horizon problem is solved (same minimiser): 'riccati' "
        "(backward Riccati recursion, O(N)), 'structured' (banded KKT, O(N)) or 'qr' (the paper's Householder "
        "QR, eqs. 17-23)")
    backend: Literal["compiled", "reference"] = Field(
        MODE_DECIDES, description="'compiled' (default with the riccati solver): model, hold, horizon solve, plant "
        "and the "
        "constrained mode's QP assembly run as compiled kernels; 'reference' (default with the structured or qr "
        "solver): the numpy implementation of every stage, same results")
    settle_position_m: Finite = Field(1e-4, gt=0, le=1, description="End-point position tolerance in m")
    settle_speed_m_s: Finite = Field(1e-3, gt=0, le=1, description="Speed that counts as stopped in m/s")
    settle_angle_rad: Finite = Field(1e-4, gt=0, le=1, description="End-point angle tolerance in rad")
    settle_rate_rad_s: Finite = Field(1e-3, gt=0, le=1, description="Angular speed that counts as stopped in rad/s")
    tail_max_s: Finite = Field(3.0, ge=0, le=600, description="Longest time in s the end point is held for settling")
    plant_substeps: Count = Field(1, ge=1, le=50, description="RK4 steps of the nonlinear model per sample (count)")
    require_settled: StrictBool = Field(True, description="Fail with code not_settled instead of returning an "
                                        "unsettled plan, and (constrained mode) with code infeasible at the first step "
                                        "that cannot keep the corridor; false: such steps are taken with slack (at "
                                        "most what the work estimate counts) and reported")
    speed_m_s: Finite | None = Field(None, ge=MIN_SPEED, le=100,
                                     description="Target mean tool speed along the corridor "
                                     "in m/s; sets samples_per_segment (exclusive with it, total_time_s, fastest); a "
                                     f"layout without a timing setting is timed at {DEFAULT_LAYOUT_SPEED_M_S:g} m/s")
    total_time_s: Finite | None = Field(None, gt=0, le=3600, description="Time in s the corridor's range sequence "
                                        "takes; sets samples_per_segment")
    force_rate_n_s: Finite | PerDrive | Literal["off"] | None = Field(
        None, description="Constrained mode: largest rate of change of each drive force, N/s: one number for every "
        "drive or one per drive; null (default): each drive's force_max per "
        f"{DEFAULT_FORCE_RISE_S:g} s; 'off': no limit")
    tool_speed_max_m_s: Finite | None = Field(
        None, ge=MIN_SPEED, le=100, description="Constrained mode: largest speed of the tool point, |(x_dot, y_dot)| "
        "in m/s (at least the smallest speed_m_s), held at every sample (by a 16-sided polygon inside the circle of "
        "that radius: the plan's speed stays within 2 % below the limit in the worst direction); null (default): no "
        "limit")
    fastest: StrictBool = Field(False, description="Constrained mode: the shortest timing (samples_per_segment) whose "
                          "plan keeps the corridor and the drive force, stroke and speed limits")

    @model_validator(mode="before")
    @classmethod
    def _nulls_are_defaults(cls, data: Any) -> Any:
        if isinstance(data, dict) and any(data.get(k, 0) is None for k in (*_MODE_FIELDS, "backend")):
            data = {k: v for k, v in data.items() if not (v is None and k in (*_MODE_FIELDS, "backend"))}
        return data

    @field_validator("q_u")
    @classmethod
    def _positive(cls, v: np.ndarray | None) -> np.ndarray | None:
        if v is not None and np.any(v <= 0):
            raise fail("must be a list with one positive number per drive")
        return v

    @field_validator("force_rate_n_s", mode="before")
    @classmethod
    def _rate_shape(cls, v: Any) -> Any:
        ok = (v is None or v == "off" or (isinstance(v, int | float) and not isinstance(v, bool))
              or (isinstance(v, list) and v and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)))
        if not ok:
            raise fail("must be a number of N/s, a list with one per drive, 'off' or null")
        return v

    @field_validator("force_rate_n_s")
    @classmethod
    def _rate(cls, v: Any) -> Any:
        if v is not None and not isinstance(v, str) and np.any(np.asarray(v) <= 0):
            raise fail("must be > 0 (one number, or one per drive), 'off' or null")
        return v

    @model_validator(mode="after")
    def _resolve(self) -> Settings:
        given = [k for k in TIMING_FIELDS if k in self.model_fields_set and getattr(self, k) not in (None, False)]
        if len(given) > 1:
            raise fail(f"give only one of samples_per_segment, segment_samples, speed_m_s, total_time_s, fastest; got "
                       f"{', '.join(given)}",
                       given[1])
        if self.fastest and self.mode != "constrained":
            raise fail("needs mode 'constrained' (only that mode keeps the drive limits)", "fastest")
        if self.tool_speed_max_m_s is not None and self.mode != "constrained":
            raise fail("needs mode 'constrained' (only that mode keeps a speed limit)", "tool_speed_max_m_s")
        if self.backend == "compiled" and self.solver != "riccati":
            raise fail(f"the compiled backend solves the horizon problem by the Riccati recursion; use backend "
                       f"'reference' for the {self.solver} solver", "solver")
        # fill in what the mode decides, bypassing pydantic's __setattr__ so that they stay out
        # of model_fields_set: a dump with exclude_unset gives back what the client sent
        filled: dict[str, Any] = {k: v for k, v in MODE_DEFAULTS[self.mode].items() if getattr(self, k) is None}
        if self.N is None and self.mode == "constrained":  # the default robot's; a request's own: PlanRequest
            filled["N"] = default_horizon(self.Ts, builtin_description(DEFAULT_ROBOT), self.force_rate_n_s)
        if self.samples_per_segment is None:
            filled["samples_per_segment"] = (self.N if self.N is not None
                                             else default_samples_per_segment(self.Ts, self.mode))
        if self.backend is None:
            filled["backend"] = "compiled" if self.solver == "riccati" else "reference"
        for key, value in filled.items():
            object.__setattr__(self, key, value)
        if self.mode == "paper":
            self._check_conditioning()
        return self

    def _check_conditioning(self) -> None:
        """Paper mode: the largest range penalty over the smallest force penalty must be at
        most MAX_PENALTY_RATIO (beyond, the horizon problem is too ill-conditioned to solve)."""
        given = [(float(np.max(q)), name) for name, q in (("q_ra", self.q_ra), ("q_rb", self.q_rb)) if q is not None]
        top, name = max(given) if given else (self.k_r, "k_r")
        message = self.conditioning_error(top)
        if message:
            raise fail(message, name)

    def conditioning_error(self, range_penalty: float) -> str | None:
        """Why ``range_penalty`` over these settings' smallest force penalty is too large a
        ratio (paper mode), or None."""
        low, low_name = (float(np.min(self.q_u)), "q_u") if self.q_u is not None else (self.k_u, "k_u")
        if self.mode != "paper" or range_penalty <= MAX_PENALTY_RATIO * low:
            return None
        return (f"the range penalty {range_penalty:g} over the force penalty {low_name} = {low:g} is "
                f"{range_penalty / low:.3g}, more than {MAX_PENALTY_RATIO:g}: the paper mode's horizon problem is "
                f"then too ill-conditioned to solve; lower the range penalty or raise settings.{low_name}")

    @property
    def tail_steps(self) -> int:
        """Most samples the end point is held for settling."""
        return int(math.ceil(self.tail_max_s / self.Ts))


def _robot_kind(value: Any) -> str:
    return "~name" if isinstance(value, str) else "~description"


RobotSpec = Annotated[
    Annotated[str, Tag("~name")] | Annotated[RobotDescription, Tag("~description")],
    Discriminator(_robot_kind),
]


#: a small corridor that plans (the OpenAPI document's example request: Swagger UI's "Try it
#: out" and the API fuzz tests start from it): the start point, two 0.02 m boxes, the end point
EXAMPLE_REQUEST: dict[str, Any] = {
    "name": "example: two cells of Table I",
    "robot": DEFAULT_ROBOT,
    "segments": [{"lower": [-0.08, 0.0, 0.0], "upper": [-0.08, 0.0, 0.0]},
                 {"lower": [-0.08, 0.0, 0.0], "upper": [-0.06, 0.02, 0.0]},
                 {"lower": [-0.06, 0.02, 0.0], "upper": [-0.04, 0.04, 0.0]},
                 {"lower": [-0.04, 0.04, 0.0], "upper": [-0.04, 0.04, 0.0]}],
    "settings": {"Ts": 0.01, "N": 20},
}


class PlanRequest(Strict):
    """A plan request: a robot, and a corridor (``segments``), a trajectory to track
    (``reference``) or a workspace to segment (``layout``), with settings."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [EXAMPLE_REQUEST]})

    name: str | None = Field(None, max_length=200, description="Free-text name of the corridor")
    robot: RobotSpec = Field(DEFAULT_ROBOT, description="Built-in robot name (GET /v1/robots) or a robot "
                             "description")
    segments: list[Segment] | None = Field(None, min_length=2, max_length=MAX_SEGMENTS,
                                           description="The corridor: ranges in order, first the start point, "
                                           "last the end point")
    reference: Reference | None = Field(None, description="Instead of segments: a trajectory to track "
                                        "(the paper's criterion (12))")
    layout: Layout | None = Field(None, description="Instead of segments: a workspace with obstacles to "
                                  "segment into a corridor (Section V.B)")
    settings: Settings = Field(default_factory=lambda: Settings.model_validate({}), description="Planner settings")
    start: Pose3 | None = Field(None, description="Shorthand for layout.start: start pose [x, y, psi] in m, m, rad")
    end: Pose3 | None = Field(None, description="Shorthand for layout.end: end pose [x, y, psi] in m, m, rad")
    psi_range: Annotated[list[Coordinate], Field(min_length=2, max_length=2)] | None = Field(
        None, description="Shorthand for layout.psi_range: allowed platform angle [min, max] in rad")

    @model_validator(mode="before")
    @classmethod
    def _shorthands(cls, data: Any) -> Any:
        """Top-level ``start``, ``end`` and ``psi_range`` fill the layout's (which win)."""
        if isinstance(data, dict) and isinstance(data.get("layout"), dict):
            extra = {k: data[k] for k in ("start", "end", "psi_range")
                     if data.get(k) is not None and data["layout"].get(k) is None}
            if extra:
                data = {**data, "layout": {**data["layout"], **extra}}
        return data

    @field_validator("robot")
    @classmethod
    def _known_robot(cls, v: str | RobotDescription) -> str | RobotDescription:
        if isinstance(v, str) and v not in builtin_robot_names():
            raise fail(f"unknown robot {v!r}; built-in robots: {', '.join(builtin_robot_names())}")
        return v

    @model_validator(mode="after")
    def _one_corridor(self) -> PlanRequest:
        given = [k for k in ("segments", "reference", "layout") if getattr(self, k) is not None]
        if len(given) != 1:
            raise fail(f"give exactly one of 'segments' (a corridor), 'reference' (a trajectory to track) or "
                       f"'layout' (obstacles to segment); got {', '.join(given) or 'none'}", "segments")
        st = self.settings
        if st.mode == "constrained" and "N" not in st.model_fields_set and self.robot != DEFAULT_ROBOT:
            # the default horizon of the request's robot (Settings alone knows only the default robot's)
            N = default_horizon(st.Ts, self.robot_description, st.force_rate_n_s)
            object.__setattr__(st, "N", N)
        n_legs = self.robot_description.n_legs
        if st.q_u is not None and len(st.q_u) != n_legs:
            raise fail(f"must have one entry per drive ({n_legs}), got {len(st.q_u)}", "settings.q_u")
        rate = st.force_rate_n_s
        if isinstance(rate, np.ndarray) and len(rate) != n_legs:
            raise fail(f"must be one number or one per drive ({n_legs}), got {len(rate)}", "settings.force_rate_n_s")
        if self.segments is not None:
            for i, seg in enumerate(self.segments):
                for name in ("q_ra", "q_rb"):
                    q = getattr(seg, name)
                    message = None if q is None else st.conditioning_error(float(np.max(q)))
                    if message:
                        raise fail(message, f"segments[{i}].{name}")
            if st.segment_samples is not None:
                if len(st.segment_samples) != len(self.segments):
                    raise fail(f"must have one count per segment ({len(self.segments)}), got "
                               f"{len(st.segment_samples)}", "settings.segment_samples")
                steps = sum(st.segment_samples)
                if steps > MAX_TOTAL_STEPS:
                    raise fail(f"{steps} samples in all exceeds the limit of {MAX_TOTAL_STEPS}",
                               "settings.segment_samples", code="too_large")
            steps = len(self.segments) * st.samples_per_segment
            if st.segment_samples is None and steps > MAX_TOTAL_STEPS:
                raise fail(f"{len(self.segments)} segments x {st.samples_per_segment} samples = {steps} steps exceeds "
                           f"the limit of {MAX_TOTAL_STEPS}", "settings.samples_per_segment", code="too_large")
        if self.layout is not None and not any(k in st.model_fields_set and getattr(st, k) not in (None, False)
                                               for k in TIMING_FIELDS):
            # a layout without a timing: a tool speed (limits.DEFAULT_LAYOUT_SPEED_M_S), kept out
            # of model_fields_set like the mode's defaults
            object.__setattr__(st, "speed_m_s", DEFAULT_LAYOUT_SPEED_M_S)
        if st.tail_steps > MAX_TOTAL_STEPS:
            raise fail(f"a settling tail of {st.tail_max_s:g} s at Ts = {st.Ts:g} s is {st.tail_steps} samples, more "
                       f"than the limit of {MAX_TOTAL_STEPS}; raise settings.Ts or lower settings.tail_max_s",
                       "settings.Ts", code="too_large")
        return self

    @property
    def robot_description(self) -> RobotDescription:
        """The robot's description (a built-in one looked up by name)."""
        return builtin_description(self.robot) if isinstance(self.robot, str) else self.robot

    def to_json_dict(self) -> dict[str, Any]:
        """The request as the client would send it again: what it gave, in JSON types."""
        return self.model_dump(mode="json", exclude_unset=True)


def parse_request(raw: Any) -> PlanRequest:
    """Validate a request (a dict in the one JSON shape, or a :class:`PlanRequest`);
    raises :class:`~planner.errors.PlannerError` naming the first failing field."""
    if isinstance(raw, PlanRequest):
        return raw
    if not isinstance(raw, dict):
        raise PlannerError("invalid_input", "a plan request must be a JSON object", "body")
    try:
        return PlanRequest.model_validate(raw)
    except ValidationError as exc:
        raise planner_error(exc) from None
