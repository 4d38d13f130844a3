"""Giuffrè-Menegotto-Pinto hysteresis with Filippou isotropic hardening (OpenSees ``Steel02``).

Why it is here: the study of online model updating needs a tested specimen whose law lies
outside every updater's parametric family (Bilinear, Bouc-Wen/BWBN, the play-operator basis of
``online_improved``). GMP has curved Bauschinger transitions whose sharpness depends on the
plastic excursion, and a yield surface that grows with the strain history: neither is a
Bilinear, a Bouc-Wen nor a Masing hysteron sum.

Equivalent OpenSees command (mm, kN)::

    uniaxialMaterial Steel02 $tag $fy $k0 $alpha $R0 $cR1 $cR2 $a1 $a2 $a3 $a4

Algorithm (after SRC/material/uniaxial/Steel02.cpp, the f2c of FEDEAS ``Steel02.f``), with
``Esh = alpha*k0``, ``dy = fy/k0`` and every quantity measured from the last commit:

* each branch runs from the last reversal point ``(d_r, f_r)`` towards the intersection
  ``(d_0, f_0)`` of its elastic line and the (shifted) hardening asymptote, as
  ``f* = alpha*x + (1 - alpha)*x / (1 + |x|**R)**(1/R)`` with ``x = (d - d_r)/(d_0 - d_r)``
  and ``f = f_r + f*·(f_0 - f_r)``;
* ``R = R0*(1 - cR1*xi/(cR2 + xi))``, ``xi = |d_pl - d_0| / dy``: the curvature of the
  transition softens with the previous plastic excursion (Bauschinger effect);
* at a reversal the asymptote is shifted by ``shift = 1 + a1*((d_max - d_min)/(2*a2*dy))**0.8``
  (compression side; ``a3, a4`` on the tension side): isotropic hardening.

The floating-point operations are OpenSees's, in its order (``sigInit = 0``), so forces and
tangents agree with Steel02 to the last bit; ``tests/sim_actuator`` checks it against the real
OpenSeesPy material. Limit cases that follow from the equations: the first loading from the
virgin state is the closed-form curve above with ``d_r = f_r = 0``, ``d_0 = dy``, ``f_0 = fy``
and ``R = R0``; ``R0 -> inf`` with ``a1 = a3 = 0`` is the Bilinear (Steel01) law.

Two deliberate differences, both where Steel02's arithmetic breaks down for very large R:
``|x|**R`` overflowing makes C's ``pow`` return inf and Steel02 drop the curved term (wrong by
up to (1 - alpha)·|f_0 - f_r|), while here ``(1 + |x|**R)**(1/R)`` is taken as its exact value
``|x|``; and a reversal exactly on the hardening asymptote (possible only when
R is so large that the curve reaches it in floating point) makes Steel02 divide by zero and
return NaN; here the branch is that asymptote, ``f = f_r + alpha*k0*(d - d_r)``, its limit.
"""

from __future__ import annotations

import math
import sys
from typing import NamedTuple

from sim_actuator.checks import NON_NEGATIVE, POSITIVE, at_least, within
from sim_actuator.models.base import HysteresisBase, Param, trial_input_error

__all__ = ["MenegottoPinto", "MenegottoPintoState"]

_DBL_EPSILON = sys.float_info.epsilon

_VIRGIN, _LOADING, _UNLOADING, _AT_REST = 0.0, 1.0, 2.0, 3.0
"""Branch flag ``kon`` of Steel02: never moved, loading (+), unloading (-), initial state."""


class MenegottoPintoState(NamedTuple):
    """Committed state of a :class:`MenegottoPinto` specimen, as Steel02 keeps it."""

    d: float
    f: float
    k: float
    """Tangent stiffness at the committed point."""
    d_max: float
    """Largest displacement reached (Steel02 ``epsmax``), at least dy."""
    d_min: float
    """Smallest displacement reached (``epsmin``), at most -dy."""
    d_pl: float
    """Plastic excursion reference (``epspl``)."""
    d_0: float
    """Asymptote intersection of the current branch (``epss0``)."""
    f_0: float
    """Its force (``sigs0``)."""
    d_r: float
    """Last reversal point (``epsr``)."""
    f_r: float
    """Its force (``sigr``)."""
    kon: float
    """Branch flag: 0 virgin, 1 loading, 2 unloading, 3 at rest."""


class MenegottoPinto(HysteresisBase):
    """GMP with isotropic hardening; OpenSees uniaxial-material semantics (see module doc)."""

    __slots__ = ("R0", "a1", "a2", "a3", "a4", "alpha", "cR1", "cR2", "fy", "k0")

    name = "menegotto-pinto"
    PARAMS = (
        Param("k0", "initial stiffness", "force/displacement (e.g. kN/mm)", POSITIVE),
        Param("fy", "yield force", "force (e.g. kN)", POSITIVE),
        Param("alpha", "hardening-asymptote to initial stiffness ratio (Steel02 b)", "-",
              within(0.0, 1.0)),
        Param("R0", "sharpness of the virgin elastic-plastic transition", "-", at_least(1.0),
              15.0),
        Param("cR1", "softening of R with the plastic excursion", "-", within(0.0, 1.0), 0.925),
        Param("cR2", "excursion scale of that softening", "-", POSITIVE, 0.15),
        Param("a1", "isotropic growth of the negative yield force, fraction of fy", "-",
              NON_NEGATIVE, 0.0),
        Param("a2", "excursion (in yield displacements) that a1 refers to", "-", POSITIVE, 1.0),
        Param("a3", "isotropic growth of the positive yield force, fraction of fy", "-",
              NON_NEGATIVE, 0.0),
        Param("a4", "excursion (in yield displacements) that a3 refers to", "-", POSITIVE, 1.0),
    )
    STATE = MenegottoPintoState

    k0: float
    fy: float
    alpha: float
    R0: float
    cR1: float
    cR2: float
    a1: float
    a2: float
    a3: float
    a4: float

    def __init__(
        self,
        *,
        k0: float,
        fy: float,
        alpha: float,
        R0: float = 15.0,
        cR1: float = 0.925,
        cR2: float = 0.15,
        a1: float = 0.0,
        a2: float = 1.0,
        a3: float = 0.0,
        a4: float = 1.0,
    ) -> None:
        self._init_params(
            k0=k0, fy=fy, alpha=alpha, R0=R0, cR1=cR1, cR2=cR2, a1=a1, a2=a2, a3=a3, a4=a4
        )
        self._start()

    def _virgin(self) -> tuple[float, ...]:
        dy = self.fy / self.k0
        return (0.0, 0.0, self.k0, dy, -dy, 0.0, 0.0, 0.0, 0.0, 0.0, _VIRGIN)

    @property
    def yield_displacement(self) -> float:
        """dy = fy / k0."""
        return self.fy / self.k0

    def set_trial(self, d: float) -> tuple[float, float]:
        c = self._committed
        d_step = d - c[0]
        if not math.isfinite(d_step):
            raise trial_input_error(self.name, d)
        k0, fy = self.k0, self.fy
        esh = self.alpha * k0
        dy = fy / k0
        d_max, d_min, d_pl, d_0, f_0, d_r, f_r, kon = c[3:11]
        if kon in (_VIRGIN, _AT_REST):
            if abs(d_step) < 10.0 * _DBL_EPSILON:
                self._trial = (d, 0.0, k0, d_max, d_min, d_pl, d_0, f_0, d_r, f_r, _AT_REST)
                return 0.0, k0
            d_max = dy
            d_min = -dy
            if d_step < 0.0:
                kon, d_0, f_0, d_pl = _UNLOADING, d_min, -fy, d_min
            else:
                kon, d_0, f_0, d_pl = _LOADING, d_max, fy, d_max
        if kon == _UNLOADING and d_step > 0.0:
            kon = _LOADING
            d_r, f_r = c[0], c[1]
            if c[0] < d_min:
                d_min = c[0]
            d1 = (d_max - d_min) / (2.0 * (self.a4 * dy))
            shift = 1.0 + self.a3 * d1**0.8
            d_0 = (fy * shift - esh * dy * shift - f_r + k0 * d_r) / (k0 - esh)
            f_0 = fy * shift + esh * (d_0 - dy * shift)
            d_pl = d_max
        elif kon == _LOADING and d_step < 0.0:
            kon = _UNLOADING
            d_r, f_r = c[0], c[1]
            if c[0] > d_max:
                d_max = c[0]
            d1 = (d_max - d_min) / (2.0 * (self.a2 * dy))
            shift = 1.0 + self.a1 * d1**0.8
            d_0 = (-fy * shift + esh * dy * shift - f_r + k0 * d_r) / (k0 - esh)
            f_0 = -fy * shift + esh * (d_0 + dy * shift)
            d_pl = d_min
        if d_0 == d_r:  # reversed exactly on the asymptote (R0 -> inf): Steel02 gives NaN
            force, tangent = f_r + esh * (d - d_r), esh
            self._trial = (d, force, tangent, d_max, d_min, d_pl, d_0, f_0, d_r, f_r, kon)
            return force, tangent
        xi = abs((d_pl - d_0) / dy)
        r = self.R0 * (1.0 - (self.cR1 * xi) / (self.cR2 + xi))
        ratio = (d - d_r) / (d_0 - d_r)
        try:
            dum1 = 1.0 + abs(ratio) ** r
            dum2 = dum1 ** (1 / r)
        except OverflowError:  # |ratio|**r > 1e308: (1 + |ratio|**r)**(1/r) is |ratio| exactly
            dum1, dum2 = math.inf, abs(ratio)
        b = self.alpha
        force = b * ratio + (1.0 - b) * ratio / dum2
        force = force * (f_0 - f_r) + f_r
        tangent = b + (1.0 - b) / (dum1 * dum2)
        tangent = tangent * (f_0 - f_r) / (d_0 - d_r)
        self._trial = (d, force, tangent, d_max, d_min, d_pl, d_0, f_0, d_r, f_r, kon)
        return force, tangent

    @property
    def initial_tangent(self) -> float:
        return self.k0
