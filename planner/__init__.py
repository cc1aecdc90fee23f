"""rangeplan's numerical library: range-space predictive control of planar parallel robots
(after *Range-space predictive control for optimal robot motion*; ``docs/architecture.md``).

Layers, each importing only those below it (enforced by import-linter)::

    orchestrator   plan(): validate -> model -> corridor -> controller -> simulate -> result
    constraints    the constrained mode: constraint rows, QP per sample (stage-wise dual active set)
    corridor       segmentation of layouts into cells, range sequences      | horizon: eqs. 10-23
    model          the robot: kinematics, reach, dynamics (eqs. 1-8), hold (eq. 9), plant
    schema         the request and result models (pydantic), bounds and defaults
    errors         PlannerError

Glossary (paper symbol -> code name):

==============  ==============================================================
``y``           pose ``(x, y, psi)`` of the tool point [m, m, rad]; ``pose``
``x``           state ``(y, y_dot)``; ``X`` in a simulation
``s``           physical coordinates (``dynamics.physical_coordinates``)
``R``           ``ds/dy`` (``dynamics.R_matrix``); ``J_l``: its leg-length rows
``u``           drive forces [N], one per leg (``RobotModel.n_legs`` legs); in the
                generic horizon solvers ``n`` and ``m`` are the state and input sizes
``A(x), B(x)``  factorised model (``dynamics.factorised``, eq. 8)
``Ad, Bd``      zero-order hold (``discretisation.zoh_factorised``, eq. 9)
``F, G``        predictions (``horizon.prediction_matrices``, eq. 11)
``N``           horizon [samples] (``Settings.N``)
``r_a, r_b``    range limits: ``Segment.lower``, ``Segment.upper``; per sample
                ``RangeSequence.lower`` / ``.upper``
``Q_ra, Q_rb``  range penalties ``k_r`` or ``q_ra``, ``q_rb`` (diagonals)
``Q_u``         force penalty ``k_u`` or ``q_u``
(Table I)       samples each segment is held: ``samples_per_segment`` (``S`` in
                formulas)
``T_s``         sample time ``Settings.Ts`` [s]
==============  ==============================================================
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ._lazy import lazy_getattr
from ._version import __version__

if TYPE_CHECKING:  # the names below, for type checkers; at run time they load on first use
    from .errors import PlannerError
    from .model import RobotModel, load_robot
    from .orchestrator import WorkEstimate, estimate_work, plan, segment, to_csv, warm_up
    from .schema import PlanRequest, PlanResult, SegmentationResult, Settings, parse_request

__all__ = ["__version__", "plan", "segment", "warm_up", "to_csv", "estimate_work", "WorkEstimate",
           "PlanRequest", "PlanResult", "SegmentationResult", "Settings",
           "parse_request", "RobotModel", "load_robot", "PlannerError"]

#: where each public name lives: ``import planner`` (or ``planner.schema`` alone, e.g. for
#: ``rangeplan --help``) loads no numba, scipy or shapely until a name that needs them is used
_HOME = {"plan": "orchestrator", "segment": "orchestrator", "warm_up": "orchestrator", "to_csv": "orchestrator",
         "estimate_work": "orchestrator", "WorkEstimate": "orchestrator", "PlanRequest": "schema",
         "PlanResult": "schema", "SegmentationResult": "schema", "Settings": "schema", "parse_request": "schema",
         "RobotModel": "model", "load_robot": "model", "PlannerError": "errors"}


__getattr__ = lazy_getattr(__name__, _HOME)  # PEP 562: the public names, imported on first use


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
