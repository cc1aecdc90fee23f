"""Contouring a CAM program (issue 22): the parsed program model (what
:func:`planner.exchange.read_gcode` returns), the contour request
(:class:`ContourRequest`: the CLI's options, the body of ``POST /v1/contour``) and the
``contour`` section of a :class:`~planner.schema.PlanResult`.

Every length is in m, angle in rad, time in s, feed in m/s, in the program's own frame
(program zero at [0, 0]); the request's ``origin`` places program zero in the robot frame.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from ._types import Finite, FloatArray, Strict, Vec2, fail
from .limits import MAX_COORDINATE
from .request import TIMING_FIELDS, Settings
from .robot import RobotDescription

__all__ = ["CONTOUR_FEEDS", "DEFAULT_CONTOUR_TOLERANCE_M", "DEFAULT_Z_ACCEL_M_S2", "MAX_CONTOUR_TOLERANCE_M",
           "MAX_PROGRAM_BYTES", "MIN_CONTOUR_TOLERANCE_M",
           "ContourRequest", "ContourSection", "PassSummary", "PathElement", "Program", "ProgramBlock",
           "ProgramComment", "ProgramWord"]

#: largest G-code program read (bytes of text); larger is ``too_large``
MAX_PROGRAM_BYTES = 2_000_000
#: the tolerance when neither the request nor the program's G64 P gives one [m]
DEFAULT_CONTOUR_TOLERANCE_M = 5e-5
#: smallest tolerance accepted [m]: ten times the constrained mode's corridor margin
MIN_CONTOUR_TOLERANCE_M = 1e-5
#: the largest tolerance a request may give [m]
MAX_CONTOUR_TOLERANCE_M = 0.01
#: the Z axis acceleration when the request gives none [m/s^2] (a small router's Z: LinuxCNC's
#: sample configurations give 0.25..1.3 m/s^2)
DEFAULT_Z_ACCEL_M_S2 = 1.0
#: the feeds of a contour plan
CONTOUR_FEEDS = ("program", "fastest")


class _Out(BaseModel):
    model_config = ConfigDict(extra="forbid")


class PathElement(_Out):
    """One programmed XY move: a straight line or a circular arc (XY plane, G17); read back
    (``read_gcode(readback=True)``) also a move of the C axis alone (a line of length 0)."""

    kind: Literal["line", "arc"] = Field(description="'line' (G0/G1) or 'arc' (G2/G3)")
    line: int = Field(description="Source line number (1-based)")
    start: Vec2 = Field(description="Start point [x, y] in m (program frame)")
    end: Vec2 = Field(description="End point [x, y] in m (program frame)")
    centre: Vec2 | None = Field(default=None, description="Arc centre [x, y] in m; null for a line")
    radius_m: float | None = Field(default=None, description="Arc radius (from the centre to the start), m")
    start_angle_rad: float | None = Field(default=None, description="Angle of the start point about the centre, rad")
    sweep_rad: float | None = Field(default=None, description="Signed swept angle, rad (> 0 counter-clockwise, G3; < 0 "
                                    "clockwise, G2; +-2 pi for a full circle)")
    length_m: float = Field(description="Length of the move in XY, m")
    z_start_m: float = Field(description="Z at the start, m")
    z_end_m: float = Field(description="Z at the end, m")
    feed_m_s: float = Field(description="Programmed feed F, m/s")
    exact_stop: bool = Field(default=False, description="G61 active: the tool stops at the end of this move")
    c_start_rad: float | None = Field(default=None, description="The C axis (the platform angle psi) at the start, rad "
                                      "(degrees in the program); null: a program read without readback (no C axis)")
    c_end_rad: float | None = Field(default=None, description="The C axis (the platform angle psi) at the end, rad; "
                                    "null without readback")
    duration_s: float | None = Field(default=None, description="G93 inverse time: the time the move takes, 60 / F s; "
                                     "null for a rapid or a move in units per minute (G94)")

    def point_at(self, s: np.ndarray) -> np.ndarray:
        """Points at arc length ``s`` (n,) from the start, (n, 2) [m]."""
        s = np.asarray(s, float)
        if self.kind == "line":
            t = s / self.length_m if self.length_m > 0 else np.zeros_like(s)
            return self.start + t[:, None] * (self.end - self.start)
        assert self.centre is not None and self.radius_m is not None and self.start_angle_rad is not None
        assert self.sweep_rad is not None
        a = self.start_angle_rad + np.sign(self.sweep_rad) * s / self.radius_m
        return self.centre + self.radius_m * np.stack((np.cos(a), np.sin(a)), axis=1)


class ProgramBlock(_Out):
    """A piece of the program in order: a cut pass (feed moves below the cutting height),
    an XY travel (a rapid, or a feed move above the cutting height), or a dwell (plunge,
    retract, G4, or an exact stop)."""

    kind: Literal["cut", "travel", "dwell"] = Field(description="What the piece is")
    line: int = Field(description="Source line of its first move (1-based)")
    elements: list[PathElement] = Field(default_factory=list, description="cut: the moves, in order; travel: one")
    rapid: bool = Field(default=False, description="travel: a G0 rapid (else a feed move above the cutting height)")
    duration_s: float = Field(default=0.0, description="dwell: its time, s (Z at the feed or rapid speed, G4 P)")
    reason: str = Field(default="", description="dwell: 'plunge', 'retract', 'G4' or 'pause' (M0/M1)")
    z_start_m: float | None = Field(default=None, description="dwell: Z at its start, m (program frame)")
    z_moves: list[tuple[float, float, int]] = Field(default_factory=list, description="dwell: its pieces in "
                                                    "order, each [seconds, Z at its end in m, source line]: the Z "
                                                    "moves and waits it joins")


class ProgramWord(_Out):
    line: int = Field(description="Source line (1-based)")
    word: str = Field(description="The word as written, upper case (e.g. 'M3', 'S12000', 'T1', 'G64 P0.02')")


class ProgramComment(_Out):
    line: int = Field(description="Source line (1-based)")
    text: str = Field(description="The comment's text")


class Program(_Out):
    """A G-code program read by :func:`planner.exchange.read_gcode` (SI, program frame)."""

    blocks: list[ProgramBlock] = Field(description="The program's pieces, in order")
    tolerance_m: float | None = Field(description="The path tolerance of the last G64 P, m; null without one")
    units: Literal["mm", "inch"] = Field(description="The length units the program ended in")
    lines: int = Field(description="Lines read (count)")
    words: list[ProgramWord] = Field(description="Spindle, tool and mode words accepted without motion (M3, M5, "
                                     "M6, S, T, G64, G61, ...), in order")
    comments: list[ProgramComment] = Field(description="Comments, in order")
    warnings: list[str] = Field(description="What was accepted with a caveat (no M2/M30, ...)")
    start: Vec2 = Field(description="Where the program's first XY move starts [x, y] in m (X0 Y0 unless the "
                        "program moved before)")

    @property
    def passes(self) -> list[ProgramBlock]:
        """The cut passes, in order."""
        return [b for b in self.blocks if b.kind == "cut"]


class ContourRequest(Strict):
    """Contour a G-code program: the body of ``POST /v1/contour`` and what ``rangeplan
    contour`` builds from its options."""

    name: str | None = Field(default=None, max_length=200, description="A name for the plan")
    program: str = Field(description="The G-code program's text (RS274NGC, LinuxCNC dialect)")
    origin: list[Finite] | Literal["fit"] = Field(
        default_factory=lambda: [0.0, 0.0],
        description="Where program zero (X0 Y0) sits in the robot frame [x, y], m; 'fit': where the program's "
        "moves (its cuts, and the boxes its travel moves plan in) lie, with a margin, inside the region the robot "
        "reaches at psi 0, centred on it when they can (the result's contour.origin says where)")
    tolerance_m: Finite | None = Field(default=None, description="Largest distance of the tool point from the "
                                       "programmed path while cutting, m; default: the program's G64 P, else "
                                       "5e-5 m (0.05 mm)")
    feed: Literal["program", "fastest"] = Field(default="program", description="'program': never faster than the "
                                                "programmed F; 'fastest': as fast as the drives allow")
    cut_below_m: Finite = Field(default=0.0, description="Feed moves with Z below this cut (program frame), m")
    z_rapid_m_s: Finite = Field(default=0.05, gt=0, le=10.0, description="The Z axis speed, m/s: the speed of Z "
                                "rapids (retracts, approaches: their dwell time) and the largest Z speed of a cut "
                                "whose Z moves (a ramp, a helix, a tab's flank)")
    z_accel_m_s2: Finite = Field(default=DEFAULT_Z_ACCEL_M_S2, gt=0, le=100.0, description="The Z axis "
                                 "acceleration, m/s^2: the Z of a cut whose Z moves (ramps, helices, tabs: planned "
                                 "with the XY motion) never accelerates faster, its samples' second differences "
                                 "included; where Z would, the pass is cut slower there")
    robot: str | RobotDescription = Field(default="moving-slide",
                                          description="Built-in robot name or a full description")
    settings: dict[str, Any] = Field(default_factory=dict, description="Plan settings (Ts, N, k_r, k_u, ...; not the "
                                     "timing options, which the feed decides)")

    @field_validator("program")
    @classmethod
    def _size(cls, v: str) -> str:
        n = len(v.encode())
        if n > MAX_PROGRAM_BYTES:
            raise fail(f"the program has {n} bytes, more than the limit of {MAX_PROGRAM_BYTES}", None, "too_large")
        return v

    @field_validator("origin")
    @classmethod
    def _origin(cls, v: list[float] | str) -> list[float] | str:
        if isinstance(v, str):
            return v
        if len(v) != 2:
            raise fail(f"must be [x, y] or 'fit', got {len(v)} numbers")
        if any(abs(x) > MAX_COORDINATE for x in v):
            raise fail(f"must be within +-{MAX_COORDINATE:g} m")
        return v

    @field_validator("tolerance_m")
    @classmethod
    def _tol(cls, v: float | None) -> float | None:
        if v is not None and v < MIN_CONTOUR_TOLERANCE_M:
            raise fail(f"{v:g} m is below what the planner can hold: the tube's cells keep a 1e-06 m margin for the "
                       "model's one-step error, and a cell narrower than ten margins leaves a sample no room; give "
                       f"at least {MIN_CONTOUR_TOLERANCE_M:g} m")
        if v is not None and v > MAX_CONTOUR_TOLERANCE_M:
            raise fail(f"must be at most {MAX_CONTOUR_TOLERANCE_M:g} m, got {v:g}")
        return v

    @model_validator(mode="after")
    def _settings(self) -> ContourRequest:
        for k in TIMING_FIELDS:
            if k in self.settings:
                raise fail(f"the contour's timing comes from 'feed'; remove settings.{k}", f"settings.{k}")
        if self.settings.get("mode", "constrained") != "constrained":
            raise fail("contouring plans in the constrained mode only", "settings.mode")
        return self

    def plan_settings(self) -> Settings:
        """The validated plan settings; raises :class:`~planner.errors.PlannerError` naming
        ``settings.<field>``."""
        from pydantic import ValidationError

        from .errors import planner_error

        try:
            return Settings.model_validate(self.settings)
        except ValidationError as exc:
            raise planner_error(exc, "settings") from None


class PassSummary(_Out):
    index: int = Field(description="Pass number (0-based, in program order)")
    first_line: int = Field(description="Source line of its first move")
    last_line: int = Field(description="Source line of its last move")
    elements: int = Field(description="Lines and arcs (count)")
    cells: int = Field(description="Tube cells planned through (count)")
    length_m: float = Field(description="Programmed length, m")
    time_s: float = Field(description="Time from the start to the end of the pass, s")
    max_deviation_m: float = Field(description="The two-sided deviation of the pass (G64 P as LinuxCNC means "
                                   "it): the larger of the largest distance of a sample or of the chord between two "
                                   "samples from the programmed path and max_path_deviation_m, m")
    max_path_deviation_m: float = Field(description="Largest distance of a point of the programmed path (its "
                                        "corners included) from the cut (the samples and the straight moves "
                                        "between them), m")
    max_speed_m_s: float = Field(description="Largest tool speed (sample to sample), m/s")
    max_programmed_feed_m_s: float = Field(description="Largest programmed F of its moves, m/s")
    max_feed_ratio: float | None = Field(default=None, description="Largest tool speed over the programmed F of "
                                         "the move being cut (the samples' speeds and the straight moves between "
                                         "samples as the exported program runs them, each against the smaller F "
                                         "of its two ends): at most 1 in feed 'program', by how much F was "
                                         "exceeded in 'fastest'")


class ContourSection(_Out):
    """What a contour plan adds to the :class:`~planner.schema.PlanResult`."""

    cutting: list[bool] = Field(description="Per sample: true while realising a cut")
    program_line: list[int | None] = Field(description="Per sample: the source line being cut; null for travel, "
                                           "plunge, retract and dwell")
    tolerance_m: float = Field(description="The tolerance planned to, m")
    max_deviation_m: float = Field(description="The two-sided deviation (G64 P as LinuxCNC means it): the larger "
                                   "of the largest distance from the programmed path (computed from its lines and "
                                   "arcs) of a cutting sample or of the straight move from it to the next, and "
                                   "max_path_deviation_m; within tolerance_m, m")
    max_path_deviation_m: float = Field(description="Largest distance of a point of the programmed path (its "
                                        "corners included) from the cut of its pass (the samples and the straight "
                                        "moves between them), over the passes, m")
    deviation_m: FloatArray = Field(description="Per sample: the largest distance from the programmed path of the "
                                    "sample and of the straight move to the next while cutting; 0 elsewhere, m")
    feed: Literal["program", "fastest"] = Field(description="The feed planned")
    cycle_time_s: float = Field(description="The whole program's time, s")
    cut_time_s: float = Field(description="Time spent cutting, s")
    max_feed_ratio: float | None = Field(default=None, description="Largest tool speed while cutting over the "
                                         "programmed F of the move being cut (the passes' largest): at most 1 in "
                                         "feed 'program' (F is the process limit); in 'fastest', which ignores F, "
                                         "by how much F was exceeded")
    passes: list[PassSummary] = Field(description="One summary per cut pass")
    origin: list[float] = Field(description="Program zero in the robot frame [x, y], m")
    words: list[ProgramWord] = Field(description="Spindle, tool and mode words of the program")
    comments: list[ProgramComment] = Field(description="Comments of the program")
    warnings: list[str] = Field(description="Warnings from reading and planning")
    z_m: FloatArray | None = Field(default=None, description="Per sample: the tool's Z, m (program frame): the "
                                   "pass's Z while cutting, the programmed Z moves while the robot rests in a "
                                   "plunge or retract; null in a plan made before Z was kept")
    source_line: list[int] | None = Field(default=None, description="Per sample: the last source line whose move "
                                          "or dwell the plan has reached (non-decreasing; 0 before the first); the "
                                          "words of a line are issued before the first sample that reaches it")
    dwell: list[str | None] | None = Field(default=None, description="Per sample: the dwell being realised "
                                           "('plunge', 'retract', 'G4', 'pause'), null while moving in XY")
