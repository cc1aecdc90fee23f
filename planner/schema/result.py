"""The plan result: one documented type, built in one place
(:func:`planner.orchestrator.result.build_result`), the HTTP API's response model.

In Python the per-sample arrays are numpy arrays (one row per sample ``k = 0..K``,
``time[k] = k Ts``); in JSON they are lists. ``drives.force[k]`` is applied from sample
``k`` to ``k+1`` (zero-order hold; the last row is zero: the plan ends at rest), and
``pose[k+1]`` is what the nonlinear model gives from sample ``k`` under ``force[k]``.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from ._types import FloatArray, Points2, Rows, Rows3, Vec2, Vec3
from .contour import ContourSection
from .request import Settings

__all__ = ["CorridorSamples", "CorridorSegment", "Drives", "Metrics", "PlanResult", "Timing", "UNITS",
           "SegmentationResult", "SegmentationCell", "HalfPlanes", "RobotSummary"]


class _Out(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Drives(_Out):
    length: Rows = Field(description="Leg lengths per sample, one column per leg, m")
    velocity: Rows = Field(description="Leg sliding speeds per sample, one column per leg, m/s")
    force: Rows = Field(description="Drive forces per sample (held until the next sample), one column per leg, N")


class CorridorSegment(_Out):
    lower: Vec3 = Field(description="Lower range limit [x, y, psi] in m, m, rad")
    upper: Vec3 = Field(description="Upper range limit [x, y, psi] in m, m, rad")
    polygon: Points2 | None = Field(None, description="The exact cell outline [[x, y], ...] in m when the segment "
                                    "has one (layout cells); null: the box lower..upper")


class CorridorSamples(_Out):
    lower: Rows3 = Field(description="Per-sample lower range limit [x, y, psi] in m, m, rad (the range the "
                         "criterion used; sample 0: the start point)")
    upper: Rows3 = Field(description="Per-sample upper range limit [x, y, psi] in m, m, rad")
    violation_m: FloatArray = Field(description="Per-sample distance of (x, y) outside its range, m")
    segments: list[CorridorSegment] | None = Field(description="The corridor's segments; null for a tracking "
                                                   "request")


class Metrics(_Out):
    """Figures computed from the returned trajectory (both modes), plus the constrained
    mode's solver figures and verdicts (null in paper mode)."""

    duration_s: float = Field(description="Trajectory duration, s")
    steps: int = Field(description="Samples planned after the start (count)")
    settled: bool = Field(description="Whether the robot settled at the end point")
    end_error_m: float = Field(description="Final distance of (x, y) from the end point, m")
    end_error_rad: float = Field(description="Final angle error, rad")
    end_speed_m_s: float = Field(description="Final tool speed, m/s")
    overshoot_m: float = Field(description="How far the robot passes the end point, measured along the approach "
                               "direction (from the last cell's centre to the end point, or from the cell before it "
                               "where the end point is the last cell's centre), over the samples from the last cell "
                               "on, m")
    max_corridor_violation_m: float = Field(description="Largest distance of (x, y) outside the union of the "
                                            "segments, m")
    max_corridor_violation_rad: float = Field(description="Largest angle outside the psi ranges of the segments the "
                                              "sample's (x, y) lies in (of the nearest ones where it lies in none), "
                                              "rad")
    time_indexed_violation_m: float = Field(description="Largest distance of (x, y) outside that sample's range, m")
    time_indexed_violation_rad: float = Field(description="Largest angle outside that sample's psi range, rad")
    max_drive_force_n: float = Field(description="Largest drive force magnitude, N")
    max_force_rate_n_s: float = Field(description="Largest change of a drive force from one sample to the next "
                                      "(from zero before the start) divided by Ts, N/s")
    force_limit_n: float = Field(description="Smallest drive force limit of the robot, N")
    max_force_ratio: float = Field(description="Largest |force| / force limit (dimensionless)")
    max_drive_speed_m_s: float = Field(description="Largest leg sliding speed, m/s")
    max_speed_ratio: float = Field(description="Largest |leg speed| / speed limit (dimensionless)")
    max_stroke_violation_m: float = Field(description="Largest leg length outside its stroke, m")
    max_tool_speed_m_s: float = Field(description="Largest speed of the tool point, |(x_dot, y_dot)|, over the "
                                      "samples, m/s")
    min_singularity_measure: float = Field(description="Smallest singularity measure along the path "
                                           "(dimensionless; singular near 0)")
    energy: float = Field(description="Sum of squared drive forces times Ts, N^2 s")
    path_length_m: float = Field(description="Length of the tool path, m")
    compute_ms: float = Field(description="Planner compute time of the whole plan() call, ms")
    # constrained mode
    contained: bool | None = Field(None, description="Constrained mode: no step needed slack and the actual "
                                   "trajectory lies in the corridor: (x, y) in the union of the segments (and of the "
                                   "exact cells) to 1e-9 m, psi in the psi ranges of the segments it is in to 1e-7 rad")
    within_limits: bool | None = Field(None, description="Constrained mode: drive forces, leg speeds and strokes "
                                       "within their limits on the actual trajectory, each drive-force change "
                                       "from one sample to the next (from zero before the start) within its "
                                       "force_rate_n_s x Ts to 1e-9 relative, and the tool speed within "
                                       "settings.tool_speed_max_m_s (where set) to 1e-9 relative")
    max_polygon_violation_m: float | None = Field(None, description="Constrained mode, corridors with exact cell "
                                                  "polygons: largest distance outside their union, m")
    infeasible_steps: int | None = Field(None, description="Constrained mode: steps whose QP needed slack (count)")
    constraint_slack_max_m: float | None = Field(None, description="Constrained mode: largest corridor or stroke "
                                                 "slack, m")
    speed_slack_max_m_s: float | None = Field(None, description="Constrained mode: largest leg-speed slack, m/s")
    predicted_violation_max_m: float | None = Field(None, description="Constrained mode: largest violation of a "
                                                    "constraint row by the QP's own solution (m, m/s or rad)")
    model_mismatch_max_m: float | None = Field(None, description="Constrained mode: largest distance between "
                                               "the predicted and the actual next position, m")
    model_mismatch_max_rad: float | None = Field(None, description="Constrained mode: the same for the angle, rad")
    qp_solver: str | None = Field(None, description="Constrained mode: the QP solver: 'stagewise' (the compiled "
                                  "backend's dual active-set method on the stage-wise problem, DAQP where it does not "
                                  "finish a step) or 'daqp' (the reference backend)")
    qp_fallbacks: int | None = Field(None, description="Constrained mode, compiled backend: steps the stage-wise "
                                     "solver handed to DAQP (count)")
    qp_relaxed_steps: int | None = Field(None, description="Constrained mode, compiled backend: steps whose QP was "
                                         "infeasible by less than 8e-7 (m, m/s, rad or N) and was solved with its rows "
                                         "widened by that much, inside the 1e-6 m corridor margin (count)")
    qp_iterations_median: float | None = Field(None, description="Constrained mode: median QP iterations per step "
                                               "(active-set changes)")
    qp_iterations_max: int | None = Field(None, description="Constrained mode: most QP iterations in one step")
    qp_time_ms: float | None = Field(None, description="Constrained mode: time in the controller (assembly and "
                                     "solves), ms")
    qp_failures: int | None = Field(None, description="Constrained mode: steps where even the slack QP failed")
    qp_refinements: int | None = Field(None, description="Constrained mode: QPs solved again after refining the "
                                       "one-step model correction (count)")


class Timing(_Out):
    method: Literal["samples_per_segment", "segment_samples", "speed_m_s", "total_time_s", "fastest"] = Field(
        description="How the timing was chosen")
    samples_per_segment: int = Field(description="Samples each segment is held (count); with per-segment counts the "
                                     "largest")
    segment_samples: list[int] | None = Field(None, description="Samples each segment is held, per segment (count); "
                                              "null when they are all samples_per_segment")
    sequence_time_s: float | None = Field(description="Time the range sequence takes (all segments), s; null for "
                                          "a tracking request")
    moving_time_s: float | None = Field(description="Time between the start and the end point segments, s")
    path_length_m: float | None = Field(description="Length of the polyline through the segment centres, m")
    evaluations: int | None = Field(None, description="fastest: candidate timings planned, whole or from a "
                                    "remembered step on (count)")
    feasible: bool | None = Field(None, description="fastest: whether a feasible timing was found")
    one_fewer_sample_infeasible: bool | None = Field(None, description="fastest: one sample fewer in any moving "
                                                     "segment was planned and is infeasible")


#: the unit of each output array
UNITS: dict[str, Any] = {"time": "s", "pose": ["m", "m", "rad"], "velocity": ["m/s", "m/s", "rad/s"],
                         "acceleration": ["m/s^2", "m/s^2", "rad/s^2"], "drives.length": "m",
                         "drives.velocity": "m/s", "drives.force": "N", "energy": "N^2 s"}


class PlanResult(_Out):
    """A planned trajectory with its drive forces and metrics (SI units)."""

    plan_id: str | None = Field(None, description="Id to fetch this result again at GET /v1/plans/{id} (set by "
                                "the service)")
    name: str | None = Field(description="Name of the request")
    robot: str = Field(description="Robot name")
    mode: Literal["paper", "constrained"] = Field(description="Controller mode")
    criterion: Literal["range-space", "tracking"] = Field(description="'range-space' (a corridor) or 'tracking' "
                                                          "(a reference trajectory)")
    settings: Settings = Field(description="The settings used, with every default filled in")
    units: dict[str, Any] = Field(description="Unit of each output array")
    time: FloatArray = Field(description="Sample times, s")
    pose: Rows3 = Field(description="Tool pose per sample [x, y, psi] in m, m, rad")
    velocity: Rows3 = Field(description="Velocity per sample in m/s, m/s, rad/s")
    acceleration: Rows3 = Field(description="Acceleration per sample (the model's, under that sample's force) "
                                "in m/s^2, m/s^2, rad/s^2")
    drives: Drives
    corridor: CorridorSamples
    metrics: Metrics
    timing: Timing
    contour: ContourSection | None = Field(None, description="Contour plans (POST /v1/contour, rangeplan contour): "
                                           "per sample whether it cuts and the source line, the deviation from the "
                                           "programmed path, per-pass summaries, the cycle time; null otherwise")

    def to_json_dict(self) -> dict[str, Any]:
        """The result as JSON types (lists, not arrays)."""
        return self.model_dump(mode="json")

    def to_json(self) -> bytes:
        """Compact UTF-8 JSON."""
        return self.model_dump_json().encode()


class SegmentationCell(_Out):
    id: int = Field(description="Cell index")
    polygon: Points2 = Field(description="Cell outline [[x, y], ...] in m, counter-clockwise")
    state: Literal["free", "blocked", "unreachable"] = Field(description="Whether the tool point may use the cell")


class HalfPlanes(_Out):
    A: Rows = Field(description="Unit outward normals, one row per edge")
    b: FloatArray = Field(description="Offsets: the cell is A p <= b, m")


class SegmentationResult(_Out):
    """A layout cut into cells, the chosen path of cells and the corridor's segments."""

    cell: dict[str, Any] = Field(description="Cell shape and size (m)")
    bounds: dict[str, Vec2] = Field(description="Workspace bounds {lower, upper} in m")
    clearance: float = Field(description="Clearance kept from obstacles, m")
    psi_range: Vec2 = Field(description="Platform angle range used, rad")
    cells: list[SegmentationCell] = Field(description="Every cell")
    counts: dict[str, int] = Field(description="Cells per state (count)")
    path: list[int] = Field(description="Cell ids from start to end")
    turns: int = Field(description="Turns along the path (count)")
    segments: list[dict[str, Any]] = Field(description="Corridor segments {lower, upper, polygon} in m, m, rad "
                                           "(usable as a plan request's segments)")
    halfplanes: list[HalfPlanes | None] = Field(description="Each segment's polygon as half-planes; null for a "
                                                "point")
    grown_obstacles: list[Points2] = Field(description="Obstacle outlines grown by the clearance, m")
    start: Vec3 = Field(description="Start pose [x, y, psi] in m, m, rad")
    end: Vec3 = Field(description="End pose [x, y, psi] in m, m, rad")
    compute_ms: float = Field(description="Segmentation compute time, ms")


class RobotSummary(_Out):
    name: str = Field(description="Built-in robot name")
    description: str = Field(description="What the robot is")
    legs: int = Field(description="Number of legs and drives (count)")
