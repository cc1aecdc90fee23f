"""Bounds that keep one request's work finite, and the defaults that depend on the mode.

Every bound here appears in the request schema (and so in the OpenAPI document) or is
checked by a validator of :mod:`planner.schema.request` that names the field.
"""

from __future__ import annotations

__all__ = [
    "MAX_HORIZON", "MAX_SAMPLES_PER_SEGMENT", "MAX_SEGMENTS", "MAX_TOTAL_STEPS", "MAX_CELLS",
    "MAX_OBSTACLES", "MAX_POLYGON_POINTS", "MAX_LEGS", "MIN_TS", "MODE_DEFAULTS",
    "DEFAULT_SAMPLES_PER_SEGMENT", "DEFAULT_ROBOT", "DEFAULT_FORCE_RISE_S", "DEFAULT_LAYOUT_SPEED_M_S",
    "DEFAULT_MODE",
]

#: longest prediction horizon N [samples]
MAX_HORIZON = 200
#: most samples a segment is held [samples]
MAX_SAMPLES_PER_SEGMENT = 2000
#: most segments in a corridor
MAX_SEGMENTS = 2000
#: most samples one plan may simulate, the settling tail included [samples]
MAX_TOTAL_STEPS = 200_000
#: most cells a layout may be cut into
MAX_CELLS = 40_000
#: most obstacles in a layout
MAX_OBSTACLES = 2_000
#: most vertices of one obstacle polygon
MAX_POLYGON_POINTS = 10_000
#: most legs of a robot description
MAX_LEGS = 16
#: shortest sample time [s]
MIN_TS = 1e-4

#: Defaults that depend on ``settings.mode``, applied where the request leaves the field out.
#: The constrained mode keeps the corridor by its constraints, so its range penalty only has
#: to pull the robot along: a lighter pull (k_r) and force penalty (k_u) with a longer
#: horizon use 6-75 % less drive energy on every corridor measured, all contained and
#: settled (benchmarks/README.md, issue 6; on Table I 1.14x the IPOPT optimum instead of 1.5x).
MODE_DEFAULTS: dict[str, dict[str, float]] = {"paper": {"N": 20, "k_r": 1.0, "k_u": 1e-3},
                                              "constrained": {"N": 30, "k_r": 0.1, "k_u": 2e-4}}
#: samples each segment is held when neither samples_per_segment nor N is given
DEFAULT_SAMPLES_PER_SEGMENT = 20
#: the robot a request without ``robot`` plans for
DEFAULT_ROBOT = "moving-slide"
#: the constrained mode's default drive-force rate limit: each drive may go from zero to its
#: force_max in this time [s] (settings.force_rate_n_s)
DEFAULT_FORCE_RISE_S = 0.05
#: the mode of a request that does not choose one: the constrained mode keeps the corridor,
#: the drive limits and the end point; the paper's soft criterion is ``mode: "paper"``
DEFAULT_MODE = "constrained"
#: a layout's corridor without a timing setting is timed at this mean tool speed along its
#: cells' centre path [m/s], so that the duration does not depend on how finely the free
#: space is cut (with a fixed count per segment, 2 mm cells made a move 6x longer than 20 mm
#: cells); constrained plans at it were contained for 2-20 mm square and triangle cells
DEFAULT_LAYOUT_SPEED_M_S = 0.05
