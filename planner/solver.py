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
  optimality (KKT) conditions of the states, inputs and multipliers, ordered stage by stage,
  form a banded matrix of fixed bandwidth, solved by one banded LU (LAPACK ``gbsv``). Cost
  grows linearly in ``N``. Its solution equals the QR one to rounding (tests check 1e-9).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.linalg import get_lapack_funcs, solve_triangular

from .prediction import prediction_matrices

_gbsv = get_lapack_funcs("gbsv", dtype=np.float64)


def square_root_solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Eqs. (18)-(21): least-squares solution of ``A u = b`` by Householder QR
    (LAPACK ``geqrf``) and back substitution of ``R1 u = c1`` (the paper prints
    ``u = R1^T c1``; it is ``u = R1^-1 c1``)."""
    Q, R1 = np.linalg.qr(A, mode="reduced")
    c1 = Q.T @ b
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
def _kkt_pattern(N: int, n: int, m: int, p: int):
    """Where each value of the stage-wise KKT matrix goes in LAPACK band storage.

    Unknowns ordered per stage ``s = 0..N-1`` as ``[u_s, lam_{s+1}, x_{s+1}]``
    (``nb = m + 2n`` each). Conditions (halved criterion, ``H = C^T (Qa^2 + Qb^2) C``,
    ``q = C^T (Qa^2 ra + Qb^2 rb)``, ``Ru = Qu^2``)::

        Ru_s u_s + Bd^T lam_{s+1}                        = 0
        Bd u_s - x_{s+1} + Ad x_s                         = -Ad x_0 (s = 0), else 0
        H_{s+1} x_{s+1} - lam_{s+1} + Ad^T lam_{s+2}       = q_{s+1}

    Values are gathered from ``v = [Ru (N m m), Bd (n m), Ad (n n), Hpose (N p p), -1]``.
    """
    nb = m + 2 * n
    dim = N * nb
    kl = ku = nb - 1
    s = np.arange(N)[:, None, None]
    rows, cols, src = [], [], []

    def add(r, c, v):
        r, c, v = np.broadcast_arrays(r, c, v)
        rows.append(r.ravel()); cols.append(c.ravel()); src.append(v.ravel())

    off_Ru, off_B = 0, N * m * m
    off_A = off_B + n * m
    off_H = off_A + n * n
    off_m1 = off_H + N * p * p
    a, b = np.arange(m)[None, :, None], np.arange(m)[None, None, :]
    add(s * nb + a, s * nb + b, off_Ru + s * m * m + a * m + b)  # Ru_s
    i, a = np.arange(n)[None, :, None], np.arange(m)[None, None, :]
    lam, u = s * nb + m + i, s * nb + a
    add(lam, u, off_B + i * m + a)  # Bd
    add(u, lam, off_B + i * m + a)  # Bd^T
    k = np.arange(n)
    add(s[:, :, 0] * nb + m + k, s[:, :, 0] * nb + m + n + k, off_m1)  # -I
    add(s[:, :, 0] * nb + m + n + k, s[:, :, 0] * nb + m + k, off_m1)
    c1, c2 = np.arange(p)[None, :, None], np.arange(p)[None, None, :]
    add(s * nb + m + n + c1, s * nb + m + n + c2, off_H + s * p * p + c1 * p + c2)  # H (pose block)
    if N > 1:
        s1 = np.arange(1, N)[:, None, None]
        i, j = np.arange(n)[None, :, None], np.arange(n)[None, None, :]
        lam, xs = s1 * nb + m + i, (s1 - 1) * nb + m + n + j
        add(lam, xs, off_A + i * n + j)  # Ad
        add(xs, lam, off_A + i * n + j)  # Ad^T
    rows, cols, src = (np.concatenate(z) for z in (rows, cols, src))
    flat = (kl + ku + rows - cols) * dim + cols
    x_rows = (np.arange(N)[:, None] * nb + m + n + np.arange(p)).ravel()
    return kl, ku, dim, flat, src, x_rows


def solve_structured(Ad, Bd, C, x0, qa, qb, qu, ra, rb) -> np.ndarray:
    """Same minimiser as :func:`solve_qr`, in ``O(N)``: one banded LU of the stage-wise
    optimality conditions. ``C`` must select the first ``p`` states (``C = [I 0]``), as it
    does for the pose output of eq. (9). Returns the input sequence, shape (N, m)."""
    N, m = qu.shape
    n = Ad.shape[0]
    p = C.shape[0]
    kl, ku, dim, flat, src, x_rows = _kkt_pattern(N, n, m, p)
    qa2, qb2 = qa * qa, qb * qb
    Ru = np.zeros((N, m, m))
    Ru[:, np.arange(m), np.arange(m)] = qu * qu
    H = np.zeros((N, p, p))
    H[:, np.arange(p), np.arange(p)] = qa2 + qb2
    v = np.concatenate((Ru.ravel(), Bd.ravel(), Ad.ravel(), H.ravel(), (-1.0,)))
    ab = np.zeros((2 * kl + ku + 1) * dim)
    ab[flat] = v[src]
    rhs = np.zeros(dim)
    rhs[m:m + n] = -(Ad @ x0)
    rhs[x_rows] = (qa2 * ra + qb2 * rb).ravel()
    _, _, sol, info = _gbsv(kl, ku, ab.reshape(2 * kl + ku + 1, dim), rhs, overwrite_ab=1, overwrite_b=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"banded KKT solve failed (gbsv info {info})")
    return sol.reshape(N, m + 2 * n)[:, :m]


SOLVERS = {"qr": solve_qr, "structured": solve_structured}
