"""Bilinear kinematic hardening plus saturating (Voce) isotropic hardening: one return map.

Why it is here: a steel or buckling-restrained specimen whose yield force grows with the
plastic work and then levels off is neither a Bilinear (its loops stop growing) nor Steel02's
isotropic shift (``1 + a1·(excursion)**0.8`` grows without bound). Labs meet it often enough
that the diagnosis must be able to take it as the baseline instead of blaming its growth on an
effect. With ``q_iso = 0`` the law is the Bilinear (Steel01 without isotropic terms) to
rounding.

The classic 1-D rate-independent plasticity (Lemaitre & Chaboche; the combined hardening of
OpenSees ``Hardening`` with a Voce isotropic law instead of a linear one), in forces:

* elastic predictor ``f* = f_c + k0 (d − d_c)``, relative force ``ξ = f* − b`` (``b`` the
  kinematic back force);
* yield radius ``r(p) = fy (1 + q_iso (1 − exp(−p / (p_sat·dy))))``, ``p`` the accumulated
  plastic displacement, ``dy = fy/k0``;
* if ``|ξ| > r(p)``: the plastic increment ``λ`` solves ``|ξ| − (k0 + H) λ = r(p + λ)`` with
  ``H = alpha·k0/(1 − alpha)`` (so that the post-yield stiffness without isotropic growth is
  ``alpha·k0``), by Newton from ``λ = 0`` — the residual is convex and decreasing, so the
  iterates rise monotonically to the root; then ``f = f* − k0 λ sign ξ``, ``b += H λ sign ξ``,
  ``p += λ``.

``sim_actuator.models.paths`` drives the same algorithm compiled (``LAW_ISOTROPIC_BILINEAR``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from sim_actuator.checks import NON_NEGATIVE, POSITIVE, within
from sim_actuator.models.base import HysteresisBase, Param, trial_input_error

__all__ = ["IsotropicBilinear", "IsotropicBilinearState", "return_map"]

NEWTON_ITERATIONS = 60
"""More than enough: the iterates of a convex decreasing residual converge quadratically."""


class IsotropicBilinearState(NamedTuple):
    """Committed state of an :class:`IsotropicBilinear` specimen."""

    d: float
    f: float
    back: float
    """Kinematic back force."""
    p: float
    """Accumulated plastic displacement (>= 0)."""


def return_map(k0: float, fy: float, alpha: float, q_iso: float, p_sat: float,
               d_c: float, f_c: float, back: float, p: float,
               d: float) -> tuple[float, float, float, bool]:
    """(force, back force, accumulated plastic displacement, plastic?) of a trial to ``d``
    from the committed (d_c, f_c, back, p); the module docstring's algorithm."""
    h = alpha * k0 / (1.0 - alpha)
    scale = p_sat * fy / k0
    grow = q_iso * fy
    trial = f_c + k0 * (d - d_c)
    xi = trial - back
    size = abs(xi)
    radius = fy + grow * (1.0 - math.exp(-p / scale))
    if size <= radius:
        return trial, back, p, False
    lam = 0.0
    for _ in range(NEWTON_ITERATIONS):
        decay = math.exp(-(p + lam) / scale)
        g = size - (k0 + h) * lam - fy - grow * (1.0 - decay)
        step = g / (k0 + h + grow / scale * decay)
        lam += step
        if abs(step) <= 1e-15 * (abs(lam) + fy / k0):
            break
    sign = 1.0 if xi > 0.0 else -1.0
    return trial - k0 * lam * sign, back + h * lam * sign, p + lam, True


class IsotropicBilinear(HysteresisBase):
    """Kinematic (alpha) and saturating isotropic (q_iso, p_sat) hardening; module doc."""

    __slots__ = ("alpha", "fy", "k0", "p_sat", "q_iso")

    name = "isotropic-bilinear"
    PARAMS = (
        Param("k0", "initial (elastic) stiffness", "force/displacement (e.g. kN/mm)", POSITIVE),
        Param("fy", "initial yield force", "force (e.g. kN)", POSITIVE),
        Param("alpha", "kinematic post-yield to initial stiffness ratio", "-",
              within(0.0, 1.0)),
        Param("q_iso", "saturated growth of the yield force, fraction of fy", "-", NON_NEGATIVE,
              0.0),
        Param("p_sat", "accumulated plastic displacement (in yield displacements) for 63 % "
              "of that growth", "-", POSITIVE, 10.0),
    )
    STATE = IsotropicBilinearState

    k0: float
    fy: float
    alpha: float
    q_iso: float
    p_sat: float

    def __init__(self, *, k0: float, fy: float, alpha: float, q_iso: float = 0.0,
                 p_sat: float = 10.0) -> None:
        self._init_params(k0=k0, fy=fy, alpha=alpha, q_iso=q_iso, p_sat=p_sat)
        self._start()

    def _virgin(self) -> tuple[float, ...]:
        return (0.0, 0.0, 0.0, 0.0)

    @property
    def yield_displacement(self) -> float:
        """dy = fy / k0."""
        return self.fy / self.k0

    def set_trial(self, d: float) -> tuple[float, float]:
        d_c, f_c, back, p = self._committed
        if not math.isfinite(d - d_c):
            raise trial_input_error(self.name, d)
        force, back, p_new, plastic = return_map(self.k0, self.fy, self.alpha, self.q_iso,
                                                 self.p_sat, d_c, f_c, back, p, d)
        self._trial = (d, force, back, p_new)
        if not plastic:
            return force, self.k0
        h = self.alpha * self.k0 / (1.0 - self.alpha)
        iso = self.q_iso * self.k0 / self.p_sat * math.exp(-p_new * self.k0
                                                           / (self.p_sat * self.fy))
        return force, self.k0 * (h + iso) / (self.k0 + h + iso)

    @property
    def initial_tangent(self) -> float:
        return self.k0
