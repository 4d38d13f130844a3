"""Linear elastic specimen, f = k*d: the reference case for tests and for rig commissioning."""

from __future__ import annotations

import math
from typing import NamedTuple

from sim_actuator.checks import POSITIVE
from sim_actuator.models.base import HysteresisBase, Param, trial_input_error

__all__ = ["Elastic", "ElasticState"]


class ElasticState(NamedTuple):
    """Committed state of an :class:`Elastic` spring (its force is k*d)."""

    d: float


class Elastic(HysteresisBase):
    """Linear spring; path independent, but keeps trial/commit state like every other model."""

    __slots__ = ("k",)

    name = "elastic"
    PARAMS = (Param("k", "stiffness", "force/displacement (e.g. kN/mm)", POSITIVE),)
    STATE = ElasticState

    k: float

    def __init__(self, *, k: float) -> None:
        self._init_params(k=k)
        self._start()

    def _virgin(self) -> tuple[float, ...]:
        return (0.0,)

    def set_trial(self, d: float) -> tuple[float, float]:
        if not math.isfinite(d):
            raise trial_input_error(self.name, d)
        self._trial = (d,)
        return self.k * d, self.k

    @property
    def initial_tangent(self) -> float:
        return self.k

    @property
    def committed(self) -> tuple[float, float]:
        d = self._committed[0]
        return d, self.k * d
