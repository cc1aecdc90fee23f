"""The plan request and result as pydantic models: one JSON shape for the CLI file, the
HTTP body and the editor's save file. Every numeric field states its SI unit.

The models check shape and types (and publish them in OpenAPI); the numerical library
(:func:`planner.request.parse_request`) then checks meaning (ranges, reachability) and names
the field of any error.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field

from planner.request import DEFAULT_SAMPLES_PER_SEGMENT, MAX_HORIZON, MAX_SAMPLES_PER_SEGMENT, MAX_SEGMENTS, MODE_DEFAULTS

Finite = Annotated[float, Field(allow_inf_nan=False)]
Pose = Annotated[list[Finite], Field(min_length=3, max_length=3,
                                     description="[x, y, psi]: position of the tool point in m, angle in rad")]
Point2 = Annotated[list[Finite], Field(min_length=2, max_length=2, description="[x, y] in m")]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class SegmentModel(Strict):
    lower: Pose = Field(description="Lower range limit r_a = [x_a, y_a, psi_a] (m, m, rad)")
    upper: Pose = Field(description="Upper range limit r_b = [x_b, y_b, psi_b] (m, m, rad)")
    q_ra: list[Finite] | None = Field(None, min_length=3, max_length=3,
                                      description="Diagonal of Q_ra for this segment's samples (1/m, 1/m, 1/rad)")
    q_rb: list[Finite] | None = Field(None, min_length=3, max_length=3,
                                      description="Diagonal of Q_rb for this segment's samples (1/m, 1/m, 1/rad)")
    polygon: list[Point2] | None = Field(None, description="Exact convex cell (e.g. a triangle) the box encloses, "
                                         "vertices in m; used by the constrained mode")


class SettingsModel(Strict):
    Ts: Finite = Field(0.01, gt=0, le=1.0, description="Sample time in s")
    N: int | None = Field(None, ge=1, le=MAX_HORIZON, description="Prediction horizon in samples; default "
                          f"{MODE_DEFAULTS['paper']['N']} in paper mode, {MODE_DEFAULTS['constrained']['N']} in "
                          "constrained mode")
    samples_per_segment: int | None = Field(None, ge=1, le=MAX_SAMPLES_PER_SEGMENT,
                                            description="Samples each segment is held (count); default N if N is "
                                            f"given, else {DEFAULT_SAMPLES_PER_SEGMENT}")
    k_r: Finite | None = Field(None, gt=0, description="Range penalty: Q_ra = Q_rb = k_r I (1/m, 1/rad); default "
                               f"{MODE_DEFAULTS['paper']['k_r']:g} in paper mode, "
                               f"{MODE_DEFAULTS['constrained']['k_r']:g} in constrained mode")
    k_u: Finite | None = Field(None, gt=0, description="Drive-force penalty: Q_u = k_u I (1/N); default "
                               f"{MODE_DEFAULTS['paper']['k_u']:g} in paper mode, "
                               f"{MODE_DEFAULTS['constrained']['k_u']:g} in constrained mode")
    q_ra: list[Finite] | None = Field(None, min_length=3, max_length=3, description="Diagonal of Q_ra (1/m, 1/m, 1/rad)")
    q_rb: list[Finite] | None = Field(None, min_length=3, max_length=3, description="Diagonal of Q_rb (1/m, 1/m, 1/rad)")
    q_u: list[Finite] | None = Field(None, min_length=1, description="Diagonal of Q_u, one per drive (1/N)")
    taper: bool = Field(True, description="Spread the range out of the start point and narrow it onto the end point")
    solver: Literal["riccati", "structured", "qr"] = Field(
        "riccati", description="How the horizon problem is solved (same solution): 'riccati' (default: "
        "Riccati recursion, the whole loop compiled), 'structured' (banded KKT, numpy reference) or 'qr' "
        "(the paper's Householder QR, numpy reference)")
    mode: Literal["paper", "constrained"] = Field("paper", description="'paper': the seed's soft range "
                                                  "criterion; 'constrained': hard corridor and drive limits")
    settle_position_m: Finite = Field(1e-4, gt=0, le=1, description="End-point position tolerance in m")
    settle_speed_m_s: Finite = Field(1e-3, gt=0, le=1, description="Speed that counts as stopped in m/s")
    settle_angle_rad: Finite = Field(1e-4, gt=0, le=1, description="End-point angle tolerance in rad")
    settle_rate_rad_s: Finite = Field(1e-3, gt=0, le=1, description="Angular speed that counts as stopped in rad/s")
    tail_max_s: Finite = Field(3.0, ge=0, le=600, description="Longest time in s the end point is held for settling")
    plant_substeps: int = Field(1, ge=1, le=50, description="RK4 steps of the nonlinear model per sample (count)")
    require_settled: bool = Field(True, description="Fail with code not_settled instead of returning an unsettled plan")
    speed_m_s: Finite | None = Field(None, gt=0, le=100, description="Target mean tool speed along the corridor "
                                     "in m/s; sets samples_per_segment (exclusive with it, total_time_s, fastest)")
    total_time_s: Finite | None = Field(None, gt=0, le=3600, description="Time in s the corridor's range sequence "
                                        "takes; sets samples_per_segment")
    fastest: bool = Field(False, description="Constrained mode: the shortest timing (samples_per_segment) whose "
                          "plan keeps the corridor and the drive force, stroke and speed limits")


class CylinderModel(Strict):
    mass: Finite = Field(ge=0, description="Mass in kg")
    com: Finite = Field(description="Distance of the centre of mass from the base pivot (cylinder) or the "
                        "platform pivot (rod) in m")
    inertia: Finite = Field(ge=0, description="Moment of inertia about the centre of mass in kg m^2")


class LegModel(Strict):
    cylinder: CylinderModel
    rod: CylinderModel
    friction: Finite = Field(0.0, ge=0, description="Viscous friction on the leg's sliding speed in N s/m")
    length_min: Finite = Field(gt=0, description="Shortest leg length in m")
    length_max: Finite = Field(gt=0, description="Longest leg length in m")
    force_max: Finite = Field(gt=0, description="Drive force limit in N")
    speed_max: Finite = Field(gt=0, description="Drive speed limit in m/s")


class PlatformModel(Strict):
    mass: Finite = Field(gt=0, description="Platform mass in kg")
    inertia: Finite = Field(gt=0, description="Platform moment of inertia about its centre in kg m^2")


class RobotModel(Strict):
    name: str = "custom"
    description: str = ""
    base_pivots: list[Point2] = Field(min_length=3, description="Base pivots A_i, world frame, m")
    platform_pivots: list[Point2] = Field(min_length=3, description="Platform pivots b_i, platform frame "
                                          "about the platform centre, m")
    platform: PlatformModel
    legs: Union[LegModel, list[LegModel]] = Field(description="One leg description shared by all legs, or one per leg")
    tool_offset: Point2 = Field([0.0, 0.0], description="Tool point in the platform frame, m")


class ReferenceModel(Strict):
    pose: list[Pose] = Field(min_length=2, description="Desired pose per sample, [x, y, psi] in m, m, rad; "
                             "the first is the start")


class ObstacleModel(Strict):
    type: Literal["rectangle", "polygon", "circle"] = Field(description="Obstacle shape")
    lower: Point2 | None = Field(None, description="Rectangle lower corner [x, y] in m")
    upper: Point2 | None = Field(None, description="Rectangle upper corner [x, y] in m")
    points: list[Point2] | None = Field(None, description="Polygon vertices [[x, y], ...] in m")
    center: Point2 | None = Field(None, description="Circle centre [x, y] in m")
    radius: Finite | None = Field(None, gt=0, description="Circle radius in m")


class CellModel(Strict):
    shape: Literal["square", "triangle"] = Field("square", description="Cell shape")
    size: Finite | None = Field(None, gt=0, description="Cell edge length in m; default from the start-end "
                                "distance and the sample time")


class BoundsModel(Strict):
    lower: Point2 = Field(description="Workspace lower corner [x, y] in m")
    upper: Point2 = Field(description="Workspace upper corner [x, y] in m")


class LayoutModel(Strict):
    bounds: BoundsModel
    obstacles: list[ObstacleModel] = Field([], description="Obstacles in the workspace")
    clearance: Finite = Field(0.0, ge=0, description="Distance in m the tool point keeps from every obstacle")
    cell: CellModel = Field(CellModel(), description="Cell shape and size")
    start: Pose | None = Field(None, description="Start pose [x, y, psi] in m, m, rad (required here or at the "
                               "request's top level)")
    end: Pose | None = Field(None, description="End pose [x, y, psi] in m, m, rad (required here or at the "
                             "request's top level)")
    psi_range: list[Finite] | None = Field(None, min_length=2, max_length=2,
                                           description="Allowed platform angle [min, max] in rad along the corridor")


class PlanRequestModel(Strict):
    """A plan request: a robot, and a corridor (segments), a reference trajectory, or a layout."""

    name: str | None = Field(None, max_length=200, description="Free-text name of the corridor")
    robot: Union[str, RobotModel] = Field("moving-slide", description="Built-in robot name or a robot description")
    segments: list[SegmentModel] | None = Field(None, min_length=2, max_length=MAX_SEGMENTS,
                                                description="The corridor: ranges in order, first the start point, "
                                                "last the end point")
    reference: ReferenceModel | None = Field(None, description="Instead of segments: a trajectory to track "
                                             "(the paper's criterion (12))")
    layout: LayoutModel | None = Field(None, description="Instead of segments: a workspace with obstacles to "
                                       "segment into a corridor (Section V.B)")
    settings: SettingsModel = Field(SettingsModel(), description="Planner settings")
    start: Pose | None = Field(None, description="Shorthand for layout.start: start pose [x, y, psi] in m, m, rad")
    end: Pose | None = Field(None, description="Shorthand for layout.end: end pose [x, y, psi] in m, m, rad")
    psi_range: list[Finite] | None = Field(None, min_length=2, max_length=2,
                                           description="Shorthand for layout.psi_range: allowed platform angle "
                                           "[min, max] in rad")


def request_dict(model: PlanRequestModel) -> dict[str, Any]:
    """The request as the plain dict the planner takes (unset optional fields dropped)."""
    return model.model_dump(exclude_none=True, exclude_unset=False)


def format_validation_error(exc) -> str:
    """One line naming the first failing field and the cause, from a pydantic ValidationError."""
    errs = exc.errors()
    parts = []
    for e in errs[:3]:
        loc = ".".join(str(p) if not isinstance(p, int) else f"[{p}]" for p in e["loc"]).replace(".[", "[")
        parts.append(f"{loc or 'body'}: {e['msg']}")
    more = f" (+{len(errs) - 3} more)" if len(errs) > 3 else ""
    return "; ".join(parts) + more
