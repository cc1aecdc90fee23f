"""Constrained range-space predictive control (``settings.mode = "constrained"``).

Beyond the paper. The paper's criterion (22)-(23) is soft: with equal penalties it pulls the
robot toward the middle of each range and does not keep it inside. This mode keeps the same
criterion and the same model (eq. 8/9, re-linearised every sample) and adds, over the whole
horizon, hard constraints, solved as one dense quadratic program per sample with DAQP
(:mod:`~planner.constraints.qp`). The constraints are objects composed here
(:class:`~planner.constraints.composed.Constraints`), each giving its rows: the corridor and the no-overshoot half-plane
(:mod:`~planner.constraints.corridor`), the drive forces, leg speeds and leg strokes
(:mod:`~planner.constraints.drives`).

Margins and refinement. Constraints hold for the linear prediction; the plant is the
nonlinear model. The model is exact at the current state and re-linearised every sample, but
over one sample it is frozen: the plant lands up to ~2e-8 m and ~4e-7 rad from the prediction
on Table I (more at higher speed). So the first predicted state is corrected by the one-step
offset ``d = Phi(x, u0) - Ad x - Bd u0`` (an RK4 step of the plant under the guessed move
``u0``, the previous solution's; ``build`` and ``set_offset`` of the assembly), which leaves
the one-step error ``(dPhi/du - Bd)(u - u0)``. After each solve the plant is stepped under the
solution's move ``u``; while it lands farther than :data:`REFINE_TOL_M` /
:data:`REFINE_TOL_RAD` (1e-2 of the corridor margin; 0.3 of :data:`CONTAIN_TOL_RAD`, which a
zero-width psi range is kept to) from the prediction, the offset is recomputed at ``u`` and
the QP solved again (at most :data:`REFINE_MAX` times; 8 re-solves in 240 steps on Table I
with the mode's defaults). The remaining one-step mismatch (metric ``model_mismatch_max_m``)
is below 1e-9 m and 1e-8 rad on Table I, and at most the tolerances at the fastest timings,
far inside the 1 micrometre margin (:data:`~planner.constraints.corridor.MARGIN_M`; 0.2 um of
it is left when a step's rows were relaxed), which therefore keeps the actual samples inside.
Metrics are always computed on the actual (nonlinear) trajectory; ``contained`` is true only
if its corridor violation is at most :data:`CONTAIN_TOL_M` and :data:`CONTAIN_TOL_RAD`.

Backends. ``settings.backend`` picks, once at construction, the assembly that forms and
solves each step's QP: :class:`~planner.constraints.compiled.CompiledAssembly` (each step in
one compiled call: rows, offset, the stage-wise dual active-set solve of
:mod:`~planner.constraints.stagewise` and the refinement; a step that call does not finish is
done on the Python path below with DAQP) or
:class:`~planner.constraints.reference.ReferenceAssembly` (numpy, the QP in ``z`` with every
row, DAQP). Both have the interface :class:`Assembly`; the Python path of a step (build,
solve, refine, finish) is written once, here.

Infeasibility. If the hard QP has no solution, the step is solved again with the rows
softened by slack variables (:meth:`~planner.constraints.qp.DenseQP.solve_slack`; forces stay
hard). With ``settings.require_settled`` (default) the plan stops there with
``PlannerError("infeasible")`` (time and slack in the message), its work bounded by
:class:`WorkBound` (where the bound stops the step's solves, the message says the slack was
not computed within it); otherwise every such step is
counted (``infeasible_steps``), its slack reported (``constraint_slack_max_m``,
``speed_slack_max_m_s``) and the result marks the plan not contained, within ``slack`` (the
steps and slack-problem iterations the work estimate counts,
:func:`planner.orchestrator.work.slack_allowance`: a slack step costs 100-3000x a compiled
step); the plan stops with ``infeasible`` where either runs out.
An infeasible step is first solved again with its rows widened by
:data:`~planner.constraints.rows.RELAX_M` (both backends, as the compiled step does). On a
stretch of such steps the compiled step proves each hard QP infeasible on the rows that proved
the previous one's (the active set and the violated row of its verdict, a sample later), and
solves the whole hard QP only where those rows alone have a solution: the same steps relaxed,
at a fraction of the active-set changes (``step_kernels.constrained_step``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol

import numpy as np

from ..corridor import RangeSequence
from ..corridor.geometry import corridor_gaps
from ..errors import PlannerError
from ..model import RobotModel
from ..schema import Segment, Settings
from .compiled import MAX_ITERATIONS, CompiledAssembly
from .composed import Constraints
from .corridor import MARGIN_M, MARGIN_RAD
from .qp import DAQP_SETTINGS, SLACK_ITER_LIMIT, WORK_BOUND_FLAG, DenseQP, QPSolution, daqp_iterations, small_solve
from .reference import ReferenceAssembly
from .rows import RELAX_M, ROW_UNIT_M, RowKind
from .stagewise import INFEASIBLE, SOLVED, shifted

__all__ = ["CONTAIN_TOL_M", "CONTAIN_TOL_RAD", "REFINE_MAX", "REFINE_TOL_M", "REFINE_TOL_RAD", "Assembly",
           "ConstrainedController", "ControllerStats", "HARD_ITER_LIMIT", "LoopRecord", "Memory", "STEP_WORK_FLOOR_S",
           "WorkBound"]

#: a plan is "contained" when its actual corridor violation is at most this [m] ...
CONTAIN_TOL_M = 1e-9
#: ... and its angle at most this outside the psi ranges [rad] (a zero-width psi range is
#: kept to the one-step mismatch the refinement leaves, ~1e-8 rad)
CONTAIN_TOL_RAD = 1e-7
#: re-solve while the plant's next pose under the solution's first move lands farther than
#: this from the QP's prediction of it (position [m], angle [rad]): 1e-2 of the corridor margin,
#: and 0.3 of the angle that ``contained`` allows (zero-width psi ranges are kept to it)
REFINE_TOL_M = 1e-8
REFINE_TOL_RAD = 3e-8
REFINE_MAX = 3
#: DAQP's own iteration limit of a hard solve
HARD_ITER_LIMIT = int(DAQP_SETTINGS["iter_limit"])
#: the work [CPU s] every step on the Python path may take whatever the plan used before it
#: (:meth:`WorkBound.for_step`): its QPs when small are solved, so that the bound cuts only the
#: work that grows with the horizon (users case 38, 5 legs, N 49: an accepted plan past 1.3x
#: its 0.052 s estimate whose three Python-path steps take 5-10 ms each; a refused step at N
#: 100 takes 0.5-6 s)
STEP_WORK_FLOOR_S = 0.05


class Assembly(Protocol):
    """Forms and solves the QP of a step: :class:`CompiledAssembly` or
    :class:`ReferenceAssembly`, each with its own step data (``qp``)."""

    def build(self, k: int, x: np.ndarray, Ad: np.ndarray, Bd: np.ndarray, y_nom: np.ndarray | None,
              u_prev: np.ndarray, u0: np.ndarray) -> Any: ...

    def set_offset(self, qp: Any, u: np.ndarray, x1: np.ndarray) -> None: ...

    def solve(self, qp: Any, start: np.ndarray | None, iter_limit: int | None = None) -> QPSolution: ...

    def relax(self, qp: Any, only: RowKind | None = None) -> None: ...

    def one_step_error(self, qp: Any, u: np.ndarray) -> tuple[np.ndarray, float, float]: ...

    def dense(self, qp: Any) -> DenseQP: ...

    def violation(self, qp: Any, sol: QPSolution) -> float: ...

    def finish(self, qp: Any, z: np.ndarray, hard: QPSolution | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


@dataclass(frozen=True)
class WorkBound:
    """The work a plan that stops at its first infeasible step (``require_settled``) may take
    (issue 33 goal 2, issue 31 goal 6: a refusal's own work within 1.5x its estimate, like a
    plan's): ``seconds`` of CPU time (``time.process_time``) from ``start``, the plan's
    ``factor`` times its work estimate ``estimate_s``. A step on the Python path (DAQP: its
    hard QP, relaxed, then the slack problem) gives each solve the iterations that what is left
    pays for (:func:`~planner.constraints.qp.daqp_iterations`), or :data:`STEP_WORK_FLOOR_S`
    of the step's where that is more; DAQP's own limits where they are less. Where the bound
    stops them, the refusal says what was found and that the rest was not computed within the
    bound."""

    seconds: float  #: CPU seconds the plan may take
    start: float  #: ``time.process_time()`` at the plan's start
    estimate_s: float  #: the request's work estimate [s]
    factor: float  #: ``seconds / estimate_s``

    @classmethod
    def of(cls, estimate_s: float, factor: float, start: float) -> WorkBound:
        """``factor`` times the estimate ``estimate_s`` from ``start``."""
        return cls(factor * estimate_s, start, estimate_s, factor)

    def left(self) -> float:
        """CPU seconds left [s] (negative past the bound)."""
        return self.seconds - (time.process_time() - self.start)

    def for_step(self) -> Callable[[], float]:
        """For a step starting now: a function giving the work it has left [s], what is left of
        the bound or of :data:`STEP_WORK_FLOOR_S` from now, whichever is more."""
        floor = time.process_time() + STEP_WORK_FLOOR_S
        return lambda: max(self.left(), floor - time.process_time())

    def words(self) -> str:
        """The bound, in words."""
        return f"the request's work bound, {self.factor:g}x its estimate of {self.estimate_s:.3g} s"


@dataclass
class ControllerStats:
    """What the controller counts over a plan (reported by :meth:`ConstrainedController.report`)."""

    iterations: list[int] = field(default_factory=list)  #: solver iterations per step
    fallbacks: int = 0  #: steps the stage-wise solver handed to DAQP
    relaxed: int = 0  #: steps solved with the rows widened by ``RELAX_M``
    solve_s: float = 0.0  #: time in the controller [s]
    failures: int = 0  #: steps whose slack problem failed too
    refinements: int = 0  #: re-solves at a refined offset
    infeasible: int = 0  #: steps that needed the slack problem
    first_infeasible_s: float = 0.0  #: the time of the first of them [s]
    slack_iterations: int = 0  #: DAQP iterations of their slack problems
    slack_max_m: float = 0.0  #: largest corridor or stroke slack [m]
    speed_slack_max_m_s: float = 0.0  #: largest leg-speed slack [m/s]
    violation_max_m: float = 0.0  #: largest violation of a hard row at the solutions [m, m/s or rad]
    mismatch_m: float = 0.0  #: largest distance of the plant's next position from the prediction [m]
    mismatch_rad: float = 0.0  #: and of its angle [rad]


@dataclass(slots=True, eq=False)
class Memory:
    """What the controller carries from one step to the next, as arrays that the Python step
    and the compiled loop (:func:`planner.orchestrator.kernels.simulate_constrained`) update
    in place. ``flags[HAVE_PREV]``: ``z_prev`` and ``y_nom`` hold a previous step's;
    ``flags[HAVE_WARM]``: ``warm`` holds a warm start; ``flags[HAVE_PRED]``: ``x1_pred`` holds a
    prediction of the current state."""

    HAVE_PREV: ClassVar[int] = 0
    HAVE_WARM: ClassVar[int] = 1
    HAVE_PRED: ClassVar[int] = 2

    z_prev: np.ndarray  #: (N m,) the previous step's moves (scaled)
    y_nom: np.ndarray  #: (N, 3) nominal poses of the leg linearisation (the previous prediction, shifted)
    u_prev: np.ndarray  #: (n_legs,) the forces applied over the previous sample [N]
    warm: np.ndarray  #: (6N + N m,) the previous solution ``(X, z)`` shifted by one sample
    x1_pred: np.ndarray  #: (6,) the prediction of the current state
    flags: np.ndarray  #: (3,) int64, see the class docstring

    @classmethod
    def empty(cls, N: int, m: int) -> Memory:
        """Before the first step: nothing remembered, at rest (zero force)."""
        return cls(np.zeros(N * m), np.zeros((N, 3)), np.zeros(m), np.zeros(6 * N + N * m), np.zeros(6),
                   np.zeros(3, np.int64))

    def remember(self, z: np.ndarray, X: np.ndarray, y_nom: np.ndarray, umax: np.ndarray,
                 Y: np.ndarray | None = None) -> None:
        """After a step with moves ``z`` (scaled), predicted states ``X`` (N, 6), next nominal
        poses ``y_nom`` and (if solved stage-wise) its solution ``Y = (X, z)``."""
        N, m = y_nom.shape[0], len(umax)
        self.z_prev[:] = z
        self.y_nom[:] = y_nom
        self.u_prev[:] = z[:m] * umax
        self.x1_pred[:] = X[0]
        self.warm[:] = shifted(Y if Y is not None else np.concatenate((np.ravel(X), z)), N, m)
        self.flags[:] = 1


@dataclass(slots=True, eq=False)
class LoopRecord:
    """What the compiled loop counts, in place (:meth:`ConstrainedController.absorb` adds it
    to the statistics)."""

    iterations: np.ndarray  #: (max_steps,) int64, per step
    counts: np.ndarray  #: (2,) int64: refinements, relaxed steps
    worst: np.ndarray  #: (3,): largest row violation [m, m/s, rad], one-step mismatch [m], [rad]


class ConstrainedController:
    """Receding-horizon controller with hard constraints (see the module docstring).

    Called as ``controller(k, x, Ad, Bd) -> u`` [N] by
    :func:`planner.orchestrator.simulate.simulate`; :meth:`report` returns its metrics. With
    the compiled backend, ``simulate`` runs stretches of steps in its compiled loop instead
    (:meth:`loop_arguments`), calling the controller only for a step that loop does not
    finish."""

    #: let ``simulate`` run the compiled loop (tests that record every step switch it off)
    compiled_loop: ClassVar[bool] = True

    def __init__(self, model: RobotModel, seq: RangeSequence, st: Settings,
                 segments: Sequence[Segment] | None = None, abandon: bool = False,
                 slack: tuple[int, int] = (0, 0), bound: WorkBound | None = None):
        self.model, self.seq, self.st = model, seq, st
        #: the work the plan may take (:class:`WorkBound`; None: no bound): with
        #: ``require_settled`` only (a plan with slack steps has its own, ``slack``)
        self.bound = bound if st.require_settled else None
        #: with ``require_settled`` false: the infeasible steps and the slack-problem iterations
        #: the plan may take (the work estimate's, :func:`planner.orchestrator.work.slack_allowance`)
        self.slack_steps, self.slack_iterations = slack
        #: raise ``infeasible`` at the first step the compiled solve finds infeasible, without the
        #: DAQP fallback and the slack problem (a ``fastest`` candidate needs only the verdict)
        self.abandon = abandon
        self.N, self.n_legs = st.N, model.n_legs
        #: consecutive segments that do not touch (the margins allowed): the geometric cause of
        #: an infeasible plan, if any
        self.gaps = corridor_gaps(segments, 2 * MARGIN_M, 2 * MARGIN_RAD) if segments is not None else []
        self.constraints = Constraints.of(model, seq, segments, st)
        #: the ranges the criterion reads (the stop boxes at the end: ``criterion_sequence``)
        self.criterion = self.constraints.corridor.criterion_sequence(seq)
        #: the strategy that forms and solves each step's QP, by ``settings.backend``
        self.assembly: Assembly = (CompiledAssembly if st.backend == "compiled" else ReferenceAssembly)(
            model, self.criterion, st, self.constraints)
        if abandon and isinstance(self.assembly, CompiledAssembly):
            # a candidate is abandoned at a step the compiled solve does not finish: at the plain
            # limit, as before the limit followed the horizon (a fastest search at Ts 1 ms, N 100,
            # 6 legs, took 7x the CPU with the larger one: its candidates ran on where they used to stop)
            self.assembly.max_iterations = MAX_ITERATIONS
        #: what the controller carries from one step to the next (the compiled loop updates it too)
        self.memory = Memory.empty(self.N, self.n_legs)
        self.stats = ControllerStats()

    @property
    def z_prev(self) -> np.ndarray | None:
        """The previous step's moves (scaled, N n_legs), None before the first step."""
        return self.memory.z_prev if self.memory.flags[Memory.HAVE_PREV] else None

    @property
    def y_nom(self) -> np.ndarray | None:
        """Nominal poses (N, 3) of the leg linearisation (the previous prediction, shifted), or None."""
        return self.memory.y_nom if self.memory.flags[Memory.HAVE_PREV] else None

    @property
    def u_prev(self) -> np.ndarray:
        """The forces applied over the previous sample [N] (zero before the start: at rest)."""
        return self.memory.u_prev

    def guess(self) -> np.ndarray:
        """The guessed move of the offset [N]: the previous solution's move of sample 1 (its
        first move after the shift), zero at the first step."""
        m = self.n_legs
        if self.z_prev is None:
            return np.zeros(m)
        b = min(1, self.N - 1)
        return self.z_prev[b * m:(b + 1) * m] * self.constraints.forces.umax

    def warm_start(self) -> np.ndarray | None:
        """The previous solution's moves shifted by one sample (the last move repeated), or None."""
        mem = self.memory
        return mem.warm[6 * self.N:].copy() if mem.flags[Memory.HAVE_WARM] else None

    def __call__(self, k: int, x: np.ndarray, Ad: np.ndarray, Bd: np.ndarray) -> np.ndarray:
        t0 = time.perf_counter()
        stats, asm, mem = self.stats, self.assembly, self.memory
        if mem.flags[Memory.HAVE_PRED]:  # how far the plant landed from the prediction
            p = mem.x1_pred
            stats.mismatch_m = max(stats.mismatch_m, math.hypot(x[0] - p[0], x[1] - p[1]))
            stats.mismatch_rad = max(stats.mismatch_rad, abs(float(x[2] - p[2])))
        if isinstance(asm, CompiledAssembly):  # the whole step in one compiled call
            warm = mem.warm if mem.flags[Memory.HAVE_WARM] else None
            out = asm.step(k, x, Ad, Bd, self.y_nom, self.u_prev, self.guess(), warm, (REFINE_TOL_M, REFINE_TOL_RAD),
                           REFINE_MAX)
            if out.status == SOLVED:
                stats.iterations.append(out.iterations)
                stats.refinements += out.refinements
                stats.relaxed += out.relaxed
                stats.violation_max_m = max(stats.violation_max_m, out.violation * ROW_UNIT_M)
                mem.remember(out.z, out.X, out.y_nom, self.constraints.forces.umax, out.Y)
                stats.solve_s += time.perf_counter() - t0
                return mem.u_prev
            if self.abandon:
                raise self.infeasible_error(f"at t = {k * self.st.Ts:.3f} s the step's QP is infeasible")
            stats.fallbacks += 1
            # the compiled step proved the QP infeasible with its rows widened by RELAX_M at the
            # guessed move's offset (no refinement), which is the QP built below: DAQP is not
            # asked the same question twice (issue 31: 2 of a fallback's 3 hard solves)
            proved = out.status == INFEASIBLE and out.relaxed and out.refinements == 0
        else:
            proved = False
        qp = asm.build(k, x, Ad, Bd, self.y_nom, self.u_prev, self.guess())
        start = self.warm_start()
        # with a work bound each DAQP solve of the step gets the iterations that what is left
        # pays for, or the step's floor (a small QP is solved whatever the plan used): users
        # case 7 (6 legs, N 100, Ts 1 ms) had used 1.68 CPU s of its 1.55 when its step at t =
        # 0.766 s came here, and three hard solves took 1.6 s more, none to a verdict
        left = self.bound.for_step() if self.bound is not None else None
        nz = self.N * self.n_legs

        def limit() -> int | None:
            """DAQP's iteration limit of the next hard solve (None: its own)."""
            if left is None or small_solve(qp.rows.n_hard + nz, nz, HARD_ITER_LIMIT):
                return None
            return daqp_iterations(left(), qp.rows.n_hard + nz, nz, HARD_ITER_LIMIT)

        sol = QPSolution(np.zeros(0), INFEASIBLE, 0) if proved else asm.solve(qp, start, limit())
        iterations = sol.iterations
        if not sol.ok:  # as the compiled step: once more with the rows widened by RELAX_M
            asm.relax(qp)
            sol = QPSolution(np.zeros(0), INFEASIBLE, 0) if proved else asm.solve(qp, start, limit())
            iterations += sol.iterations
            # the relaxed hard QP found infeasible (by the compiled dual method, or DAQP's verdict)
            proved = proved or sol.flag == INFEASIBLE
            if not sol.ok:
                # the speed rows (leg speeds, arrival) by RELAX_M more: what the slack problem
                # accepts as a numerical failure (slack <= RELAX_M, _slack_step) at a twentieth
                # of its cost (issue 31: at Ts 1 ms the arrival rows of the last samples before
                # the end point, infeasible by 1e-8 m/s, took 0.6 s a step on the slack problem)
                asm.relax(qp, RowKind.SPEED)
                sol = asm.solve(qp, start, limit())
                iterations += sol.iterations
            stats.relaxed += 1 if sol.ok else 0
        # while the plant under the solution's first move lands farther from the prediction
        # than the tolerance, recompute the offset at that move and solve again
        for _ in range(REFINE_MAX):
            if not sol.ok:
                break
            u1 = self.constraints.forces.forces(sol.z)
            x1, e_m, e_rad = asm.one_step_error(qp, u1)
            if e_m <= REFINE_TOL_M and e_rad <= REFINE_TOL_RAD:
                break
            asm.set_offset(qp, u1, x1)
            sol = asm.solve(qp, sol.z)
            iterations += sol.iterations
            stats.refinements += 1
        if sol.ok:
            z, hard = sol.z, sol
            # how well the solver met the rows it was given (m, m/s, rad)
            stats.violation_max_m = max(stats.violation_max_m, float(asm.violation(qp, sol) * ROW_UNIT_M))
        else:
            rows = qp.rows  # the arrival rows: the speed rows before the legs' (the registry's row order)
            arrival = (rows.kinds == RowKind.SPEED) & (np.arange(rows.n_rows) < rows.speed0)
            z, slack_iterations = self._slack_step(k, asm.dense(qp), arrival, proved, left)
            hard = None
            iterations += slack_iterations
        stats.iterations.append(iterations)
        z, Xp, y_nom = asm.finish(qp, z, hard)
        self._clip_first_rates(z)
        mem.remember(z, Xp, y_nom, self.constraints.forces.umax)
        stats.solve_s += time.perf_counter() - t0
        return mem.u_prev

    def snapshot(self) -> tuple[Memory, ControllerStats]:
        """Copies of the memory and the statistics (to resume from, :meth:`restore`)."""
        mem = self.memory
        copy = Memory(mem.z_prev.copy(), mem.y_nom.copy(), mem.u_prev.copy(), mem.warm.copy(), mem.x1_pred.copy(),
                      mem.flags.copy())
        return copy, dataclasses.replace(self.stats, iterations=list(self.stats.iterations))

    def restore(self, memory: Memory, stats: ControllerStats) -> None:
        """Continue from a :meth:`snapshot` (into this controller's own arrays)."""
        mem = self.memory
        for name in ("z_prev", "y_nom", "u_prev", "warm", "x1_pred", "flags"):
            getattr(mem, name)[...] = getattr(memory, name)
        self.stats = dataclasses.replace(stats, iterations=list(stats.iterations))
        if isinstance(self.assembly, CompiledAssembly) and self.assembly.proof.size:
            self.assembly.proof[0] = 0  # the last proof was of another step: the next step solves all its rows

    def loop_arguments(self, max_steps: int) -> tuple[tuple, LoopRecord] | None:
        """For :func:`planner.orchestrator.kernels.simulate_constrained`: its arguments from
        ``z_prev`` on (the memory, the record, the step's constants) and the record, or None
        (reference backend, or switched off)."""
        asm = self.assembly
        if not (self.compiled_loop and isinstance(asm, CompiledAssembly)):
            return None
        mem, stats = self.memory, self.stats
        record = LoopRecord(np.zeros(max_steps, np.int64), np.zeros(2, np.int64),
                            np.array([stats.violation_max_m, stats.mismatch_m, stats.mismatch_rad]))
        args = (mem.z_prev, mem.y_nom, mem.u_prev, mem.warm, mem.x1_pred, mem.flags, record.iterations,
                record.counts, record.worst, *asm.step_constants((REFINE_TOL_M, REFINE_TOL_RAD), REFINE_MAX))
        return args, record

    def absorb(self, record: LoopRecord, k0: int, k1: int, seconds: float) -> None:
        """Add the compiled loop's steps ``k0..k1-1`` (and its time) to the statistics."""
        stats = self.stats
        stats.iterations.extend(int(i) for i in record.iterations[k0:k1])
        stats.refinements += int(record.counts[0])
        stats.relaxed += int(record.counts[1])
        record.counts[:] = 0
        stats.violation_max_m, stats.mismatch_m, stats.mismatch_rad = (float(v) for v in record.worst)
        stats.solve_s += seconds

    def infeasible_error(self, what: str, also: str = "") -> PlannerError:
        """``PlannerError("infeasible")`` saying ``what`` and the remedy: where consecutive
        segments do not touch (:func:`~planner.corridor.geometry.corridor_gaps`) that is the
        cause, which more time does not cure, and the error names the segment; otherwise the
        orchestrator adds the advice it checked (more time). ``also``: a further remedy."""
        gaps = self.gaps
        if gaps:
            g = gaps[0]
            return PlannerError("infeasible", f"{what}: {g.describe()}; the robot would have to jump between them "
                                "within one sample, which no timing allows: connect or widen the segments"
                                + (f", or {also}" if also else ""), f"segments[{g.index + 1}]")
        return PlannerError("infeasible", what + (f"; {also}" if also else ""), "settings")

    def _clip_first_rates(self, z: np.ndarray) -> None:
        """The applied (first) moves ``z[:m]`` clipped, in place, to the force-rate limit of
        the force just applied: a relaxed solve may use its rows' widening by ``RELAX_M`` of
        force_max (6e-4 of a 20 N/s x 0.01 s step), a solve its tolerance (issue 31). The
        compiled twin: ``step_kernels.clip_first_rates``."""
        rate = self.constraints.rate.step
        if rate is not None:
            m, umax = self.n_legs, self.constraints.forces.umax
            z[:m] = np.minimum(np.maximum(z[:m], (self.memory.u_prev - rate) / umax),
                               (self.memory.u_prev + rate) / umax)

    def _previous_plan(self, zmax: np.ndarray) -> np.ndarray:
        """The previous step's moves shifted by one sample (zero before the first), the first
        kept within the force-rate limit of the force just applied and all within ``zmax``:
        what a step applies when not even its slack problem could be solved."""
        mem, m = self.memory, self.n_legs
        z = mem.warm[6 * self.N:].copy() if mem.flags[Memory.HAVE_WARM] else np.zeros(len(zmax))
        rate = self.constraints.rate.step
        if rate is not None:
            z0 = mem.u_prev / self.constraints.forces.umax
            z[:m] = np.clip(z[:m], z0 - rate / self.constraints.forces.umax, z0 + rate / self.constraints.forces.umax)
        return np.clip(z, -zmax, zmax)

    def _slack_step(self, k: int, dense: DenseQP, arrival: np.ndarray, proved: bool = True,
                    work: Callable[[], float] | None = None) -> tuple[np.ndarray, int]:
        """The step's moves from the slack problem (``arrival``: the mask of the arrival rows,
        softened apart) and its iterations; counts the step and its slack, raises
        ``infeasible`` with ``require_settled`` or past :attr:`slack_steps`. ``proved``: the
        step's hard QP, its rows widened by ``RELAX_M``, was found infeasible (not left unsolved
        at the work bound); what the refusal says where :attr:`bound` stops the slack problem.
        ``work``: the work the step has left [s] (:meth:`WorkBound.for_step`)."""
        nz = len(dense.f)
        stats = self.stats
        left = self.slack_iterations - stats.slack_iterations
        if not self.st.require_settled and (stats.infeasible >= self.slack_steps or left <= 0):
            # a slack step costs 100-3000x a compiled step: their work is bounded (the work
            # estimate counts it), the plan stops here with what they found so far
            spent = (f"{self.slack_steps} steps" if stats.infeasible >= self.slack_steps
                     else f"{self.slack_iterations} iterations of its slack problems ({stats.infeasible} steps)")
            raise self.infeasible_error(
                f"with settings.require_settled false a plan may take {self.slack_steps} steps that cannot keep the "
                f"corridor and {self.slack_iterations} slack-problem iterations (the work estimate's bound: each such "
                f"step costs 100x a normal one or more); this plan took {spent} from t = "
                f"{stats.first_infeasible_s:.3f} s and stops at t = {k * self.st.Ts:.3f} s (segment "
                f"{int(self.seq.segment[min(k, self.seq.K - 1)])}; "
                f"{_slack_words(stats.failures < stats.infeasible, stats.slack_max_m, stats.speed_slack_max_m_s)})")
        bound = self.bound
        sol = dense.solve_slack(arrival, None if self.st.require_settled else int(min(left, SLACK_ITER_LIMIT)),
                                self.warm_start(), None if bound is None else work)
        stats.slack_iterations += sol.iterations
        if bound is not None and sol.flag == WORK_BOUND_FLAG:
            # stopped at the request's work bound: the refusal says what was proved, no figure
            stats.failures += 1
            stats.infeasible += 1
            if stats.infeasible == 1:
                stats.first_infeasible_s = k * self.st.Ts
            where = f"at t = {k * self.st.Ts:.3f} s (segment {int(self.seq.segment[min(k, self.seq.K - 1)])})"
            what = (f"{where} the robot cannot keep the corridor within its drive limits (its QP, rows widened by "
                    f"{RELAX_M * 1e6:g} um, has no solution with the drive forces and force rates held; by how much "
                    f"the corridor would be left was not computed within {bound.words()})" if proved else
                    f"{where} the step's QP was not solved within {bound.words()}: whether the robot can keep the "
                    "corridor there within its drive limits, and by how much it would leave it, was not computed")
            raise self.infeasible_error(what, "set require_settled to false to get the plan with its violations "
                                        "reported")
        zs = sol.z
        if not sol.ok:  # even the slack problem failed: go on with the previous plan's moves
            self.stats.failures += 1
            zs = np.zeros(nz + 4)
            zs[:nz] = self._previous_plan(dense.zmax)
        sl = zs[nz:] * ROW_UNIT_M  # corridor [m], stroke [m], leg speed [m/s], arrival speed [m/s]
        slack = float(max(sl[0], sl[1]))
        speed = float(max(sl[2], sl[3]))
        if sol.ok and slack <= RELAX_M and speed <= RELAX_M:
            # a numerical failure, not an infeasible step: DAQP called the hard QP (and the one
            # widened by RELAX_M) infeasible, yet the slack problem meets every row to within
            # RELAX_M, which is what a relaxed solve allows (issue 31: at Ts 1 ms the QPs of the
            # last samples before the end point, 3e-12 m of slack, were reported as infeasible)
            self.stats.relaxed += 1
            self.stats.violation_max_m = max(self.stats.violation_max_m, slack)
            return zs[:nz], sol.iterations
        if stats.infeasible == 0:
            stats.first_infeasible_s = k * self.st.Ts
        self.stats.slack_max_m = max(self.stats.slack_max_m, slack)
        self.stats.speed_slack_max_m_s = max(self.stats.speed_slack_max_m_s, speed)
        self.stats.infeasible += 1
        if self.st.require_settled:  # strict: stop at the first step that cannot keep the corridor
            raise self.infeasible_error(
                f"at t = {k * self.st.Ts:.3f} s (segment {int(self.seq.segment[min(k, self.seq.K - 1)])}) the robot "
                f"cannot keep the corridor within its drive limits ({_slack_words(sol.ok, slack, speed)})",
                "set require_settled to false to get the plan with its violations reported")
        return zs[:nz], sol.iterations

    def report(self) -> dict:
        """The controller's metrics (names as in :class:`planner.schema.Metrics`)."""
        s = self.stats
        it = np.array(s.iterations) if s.iterations else np.zeros(1)
        return {
            "qp_solver": "stagewise" if isinstance(self.assembly, CompiledAssembly) else "daqp",
            "qp_fallbacks": s.fallbacks,
            "qp_relaxed_steps": s.relaxed,
            "qp_iterations_median": float(np.median(it)),
            "qp_iterations_max": int(it.max()),
            "qp_time_ms": s.solve_s * 1e3,
            "qp_failures": s.failures,
            "qp_refinements": s.refinements,
            "infeasible_steps": s.infeasible,
            "constraint_slack_max_m": s.slack_max_m,
            "speed_slack_max_m_s": s.speed_slack_max_m_s,
            "predicted_violation_max_m": s.violation_max_m,
            "model_mismatch_max_m": s.mismatch_m,
            "model_mismatch_max_rad": s.mismatch_rad,
        }


def _slack_words(solved: bool, slack_m: float, speed_m_s: float) -> str:
    """What the slack problem of an infeasible step found, in figures that are not zero (a
    figure below 1 nm or 1 nm/s is left out: the rows it softened were not the cause)."""
    if not solved:
        return "its QP has no solution with the drive forces and force rates held, even with the corridor softened"
    parts = []
    if slack_m >= 1e-9:
        parts.append(f"the corridor would be left by {slack_m * 1e3:.3g} mm" if slack_m >= 1e-3
                     else f"the corridor would be left by {slack_m * 1e6:.3g} um")
    if speed_m_s >= 1e-9:
        parts.append(f"a leg, the tool or the arrival would be {speed_m_s * 1e3:.3g} mm/s too fast")
    return "; ".join(parts) if parts else "its QP is infeasible by less than 1 nm, a numerical failure"
