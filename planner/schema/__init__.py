"""The one definition of every shape rangeplan reads or writes (pydantic models).

- :class:`PlanRequest` (with :class:`Segment`, :class:`Reference`, :class:`Layout`,
  :class:`Settings`, :class:`RobotDescription`): the request of the CLI file, the HTTP body,
  the editor's save file and storage. Validation is complete and names the field.
- :class:`PlanResult` (with :class:`Metrics`, :class:`Timing`, :class:`Drives`,
  :class:`CorridorSamples`): the result, and :class:`SegmentationResult`.
- :class:`ImportOptions`, :class:`ImportReport`, :class:`ImportResult`: drawing import.
- :class:`ContourRequest`, :class:`Program`, :class:`ContourSection`: contouring a G-code program.
- :mod:`~planner.schema.limits`: the bounds on work and the mode defaults.
"""

from .contour import (
                     CONTOUR_FEEDS,
                     DEFAULT_CONTOUR_TOLERANCE_M,
                     MAX_CONTOUR_TOLERANCE_M,
                     MAX_PROGRAM_BYTES,
                     MIN_CONTOUR_TOLERANCE_M,
                     ContourRequest,
                     ContourSection,
                     PassSummary,
                     PathElement,
                     Program,
                     ProgramBlock,
                     ProgramComment,
                     ProgramWord,
)
from .drawing import (
                     DRAWING_UNITS,
                     PARTIAL_LAYOUT,
                     DrawingShape,
                     ImportOptions,
                     ImportReport,
                     ImportResult,
                     OpenChain,
)
from .errors import error_details, field_path, format_validation_error, planner_error
from .layout import SQRT3_2, Bounds, Cell, Circle, Layout, Obstacle, Polygon, Rectangle, cell_count
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
                     MAX_CELLS,
                     MAX_COORDINATE,
                     MAX_HOLES,
                     MAX_HORIZON,
                     MAX_LEGS,
                     MAX_OBSTACLES,
                     MAX_PENALTY,
                     MAX_PENALTY_RATIO,
                     MAX_PHYSICAL,
                     MAX_POLYGON_POINTS,
                     MAX_SAMPLES_PER_SEGMENT,
                     MAX_SEGMENTS,
                     MAX_TOTAL_STEPS,
                     MIN_CELL_SIZE,
                     MIN_SPEED,
                     MIN_TS,
                     MODE_DEFAULTS,
                     SLACK_BUDGET_S,
                     WORK_COSTS,
)
from .records import CorridorRecord
from .request import (
                     TIMING_FIELDS,
                     PlanRequest,
                     Reference,
                     Segment,
                     Settings,
                     default_horizon,
                     default_samples_per_segment,
                     parse_request,
)
from .result import (
                     UNITS,
                     CorridorSamples,
                     CorridorSegment,
                     Drives,
                     HalfPlanes,
                     Metrics,
                     PlanResult,
                     RobotSummary,
                     SegmentationCell,
                     SegmentationResult,
                     Timing,
)
from .robot import (
                     BodyDescription,
                     LegDescription,
                     PlatformDescription,
                     RobotDescription,
                     builtin_description,
                     builtin_robot_names,
)

__all__ = [
    "PlanRequest", "Segment", "Reference", "Settings", "parse_request", "TIMING_FIELDS", "Layout", "Bounds",
    "Cell", "Circle", "Obstacle", "Polygon", "Rectangle", "cell_count", "SQRT3_2", "RobotDescription",
    "LegDescription", "BodyDescription", "PlatformDescription", "builtin_description", "builtin_robot_names",
    "PlanResult", "Metrics", "Timing", "Drives", "CorridorSamples", "CorridorSegment", "UNITS",
    "SegmentationResult", "SegmentationCell", "HalfPlanes", "RobotSummary",
    "CorridorRecord", "ImportOptions", "ImportReport", "ImportResult", "DrawingShape", "OpenChain", "DRAWING_UNITS",
    "PARTIAL_LAYOUT",
    "CONTOUR_FEEDS", "DEFAULT_CONTOUR_TOLERANCE_M", "MAX_CONTOUR_TOLERANCE_M",
    "MAX_PROGRAM_BYTES", "MIN_CONTOUR_TOLERANCE_M", "ContourRequest",
    "ContourSection", "PassSummary", "PathElement", "Program", "ProgramBlock", "ProgramComment", "ProgramWord",
    "error_details", "field_path", "format_validation_error", "planner_error",
    "DEFAULT_FORCE_RISE_S", "DEFAULT_LAYOUT_SPEED_M_S", "DEFAULT_MODE",
    "DEFAULT_ROBOT", "DEFAULT_SAMPLES_PER_SEGMENT", "DEFAULT_HORIZON_RAMPS",
    "DEFAULT_HORIZON_BRAKES", "DEFAULT_HORIZON_MAX", "DEFAULT_SEGMENT_S", "default_horizon",
    "default_samples_per_segment", "MAX_CELLS", "MAX_HORIZON", "MAX_LEGS", "MAX_OBSTACLES",
    "MAX_HOLES", "MAX_POLYGON_POINTS", "MAX_SAMPLES_PER_SEGMENT", "MAX_SEGMENTS", "MAX_TOTAL_STEPS", "MIN_TS",
    "MODE_DEFAULTS", "SLACK_BUDGET_S",
    "MAX_COORDINATE", "MAX_PENALTY", "MAX_PENALTY_RATIO", "MAX_PHYSICAL", "MIN_CELL_SIZE", "MIN_SPEED", "WORK_COSTS",
]
