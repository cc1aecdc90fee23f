"""QP solver comparison for the constrained mode (issue 6).

Records the real per-step QPs of a constrained plan (Table I by default: the hard problem of
every step, with the warm start the planner gives it), then solves each with every
candidate and prints one table: median and total solve time (setup included: every step is a
new problem), median/max iterations, failures (not solved, or a row violated by more than
1e-9 m), max constraint violation in m (rows are in units of ROW_UNIT_M = 1 mm of pose,
mm/s of leg speed) and the largest objective gap to DAQP's solution (relative).

Candidates: DAQP (dense dual active set; warm and cold), OSQP (ADMM, sparse; warm),
ProxSuite ProxQP (dense augmented Lagrangian; cold and warm), Clarabel (interior point;
no warm start). Tolerances are set as tight as each solver supports sensibly (1e-9 primal).
A last row times the DAQP calls the planner itself makes: the same QPs with the equalities
eliminated and only the rows near a bound (see planner/constrained.py).

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
from planner import constrained as C
from planner.plan import plan

ROOT = Path(__file__).resolve().parents[1]
TABLE1 = ROOT / "static" / "examples" / "table1.json"


def record_problems(req: dict) -> tuple[list[dict], dict, list[dict]]:
    """The hard QP in z of every solve (every row, as the numpy reference states it), and
    the DAQP calls the planner actually makes (equalities eliminated, rows screened)."""
    import daqp

    probs, calls = [], []
    orig = C.ConstrainedController._solve_hard
    orig_daqp = daqp.solve

    def rec(self, qp, z_start=None):
        z, flag, info = orig(self, qp, z_start)
        self.z_problem(qp)
        nz, nh = qp["n_bounds"], qp["n_hard"]
        if z_start is None and self._z_prev is not None:
            z_start = np.concatenate((self._z_prev[self.m:], self._z_prev[-self.m:]))
        probs.append({"H": qp["H"].copy(), "f": qp["f"].copy(), "A": qp["A"][:nh].copy(),
                      "bl": qp["bl"][:nh].copy(), "bu": qp["bu"][:nh].copy(), "nz": nz,
                      "z0": None if z_start is None else z_start.copy(), "z_daqp": z.copy(), "flag": flag})
        return z, flag, info

    def rec_daqp(H, f, A, bu, bl, sense, **kw):
        calls.append({"args": (H.copy(), f.copy(), A.copy(), bu.copy(), bl.copy(), sense.copy()), "kw": dict(kw)})
        return orig_daqp(H, f, A, bu, bl, sense, **kw)

    C.ConstrainedController._solve_hard = rec
    C.daqp.solve = rec_daqp
    try:
        res = plan(req)
    finally:
        C.ConstrainedController._solve_hard = orig
        C.daqp.solve = orig_daqp
    return probs, res, calls


def violation_m(p, z) -> float:
    r = p["A"] @ z
    v = np.maximum(np.maximum(p["bl"] - r, r - p["bu"]), 0.0).max(initial=0.0) * C.ROW_UNIT_M
    vb = np.maximum(np.abs(z) - 1.0, 0.0).max(initial=0.0) * C.ROW_UNIT_M  # force bound, scaled
    return float(max(v, vb))


def objective(p, z) -> float:
    return float(0.5 * z @ p["H"] @ z + p["f"] @ z)


# ---- candidates: each returns (z, ok, iterations) -------------------------------------

def s_daqp(p, warm):
    import daqp

    nz = p["nz"]
    bu = np.concatenate((np.ones(nz), p["bu"]))
    bl = np.concatenate((-np.ones(nz), p["bl"]))
    sense = np.zeros(len(bu), dtype=np.int32)
    sense[bu - bl <= 0] = 5
    kw = dict(C.DAQP_SETTINGS)
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
    lo = np.concatenate((-np.ones(nz), np.maximum(p["bl"], -1e30)))
    up = np.concatenate((np.ones(nz), np.minimum(p["bu"], 1e30)))
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
            -np.ones(nz), np.ones(nz))
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
    b = np.concatenate((bu[eq], bu[fin_u], -bl[fin_l], np.ones(nz), np.ones(nz)))
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


CANDIDATES = [("daqp (warm)", s_daqp, True), ("daqp (cold)", s_daqp, False), ("osqp (warm)", s_osqp, True),
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
    probs, res, calls = record_problems(req)
    probs = probs[::args.every]
    mt = res["metrics"]
    print(f"Table I, constrained, samples_per_segment={res['settings']['samples_per_segment']}: "
          f"{len(probs)} QPs ({probs[0]['nz']} variables, "
          f"{len(probs[0]['bu'])}-{max(len(p['bu']) for p in probs)} rows)")
    print(f"one-step plant vs prediction mismatch: {mt['model_mismatch_max_m']:.2e} m, "
          f"{mt['model_mismatch_max_rad']:.2e} rad; actual corridor violation {mt['max_corridor_violation_m']:.1e} m")
    print("Rows below: each candidate on the whole QP in z (every hard row, equalities as equalities).")
    print()
    hdr = f"{'solver':18s} {'median ms':>10s} {'total ms':>9s} {'iter med':>8s} {'iter max':>8s} " \
          f"{'failures':>8s} {'max viol m':>11s} {'obj gap':>9s}"
    print(hdr)
    print("-" * len(hdr))
    for name, fn, warm in CANDIDATES:
        times, iters, fails, viol, gap = [], [], 0, 0.0, 0.0
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
                o_ref = objective(p, p["z_daqp"])
                gap = max(gap, abs(objective(p, z) - o_ref) / max(abs(o_ref), 1e-12))
        except Exception as exc:  # a candidate missing or broken: say so, keep going
            print(f"{name:18s} error: {exc!r}")
            continue
        print(f"{name:18s} {statistics.median(times) * 1e3:10.3f} {sum(times) * 1e3:9.1f} "
              f"{statistics.median(iters):8.0f} {max(iters):8d} {fails:8d} {viol:11.1e} {gap:9.1e}")
    # the QPs the planner gives DAQP: equalities eliminated (fewer variables, forces as rows),
    # only the rows near a bound (planner/constrained.py); violation and gap are checked by
    # the planner against every row, so only time and iterations here
    import daqp

    times, iters = [], []
    for c in calls:
        best = np.inf
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            _, _, _, info = daqp.solve(*c["args"], **c["kw"])
            best = min(best, time.perf_counter() - t0)
        times.append(best)
        iters.append(int(info["iterations"]))
    nvar = [len(c["args"][1]) for c in calls]
    nrow = [c["args"][2].shape[0] for c in calls]
    print(f"{'daqp (planner)':18s} {statistics.median(times) * 1e3:10.3f} {sum(times) * 1e3:9.1f} "
          f"{statistics.median(iters):8.0f} {max(iters):8d} {'-':>8s} {'-':>11s} {'-':>9s}")
    print(f"  the planner's own {len(calls)} DAQP calls (refinements and re-solves included): "
          f"{statistics.median(nvar):.0f} variables, {statistics.median(nrow):.0f} rows median "
          f"(max {max(nrow)}); equalities eliminated, rows screened")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
