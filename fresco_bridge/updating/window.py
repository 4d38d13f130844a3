"""The paper's sliding sample window with exponential forgetting (Eqs. 1-3).

The window holds the latest ``L`` samples ``(X_1, Y_1) … (X_L, Y_L)`` of the tested element,
``(X_L, Y_L)`` the newest; sample ``i`` weighs ``lambda_i = (1 - mu)/(1 - mu**L) * mu**(L - i)``,
so the weights sum to 1 and the newest dominates (mu = 0.1: 0.9, 0.09, 0.009, …). While fewer
than ``L`` samples exist, ``L`` is the number held (the weights still sum to 1).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .base import UpdaterError

FloatArray = npt.NDArray[np.float64]

__all__ = ["SampleWindow", "forgetting_weights"]


def forgetting_weights(length: int, mu: float) -> FloatArray:
    """lambda_1..lambda_L, oldest first (Eq. 2); they sum to 1 (Eq. 3)."""
    if length < 1:
        raise UpdaterError(f"forgetting window: length must be >= 1, got {length}")
    if not 0.0 < mu < 1.0:
        raise UpdaterError(f"forgetting factor must satisfy 0 < mu < 1, got {mu!r}")
    powers = mu ** np.arange(length - 1, -1, -1, dtype=np.float64)  # mu**(L-i), i = 1..L
    weights: FloatArray = (1.0 - mu) / (1.0 - mu**length) * powers
    return weights


class SampleWindow:
    """The latest ``length`` (input row, target) pairs, oldest first, in a preallocated buffer."""

    __slots__ = ("_n", "_weights", "length", "mu", "x", "y")

    def __init__(self, length: int, n_inputs: int, mu: float) -> None:
        self._weights = forgetting_weights(length, mu)
        self.length = length
        self.mu = mu
        self.x = np.empty((length, n_inputs))
        self.y = np.empty(length)
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def push(self, row: FloatArray, target: float) -> None:
        """Append the newest sample; the oldest leaves once the window is full."""
        if self._n == self.length:
            self.x[:-1] = self.x[1:]
            self.y[:-1] = self.y[1:]
            self._n -= 1
        self.x[self._n] = row
        self.y[self._n] = target
        self._n += 1

    def samples(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(X, Y, lambda) of the samples held, oldest first; lambda sums to 1."""
        n = self._n
        weights = self._weights if n == self.length else forgetting_weights(n, self.mu)
        return self.x[:n], self.y[:n], weights

    def copy(self) -> SampleWindow:
        other = SampleWindow.__new__(SampleWindow)
        other.length, other.mu, other._n = self.length, self.mu, self._n
        other._weights = self._weights
        other.x, other.y = self.x.copy(), self.y.copy()
        return other
