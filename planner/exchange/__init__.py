"""The edges where units change: drawings in, machine programs out.

- :func:`import_drawing`: a DXF or SVG drawing (its own units) -> a
  :class:`~planner.schema.Layout` in m with an :class:`~planner.schema.ImportReport`
  (:func:`estimate_import`: its compute time, counted before the work);
- :func:`read_gcode`: a CAM program (RS274NGC) -> a :class:`~planner.schema.Program` of lines
  and arcs in m, cut passes, travel and dwells (``readback=True``: the planner's own G-code
  read back, G93 and the C axis; :func:`toolpath`: a program's path as a timed polyline);
- :func:`export`: a :class:`~planner.schema.PlanResult` (SI) -> LinuxCNC G-code (mm,
  degrees, inverse-time feed: :func:`to_gcode`), a leg-length stream for ``halstreamer``
  (mm: :func:`to_joints`) or a DXF of the path, the corridor and the obstacles (mm:
  :func:`to_dxf`).
"""


from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_getattr
from .dxf_export import DXF_LAYERS, to_dxf
from .formats import EXPORT_FORMATS, ExportFormat, export, export_format_for
from .gcode import to_gcode
from .joints import joint_columns, to_joints

if TYPE_CHECKING:  # the readers, for type checkers; at run time they load on first use
    from .drawing import DRAWING_FORMATS, ImportWork, drawing_format, estimate_import, import_drawing
    from .gcode_in import Toolpath, read_gcode, toolpath

#: the readers load on first use (PEP 562): writing a plan's output (``app.formats``, every
#: ``rangeplan plan``) needs neither shapely nor scipy.spatial, which the drawing reader imports
_LAZY = {"DRAWING_FORMATS": "drawing", "drawing_format": "drawing", "import_drawing": "drawing",
         "estimate_import": "drawing", "ImportWork": "drawing",
         "read_gcode": "gcode_in", "Toolpath": "gcode_in", "toolpath": "gcode_in"}

__all__ = ["DRAWING_FORMATS", "DXF_LAYERS", "EXPORT_FORMATS", "ExportFormat", "ImportWork", "Toolpath",
           "drawing_format", "estimate_import", "export", "export_format_for", "import_drawing", "joint_columns",
           "read_gcode", "to_dxf", "to_gcode", "to_joints", "toolpath"]


__getattr__ = lazy_getattr(__name__, _LAZY)
