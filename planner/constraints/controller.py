"""Constrained range-space predictive control (``settings.mode = "constrained"``).

Beyond the paper. The paper's criterion (22)-(23) is soft: with equal penalties it pulls the
robot toward the middle of each range and does not keep it inside. This mode keeps the same
criterion and the same model (eq. 8/9, re-linearised every sample) and adds, over the whole
horizon, hard constraints solved as one dense quadratic program per sample with DAQP (a dual
active-set solver; chosen by ``benchmarks/bench_qp.py`` over OSQP, ProxSuite and Clarabel):

* **corridor**: the predicted pose of sample ``j`` lies in that sample's range of the range
  sequence (the time-indexed range, taper included), shrunk by :data:`MARGIN_M` /
  :data:`MARGIN_RAD` on every side that is wide enough; for segments that carry an exact
  convex ``polygon`` (triangles from the segmentation) the polygon's half-planes replace the
  x/y box (mapped by the same per-axis affine taper as the box);
* **drive forces**: ``|u_i| <= force_max_i`` (bounds, always hard: they are physical);
* **leg speeds**: ``|J_l(y0_j) y_dot_j| <= speed_max (1 - SPEED_MARGIN)``, exact in the
  velocity, the Jacobian taken at a nominal pose: the previous step's predicted pose (shifted)
  and, for the first sample, the plant's own next pose under the guessed move;
* **leg strokes**: ``length_min <= l(y0_j) + J_l(y0_j) (y_j - y0_j) <= length_max``
  (linearised the same way). With the corridor hard these rows are implied (every pose of
  every segment is within stroke: ``check_segments``, exact for boxes), so they enter only
  the slack problem, where the corridor is soft; tests check the actual leg lengths;
* **no overshoot**: from the last segment before the end point on, the predicted position
  never passes the end point along the approach direction (half-plane).

Why the time-indexed range and not the union of the current and the next segment: the union
of two cells is not convex in general (an L at a turn), while each time-indexed range is a
convex box (or polygon), and consecutive ranges share an edge, so the robot crosses from one
to the next between two samples. The taper out of the start and onto the end makes the range
sequence start and end at the points, so the same constraints give the terminal condition:
once the samples whose range is the end point enter the horizon, the predicted robot must be
there (to within :data:`END_TOL_M`) for ``samples_per_segment + 1`` samples, i.e. at rest.
A point range in x/y is a corner of its neighbouring cell in many corridors (Table I), so it
is constrained to the box ``end +- END_TOL_M`` intersected with the neighbouring cell shrunk
by the margin: the robot stops within a few micrometres of the end point, inside the cell.

Margins. Constraints hold for the linear prediction; the plant is the nonlinear model. The
model is exact at the current state and re-linearised every sample, but over one sample it
is frozen: the plant lands up to ~2e-8 m and ~4e-7 rad from the prediction on Table I (more
at higher speed). So the first predicted state is corrected by ``d = Phi(x, u0) - Ad x -
Bd u0`` (:meth:`ConstrainedController.first_step_offset`: an RK4 step of the plant under the
guessed move ``u0``, the previous solution's), which leaves the one-step error
``(dPhi/du - Bd)(u - u0)``. After each solve the plant is stepped under the solution's move
``u``; while it lands farther than :data:`REFINE_TOL_M` / :data:`REFINE_TOL_RAD` (1e-3 and 1e-2
of the margins) from the prediction, the offset is recomputed at ``u`` and the QP solved
again (at most :data:`REFINE_MAX` times; 38 re-solves in 240 steps on Table I). The remaining one-step
mismatch (metric ``model_mismatch_max_m``, printed by ``benchmarks/bench_qp.py``) is below
1e-9 m and 1e-8 rad on Table I, far inside the 1 micrometre margin, which therefore keeps the
actual samples inside. Metrics are always computed on the actual (nonlinear) trajectory;
``contained`` is true only if its corridor violation is at most :data:`CONTAIN_TOL_M`.

Speed (issue 6: Table I in ~75 ms against IPOPT's ~10 s). The QP of a step is assembled by
:mod:`planner.constrained_kernels` (compiled; the numpy :meth:`~ConstrainedController.build_numpy`
is the reference), and two reformulations shrink what DAQP is given without changing the
minimiser:

* **equalities eliminated**: a point range (psi = 0 along Table I: one equality per sample)
  is an equality row, which costs DAQP about as much as the rest of the solve together.
  Where a sample has equalities, its move is parametrised on the null space of their one-step
  effect, ``z_i = Z_i w_i + K_i (c_i - C_i Y_i)`` (:func:`~planner.constrained_kernels.reduce_setup`);
  the QP in ``w`` has fewer variables and no equalities, its force bounds become rows;
* **rows screened**: DAQP gets only the rows within :data:`SCREEN_ROWS` of a bound at the
  warm start (and forces within :data:`SCREEN_FORCE` of ``force_max``); at its solution every
  row is checked, and a violated one is added and the QP solved again (1 of 240 steps on
  Table I). A solution of fewer rows that meets all rows solves the whole QP.

Infeasibility. If the QP has no solution (e.g. limits too tight for the requested time),
the step is solved again with the corridor, stroke and speed rows softened by three slack
variables (corridor m, stroke m, leg speed m/s) with a large quadratic + linear penalty;
forces stay hard. With ``settings.require_settled`` (default) the plan stops there with
``PlannerError("infeasible")`` (time and slack in the message); otherwise every such step is
counted (``infeasible_steps``), its slack reported (``constraint_slack_max_m``,
``speed_slack_max_m_s``) and :func:`finalize` marks the plan not contained.
"""

from __future__ import annotations

import math
import time
from typing import Any

import daqp
import numpy as np

from ..corridor.geometry import halfplanes
from ..errors import PlannerError
from ..model import kinematics
from ..model.plant import rk4_sample
from . import kernels as ck

#: corridor margin [m]: constraints use each range shrunk by this on every side
MARGIN_M = 1e-6
#: angle margin [rad]
MARGIN_RAD = 1e-6
#: half-size of the box about a point range (end point) in x/y [m]
END_TOL_M = 3e-6
#: half-size of the angle box about a point angle range at the end [rad]
END_TOL_RAD = 3e-6
#: relative margin on the leg speed limit [-]
SPEED_MARGIN = 1e-5
#: a plan is "contained" when its actual corridor violation is at most this [m]
CONTAIN_TOL_M = 1e-9
#: slack below this counts as zero (solver rounding) [m]
SLACK_TOL = 1e-10
#: penalty weights of the slack variables (relative to the scaled criterion, which is O(1))
SLACK_RHO2 = 1e8
SLACK_RHO1 = 1e6
#: rows are scaled so that 1 unit = this many metres before the solver sees them
ROW_UNIT_M = 1e-3

#: re-solve while the plant's next pose under the solution's first move lands farther than
#: this from the QP's prediction of it (position [m], angle [rad]): 1e-3 and 1e-2 of the margins
REFINE_TOL_M = 1e-9
REFINE_TOL_RAD = 1e-8
REFINE_MAX = 3

#: move blocking: the first moves are free, later ones are held over 2 and then 4 samples
MOVE_BLOCKING = False
BLOCK_PLAN = ((6, 1), (8, 2))  # (samples, block length) in order; the rest in blocks of 4


def move_blocks(N: int) -> np.ndarray:
    """Block lengths (sum ``N``) of the moves: :data:`BLOCK_PLAN`, then blocks of 4."""
    out, left = [], N
    for samples, length in BLOCK_PLAN:
        take = min(samples, left)
        while take > 0:
            b = min(length, take)
            out.append(b)
            take -= b
            left -= b
    while left > 0:
        out.append(min(4, left))
        left -= out[-1]
    return np.array(out, int)


#: the solver gets only the rows within this of a bound (row units: mm, mm of stroke, mm/s of
#: leg speed, by row kind: corridor, stroke, speed) at the warm start's prediction, and the
#: equalities; rows violated at its solution by more than SCREEN_TOL are added and it re-solves
SCREEN_ROWS = (1.0, 1.0, 50.0)
SCREEN_TOL = 1e-9
#: with the equalities eliminated the force bounds are rows too: given to the solver where
#: the warm start's force is within this fraction of force_max of the bound
SCREEN_FORCE = 0.2
#: eliminate the equality rows (point ranges) through the dynamics instead of giving them to
#: the solver (compiled path, without move blocking)
ELIMINATE_EQUALITIES = True

DAQP_SETTINGS = dict(primal_tol=1e-9, dual_tol=1e-12, iter_limit=2000)


class PoseSets:
    """The convex set each sample's predicted pose must lie in (see module docstring).

    ``lo``/``hi`` (K, 3): the box per sample 1..K (shrunk); ``hp[j]``: ``(A (h, 2), b (h,))``
    or ``None``, half-planes replacing the x/y box rows of sample ``j`` (0-based index into
    the sequence); ``approach``: ``(d (2,), b)`` with ``d . p <= b`` from sample index
    ``approach_from`` on, or ``None``.
    """

    def __init__(self, seq, segments, S: int):
        K = seq.K
        lo, hi = seq.lower.copy(), seq.upper.copy()
        w = hi - lo
        marg = np.array([MARGIN_M, MARGIN_M, MARGIN_RAD])
        shrink = np.minimum(marg, 0.5 * w)
        lo += shrink
        hi -= shrink
        self.hp = [None] * K
        self.approach = None
        self.approach_from = K
        if segments is not None:
            n = len(segments)
            boxes = [(s.lower[:2], s.upper[:2]) for s in segments]
            for j in range(K):
                si = int(seq.segment[j])
                seg = segments[si]
                # x/y point range near the end: tiny box intersected with a neighbouring cell
                if np.all(w[j, :2] <= 2 * MARGIN_M) and si >= n - 2:
                    p = 0.5 * (seq.lower[j, :2] + seq.upper[j, :2])
                    for h in (si, si - 1, si + 1, n - 2):
                        if 0 <= h < n and not segments[h].is_point:
                            blo, bhi = boxes[h][0] + MARGIN_M, boxes[h][1] - MARGIN_M
                            if np.all(blo - END_TOL_M <= p) and np.all(p <= bhi + END_TOL_M):
                                lo[j, :2] = np.maximum(p - END_TOL_M, blo)
                                hi[j, :2] = np.minimum(p + END_TOL_M, bhi)
                                # a point angle too: an equality on psi at every sample
                                # cannot damp a residual rotation (with one constant move per
                                # sample the rate only flips sign), so give it the same kind
                                # of box inside the cell's angle range where there is room
                                q = seq.lower[j, 2]
                                plo = segments[h].lower[2] + MARGIN_RAD
                                phi_ = segments[h].upper[2] - MARGIN_RAD
                                if w[j, 2] <= 2 * MARGIN_RAD and phi_ > plo and \
                                        plo - END_TOL_RAD <= q <= phi_ + END_TOL_RAD:
                                    lo[j, 2] = max(q - END_TOL_RAD, plo)
                                    hi[j, 2] = min(q + END_TOL_RAD, phi_)
                                break
                poly = getattr(seg, "polygon", None)
                if poly is not None and not seg.is_point:
                    sw = seg.upper[:2] - seg.lower[:2]
                    if np.all(sw > 0) and np.all(w[j, :2] > 4 * MARGIN_M):
                        # the same per-axis affine map that tapers the box
                        V = seq.lower[j, :2] + (np.asarray(poly, float) - seg.lower[:2]) * (w[j, :2] / sw)
                        A, b = halfplanes(V)
                        self.hp[j] = (A, b - MARGIN_M)
            if n >= 3 and segments[-1].is_point:
                d = segments[-1].centre[:2] - segments[-2].centre[:2]
                nd = float(np.hypot(*d))
                if nd > 1e-12:
                    d = d / nd
                    self.approach = (d, float(d @ segments[-1].centre[:2]))
                    self.approach_from = max((n - 2) * S - 1, 0)
        self.lo, self.hi = lo, hi
        self.has_hp = np.array([h is not None for h in self.hp], bool)
        # the half-planes flattened for the compiled assembly: those of sequence index s
        # are hp_A[hp_ptr[s]:hp_ptr[s + 1]]
        counts = [0 if h is None else len(h[1]) for h in self.hp]
        self.hp_ptr = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
        self.hp_A = np.ascontiguousarray(np.vstack([h[0] for h in self.hp if h is not None] or [np.zeros((0, 2))]),
                                         dtype=float)
        self.hp_b = np.concatenate([h[1] for h in self.hp if h is not None] or [np.zeros(0)]).astype(float)


class ConstrainedController:
    """Receding-horizon controller with hard constraints (see module docstring).

    Called as ``controller(k, x, Ad, Bd) -> u`` by :func:`planner.plan.simulate`;
    :meth:`report` returns its metrics.
    """

    def __init__(self, robot, seq, st, segments=None):
        self.robot, self.seq, self.st = robot, seq, st
        #: the step's QP assembled and solved by the compiled path (equalities eliminated,
        #: rows screened); False (``backend: "reference"``): by the numpy reference (the QP
        #: in ``z`` with every row)
        self.compiled = st.backend == "compiled"
        self.N, self.m = st.N, robot.n_legs
        self.umax = np.asarray(robot.force_max, float)
        self.sets = PoseSets(seq, segments, st.samples_per_segment)
        N, m = self.N, self.m
        i, j = np.indices((N, N))
        self._lag = np.where(i >= j, i - j, N)
        self.blocks = move_blocks(N) if MOVE_BLOCKING else np.ones(N, int)
        nb = len(self.blocks)
        self._block_of = np.repeat(np.arange(nb), self.blocks)  # block index per sample
        self._starts = np.concatenate(([0], np.cumsum(self.blocks)[:-1]))
        self.nz = nb * m
        # constrained samples: every sample up to the end of the first held block, then the
        # last sample of each block (a move held over several samples cannot meet equality
        # ranges, e.g. psi = const, at all of them; the near samples, which the plant
        # actually visits, are all constrained)
        ends = np.cumsum(self.blocks) - 1
        first_held = int(np.argmax(self.blocks > 1)) if np.any(self.blocks > 1) else nb
        self._con = np.unique(np.concatenate((np.arange(self._starts[first_held] if first_held < nb else N),
                                              ends)))
        self._z_prev = None  # previous scaled solution (nb m,)
        self._y_nom = None  # nominal poses (N, 3) for the leg linearisation
        self.stats = {"steps": 0, "iterations": [], "slack": [], "solve_s": 0.0, "infeasible": 0,
                      "pred_violation": 0.0, "fail": 0, "refines": 0, "screen_resolves": 0,
                      "mismatch_m": 0.0, "mismatch_rad": 0.0, "speed_slack": 0.0}
        self._x1_pred = None
        self.last_qp = None  # the last QP, for benchmarks
        self.correct = True  # one-step nonlinear correction (benchmarks switch it off to compare)
        self._rb = robot.packed
        self._r0 = np.ascontiguousarray(robot.r0, dtype=float)
        self._base = np.ascontiguousarray(robot.base, dtype=float)
        self._lmin = np.ascontiguousarray(robot.length_min, dtype=float)
        self._lmax = np.ascontiguousarray(robot.length_max, dtype=float)
        self._vmax = np.ascontiguousarray(robot.speed_max * (1.0 - SPEED_MARGIN), dtype=float)
        self._screen = np.array(SCREEN_ROWS, float)
        self._du_leg = np.ascontiguousarray((np.asarray(seq.qu, float) * self.umax) ** 2)  # input weight per drive
        self._du = (self.blocks[:, None] * self._du_leg).ravel()  # per column of z (block lengths)
        self._lower = None  # padded range sequence, on first use
        self._no_poses = np.zeros((0, 3))
        self._ncol = (m * (self._block_of + 1)).astype(np.int64)  # columns of Gx non-zero in sample i
        self._con = self._con.astype(np.int64)
        self._block_of = self._block_of.astype(np.int64)
        app = self.sets.approach
        self._app = (app is not None, np.asarray(app[0] if app else np.zeros(2), dtype=float),
                     float(app[1]) if app else 0.0, int(self.sets.approach_from))

    # ---- the QP of one step ---------------------------------------------------------
    def _plant(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The plant's state one sample after ``x`` under the move ``u`` (as the plan loop)."""
        if self.compiled:
            return ck.plant_step(self._rb, x, np.ascontiguousarray(u, dtype=float), self.st.Ts,
                                 self.st.plant_substeps)
        return rk4_sample(self.robot, x, u, self.st.Ts, self.st.plant_substeps)

    def first_step_offset(self, x: np.ndarray, Ad: np.ndarray, Bd: np.ndarray, u0=None, x1=None) -> np.ndarray:
        """``d = Phi(x, u0) - Ad x - Bd u0``: how far the plant's one-sample map ``Phi`` (the
        nonlinear model integrated as the plan loop does) lands from the linear prediction
        under ``u0``, the first move of the previous solution shifted. Adding ``d`` to the
        first predicted state leaves a one-step error ``(dPhi/du - Bd)(u - u0)`` only,
        second order in small quantities (see the module docstring)."""
        if u0 is None:
            if self._z_prev is None:
                u0 = np.zeros(self.m)
            else:  # the previous solution's move of sample 1 (as _shifted_moves()[0])
                b = self._block_of[min(1, self.N - 1)]
                u0 = self._z_prev[b * self.m:(b + 1) * self.m] * self.umax
        self._u0 = u0
        if x1 is None:
            x1 = self._plant(x, u0)
        self._x1 = x1
        self._d = ck.offset(x1, x, u0, Ad, Bd) if self.compiled else x1 - Ad @ x - Bd @ u0
        return self._d

    def build(self, k: int, x: np.ndarray, Ad: np.ndarray, Bd: np.ndarray, u0=None) -> dict:
        """The QP of step ``k`` (see :meth:`build_numpy`), assembled by
        :mod:`planner.constrained_kernels` (or by the numpy reference if not ``compiled``)."""
        if not self.compiled:
            return self.build_numpy(k, x, Ad, Bd, u0)
        seq, sets = self.seq, self.sets
        x = np.ascontiguousarray(x, dtype=float)
        if self._lower is None:  # the range sequence padded as RangeSequence.window does
            pad = lambda a: np.ascontiguousarray(np.concatenate((a, np.repeat(a[-1:], self.N, axis=0))),  # noqa: E731
                                                 dtype=float)
            self._lower, self._upper, self._qa, self._qb = (pad(a) for a in (seq.lower, seq.upper, seq.qa, seq.qb))
        app_on, app_d, app_b, app_from = self._app
        (W, tgt, col, val, b0l, b0u, kinds, n_hard, rs, rl) = ck.assemble(
            self._block_of, k, seq.K, self._lower, self._upper, self._qa, self._qb, self._con, sets.lo, sets.hi,
            sets.has_hp, sets.hp_ptr, sets.hp_A, sets.hp_b, app_on, app_d, app_b, app_from,
            self._y_nom if self._y_nom is not None else self._no_poses, x, self._r0, self._base, self._vmax,
            self._lmin, self._lmax, ROW_UNIT_M)
        qp = {"col": col, "val": val, "b0l": b0l, "b0u": b0u, "kinds": kinds, "n_hard": n_hard,
              "n_bounds": self.nz, "W": W, "tgt": tgt, "x": x, "Ad": Ad, "Bd": Bd,
              "row_speed0": rs, "row_stroke0": rl}
        if ELIMINATE_EQUALITIES and len(self.blocks) == self.N:
            red = ck.reduce_setup(Ad, Bd, self.umax, W, self._du_leg, col, val, b0l, b0u, n_hard, self.N)
            if red[0]:
                qp["red"] = red
        self.set_free(qp, Ad, Bd, u0)
        return qp

    def z_problem(self, qp, with_A: bool = True) -> dict:
        """The step's QP in ``z`` (every row, as :meth:`build_numpy` states it): adds what
        the compiled path has not formed of ``P, Gx, free, f, bl, bu, H, scale`` and ``A``
        to ``qp``, and returns ``qp``."""
        if "Gx" not in qp:
            P, Gx = np.empty((self.N + 1, 6, 6)), np.empty((6 * self.N, self.nz))
            ck.prediction(qp["Ad"], qp["Bd"], self.umax, self._block_of, len(self.blocks), P, Gx)
            qp["P"], qp["Gx"] = P, Gx
        if "free" not in qp:
            qp["free"], qp["f1"], qp["bl"], qp["bu"] = ck.free_parts(
                qp["P"], qp["x"], qp["d"], qp["Gx"], self._ncol, qp["W"], qp["tgt"], qp["col"], qp["val"],
                qp["b0l"], qp["b0u"])
        if "H" not in qp:
            H = np.empty((self.nz, self.nz))
            qp["scale"] = ck.hessian(qp["Ad"], qp["Bd"], self.umax, qp["W"], self._block_of, self._du, H)
            qp["H"] = H
        if "f" not in qp:
            qp["f"] = qp["f1"] * qp["scale"]
        if with_A and "A" not in qp:
            qp["A"] = self.full_matrix(qp)
        return qp

    def build_numpy(self, k: int, x: np.ndarray, Ad: np.ndarray, Bd: np.ndarray, u0=None) -> dict:
        """The condensed QP of step ``k`` in the scaled inputs ``z = u / force_max``::

            min 0.5 z'Hz + f'z   s.t.  -1 <= z <= 1,  bl <= A z <= bu  (rows with bl == bu: equal)

        Every row is a linear function ``Sel`` of the predicted states ``X = free + Gx z``
        (``Sel`` picks a pose coordinate, a half-plane normal, a leg Jacobian row, ...), so
        ``A = Sel Gx`` and the bounds are ``b0 - Sel free``; a refinement of the one-step
        offset only changes ``free`` (see :meth:`set_free`). Rows are in units of
        :data:`ROW_UNIT_M` (m, m/s or rad). ``stroke`` holds the leg-stroke rows, used only
        in the slack problem: with the corridor hard they are implied, since every pose of
        every segment is within stroke (``check_segments``, exact for boxes)."""
        N, m, robot, seq = self.N, self.m, self.robot, self.seq
        P = np.empty((N + 1, 6, 6))
        P[0] = np.eye(6)
        for q in range(1, N + 1):
            P[q] = Ad @ P[q - 1]
        blocks = np.zeros((N + 1, 6, m))
        blocks[:N] = P[:N] @ (Bd * self.umax)
        Gx = blocks[self._lag].transpose(0, 2, 1, 3).reshape(6 * N, N, m)
        if len(self.blocks) < N:
            Gx = np.add.reduceat(Gx, self._starts, axis=1)  # moves held per block
        Gx = Gx.reshape(6 * N, self.nz)
        nzv = self.nz
        lo, hi, qa, qb, qu = seq.window(k, N)
        idx = np.minimum(np.arange(k, k + N), seq.K - 1)
        Gp2 = Gx.reshape(N, 6, nzv)[:, :3].reshape(3 * N, nzv)
        W = (qa * qa + qb * qb).ravel()
        H = (Gp2.T * W) @ Gp2
        H[np.diag_indices(nzv)] += (self.blocks[:, None] * (qu[0] * self.umax) ** 2).ravel()
        scale = 1.0 / max(float(np.max(np.diag(H))), 1e-300)
        H *= scale

        sets = self.sets
        sel_r, sel_c, sel_v, b0l, b0u = [], [], [], [], []
        nrow = 0

        def add(cols, vals, bl_, bu_):  # cols/vals (r, c): c entries per row
            nonlocal nrow
            r = cols.shape[0]
            sel_r.append(np.repeat(np.arange(nrow, nrow + r), cols.shape[1]))
            sel_c.append(cols.ravel())
            sel_v.append(vals.ravel())
            b0l.append(bl_)
            b0u.append(bu_)
            nrow += r

        plo, phi = sets.lo[idx], sets.hi[idx]
        has_hp = sets.has_hp[idx]
        jj = self._con  # samples that carry constraints (all free moves, then block ends)
        nc = len(jj)
        for ax in range(3):
            sel = jj if ax == 2 else jj[~has_hp[jj]]
            if sel.size:
                add((6 * sel + ax)[:, None], np.ones((sel.size, 1)), plo[sel, ax], phi[sel, ax])
        for j in jj[has_hp[jj]]:
            A_, b_ = sets.hp[idx[j]]
            add(6 * j + np.tile(np.arange(2), (len(b_), 1)), A_, np.full(len(b_), -np.inf), b_)
        if sets.approach is not None:
            sel = jj[idx[jj] >= sets.approach_from]
            if sel.size:
                d, b = sets.approach
                add(6 * sel[:, None] + np.arange(2), np.tile(d, (sel.size, 1)),
                    np.full(sel.size, -np.inf), np.full(sel.size, b))
        # legs, linearised about the nominal poses (the previous step's prediction, shifted)
        y_nom = self._y_nom if self._y_nom is not None else np.tile(x[:3], (N, 1))
        y_nom = y_nom[jj]
        J = kinematics.leg_jacobians(robot, y_nom)  # (nc, n, 3)
        vmax = robot.speed_max * (1.0 - SPEED_MARGIN)
        cols = (6 * jj[:, None, None] + 3 + np.arange(3)) + np.zeros((1, m, 1), int)
        add(cols.reshape(nc * m, 3), J.reshape(nc * m, 3), np.tile(-vmax, nc), np.tile(vmax, nc))
        n_hard = nrow
        off = kinematics.leg_lengths(robot, y_nom) - np.einsum("jia,ja->ji", J, y_nom)
        add((cols - 3).reshape(nc * m, 3), J.reshape(nc * m, 3), (robot.length_min - off).ravel(),
            (robot.length_max - off).ravel())
        Sel = np.zeros((nrow, 6 * N))
        Sel[np.concatenate(sel_r), np.concatenate(sel_c)] = np.concatenate(sel_v)
        Sel /= ROW_UNIT_M
        kinds = np.zeros(nrow, int)
        kinds[n_hard - nc * m:n_hard] = 2
        kinds[n_hard:] = 1
        qp = {"H": H, "A": Sel @ Gx, "Sel": Sel, "b0l": np.concatenate(b0l) / ROW_UNIT_M,
              "b0u": np.concatenate(b0u) / ROW_UNIT_M, "kinds": kinds, "n_hard": n_hard,
              "n_bounds": nzv, "Gx": Gx, "Gp2": Gp2, "W": W,
              "tgt": (qa * qa * lo + qb * qb * hi).ravel(), "scale": scale, "P": P, "x": x,
              "row_speed0": n_hard - nc * m, "row_stroke0": n_hard}
        self.set_free(qp, Ad, Bd, u0)
        return qp

    def set_free(self, qp, Ad, Bd, u0=None, x1=None) -> None:
        """The parts of the QP that depend on the free response (state with ``z = 0``);
        ``x1``: the plant's next state under ``u0`` if known."""
        if not self.compiled:
            return self.set_free_numpy(qp, Ad, Bd, u0, x1)
        x = qp["x"]
        d = self.first_step_offset(x, Ad, Bd, u0, x1) if self.correct else np.zeros(6)
        qp["d"] = d
        if self.correct:
            # the first sample's leg rows at the plant's own next pose under the guessed move
            # (see set_free_numpy)
            ck.first_legs(self._x1, self._r0, self._base, self._lmin, self._lmax, ROW_UNIT_M, qp["row_speed0"],
                          qp["row_stroke0"], qp["val"], qp["b0l"], qp["b0u"])
        for key in ("free", "f1", "bl", "bu", "f", "A"):  # what depends on d or the leg rows
            qp.pop(key, None)
        if "red" in qp:
            _, _, off, ecnt, eax, ceq, K, Z, Acl, L, G, _, scale, _, Bu = qp["red"]
            qp["rzf"], qp["rXf"], qp["rf"], qp["rbl"], qp["rbu"] = ck.reduce_free(
                x, d, qp["Ad"], Bu, ecnt, eax, ceq, K, Z, Acl, L, G, off, qp["W"], qp["tgt"], self._du_leg, scale,
                qp["col"], qp["val"], qp["b0l"], qp["b0u"])
        else:
            self.z_problem(qp, with_A=False)

    def set_free_numpy(self, qp, Ad, Bd, u0=None, x1=None) -> None:
        """:meth:`set_free` in numpy (the reference)."""
        N, P, x = self.N, qp["P"], qp["x"]
        free = P[1:] @ x
        if self.correct:
            free += P[:N] @ self.first_step_offset(x, Ad, Bd, u0, x1)
        if self.correct:
            # the first predicted sample becomes the actual one: take its leg rows at the
            # plant's own next pose under the guessed move (refined with the move)
            y1 = self._x1[:3]
            J0 = kinematics.leg_jacobians(self.robot, y1)[0] / ROW_UNIT_M
            rs, rl, m = qp["row_speed0"], qp["row_stroke0"], self.m
            qp["Sel"][rs:rs + m, 3:6] = J0
            qp["Sel"][rl:rl + m, 0:3] = J0
            qp["A"][rs:rs + m] = J0 @ qp["Gx"][3:6]
            qp["A"][rl:rl + m] = J0 @ qp["Gx"][0:3]
            off0 = (kinematics.leg_lengths(self.robot, y1)[0] - J0 @ y1 * ROW_UNIT_M) / ROW_UNIT_M
            qp["b0l"][rl:rl + m] = self.robot.length_min / ROW_UNIT_M - off0
            qp["b0u"][rl:rl + m] = self.robot.length_max / ROW_UNIT_M - off0
        fr = free.ravel()
        qp["free"] = fr
        fp = free[:, :3].ravel()
        qp["f"] = (qp["Gp2"].T @ (qp["W"] * fp - qp["tgt"])) * qp["scale"]
        sf = qp["Sel"] @ fr
        qp["bl"] = qp["b0l"] - sf
        qp["bu"] = qp["b0u"] - sf

    def _shifted_moves(self) -> np.ndarray:
        """The previous solution's moves per sample (scaled), shifted by one sample (N, m)."""
        assert self._z_prev is not None
        U = self._z_prev.reshape(-1, self.m)[self._block_of]
        return np.vstack((U[1:], U[-1:]))

    def _shifted_start(self) -> np.ndarray:
        """Warm start: the shifted moves averaged over each block."""
        U = self._shifted_moves()
        return (np.add.reduceat(U, self._starts, axis=0) / self.blocks[:, None]).ravel()

    def full_matrix(self, qp) -> np.ndarray:
        """``A = Sel Gx`` of all rows (the compiled path forms only the rows it gives the
        solver; the slack problem and benchmarks need all)."""
        if "A" not in qp:
            self.z_problem(qp, with_A=False)
            A = np.empty((len(qp["b0l"]), qp["n_bounds"]))
            ck.constraint_matrix(qp["col"], qp["val"], qp["Gx"], self._ncol, A)
            return A
        return qp["A"]

    # ---- solving ------------------------------------------------------------------------
    def _start(self, z_start=None):
        if z_start is not None:
            return z_start
        if self._z_prev is not None:
            return ck.shifted_start(self._z_prev, self._block_of, self.blocks, self.m)
        return None

    def _solve_hard(self, qp, z_start=None):
        """The hard QP. Compiled: the solver gets the equalities and the rows near a bound at
        the warm start (:data:`SCREEN_ROWS`); the solution is then checked against every
        row, and a violated row is added and the QP solved again from there. A solution of
        fewer rows that meets all rows is the solution of the whole QP (the same unique
        minimiser), so this changes only the time. Sets ``qp["X"]`` (predicted states) and
        ``qp["viol"]`` (largest row violation, row units)."""
        if not self.compiled:
            return self._solve_hard_numpy(qp, z_start)
        if "red" in qp:
            return self._solve_reduced(qp, z_start)
        self.z_problem(qp, with_A=False)
        nz, nh = qp["n_bounds"], qp["n_hard"]
        start = self._start(z_start)
        X = np.empty(6 * self.N)
        keep = qp.get("keep")
        if keep is None:  # rows near a bound at the warm start's prediction
            ck.predict(qp["Gx"], self._ncol, qp["free"], start if start is not None else np.zeros(nz), X)
            keep = np.zeros(nh, bool)
            ck.screen(qp["col"], qp["val"], qp["b0l"], qp["b0u"], qp["kinds"], nh, X, self._screen, keep)
            qp["keep"] = keep
        kw: dict[str, Any] = dict(DAQP_SETTINGS)
        iters = 0
        while True:
            A, bu, bl, sense = ck.solver_problem(keep, qp["col"], qp["val"], qp["Gx"], self._ncol, qp["bl"],
                                                 qp["bu"], nz)
            if start is not None:
                kw["primal_start"] = start
            z, fval, flag, info = daqp.solve(qp["H"], qp["f"], A, bu, bl, sense, **kw)
            iters += int(info["iterations"])
            if flag < 1:  # fewer rows infeasible: the whole QP is too
                break
            ck.predict(qp["Gx"], self._ncol, qp["free"], z, X)
            worst, added = ck.check_rows(qp["col"], qp["val"], qp["b0l"], qp["b0u"], nh, X, keep, SCREEN_TOL)
            if added == 0:
                qp["X"], qp["viol"] = X, worst
                break
            self.stats["screen_resolves"] += 1
            start = z
        info = dict(info, iterations=iters)
        return z, flag, info

    def _solve_reduced(self, qp, z_start=None):
        """The hard QP with its equalities eliminated (see
        :func:`planner.constrained_kernels.reduce_setup`; the same minimiser), screened and
        checked as in :meth:`_solve_hard`, every row and force bound checked at the
        solution. Returns the moves ``z``."""
        _, _, off, ecnt, eax, ceq, K, Z, _, L, G, Hw, _, elim, Bu = qp["red"]
        N, m, nh = self.N, self.m, qp["n_hard"]
        x, d, Ad = qp["x"], qp["d"], qp["Ad"]
        start = self._start(z_start)
        ws = ck.reduce_start(start, Z, off, m) if start is not None else None
        z, X = np.empty(N * m), np.empty(6 * N)
        keep, keepf = qp.get("rkeep"), qp.get("rkeepf")
        if keep is None:  # rows near a bound at the warm start
            if ws is not None:
                ck.reduce_forward(x, d, Ad, Bu, ecnt, eax, ceq, K, Z, off, ws, z, X)
            else:
                z, X = qp["rzf"], qp["rXf"]
            keep, keepf = np.zeros(nh, bool), np.zeros(N * m, bool)
            ck.reduce_screen(qp["col"], qp["val"], qp["b0l"], qp["b0u"], qp["kinds"], nh, elim, X, z, self._screen,
                             SCREEN_FORCE, keep, keepf)
            qp["rkeep"], qp["rkeepf"] = keep, keepf
            z, X = np.empty(N * m), np.empty(6 * N)
        kw: dict[str, Any] = dict(DAQP_SETTINGS)
        iters = 0
        while True:
            A, bu, bl, sense = ck.reduce_problem(keep, keepf, qp["col"], qp["val"], G, off, L, Z, ecnt, qp["rzf"],
                                                 qp["rbl"], qp["rbu"], m)
            if ws is not None:
                kw["primal_start"] = ws
            w, fval, flag, info = daqp.solve(Hw, qp["rf"], A, bu, bl, sense, **kw)
            iters += int(info["iterations"])
            if flag < 1:  # fewer rows infeasible: the whole QP is too
                z = np.zeros(N * m)
                break
            ck.reduce_forward(x, d, Ad, Bu, ecnt, eax, ceq, K, Z, off, w, z, X)
            worst, added = ck.reduce_check(qp["col"], qp["val"], qp["b0l"], qp["b0u"], nh, elim, X, z, keep, keepf,
                                           SCREEN_TOL)
            if added == 0:
                qp["viol"], qp["X"] = worst, X
                break
            self.stats["screen_resolves"] += 1
            ws = w
        return z, flag, dict(info, iterations=iters)

    def _solve_hard_numpy(self, qp, z_start=None):
        """The hard QP in ``z`` with every row given to DAQP (the reference)."""
        nz, nh = qp["n_bounds"], qp["n_hard"]
        bu = np.concatenate((np.ones(nz), qp["bu"][:nh]))
        bl = np.concatenate((-np.ones(nz), qp["bl"][:nh]))
        sense = np.zeros(len(bu), dtype=np.int32)
        sense[bu - bl <= 0] = 5
        kw: dict[str, Any] = dict(DAQP_SETTINGS)
        if z_start is not None:
            kw["primal_start"] = z_start
        elif self._z_prev is not None:
            kw["primal_start"] = self._shifted_start()
        z, fval, flag, info = daqp.solve(qp["H"], qp["f"], qp["A"][:nh], bu, bl, sense, **kw)
        return z, flag, info

    def _solve_slack(self, qp):
        """All rows (corridor, speed and stroke) softened by three slacks >= 0 (in
        :data:`ROW_UNIT_M`: corridor m and rad, stroke m, speed m/s); forces stay hard."""
        nz = qp["n_bounds"]
        self.z_problem(qp)
        H, f, A, kinds = qp["H"], qp["f"], qp["A"], qp["kinds"]
        ns = 3
        Hs = np.zeros((nz + ns, nz + ns))
        Hs[:nz, :nz] = H
        Hs[nz:, nz:] = np.eye(ns) * SLACK_RHO2
        fs = np.concatenate((f, np.full(ns, SLACK_RHO1)))
        S = np.zeros((len(kinds), ns))
        S[np.arange(len(kinds)), kinds] = 1.0
        # two one-sided rows per two-sided row: A z - s <= bu ; bl <= A z + s
        As = np.vstack((np.hstack((A, -S)), np.hstack((A, S))))
        bu = np.concatenate((qp["bu"], np.full(len(kinds), np.inf)))
        bl = np.concatenate((np.full(len(kinds), -np.inf), qp["bl"]))
        keep = np.isfinite(bu) | np.isfinite(bl)
        As, bu, bl = As[keep], np.where(np.isfinite(bu), bu, 1e30)[keep], np.where(np.isfinite(bl), bl, -1e30)[keep]
        ub = np.concatenate((np.ones(nz), np.full(ns, 1e30), bu))
        lb = np.concatenate((-np.ones(nz), np.zeros(ns), bl))
        z, fval, flag, info = daqp.solve(Hs, fs, As, ub, lb, np.zeros(len(ub), dtype=np.int32), **DAQP_SETTINGS)
        return z, flag, info

    def __call__(self, k: int, x: np.ndarray, Ad: np.ndarray, Bd: np.ndarray) -> np.ndarray:
        t0 = time.perf_counter()
        if self._x1_pred is not None:  # how far the plant landed from the prediction
            p = self._x1_pred
            self.stats["mismatch_m"] = max(self.stats["mismatch_m"], math.hypot(x[0] - p[0], x[1] - p[1]))
            self.stats["mismatch_rad"] = max(self.stats["mismatch_rad"], abs(float(x[2] - p[2])))
        qp = self.build(k, x, Ad, Bd)
        z, flag, info = self._solve_hard(qp)
        iters = int(info["iterations"])
        # while the plant under the solution's first move lands farther from the prediction
        # than the tolerance, recompute the offset at that move and solve again
        for _ in range(REFINE_MAX):
            if flag < 1 or not self.correct:
                break
            u1 = z[:self.m] * self.umax
            if self.compiled:
                x1, e_m, e_rad = ck.one_step_error(self._rb, x, u1, Ad, Bd, self._d, self.st.Ts,
                                                   self.st.plant_substeps)
            else:
                x1 = self._plant(x, u1)
                e = np.abs(x1 - (Ad @ x + Bd @ u1 + self._d))  # plant - predicted first state
                e_m, e_rad = math.hypot(e[0], e[1]), e[2]
            if e_m <= REFINE_TOL_M and e_rad <= REFINE_TOL_RAD:
                break
            self.set_free(qp, Ad, Bd, u1, x1)
            z, flag, info = self._solve_hard(qp, z)
            iters += int(info["iterations"])
            self.stats["refines"] += 1
        self.last_qp = qp
        slack = 0.0
        hard_ok = flag >= 1
        if flag < 1:
            zs, flag2, info2 = self._solve_slack(qp)
            iters += int(info2["iterations"])
            if flag2 < 1:
                self.stats["fail"] += 1
                zs = np.zeros(qp["n_bounds"] + 3)
            z = zs[:qp["n_bounds"]]
            sl = zs[qp["n_bounds"]:] * ROW_UNIT_M  # corridor [m], stroke [m], leg speed [m/s]
            slack = float(max(sl[0], sl[1]))
            self.stats["speed_slack"] = max(self.stats["speed_slack"], float(sl[2]))
            self.stats["infeasible"] += 1
            if self.st.require_settled:  # strict: stop at the first step that cannot keep the corridor
                raise PlannerError(
                    "infeasible",
                    f"at t = {k * self.st.Ts:.3f} s the robot cannot keep the corridor within its drive "
                    f"limits (the corridor needs {slack * 1e3:.4f} mm of slack, the leg speeds "
                    f"{sl[2] * 1e3:.4f} mm/s); give it more time "
                    "(samples_per_segment, speed_m_s, total_time_s), widen the corridor, or set "
                    "require_settled to false to get the plan with its violations reported", "settings")
        else:
            # how well the solver met the rows it was given (m, m/s, rad)
            nh = qp["n_hard"]
            if self.compiled:
                v = qp["viol"] * ROW_UNIT_M
            else:
                r = qp["A"][:nh] @ z
                v = np.maximum(np.maximum(qp["bl"][:nh] - r, r - qp["bu"][:nh]), 0.0).max(initial=0.0) * ROW_UNIT_M
            self.stats["pred_violation"] = max(self.stats["pred_violation"], float(v))
        self.stats["iterations"].append(iters)
        self.stats["slack"].append(slack)
        self.stats["steps"] += 1
        if self.compiled:
            if hard_ok and "red" in qp:  # the reduced solve's own prediction
                X = qp["X"]
            else:
                self.z_problem(qp, with_A=False)
                X = np.empty(6 * self.N)
                ck.predict(qp["Gx"], self._ncol, qp["free"], np.clip(z, -1.0, 1.0), X)
            z, Xp, self._y_nom = ck.finish(z, X)
        else:
            z = np.clip(z, -1.0, 1.0)
            Xp = (qp["Gx"] @ z + qp["free"]).reshape(self.N, 6)
            self._y_nom = np.vstack((Xp[1:, :3], Xp[-1:, :3]))
        self._z_prev = z
        self._x1_pred = Xp[0]
        self.stats["solve_s"] += time.perf_counter() - t0
        return z[:self.m] * self.umax

    def report(self) -> dict:
        s = self.stats
        it = np.array(s["iterations"]) if s["iterations"] else np.zeros(1)
        return {
            "qp_solver": "daqp",
            "qp_iterations_median": float(np.median(it)),
            "qp_iterations_max": int(it.max()),
            "qp_time_ms": s["solve_s"] * 1e3,
            "qp_failures": int(s["fail"]),
            "qp_refinements": int(s["refines"]),
            "infeasible_steps": int(s["infeasible"]),
            "constraint_slack_max_m": float(max(s["slack"], default=0.0)),
            "speed_slack_max_m_s": s["speed_slack"],
            "predicted_violation_max_m": s["pred_violation"],
            "model_mismatch_max_m": s["mismatch_m"],
            "model_mismatch_max_rad": s["mismatch_rad"],
        }
