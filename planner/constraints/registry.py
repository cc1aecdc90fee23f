"""The constrained mode's row constraints, in row order: the one list (:data:`SECTIONS`), and
the compiled assembly of a step's rows generated from it (:func:`assemble`).

Each :class:`Section` names a row constraint (a
:class:`~planner.constraints.rows.RowConstraint`: made for a plan by its ``of``, its numpy
rows, and the typed tuple of arrays its kernels read, ``kernel_args``), the type of that tuple,
its count and fill kernels (:mod:`planner.constraints.kernels`, one signature for all) and
their compile costs. Everything else derives from this list: the composed constraints of a
plan (:class:`~planner.constraints.composed.Constraints`), the sections the compiled assembly
fuses (``compiled.KERNEL_SECTIONS``), the arguments of the compiled step (a tuple of the
sections' typed tuples), the numpy reference's rows, the compile-cost table and the kernel
list of :mod:`planner.orchestrator.compiling`.

Adding a row constraint (as :class:`~planner.constraints.motion.ToolSpeedConstraint` was):

1. its row class, with its numpy rows (the reference), in a module of
   :mod:`planner.constraints` (``motion.py``);
2. its typed tuple and its count and fill kernels in :mod:`planner.constraints.kernels`;
3. its :class:`Section` here, in row order: the hard rows first, the slack-only ones (the
   leg strokes) last.

(and, when users set it, the request field it reads, :mod:`planner.schema.request`).

How the fused kernel is generated: :func:`assemble` takes the sections' tuples as one tuple
(plain tuples: they unbox fastest; :func:`typed_sections`, generated from the list, makes them
the sections' typed tuples again), counts the rows of each (``numba.literal_unroll``: the loop body is compiled once per
section type), allocates them and fills them in order; :func:`section_rows` and
:func:`section_fill` dispatch on the typed tuple's type to the section's kernels
(``numba.extending.overload``, at compile time: no call through a pointer). numba's cache key
is this module's source with the kernels' (``planner._jit.KERNEL_SOURCES``), so a change to
the list recompiles.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numba import literal_unroll, types
from numba.extending import overload

from .._jit import njit
from . import kernels as ck
from .corridor import ArrivalConstraint, CorridorConstraint, EndApproachConstraint
from .drives import DriveForceRateConstraint, LegSpeedConstraint, LegStrokeConstraint
from .motion import ToolSpeedConstraint
from .rows import RowConstraint

__all__ = ["SECTIONS", "Section", "assemble", "compile_costs", "section_fill", "section_of", "section_rows",
           "typed_sections"]


@dataclass(frozen=True)
class Section:
    """One row constraint of the compiled assembly."""

    row_class: type[RowConstraint]  #: the constraint (numpy rows, ``of``, ``kernel_args``)
    args: type[NamedTuple]  #: the type of its ``kernel_args``
    count: Any  #: its count kernel ``count(step, args) -> rows``
    fill: Any  #: its fill kernel ``fill(step, args, col, val, b0l, b0u, kinds, r) -> next row``
    #: own compile time of the count and the fill kernel [CPU s] (``benchmarks/bench_start.py
    #: --profile-compile``; only ratios matter: :mod:`planner.orchestrator.compiling`)
    compile_cost: tuple[float, float]

    @property
    def hard(self) -> bool:
        """Its rows enter the hard QP (else only the slack problem)."""
        return self.row_class.hard


#: the row constraints in row order (hard first; the compiled assembly's order)
SECTIONS: tuple[Section, ...] = (
    Section(CorridorConstraint, ck.CorridorArgs, ck.corridor_count, ck.corridor_fill, (0.32, 0.96)),
    Section(EndApproachConstraint, ck.ApproachArgs, ck.approach_count, ck.approach_fill, (0.19, 0.42)),
    Section(ArrivalConstraint, ck.ArrivalArgs, ck.arrival_count, ck.arrival_fill, (0.13, 0.56)),
    Section(LegSpeedConstraint, ck.LegSpeedArgs, ck.legs_count, ck.speed_fill, (0.1, 0.46)),
    Section(DriveForceRateConstraint, ck.RateArgs, ck.rate_count, ck.rate_fill, (0.1, 0.38)),
    Section(ToolSpeedConstraint, ck.ToolSpeedArgs, ck.tool_speed_count, ck.tool_speed_fill, (0.1, 0.4)),
    Section(LegStrokeConstraint, ck.StrokeArgs, ck.legs_count, ck.stroke_fill, (0.1, 0.4)),
)

if [s.hard for s in SECTIONS] != sorted((s.hard for s in SECTIONS), reverse=True):
    raise AssertionError("registry: the hard sections come first")

_BY_ARGS = {s.args: s for s in SECTIONS}
if len(_BY_ARGS) != len(SECTIONS):
    raise AssertionError("registry: one typed tuple per section")


def _index(row_class: type[RowConstraint]) -> int:
    return next(i for i, s in enumerate(SECTIONS) if s.row_class is row_class)


#: the number of sections whose rows are hard; the sections of sample 0's leg rows (relinearised
#: at the plant's next pose: ``kernels.first_legs``); compile-time constants of :func:`assemble`
N_SECTIONS = len(SECTIONS)
N_HARD = sum(s.hard for s in SECTIONS)
SPEED_SECTION = _index(LegSpeedConstraint)
STROKE_SECTION = _index(LegStrokeConstraint)


def section_of(row_class: type[RowConstraint]) -> Section:
    """The section of a row constraint."""
    return SECTIONS[_index(row_class)]


def compile_costs() -> dict[str, float]:
    """The sections' kernels' own compile times by kernel name [CPU s]."""
    costs: dict[str, float] = {}
    for s in SECTIONS:
        for kernel, cost in zip((s.count, s.fill), s.compile_cost):
            costs[kernel.py_func.__name__] = cost
    return costs


def section_rows(step: ck.RowStep, args: NamedTuple) -> int:
    """The number of rows of the section whose typed tuple is ``args`` (compiled code only)."""
    raise NotImplementedError("called within compiled code only")


def section_fill(step: ck.RowStep, args: NamedTuple, col: np.ndarray, val: np.ndarray, b0l: np.ndarray,
                 b0u: np.ndarray, kinds: np.ndarray, r: int) -> int:
    """Fill the rows of the section whose typed tuple is ``args`` from row ``r`` on (compiled
    code only)."""
    raise NotImplementedError("called within compiled code only")


def _section(args: Any) -> Section:
    """The section whose typed tuple has the numba type ``args`` (at compile time)."""
    cls = getattr(args, "instance_class", None) if isinstance(args, types.BaseNamedTuple) else None
    if cls not in _BY_ARGS:
        raise TypeError(f"not a row constraint's typed tuple: {args}")
    return _BY_ARGS[cls]


# (the typing functions' parameters carry no annotations: numba compares them with the impl's)
@overload(section_rows)
def _section_rows(step, args):  # type: ignore[no-untyped-def]
    count = _section(args).count

    def impl(step, args):  # pragma: no cover - compiled
        return count(step, args)
    return impl


@overload(section_fill)
def _section_fill(step, args, col, val, b0l, b0u, kinds, r):  # type: ignore[no-untyped-def]
    fill = _section(args).fill

    def impl(step, args, col, val, b0l, b0u, kinds, r):  # pragma: no cover - compiled
        return fill(step, args, col, val, b0l, b0u, kinds, r)
    return impl


def typed_sections(plain: tuple) -> tuple:
    """The sections' plain tuples (as the compiled step is given them) as their typed tuples, in
    :data:`SECTIONS` order (compiled code only)."""
    raise NotImplementedError("called within compiled code only")


@overload(typed_sections)
def _typed_sections(plain):  # type: ignore[no-untyped-def]
    # generated: ``return (Args0(*plain[0]), Args1(*plain[1]), ...)`` for the registry's sections
    # (a tuple of plain tuples unboxes 3x faster than one of named tuples: numba's dispatcher
    # types a named tuple in Python, a plain one in C; 1.2 against 3.9 us for the 7 sections)
    if not isinstance(plain, types.BaseTuple) or len(plain) != N_SECTIONS:
        raise TypeError(f"the compiled step takes the {N_SECTIONS} sections' tuples, got {plain}")
    scope = {f"_Args{i}": s.args for i, s in enumerate(SECTIONS)}
    src = "def impl(plain):\n    return (" + "".join(f"_Args{i}(*plain[{i}]), " for i in range(N_SECTIONS)) + ")\n"
    exec(compile(src, f"<{__name__}.typed_sections>", "exec"), scope)
    return scope["impl"]


@njit(cache=True)
def assemble(k, N, x, y_prev, u_prev, unit, K, lower, upper, qa, qb, r0, base, plain_sections):
    """The rows and criterion of step ``k`` in one call (few calls per step: numpy's per-call
    cost dominated these sizes). Inputs: the step (``k``, horizon ``N``, state ``x``, the
    previous step's predicted poses shifted ``y_prev`` (N, 3), empty at the first step: then
    the legs are linearised at ``x``; the forces applied over the previous sample ``u_prev``),
    the row unit, the range sequence padded with ``N`` copies of its last sample (``K``
    samples; ``lower, upper, qa, qb`` as ``RangeSequence.window``), the legs (``r0``,
    ``base``), then ``plain_sections``: the ``kernel_args`` of each section of :data:`SECTIONS`,
    in that order, each as a plain tuple (typed again here: :func:`typed_sections`).

    Returns ``(W, tgt, col, val, b0l, b0u, kinds, n_hard, speed0, stroke0)``: the criterion's
    weights ``W = qa^2 + qb^2`` and targets ``tgt = qa^2 r_a + qb^2 r_b`` of samples
    ``k+1..k+N`` (3N,), the rows, the number of hard rows (the rows after them enter only the
    slack problem) and the first leg-speed and stroke rows (those of sample 0)."""
    sections = typed_sections(plain_sections)
    W, tgt = ck.criterion(k, N, K, lower, upper, qa, qb)
    step = ck.step_context(k, N, x, y_prev, u_prev, unit, K, r0, base)
    nrow = 0
    for sec in literal_unroll(sections):
        nrow += section_rows(step, sec)
    col = np.full((nrow, 3), -1, np.int64)
    val = np.zeros((nrow, 3))
    b0l = np.empty(nrow)
    b0u = np.empty(nrow)
    kinds = np.zeros(nrow, np.int64)
    starts = np.empty(N_SECTIONS + 1, np.int64)
    r = 0
    i = 0
    for sec in literal_unroll(sections):
        starts[i] = r
        r = section_fill(step, sec, col, val, b0l, b0u, kinds, r)
        i += 1
    starts[i] = r
    return W, tgt, col, val, b0l, b0u, kinds, starts[N_HARD], starts[SPEED_SECTION], starts[STROKE_SECTION]
