"""The corridor: free-space segmentation of a layout into cells and a path of cells
(Section V.B), and the range sequence the criterion reads sample by sample (Table I, Fig. 4)."""

from .ranges import RangeSequence, range_sequence, reference_sequence
from .segmentation import Segmentation, corridor_from_request, count_turns, reachable_region, segment

__all__ = ["RangeSequence", "range_sequence", "reference_sequence", "Segmentation", "corridor_from_request",
           "count_turns", "reachable_region", "segment"]
