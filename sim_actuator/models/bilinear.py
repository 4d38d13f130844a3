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

from sim_actuator.models.base import check_positive, check_range, trial_input_error

__all__ = ["Bilinear"]

_DBL_EPSILON = sys.float_info.epsilon  # the C DBL_EPSILON used by Steel01


class Bilinear:
    """Elastic-perfectly-plastic with kinematic hardening (Steel01 without isotropic terms)."""

    __slots__ = (
        "_d_c",
        "_d_t",
        "_esh",
        "_f_c",
        "_f_t",
        "_fy_one_minus_alpha",
        "_k_c",
        "_k_t",
        "alpha",
        "fy",
        "k0",
    )

    name = "bilinear"

    def __init__(self, *, k0: float, fy: float, alpha: float) -> None:
        self.k0 = check_positive(self.name, "k0", k0)
        self.fy = check_positive(self.name, "fy", fy)
        self.alpha = check_range(self.name, "alpha", alpha, 0.0, 1.0)
        self._esh = self.alpha * self.k0
        self._fy_one_minus_alpha = self.fy * (1.0 - self.alpha)
        self._d_c = self._d_t = 0.0
        self._f_c = self._f_t = 0.0
        self._k_c = self._k_t = self.k0

    def __repr__(self) -> str:
        return f"Bilinear(k0={self.k0!r}, fy={self.fy!r}, alpha={self.alpha!r})"

    @property
    def parameters(self) -> dict[str, float]:
        """The construction parameters, for rebuilding or reporting."""
        return {"k0": self.k0, "fy": self.fy, "alpha": self.alpha}

    @property
    def yield_displacement(self) -> float:
        """dy = fy / k0."""
        return self.fy / self.k0

    def set_trial(self, d: float) -> tuple[float, float]:
        d_step = d - self._d_c
        if not math.isfinite(d_step):
            raise trial_input_error(self.name, d)
        if abs(d_step) > _DBL_EPSILON:
            c1 = self._esh * d
            predictor = self._f_c + self.k0 * d_step
            upper = c1 + self._fy_one_minus_alpha
            force = upper if upper < predictor else predictor
            lower = c1 - self._fy_one_minus_alpha
            if lower > force:
                force = lower
            tangent = self.k0 if abs(force - predictor) < _DBL_EPSILON else self._esh
            self._d_t = d
            self._f_t = force
            self._k_t = tangent
            return force, tangent
        self._d_t = self._d_c
        self._f_t = self._f_c
        self._k_t = self._k_c
        return self._f_c, self._k_c

    def commit(self) -> None:
        self._d_c = self._d_t
        self._f_c = self._f_t
        self._k_c = self._k_t

    def revert_to_last_commit(self) -> None:
        self._d_t = self._d_c
        self._f_t = self._f_c
        self._k_t = self._k_c

    def revert_to_start(self) -> None:
        self._d_c = self._d_t = 0.0
        self._f_c = self._f_t = 0.0
        self._k_c = self._k_t = self.k0

    @property
    def initial_tangent(self) -> float:
        return self.k0

    @property
    def committed(self) -> tuple[float, float]:
        return self._d_c, self._f_c

    def clone(self) -> Bilinear:
        twin = Bilinear.__new__(Bilinear)
        twin.k0, twin.fy, twin.alpha = self.k0, self.fy, self.alpha
        twin._esh, twin._fy_one_minus_alpha = self._esh, self._fy_one_minus_alpha
        twin._d_c, twin._f_c, twin._k_c = self._d_c, self._f_c, self._k_c
        twin._d_t, twin._f_t, twin._k_t = self._d_t, self._f_t, self._k_t
        return twin
