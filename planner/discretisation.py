"""Zero-order-hold discretisation of the factorised model (paper eq. 9)."""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm


def zoh(A: np.ndarray, B: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (9): ``x(k+1) = Ad x(k) + Bd u(k)`` with ``Ad = expm(A Ts)`` and
    ``Bd = int_0^Ts expm(A t) dt B``, both read off one ``expm`` of the augmented
    matrix ``[[A, B], [0, 0]] Ts`` (Van Loan)."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A * Ts
    M[:n, n:] = B * Ts
    E = expm(M)
    return E[:n, :n], E[:n, n:]
