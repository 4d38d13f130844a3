"""Bilinear kinematic-hardening specimen, bit-for-bit the OpenSees ``Steel01`` material.

Equivalent OpenSees command: ``uniaxialMaterial Steel01 $tag $fy $k0 $alpha`` (default
isotropic-hardening parameters a1 = a3 = 0, a2 = a4 = 55).

Algorithm (after SRC/material/uniaxial/Steel01.cpp, ``determineTrialState``), with
``Esh = alpha*k0`` and everything measured from the last committed state (d_c, f_c, k_c):

* if ``|d - d_c| <= DBL_EPSILON`` the trial state *is* the committed state (f_c, k_c) and the
  committed displacement is kept;
* otherwise ``c = f_c + k0*(d - d_c)`` (elastic predictor) and
  ``f = max(Esh*d - fy*(1-alpha), min(Esh*d + fy*(1-alpha), c))``: the predictor clipped to
  the two hardening bounds ``Esh*d +- fy*(1-alpha)``;
* the tangent is ``k0`` when ``|f - c| < DBL_EPSILON`` (predictor accepted) and ``Esh`` otherwise.

Steel01 also tracks load reversals (CminStrain, CmaxStrain, Cloading) only to scale the two
bounds by the isotropic shifts ``1 + a1*(...)**0.8`` and ``1 + a3*(...)**0.8``. With a1 = a3 = 0
those shifts are exactly 1.0 whatever the history, so the reversal bookkeeping cannot change
force or tangent and is left out; the floating-point operations on the force path are the same
as OpenSees's and in the same order, so results agree to the last bit.
"""

from __future__ import annotations

import math
import sys
from typing import NamedTuple

from sim_actuator.checks import POSITIVE, within
from sim_actuator.models.base import HysteresisBase, Param, trial_input_error

__all__ = ["Bilinear", "BilinearState"]

_DBL_EPSILON = sys.float_info.epsilon  # the C DBL_EPSILON used by Steel01


class BilinearState(NamedTuple):
    """Committed state of a :class:`Bilinear` specimen (Steel01's CStrain, CStress, CTangent)."""

    d: float
    f: float
    k: float


class Bilinear(HysteresisBase):
    """Elastic-perfectly-plastic with kinematic hardening (Steel01 without isotropic terms)."""

    __slots__ = ("_esh", "_fy_one_minus_alpha", "alpha", "fy", "k0")

    name = "bilinear"
    PARAMS = (
        Param("k0", "initial (elastic) stiffness", "force/displacement (e.g. kN/mm)", POSITIVE),
        Param("fy", "yield force", "force (e.g. kN)", POSITIVE),
        Param("alpha", "post-yield to initial stiffness ratio", "-", within(0.0, 1.0)),
    )
    STATE = BilinearState

    k0: float
    fy: float
    alpha: float

    def __init__(self, *, k0: float, fy: float, alpha: float) -> None:
        self._init_params(k0=k0, fy=fy, alpha=alpha)
        self._esh = self.alpha * self.k0
        self._fy_one_minus_alpha = self.fy * (1.0 - self.alpha)
        self._start()

    def _virgin(self) -> tuple[float, ...]:
        return (0.0, 0.0, self.k0)

    @property
    def yield_displacement(self) -> float:
        """dy = fy / k0."""
        return self.fy / self.k0

    def set_trial(self, d: float) -> tuple[float, float]:
        d_c, f_c, k_c = self._committed
        d_step = d - d_c
        if not math.isfinite(d_step):
            raise trial_input_error(self.name, d)
        if abs(d_step) > _DBL_EPSILON:
            c1 = self._esh * d
            predictor = f_c + self.k0 * d_step
            upper = c1 + self._fy_one_minus_alpha
            force = upper if upper < predictor else predictor
            lower = c1 - self._fy_one_minus_alpha
            if lower > force:
                force = lower
            tangent = self.k0 if abs(force - predictor) < _DBL_EPSILON else self._esh
            self._trial = (d, force, tangent)
            return force, tangent
        self._trial = self._committed
        return f_c, k_c

    @property
    def initial_tangent(self) -> float:
        return self.k0
