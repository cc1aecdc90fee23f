"""The robot model (paper Section III): description -> :class:`RobotModel` (constants and
the packed array for the compiled kernels, built once), and stateless functions of the
model and a pose or state:

- :mod:`~planner.model.kinematics`: leg vectors, lengths, Jacobians, singularity measure;
- :mod:`~planner.model.reach`: stroke and singularity checks of poses and boxes;
- :mod:`~planner.model.dynamics`: eqs. 1-8 (``R``, reduced equations, factorisation);
- :mod:`~planner.model.discretisation`: eq. 9 (zero-order hold);
- :mod:`~planner.model.plant`: the nonlinear model over one sample (RK4);
- :mod:`~planner.model.kernels`: the compiled twins of the hot functions.
"""

from . import discretisation, dynamics, kernels, kinematics, plant, reach
from .kinematics import SINGULAR_TOL
from .robot import RobotModel, load_robot

__all__ = ["RobotModel", "load_robot", "SINGULAR_TOL", "discretisation", "dynamics", "kernels", "kinematics",
           "plant", "reach"]
