"""Linear elastic specimen, f = k*d: the reference case for tests and for rig commissioning."""

from __future__ import annotations

import math

from sim_actuator.models.base import check_positive, trial_input_error

__all__ = ["Elastic"]


class Elastic:
    """Linear spring; path independent, but keeps trial/commit state like every other model."""

    __slots__ = ("_d_c", "_d_t", "k")

    name = "elastic"

    def __init__(self, *, k: float) -> None:
        self.k = check_positive(self.name, "k", k)
        self._d_c = 0.0
        self._d_t = 0.0

    def __repr__(self) -> str:
        return f"Elastic(k={self.k!r})"

    @property
    def parameters(self) -> dict[str, float]:
        """The construction parameters, for rebuilding or reporting."""
        return {"k": self.k}

    def set_trial(self, d: float) -> tuple[float, float]:
        if not math.isfinite(d):
            raise trial_input_error(self.name, d)
        self._d_t = d
        return self.k * d, self.k

    def commit(self) -> None:
        self._d_c = self._d_t

    def revert_to_last_commit(self) -> None:
        self._d_t = self._d_c

    def revert_to_start(self) -> None:
        self._d_c = 0.0
        self._d_t = 0.0

    @property
    def initial_tangent(self) -> float:
        return self.k

    @property
    def committed(self) -> tuple[float, float]:
        return self._d_c, self.k * self._d_c

    def clone(self) -> Elastic:
        twin = Elastic.__new__(Elastic)
        twin.k = self.k
        twin._d_c = self._d_c
        twin._d_t = self._d_t
        return twin
