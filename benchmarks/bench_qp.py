"""QP solver comparison for the constrained mode (issues 6 and 17).

Records the real per-step QPs of a constrained plan (Table I by default: every step, with
the warm start the planner gives it), then solves each with every candidate and prints one
table: median and total solve time, median/max iterations, failures (not solved, or a row
violated by more than 1e-9 m), max constraint violation in m (rows in units of ROW_UNIT_M =
1 mm of pose, mm/s of leg speed; force and force-rate bounds in force_max) and the largest
difference of the minimiser from DAQP's (scaled moves, force / force_max).

Candidates:

* **stage-wise** (the planner's, ``planner/constraints/stagewise*.py``): the dual active-set
  method of Goldfarb and Idnani (DAQP's method) on the stage-wise problem, each ``H^-1 n`` a
  Riccati substitution (O(N)) after one factorisation per step; warm-started from the
  previous step's solution (as the planner does) and cold. Its time includes the
  factorisation (the equality elimination and the Riccati recursion): every step is a new
  problem.
* DAQP (dense dual active set; warm and cold), OSQP (ADMM, sparse; warm), ProxSuite ProxQP
  (dense augmented Lagrangian; cold and warm), Clarabel (interior point; no warm start), on
  the QP in ``z`` stated densely (its formation, ~0.2-0.5 ms with the compiled kernels, not
  counted for them).

Not measured: HPIPM (a Riccati-based interior point method, Frison) and qpOASES (a primal
online active-set method, Ferreau) have no wheels on PyPI here. Why neither method was
chosen: an interior point method needs 10-20 Riccati factorisations per QP and cannot use a
warm start, while here most steps need 0-5 active-set changes from the previous solution;
qpOASES's homotopy works on the dense condensed problem (O((N m)^2) per change) and needs
the matrices to stay fixed between solves, which the re-linearised model does not. The dual
active set keeps the exactness DAQP was chosen for (the solution ends on the active rows) at
O(N) per change.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_qp.py [--repeat 3] [--samples 20]

Needs the bench extra: ``pip install -e '.[bench]'``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from planner import plan
from planner.constraints import ROW_UNIT_M, ConstrainedController
from planner.constraints import qp as QP
from planner.constraints import stagewise as sw
from planner.constraints.dual_kernels import dual_solve
from planner.constraints.stagewise_kernels import stage_setup

ROOT = Path(__file__).resolve().parents[1]
TABLE1 = ROOT / "app" / "static" / "examples" / "table1.json"


def record_problems(req: dict) -> tuple[list[dict], object]:
    """Every step's QP of a plan of ``req``: the dense QP in z (every row, as DAQP gets it in
    the Python path) and the stage-wise solver's inputs with its warm start."""
    probs: list[dict] = []
    orig = ConstrainedController.__call__

    def rec(self, k, x, Ad, Bd):
        asm = self.assembly
        mem = self.memory
        qp = asm.build(k, x, Ad, Bd, self.y_nom, self.u_prev.copy(), self.guess())
        dense = asm.dense(qp)
        nh = dense.n_hard
        probs.append({"H": dense.H, "f": dense.f, "A": dense.A[:nh], "bl": dense.lower[:nh],
                      "bu": dense.upper[:nh], "nz": len(dense.f), "zmax": dense.zmax,
                      "z0": self.warm_start(), "qp": qp, "asm": asm,
                      "warm": mem.warm.copy() if mem.flags[1] else None})
        return orig(self, k, x, Ad, Bd)

    ConstrainedController.__call__ = rec
    ConstrainedController.compiled_loop = False
    try:
        res = plan(req)
    finally:
        ConstrainedController.__call__ = orig
        ConstrainedController.compiled_loop = True
    for p in probs:  # DAQP's minimiser, the reference
        z, ok, _ = s_daqp(p, False)
        p["z_daqp"] = z
    return probs, res


def violation_m(p, z) -> float:
    r = p["A"] @ z
    v = np.maximum(np.maximum(p["bl"] - r, r - p["bu"]), 0.0).max(initial=0.0) * ROW_UNIT_M
    vb = np.maximum(np.abs(z) - p["zmax"], 0.0).max(initial=0.0) * ROW_UNIT_M  # force bound, scaled
    return float(max(v, vb))


def objective(p, z) -> float:
    return float(0.5 * z @ p["H"] @ z + p["f"] @ z)


# ---- candidates: each returns (z, ok, iterations) -------------------------------------

def s_stagewise(p, warm):
    """The planner's solver: factorisation and dual active-set solve (compiled)."""
    qp, asm = p["qp"], p["asm"]
    R = qp.rows
    ok, ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu = stage_setup(
        qp.Ad, qp.Bd, asm.umax, asm.du, qp.W, R.col, R.val, R.lower, R.upper, R.n_hard)
    N = len(qp.W) // 3
    Y = np.empty(6 * N + p["nz"])
    w = p["warm"] if warm and p["warm"] is not None else np.zeros(0)
    status, it, _, _ = dual_solve(ecnt, eax, ceq, elim, Kp, Z, L, A, B, S, P, K, C, Bu, asm.du, qp.x, qp.d, qp.tgt,
                                  R.col, R.val, R.lower, R.upper, asm.zmax, R.n_hard, sw.SOLVE_TOL, sw.DEPENDENT_TOL,
                                  sw.WARM_TOL, 2000, w, asm._V, asm._Lm, Y)
    return Y[6 * N:].copy(), status == sw.SOLVED, int(it)


def s_daqp(p, warm):
    import daqp

    bu = np.concatenate((p["zmax"], p["bu"]))
    bl = np.concatenate((-p["zmax"], p["bl"]))
    sense = np.zeros(len(bu), dtype=np.int32)
    sense[bu - bl <= 0] = 5
    kw = dict(QP.DAQP_SETTINGS)
    if warm and p["z0"] is not None:
        kw["primal_start"] = p["z0"]
    z, _, flag, info = daqp.solve(p["H"], p["f"], p["A"], bu, bl, sense, **kw)
    return z, flag == 1, int(info["iterations"])


def s_osqp(p, warm):
    import osqp
    import scipy.sparse as sp

    nz = p["nz"]
    P = sp.triu(sp.csc_matrix(p["H"]), format="csc")
    A = sp.vstack((sp.eye(nz), sp.csc_matrix(p["A"])), format="csc")
    lo = np.concatenate((-p["zmax"], np.maximum(p["bl"], -1e30)))
    up = np.concatenate((p["zmax"], np.minimum(p["bu"], 1e30)))
    s = osqp.OSQP()
    s.setup(P, p["f"], A, lo, up, verbose=False, eps_abs=1e-9, eps_rel=1e-9, max_iter=20000, polishing=True)
    if warm and p["z0"] is not None:
        s.warm_start(x=p["z0"])
    r = s.solve()
    return r.x, r.info.status_val in (1,), int(r.info.iter)


def s_prox(p, warm):
    import proxsuite

    nz = p["nz"]
    eq = p["bu"] - p["bl"] <= 0
    A_eq, b_eq = p["A"][eq], p["bu"][eq]
    Ci, lo, up = p["A"][~eq], p["bl"][~eq], p["bu"][~eq]
    lo = np.maximum(lo, -1e20)
    up = np.minimum(up, 1e20)
    qp = proxsuite.proxqp.dense.QP(nz, int(eq.sum()), int((~eq).sum()), True)
    qp.settings.eps_abs = 1e-9
    qp.settings.eps_rel = 0.0
    qp.settings.max_iter = 10000
    if warm and p["z0"] is not None:
        qp.settings.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START
    qp.init(p["H"], p["f"], A_eq if eq.any() else None, b_eq if eq.any() else None, Ci, lo, up,
            -p["zmax"], p["zmax"])
    if warm and p["z0"] is not None:
        qp.solve(p["z0"], None, None)
    else:
        qp.solve()
    ok = qp.results.info.status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
    return qp.results.x.copy(), ok, int(qp.results.info.iter)


def s_clarabel(p, warm):
    import clarabel
    import scipy.sparse as sp

    nz = p["nz"]
    eq = p["bu"] - p["bl"] <= 0
    A, bl, bu = p["A"], p["bl"], p["bu"]
    ineq = ~eq
    fin_u = ineq & np.isfinite(bu)
    fin_l = ineq & np.isfinite(bl)
    rows = [A[eq], A[fin_u], -A[fin_l], np.eye(nz), -np.eye(nz)]
    b = np.concatenate((bu[eq], bu[fin_u], -bl[fin_l], p["zmax"], p["zmax"]))
    Ac = sp.csc_matrix(np.vstack(rows))
    P = sp.triu(sp.csc_matrix(p["H"]), format="csc")
    cones = ([clarabel.ZeroConeT(int(eq.sum()))] if eq.any() else []) + \
        [clarabel.NonnegativeConeT(int(fin_u.sum() + fin_l.sum() + 2 * nz))]
    st = clarabel.DefaultSettings()
    st.verbose = False
    st.tol_gap_abs = st.tol_gap_rel = 1e-10
    st.tol_feas = 1e-10
    sol = clarabel.DefaultSolver(P, p["f"], Ac, b, cones, st).solve()
    return np.array(sol.x), str(sol.status) == "Solved", int(sol.iterations)


CANDIDATES = [("stage-wise (warm)", s_stagewise, True), ("stage-wise (cold)", s_stagewise, False),
              ("daqp (warm)", s_daqp, True), ("daqp (cold)", s_daqp, False), ("osqp (warm)", s_osqp, True),
              ("proxsuite (warm)", s_prox, True), ("proxsuite (cold)", s_prox, False),
              ("clarabel", s_clarabel, False)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs per problem (the fastest counts)")
    ap.add_argument("--samples", type=int, default=None, help="samples_per_segment (default N = 20)")
    ap.add_argument("--every", type=int, default=1, help="use every n-th recorded problem")
    args = ap.parse_args(argv)
    req = json.loads(TABLE1.read_text())
    req["settings"] = {"mode": "constrained"}
    if args.samples:
        req["settings"]["samples_per_segment"] = args.samples
    probs, res = record_problems(req)
    probs = probs[::args.every]
    mt = res.metrics
    rows = max(len(p["bu"]) for p in probs)
    print(f"Table I, constrained, samples_per_segment={res.settings.samples_per_segment}: "
          f"{len(probs)} QPs ({probs[0]['nz']} variables, {len(probs[0]['bu'])}-{rows} rows)")
    print(f"one-step plant vs prediction mismatch: {mt.model_mismatch_max_m:.2e} m, "
          f"{mt.model_mismatch_max_rad:.2e} rad; actual corridor violation {mt.max_corridor_violation_m:.1e} m")
    print("Rows below: each candidate on every step's QP (the dense ones: the QP in z, every hard row, "
          "equalities as equalities).")
    print()
    hdr = f"{'solver':18s} {'median ms':>10s} {'total ms':>9s} {'iter med':>8s} {'iter max':>8s} " \
          f"{'failures':>8s} {'max viol m':>11s} {'max |dz|':>9s}"
    print(hdr)
    print("-" * len(hdr))
    for name, fn, warm in CANDIDATES:
        times, iters, fails, viol, dz = [], [], 0, 0.0, 0.0
        try:
            for p in probs:
                best = np.inf
                for _ in range(args.repeat):
                    t0 = time.perf_counter()
                    z, ok, it = fn(p, warm)
                    best = min(best, time.perf_counter() - t0)
                times.append(best)
                iters.append(it)
                v = violation_m(p, z) if z is not None and np.all(np.isfinite(z)) else np.inf
                if not ok or v > 1e-9:
                    fails += 1
                viol = max(viol, v)
                dz = max(dz, float(np.abs(z - p["z_daqp"]).max()) if z is not None else np.inf)
        except Exception as exc:  # a candidate missing or broken: say so, keep going
            print(f"{name:18s} error: {exc!r}")
            continue
        print(f"{name:18s} {statistics.median(times) * 1e3:10.3f} {sum(times) * 1e3:9.1f} "
              f"{statistics.median(iters):8.0f} {max(iters):8d} {fails:8d} {viol:11.1e} {dz:9.1e}")
    print()
    print("iterations: the stage-wise solver's substitutions (warm start and active-set changes), DAQP's and the "
          "others' own; max |dz|: largest difference of a minimiser from DAQP's (force / force_max)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
