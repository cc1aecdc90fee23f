"""Contouring CAM programs (issue 22): the top layer, above the orchestrator and the exchange.

- :func:`plan_contour`: a :class:`~planner.schema.ContourRequest` (a G-code program, its
  origin in the robot frame, the tolerance and the feed) -> one
  :class:`~planner.schema.PlanResult` for the whole program with its ``contour`` section;
- :func:`tube`: a pass's lines and arcs -> a tube corridor of convex cells whose every chord
  between consecutive samples stays within the tolerance; :class:`PathGeometry`: distances
  to the programmed path.
"""

from .estimate import ContourCounts, count_contour, estimate_contour
from .passes import parse_contour_request
from .plan import plan_contour
from .tube import PathGeometry, Tube, tube

__all__ = ["ContourCounts", "PathGeometry", "Tube", "count_contour", "estimate_contour", "parse_contour_request",
           "plan_contour", "tube"]
