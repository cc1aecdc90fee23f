"""The corridor: free-space segmentation of a layout into cells and a path of cells
(Section V.B), and the range sequence the criterion reads sample by sample (Table I, Fig. 4).

Segmentation, one module per step (:mod:`.segmentation` describes the whole):
:mod:`.workspace` (obstacles grown by the clearance, start and end checks), :mod:`.cells`
(square and triangle grids, default cell size, blocked cells), :mod:`.reach_region` (cells
and grid squares the robot reaches, regular; :func:`reachable_region`), :mod:`.search`
(fewest cells, then fewest turns), :mod:`.segmentation` (:func:`segment` and its result).
Plane geometry: :mod:`.geometry`; per-sample ranges: :mod:`.ranges`.
"""

from .cells import cell_size_rule
from .ranges import RangeSequence, range_sequence, reference_sequence, segment_counts
from .reach_region import reachable_region
from .search import count_turns
from .segmentation import Segmentation, remedy_cells, segment

__all__ = ["RangeSequence", "Segmentation", "cell_size_rule", "count_turns", "range_sequence", "segment_counts",
           "reachable_region", "reference_sequence", "remedy_cells", "segment"]
