"""Minimisation of the range-space criterion (paper eqs. 12-23).

The horizon problem at one step, with the model frozen at the current state::

    min_u  sum_{j=1..N} ||Qa_j (y_j - ra_j)||^2 + ||Qb_j (y_j - rb_j)||^2 + ||Qu_j u_{j-1}||^2
    s.t.   x_j = Ad x_{j-1} + Bd u_{j-1},  y_j = C x_j,  x_0 = x(k)

(eq. 22; the tracking criterion (12) is the special case ``ra = w``, ``Qb = 0``). All
penalties are diagonal and may vary over the horizon: ``qa``, ``qb`` have shape ``(N, p)``,
``qu`` shape ``(N, m)``.

Two solvers give the same minimiser:

* :func:`solve_qr` - the paper's route: predictions (11), the stacked square-root system
  (17)/(23) ``[Qa G; Qb G; Qu] u = [Qa (ra - f); Qb (rb - f); 0]``, Householder QR (19)-(20)
  and back substitution ``R1 u = c1`` (21). Cost grows as ``N^3``.
* :func:`solve_structured` - the same problem kept in its stage-wise (sparse) form: the
  inputs are eliminated stage by stage and the optimality (KKT) conditions of the states
  and multipliers, ordered stage by stage, form a banded matrix of fixed bandwidth, solved
  by one banded LU (LAPACK ``gbsv``). Cost grows linearly in ``N``. Its solution equals the QR one to
  rounding (tests check 1e-9).
"""

from __future__ import annotations

from functools import cache, lru_cache
from typing import Any, cast

import numpy as np

from .._jit import kernels_off
from .kernels import riccati
from .prediction import prediction_matrices


@cache
def _gbsv() -> Any:
    """LAPACK ``dgbsv`` (scipy loaded on first use: the compiled planner never needs it)."""
    from scipy.linalg import get_lapack_funcs

    return cast(Any, get_lapack_funcs("gbsv", dtype=np.float64))


def square_root_solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Eqs. (18)-(21): least-squares solution of ``A u = b`` by Householder QR
    (LAPACK ``geqrf``) and back substitution of ``R1 u = c1`` (the paper prints
    ``u = R1^T c1``; it is ``u = R1^-1 c1``)."""
    Q, R1 = np.linalg.qr(A, mode="reduced")
    c1 = Q.T @ b
    from scipy.linalg import solve_triangular  # loaded on first use (the paper's QR solver only)

    return solve_triangular(R1, c1, lower=False, check_finite=False)


def stacked_system(F, G, x0, qa, qb, qu, ra, rb):
    """The square-root system of eq. (23): rows ``[Qa G; Qb G; Qu]``, right side
    ``[Qa (ra - f); Qb (rb - f); 0]``. Rows whose penalty is zero everywhere (the second
    range term in tracking mode) are left out."""
    f = F @ x0
    qa, qb = qa.ravel(), qb.ravel()
    rows = [qa[:, None] * G]
    rhs = [qa * (ra.ravel() - f)]
    if np.any(qb):
        rows.append(qb[:, None] * G)
        rhs.append(qb * (rb.ravel() - f))
    rows.append(np.diag(qu.ravel()))
    rhs.append(np.zeros(qu.size))
    return np.vstack(rows), np.concatenate(rhs)


def solve_qr(Ad, Bd, C, x0, qa, qb, qu, ra, rb) -> np.ndarray:
    """The paper's route (eqs. 11, 17-23). Returns the input sequence, shape (N, m)."""
    N, m = qu.shape
    F, G = prediction_matrices(Ad, Bd, C, N)
    A, b = stacked_system(F, G, x0, qa, qb, qu, ra, rb)
    return square_root_solve(A, b).reshape(N, m)


@lru_cache(maxsize=32)
def _kkt_pattern(N: int, n: int, p: int):
    """Where each value of the stage-wise KKT matrix goes in LAPACK band storage.

    With the halved criterion, ``H = C^T (Qa^2 + Qb^2) C``, ``q = C^T (Qa^2 ra + Qb^2 rb)``
    and ``Ru = Qu^2`` (diagonal, positive), the optimality conditions of
    ``min sum x'Hx - 2q'x + u'Ru u`` subject to ``x_{s+1} = Ad x_s + Bd u_s`` are::

        Ru_s u_s + Bd^T lam_{s+1} = 0                      ->  u_s = -Ru_s^-1 Bd^T lam_{s+1}
        -S_s lam_{s+1} - x_{s+1} + Ad x_s = -Ad x_0 (s = 0), else 0,   S_s = Bd Ru_s^-1 Bd^T
        H_{s+1} x_{s+1} - lam_{s+1} + Ad^T lam_{s+2} = q_{s+1}

    Unknowns ordered per stage ``s = 0..N-1`` as ``[lam_{s+1}, x_{s+1}]`` (2n each): a
    symmetric banded matrix with ``kl = ku = 2n - 1``. Values are gathered from
    ``v = [-S (N n n), Ad (n n), diag(H) pose part (N p), -1]``.
    """
    nb = 2 * n
    dim = N * nb
    kl = ku = nb - 1
    s = np.arange(N)[:, None, None]
    i, j = np.arange(n)[None, :, None], np.arange(n)[None, None, :]
    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    src: list[np.ndarray] = []

    def add(r, c, v):
        r, c, v = np.broadcast_arrays(r, c, v)
        rows.append(r.ravel())
        cols.append(c.ravel())
        src.append(v.ravel())

    off_A = N * n * n
    off_H = off_A + n * n
    off_m1 = off_H + N * p
    add(s * nb + i, s * nb + j, s * n * n + i * n + j)  # -S_s
    k = np.arange(n)[None, :]
    add(s[:, :, 0] * nb + k, s[:, :, 0] * nb + n + k, off_m1)  # -I
    add(s[:, :, 0] * nb + n + k, s[:, :, 0] * nb + k, off_m1)
    c = np.arange(p)[None, :]
    add(s[:, :, 0] * nb + n + c, s[:, :, 0] * nb + n + c, off_H + s[:, :, 0] * p + c)  # H (diagonal, pose)
    if N > 1:
        s1 = np.arange(1, N)[:, None, None]
        lam, xs = s1 * nb + i, (s1 - 1) * nb + n + j
        add(lam, xs, off_A + i * n + j)  # Ad
        add(xs, lam, off_A + i * n + j)  # Ad^T
    row_idx, col_idx, src_idx = (np.concatenate(z) for z in (rows, cols, src))
    flat = (kl + ku + row_idx - col_idx) * dim + col_idx
    x_rows = (np.arange(N)[:, None] * nb + n + np.arange(p)).ravel()
    return kl, ku, dim, flat, src_idx, x_rows


def solve_structured(Ad, Bd, C, x0, qa, qb, qu, ra, rb) -> np.ndarray:
    """Same minimiser as :func:`solve_qr`, in ``O(N)``: the inputs eliminated stage by
    stage, one banded LU (LAPACK ``gbsv``) of the remaining optimality conditions (see
    :func:`_kkt_pattern`). ``C`` must select the first ``p`` states (``C = [I 0]``), as it
    does for the pose output of eq. (9); ``qu`` must be positive. Returns the input
    sequence, shape (N, m)."""
    N, m = qu.shape
    n = Ad.shape[0]
    p = C.shape[0]
    kl, ku, dim, flat, src, x_rows = _kkt_pattern(N, n, p)
    if qu.strides[0] == 0:  # the same Q_u at every stage (a broadcast row): one S_s block
        rinv = 1.0 / (qu[0] * qu[0])
        BRB = np.broadcast_to((Bd * rinv) @ Bd.T, (N, n, n))
    else:
        rinv = 1.0 / (qu * qu)  # Ru^-1, (N, m)
        BRB = (Bd * rinv[:, None, :]) @ Bd.T  # S_s = Bd Ru_s^-1 Bd^T, (N, n, n)
    qa2, qb2 = qa * qa, qb * qb
    v = np.concatenate(((-BRB).ravel(), Ad.ravel(), (qa2 + qb2).ravel(), (-1.0,)))
    ab = np.zeros((2 * kl + ku + 1) * dim)
    ab[flat] = v[src]
    rhs = np.zeros(dim)
    rhs[:n] = -(Ad @ x0)
    rhs[x_rows] = (qa2 * ra + qb2 * rb).ravel()
    _, _, sol, info = _gbsv()(kl, ku, ab.reshape(2 * kl + ku + 1, dim), rhs, overwrite_ab=1, overwrite_b=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"banded KKT solve failed (gbsv info {info})")
    lam = sol.reshape(N, 2 * n)[:, :n]
    return -rinv * (lam @ Bd)


def solve_riccati(Ad, Bd, C, x0, qa, qb, qu, ra, rb) -> np.ndarray:
    """Same minimiser as :func:`solve_qr`, in ``O(N)``, by the compiled backward Riccati
    recursion :func:`planner.horizon.kernels.riccati` (``C = [I 0]``, ``Ad`` with the block structure
    of eq. (9), one ``Q_u`` for the horizon: ``qu[0]`` is used). Returns the input sequence, shape (N, m)."""

    N, m = qu.shape
    if Ad.shape != (6, 6) or C.shape != (3, 6) or np.any(C != np.eye(3, 6)):
        raise ValueError("solve_riccati needs the 6-state model of eq. (9) and C = [I 0] (the pose)")
    if np.any(Ad[:, :3] != np.eye(6, 3)):
        raise ValueError("solve_riccati needs Ad = [[I, *], [0, *]] (the hold of eq. 9)")
    if kernels_off():  # the numpy reference backend: the same minimiser by the banded KKT solve
        return solve_structured(Ad, Bd, C, x0, qa, qb, qu, ra, rb)
    U = np.empty((N, m))
    c = np.ascontiguousarray
    if not riccati(c(Ad), c(Bd), c(x0, dtype=float), c(qa), c(qb), c(qu[0], dtype=float), c(ra), c(rb), U):
        raise np.linalg.LinAlgError("Riccati recursion: Ru + Bd' P Bd is not positive definite")
    return U


SOLVERS = {"qr": solve_qr, "structured": solve_structured, "riccati": solve_riccati}
