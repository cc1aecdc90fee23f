"""Equations of predictions (paper eqs. 10-11)."""

from __future__ import annotations

import numpy as np


def prediction_matrices(Ad: np.ndarray, Bd: np.ndarray, C: np.ndarray, N: int) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (11): ``y_hat = F x(k) + G u`` over the horizon ``N``, with the model frozen.

    ``F = [C A; C A^2; ...; C A^N]`` (the paper's ``f = F x(k)``) and ``G`` block
    lower-triangular with block ``(i, j) = C A^(i-j) B`` for ``i >= j`` (the paper's printed
    ``G`` is garbled; see notes/method.md). Shapes ``(N p, n)`` and ``(N p, N m)``.
    """
    n, m = Bd.shape
    p = C.shape[0]
    CA = np.empty((N + 1, p, n))  # C A^k, k = 0..N
    CA[0] = C
    for k in range(1, N + 1):
        CA[k] = CA[k - 1] @ Ad
    blocks = np.zeros((N + 1, p, m))  # C A^k B for k = 0..N-1, and a zero block at index N
    blocks[:N] = CA[:N] @ Bd
    i, j = np.indices((N, N))
    lag = np.where(i >= j, i - j, N)
    G = blocks[lag].transpose(0, 2, 1, 3).reshape(N * p, N * m)
    return CA[1:].reshape(N * p, n), G
