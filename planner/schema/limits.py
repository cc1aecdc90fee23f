"""Bounds that keep one request's work finite, and the defaults that depend on the mode.

Every bound here appears in the request schema (and so in the OpenAPI document) or is
checked by a validator of :mod:`planner.schema.request` that names the field.
"""

from __future__ import annotations

__all__ = [
    "MAX_HORIZON", "MAX_SAMPLES_PER_SEGMENT", "MAX_SEGMENTS", "MAX_TOTAL_STEPS", "MAX_CELLS",
    "MAX_OBSTACLES", "MAX_POLYGON_POINTS", "MAX_HOLES", "MAX_LEGS", "MIN_TS", "MAX_COORDINATE", "MIN_CELL_SIZE",
    "MIN_SPEED", "MAX_PENALTY", "MAX_PENALTY_RATIO", "MAX_PHYSICAL", "MODE_DEFAULTS",
    "DEFAULT_SAMPLES_PER_SEGMENT", "DEFAULT_ROBOT", "WORK_COSTS", "DEFAULT_FORCE_RISE_S",
    "DEFAULT_LAYOUT_SPEED_M_S", "DEFAULT_MODE", "SLACK_BUDGET_S", "DEFAULT_HORIZON_RAMPS", "DEFAULT_HORIZON_BRAKES",
    "DEFAULT_HORIZON_MAX", "DEFAULT_SEGMENT_S",
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
#: most vertices of one obstacle polygon, its outline and holes together
MAX_POLYGON_POINTS = 10_000
#: most holes of one obstacle polygon
MAX_HOLES = 200
#: most legs of a robot description
MAX_LEGS = 16
#: shortest sample time [s]
MIN_TS = 1e-4
#: largest magnitude of a coordinate in a request: positions and lengths [m], angles [rad]
#: (the robots are metres across; beyond this, products of coordinates overflow)
MAX_COORDINATE = 1e3
#: smallest cell edge of a layout [m] (smaller cells are also bounded by MAX_CELLS)
MIN_CELL_SIZE = 1e-6
#: slowest target tool speed ``speed_m_s`` [m/s]
MIN_SPEED = 1e-6
#: largest penalty weight (k_r, k_u and the diagonals q_ra, q_rb, q_u)
MAX_PENALTY = 1e12
#: paper mode: largest ratio of a range penalty to a force penalty (k_r / k_u, or the largest
#: q_ra, q_rb over the smallest q_u); beyond ~1e13 the horizon problem is too ill-conditioned
#: to solve in double precision (measured on Table I and psi-turn: 1e12 plans, 1e13 fails)
MAX_PENALTY_RATIO = 1e12
#: largest mass [kg], inertia [kg m^2], friction [N s/m], force [N] or speed [m/s] of a robot
MAX_PHYSICAL = 1e9

#: Defaults that depend on ``settings.mode``, applied where the request leaves the field out.
#: The constrained mode keeps the corridor by its constraints, so its range penalty only has
#: to pull the robot along: a lighter pull (k_r) and force penalty (k_u) with a longer
#: horizon use 6-75 % less drive energy on every corridor measured, all contained and
#: settled (benchmarks/README.md, issue 6; on Table I 1.14x the IPOPT optimum instead of 1.5x).
MODE_DEFAULTS: dict[str, dict[str, float]] = {"paper": {"N": 20, "k_r": 1.0, "k_u": 1e-3},
                                              "constrained": {"N": 30, "k_r": 0.1, "k_u": 2e-4}}
#: samples each segment is held when neither samples_per_segment nor N is given (paper mode;
#: the constrained mode's is at least this, :data:`DEFAULT_SEGMENT_S` at fine sample times)
DEFAULT_SAMPLES_PER_SEGMENT = 20
#: the constrained mode's default horizon follows the sample time and the robot (issue 31: a
#: fixed 30 samples is 0.3 s at Ts 10 ms but 0.03 s at Ts 1 ms, less than one force ramp, and
#: every default request at Ts 1 ms was refused): ``N Ts`` covers this many force ramps
#: (``force_max / force_rate``) ...
DEFAULT_HORIZON_RAMPS = 4.0
#: ... plus this many braking times from the drives' speed limit at the platform's acceleration
#: with every drive at its force limit (``speed_max m / sum force_max``, the legs' and
#: platform's mass ``m``): 0.25 s for the Moving Slide, 26 samples at Ts 10 ms ...
DEFAULT_HORIZON_BRAKES = 2.0
#: ... at least the mode's N (30: Table I at Ts 10 ms plans as before) and at most this many
#: samples (the step's cost is linear in N; 100 at Ts 1 and 2 ms planned every short corridor
#: of issue 31 that planned at any N but one, and 200 cost up to 40 s on the numerical
#: fallbacks of the last samples before the end point)
DEFAULT_HORIZON_MAX = 100
#: the constrained mode's default time [s] a segment is held (20 samples at Ts 10 ms, as
#: before; 100 at Ts 2 ms instead of 20, which gave 0.04 s a segment: every short corridor of
#: issue 31 refused)
DEFAULT_SEGMENT_S = 0.2
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


#: What one unit of planning work costs, for the estimate that rejects requests that cannot
#: finish within a server's time limit before they reach a worker
#: (:func:`planner.orchestrator.estimate_work`). Seconds; measured on the 2-core machine of
#: benchmarks/README.md ("Work estimate", benchmarks/bench_work.py). Since issue 20 the compiled
#: steps are costed at the dear end of what the certification run measured (a constrained step
#: near the end point, with the stop box, arrival and approach rows active, costs 2-3x a Table I
#: step; ``benchmarks/certify.py``), so that the estimate bounds the work: measured <= 1.5x the
#: estimate. Per receding-horizon step ``a + b N + c N^2 + d N^3`` for each
#: mode and backend (the constrained mode's compiled stage-wise QP about linearly since issue 17:
#: 26 / 51 / 88 us per step at N = 10 / 30 / 60; its numpy reference with DAQP about N^2.2),
#: per extra RK4 substep,
#: per sample of the range sequence, the corridor metrics and the result (linear in the samples
#: since issue 17; more with cell polygons), per cell and per obstacle of a segmentation and
#: a fixed part per segmentation (the workspace, the reach region: ~2.5-4 ms for 24-900 cells,
#: found by the certification run, issue 20), and a fixed part per request (parsing, reach
#: checks, the result).
WORK_COSTS: dict[str, float] = {
    "paper_compiled_a": 6e-6, "paper_compiled_b": 0.25e-6, "paper_compiled_c": 0.0, "paper_compiled_d": 0.0,
    "paper_reference_a": 110e-6, "paper_reference_b": 1.5e-6, "paper_reference_c": 0.0, "paper_reference_d": 0.0,
    "paper_structured_a": 130e-6, "paper_structured_b": 3e-6, "paper_structured_c": 0.0, "paper_structured_d": 0.0,
    "paper_qr_a": 200e-6, "paper_qr_b": 0.0, "paper_qr_c": 0.0, "paper_qr_d": 0.04e-6,
    "constrained_compiled_a": 25e-6, "constrained_compiled_b": 2.2e-6, "constrained_compiled_c": 0.0,
    "constrained_compiled_d": 0.0,
    "constrained_reference_a": 1500e-6, "constrained_reference_b": 0.0, "constrained_reference_c": 0.25e-6,
    "constrained_reference_d": 0.001e-6,
    "substep_compiled": 1.5e-6, "substep_reference": 150e-6,
    "sample": 2.5e-6, "sample_polygon": 1e-6,
    "cell": 5e-6, "obstacle": 1e-4, "segmentation": 3e-3, "fixed": 1.5e-3,
    "slack_step_a": 2e-3, "slack_step_d": 0.6e-6, "slack_iteration_a": 5e-6, "slack_iteration_c": 0.04e-6,
}

#: the compute [s, on the reference machine] a constrained plan with ``require_settled: false``
#: may spend on infeasible steps beyond its own estimate (issue 20). Such a step is done on the
#: Python path (the hard QP by DAQP, relaxed, then the dense slack problem by DAQP): ``slack_step_a
#: + slack_step_d N^3`` in :data:`WORK_COSTS` besides the slack problem's DAQP iterations,
#: ``slack_iteration_a + slack_iteration_c N^2`` each (~18 ms + 100-18 000 x 0.04 ms at N = 30,
#: 100-3000x a compiled step), so a corridor infeasible at every step (Table I at 3 samples per
#: segment: 336 steps, 42 s) was not bounded by its estimate. Half of this (or of the plan's own
#: estimated loop time, if more) pays for the steps, half for the iterations
#: (:func:`planner.orchestrator.work.slack_allowance`); the estimate counts both, the controller
#: stops the plan with ``infeasible`` where either runs out
SLACK_BUDGET_S = 1.0
