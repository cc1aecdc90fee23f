"""The constrained mode (beyond the paper): the range-space criterion with hard corridor,
drive-force, leg-speed, stroke, no-overshoot and (optional) tool-speed constraints, solved every sample as a
quadratic program (a dual active-set method on the stage-wise problem; DAQP as its
reference and fallback).

Modules, by concept:

==============  ==========================================================================
``rows``        what a constraint gives: rows on the predicted states (:class:`Rows`)
``corridor``    corridor boxes and cell half-planes, the end box; no overshoot at the end
``drives``      drive-force bounds, leg-speed and leg-stroke rows
``motion``      the tool-speed limit rows (optional, off by default)
``registry``    the row constraints in row order, the one list (``SECTIONS``: row class, typed
                tuple, count and fill kernels, compile costs), and the fused compiled assembly
                of a step's rows generated from it
``qp``          the DAQP wrapper, the dense QP of a step and its slack problem
``step``        the step's dense QP in compiled form (DAQP's fallback and the slack problem)
``stagewise``   the step's QP as a stage-wise problem: Riccati factorisation, dual active set
``compiled``    the compiled assembly (``backend: "compiled"``): one compiled call per step
``reference``   the numpy reference assembly (``backend: "reference"``)
``composed``    the constraints of a plan, composed (:class:`Constraints`)
``controller``  the receding-horizon controller: builds the constraints, refines, reports
``kernels``     the compiled kernels (numba): rows, dense QP, plant step; ``stagewise_kernels``
                and ``step_kernels``: the stage-wise solver and the fused step
==============  ==========================================================================
"""

from .composed import Constraints, force_rate
from .controller import CONTAIN_TOL_M, CONTAIN_TOL_RAD, ConstrainedController, ControllerStats, Memory, WorkBound
from .corridor import (
    END_TOL_M,
    END_TOL_RAD,
    MARGIN_M,
    MARGIN_RAD,
    ArrivalConstraint,
    CorridorConstraint,
    EndApproachConstraint,
)
from .drives import (
    SPEED_MARGIN,
    DriveForceConstraint,
    DriveForceRateConstraint,
    LegSpeedConstraint,
    LegStrokeConstraint,
)
from .qp import DenseQP, QPSolution
from .rows import ROW_UNIT_M, RowKind, Rows

__all__ = ["CONTAIN_TOL_M", "CONTAIN_TOL_RAD", "END_TOL_M", "END_TOL_RAD", "MARGIN_M", "MARGIN_RAD", "ROW_UNIT_M",
           "SPEED_MARGIN", "ArrivalConstraint", "ConstrainedController", "Constraints", "ControllerStats", "Memory",
           "CorridorConstraint", "DenseQP", "DriveForceConstraint", "DriveForceRateConstraint",
           "EndApproachConstraint", "LegSpeedConstraint", "LegStrokeConstraint", "QPSolution", "RowKind", "Rows",
           "WorkBound", "force_rate"]
