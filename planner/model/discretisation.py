"""Zero-order-hold discretisation of the factorised model (paper eq. 9)."""

from __future__ import annotations

import math

import numpy as np


def zoh(A: np.ndarray, B: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (9): ``x(k+1) = Ad x(k) + Bd u(k)`` with ``Ad = expm(A Ts)`` and
    ``Bd = int_0^Ts expm(A t) dt B``, both read off one ``expm`` of the augmented
    matrix ``[[A, B], [0, 0]] Ts`` (Van Loan)."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A * Ts
    M[:n, n:] = B * Ts
    from scipy.linalg import expm  # loaded on first use: the compiled planner never needs it

    E = expm(M)
    return E[:n, :n], E[:n, n:]


_PHI_NORM_MAX = 0.1  # ||A22 Ts||_1 up to which the truncated series is used
_EYE3 = np.eye(3)
_EYE3_FACT = [np.eye(3) / math.factorial(k) for k in range(40)]  # I / k!


def zoh_factorised(A22: np.ndarray, B2: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (9) for the block structure of eq. (8), ``A = [[0, I], [0, A22]]``, ``B = [[0], [B2]]``.

    The exact zero-order-hold solution is, with ``X = A22 Ts`` and the phi-functions
    ``phi_j(X) = sum_k X^k / (k + j)!``::

        Ad = [[I, Ts phi_1(X)], [0, phi_0(X)]],   Bd = [[Ts^2 phi_2(X) B2], [Ts phi_1(X) B2]]

    (``phi_0 = expm``). ``phi_2`` is summed by Horner's rule to the degree ``d`` whose
    remainder ``||X||^(d+1) / (d+1)!`` is below 1e-17 (typically 5-7: ``A22`` holds friction
    and velocity-product rates of order 1/s), then ``phi_1 = I + X phi_2`` and
    ``phi_0 = I + X phi_1``. Beyond ``||X||_1 = 0.1`` this falls back to :func:`zoh`.
    Same result as :func:`zoh` to rounding (tested), at a fraction of the cost.
    """
    n3 = A22.shape[0]
    X = A22 * Ts
    norm = 3.0 * float(np.abs(X).max())  # >= ||X||_1
    if norm > _PHI_NORM_MAX or n3 != 3:
        A = np.zeros((2 * n3, 2 * n3))
        A[:n3, n3:] = np.eye(n3)
        A[n3:, n3:] = A22
        B = np.vstack((np.zeros_like(B2), B2))
        return zoh(A, B, Ts)
    d, term = 1, norm * norm / 6.0  # remainder bound of phi_2 truncated at degree d
    while term > 1e-17 and d < 35:
        d += 1
        term *= norm / (d + 2)
    phi = _EYE3_FACT[d + 2]
    for k in range(d + 1, 1, -1):
        phi = _EYE3_FACT[k] + X @ phi
    phi2 = phi
    phi1 = _EYE3 + X @ phi2
    Ad = np.zeros((6, 6))
    Ad[:3, :3] = _EYE3
    Ad[:3, 3:] = Ts * phi1
    Ad[3:, 3:] = _EYE3 + X @ phi1
    Bd = np.empty((6, B2.shape[1]))
    Bd[:3] = (Ts * Ts) * (phi2 @ B2)
    Bd[3:] = Ts * (phi1 @ B2)
    return Ad, Bd
