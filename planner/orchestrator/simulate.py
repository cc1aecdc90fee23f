"""The receding-horizon loop (paper Sections IV-V): a fast simulation of the robot under
range-space predictive control.

At every sample ``k``: factorise the model at the current state (eq. 8), discretise it
(eq. 9), read the next ``N`` ranges, let the controller choose the move (the paper's
unconstrained minimisation, eqs. 22-23, or the constrained mode's QP), apply the first
move ``u(k)`` to the *nonlinear* model (eq. 6) integrated over one sample (RK4), and
repeat. After the corridor's last sample the end point is held until the robot settles.

``settings.backend`` chooses the implementation: ``"compiled"`` runs the paper mode's whole
loop as one compiled kernel (:func:`planner.orchestrator.kernels.simulate_paper`) and gives
other controllers the compiled model, hold and plant per step; ``"reference"`` runs every
stage on its numpy implementation. Both give the same trajectory (tests: 1e-9 m).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from ..constraints import ConstrainedController, ControllerStats, Memory
from ..corridor import RangeSequence
from ..errors import PlannerError
from ..horizon import SOLVERS
from ..model import RobotModel, dynamics, kernels
from ..model.discretisation import zoh_factorised
from ..model.plant import rk4_sample
from ..schema import Settings
from . import kernels as loop_kernels

__all__ = ["Controller", "PaperController", "Resume", "Simulation", "simulate", "C_POSE"]

#: the output matrix of eq. (9): the pose is the first three states
C_POSE = np.eye(3, 6)

#: the constrained mode's compiled loop hands control back to Python at least every this many
#: steps (~0.1 s), so that an exception raised asynchronously in the planning thread (a batch
#: item's compute limit, Ctrl-C) is delivered during a long plan, not after it
RETURN_EVERY = 2048


class Controller(Protocol):
    """Chooses the move of sample ``k`` from the state and the discretised model."""

    def __call__(self, k: int, x: np.ndarray, Ad: np.ndarray, Bd: np.ndarray) -> np.ndarray: ...

    def report(self) -> dict: ...


@dataclass
class Resume:
    """The loop at the start of step ``k``: the trajectory so far and the constrained
    controller's memory and statistics (a run can start here instead of at step 0: the
    ``fastest`` search re-plans only from the step a changed timing first shows)."""

    k: int
    X: np.ndarray  #: (>= k + 1, 6) states, rows 0..k used
    U: np.ndarray  #: (>= k, n) forces, rows 0..k-1 used
    ACC: np.ndarray  #: (>= k, 3) accelerations, rows 0..k-1 used
    memory: Memory | None  #: the controller's memory (a copy), None for the paper's controller
    stats: ControllerStats | None  #: and its statistics (a copy)


@dataclass
class Simulation:
    """The sampled trajectory of one run of the loop (SI units)."""

    X: np.ndarray  #: (steps + 1, 6) states x = (pose, velocity)
    U: np.ndarray  #: (steps + 1, n) drive forces, held from sample k to k + 1 (last row 0)
    ACC: np.ndarray  #: (steps + 1, 3) accelerations under that sample's force
    steps: int  #: samples simulated
    settled: bool  #: whether the robot settled at the end point
    resumes: dict[int, Resume] = field(default_factory=dict)  #: the states remembered (``simulate(keep=...)``)


class PaperController:
    """The paper's controller: minimise the range-space criterion (22)-(23) over the
    horizon, unconstrained, and return the first move ``u(k)``."""

    def __init__(self, seq: RangeSequence, st: Settings):
        self.seq, self.N = seq, st.N
        self.solver = SOLVERS[st.solver]

    def __call__(self, k: int, x: np.ndarray, Ad: np.ndarray, Bd: np.ndarray) -> np.ndarray:
        lo, hi, qa, qb, qu = self.seq.window(k, self.N)
        return self.solver(Ad, Bd, C_POSE, x, qa, qb, qu, lo, hi)[0]

    def report(self) -> dict:
        """Extra metrics of this controller (none for the paper's)."""
        return {}


def _settled(x: np.ndarray, end: np.ndarray, st: Settings) -> bool:
    return (math.hypot(x[0] - end[0], x[1] - end[1]) < st.settle_position_m
            and abs(x[2] - end[2]) < st.settle_angle_rad
            and math.hypot(x[3], x[4]) < st.settle_speed_m_s
            and abs(x[5]) < st.settle_rate_rad_s)


def _diverged(k: int, Ts: float) -> PlannerError:
    return PlannerError("diverged", f"the simulated robot diverged at t = {(k + 1) * Ts:.3f} s; "
                        "try a smaller sample time or larger k_u", "settings")


def _singular(t: float, x: np.ndarray) -> PlannerError:
    return PlannerError("singular", f"the robot model is degenerate at t = {t:.3f} s, pose ({x[0]:.4f} m, "
                        f"{x[1]:.4f} m, {x[2]:.4f} rad): its reduced mass matrix or the horizon problem is "
                        "singular; check the robot's masses and inertias and keep the corridor away from "
                        "singular poses", "robot")


def _simulate_compiled(robot: RobotModel, seq: RangeSequence, st: Settings) -> Simulation:
    """The paper-mode loop with the Riccati solver, run whole in
    :func:`planner.orchestrator.kernels.simulate_paper` (same steps, same stopping rule)."""
    N, Ts = st.N, st.Ts
    max_steps = seq.K + st.tail_steps

    def pad(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate((a, np.repeat(a[-1:], N, axis=0))))

    settle = np.array([st.settle_position_m, st.settle_angle_rad, st.settle_speed_m_s, st.settle_rate_rad_s])
    x0 = np.concatenate((seq.start, np.zeros(3)))
    X, U, ACC, steps, settled, status = loop_kernels.simulate_paper(
        robot.packed, x0, pad(seq.lower), pad(seq.upper), pad(seq.qa), pad(seq.qb),
        np.ascontiguousarray(seq.qu, dtype=float), seq.K, N, Ts, st.plant_substeps, max_steps,
        np.asarray(seq.end, dtype=float), settle)
    if status == loop_kernels.DIVERGED:
        raise _diverged(max(steps - 1, 0), Ts)
    if status == loop_kernels.SINGULAR:
        raise _singular(steps * Ts, X[steps])
    return Simulation(X, U, ACC, int(steps), bool(settled))


def simulate(robot: RobotModel, seq: RangeSequence, st: Settings, controller: Controller | None = None,
             resume: Resume | None = None, keep: Sequence[int] = ()) -> Simulation:
    """Run the receding-horizon loop with ``controller`` (default: the paper's). With the
    compiled backend the constrained controller's steps run in the compiled loop
    (:func:`planner.orchestrator.kernels.simulate_constrained`), and here only the steps that
    loop hands back (those its stage-wise solve did not finish). ``resume``: start there
    instead of at step 0 (the constrained controller's memory and statistics restored);
    ``keep``: the steps whose state to remember (:attr:`Simulation.resumes`)."""
    reference = st.backend == "reference"
    if controller is None:
        if not reference and resume is None and not keep:
            return _simulate_compiled(robot, seq, st)
        controller = PaperController(seq, st)
    Ts = st.Ts
    max_steps = seq.K + st.tail_steps
    X = np.empty((max_steps + 1, 6))
    U = np.zeros((max_steps + 1, robot.n_legs))
    ACC = np.empty((max_steps + 1, 3))
    k = 0
    X[0] = np.concatenate((seq.start, np.zeros(3)))
    constrained = controller if isinstance(controller, ConstrainedController) else None
    if resume is not None:
        k = min(resume.k, max_steps)
        X[:k + 1], U[:k], ACC[:k] = resume.X[:k + 1], resume.U[:k], resume.ACC[:k]
        if constrained is not None and resume.memory is not None and resume.stats is not None:
            constrained.restore(resume.memory, resume.stats)
    marks = sorted({j for j in keep if k <= j < max_steps})
    resumes: dict[int, Resume] = {}

    def remember(j: int) -> None:
        mem, stats = constrained.snapshot() if constrained is not None else (None, None)
        resumes[j] = Resume(j, X, U, ACC, mem, stats)

    settled = False
    packed = robot.packed
    loop = None
    if not reference and constrained is not None:
        loop = constrained.loop_arguments(max_steps)
    settle = np.array([st.settle_position_m, st.settle_angle_rad, st.settle_speed_m_s, st.settle_rate_rad_s])
    end = np.asarray(seq.end, dtype=float)
    while k < max_steps:
        while marks and marks[0] <= k:
            if marks.pop(0) == k:
                remember(k)
        if loop is not None and constrained is not None:
            args, record = loop
            stop = min(marks[0] if marks else max_steps, k + RETURN_EVERY)
            t0 = time.perf_counter()
            status, k_end, settled = loop_kernels.simulate_constrained(
                packed, k, stop, seq.K, Ts, st.plant_substeps, end, settle, X, U, ACC, *args)
            constrained.absorb(record, k, k_end, time.perf_counter() - t0)
            if status == loop_kernels.DIVERGED:
                raise _diverged(k_end, Ts)
            if status == loop_kernels.SINGULAR:
                raise _singular(k_end * Ts, X[k_end])
            k = k_end
            if settled or k >= max_steps:
                break
            if status == loop_kernels.OK:  # stopped at a step to remember, or to hand back control
                continue
        x = X[k]  # one step here: the paper's or reference controller, or a step the compiled loop handed back
        if reference:
            A22, B2 = dynamics.factorised_blocks(robot, x)  # eq. (8)
            Ad, Bd = zoh_factorised(A22, B2, Ts)  # eq. (9)
        else:
            A22, B2, Ad, Bd, ok = kernels.model_step(packed, x, Ts)  # eqs. (8)-(9), compiled
            if not ok:
                raise _singular(k * Ts, x)
        u = controller(k, x, Ad, Bd)
        xdot = np.concatenate((x[3:], A22 @ x[3:] + B2 @ u))  # == f(x) + G(x) u exactly (eq. 8)
        U[k] = u
        ACC[k] = xdot[3:]
        if reference:
            x = rk4_sample(robot, x, u, Ts, st.plant_substeps, xdot)
        else:
            x = kernels.rk4(packed, x, np.ascontiguousarray(u, dtype=float), Ts, st.plant_substeps, xdot)
        X[k + 1] = x
        if not np.all(np.isfinite(x)) or abs(x[0]) + abs(x[1]) > 1e3:
            raise _diverged(k, Ts)
        k += 1
        if k >= seq.K and _settled(x, seq.end, st):
            settled = True
            break
    steps = k
    U[steps] = 0.0
    ACC[steps] = dynamics.acceleration(robot, X[steps, :3], X[steps, 3:], U[steps])
    return Simulation(X[:steps + 1], U[:steps + 1], ACC[:steps + 1], steps, settled, resumes)
