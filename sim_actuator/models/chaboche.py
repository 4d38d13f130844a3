"""Chaboche-type plasticity: a sharp elastic range, three Armstrong-Frederick back-forces, a
linear kinematic term, a Voce change of the elastic range and a plastic-range memory.

Why it is here: issue 9 needs a law with a real internal state (plastic deformation, back-forces,
accumulated plastic deformation) that is outside both study specimens' laws, to be identified
online from the tested element's history (``fresco_bridge.updating.refit``). Its branches are
sums of exponentials (Armstrong-Frederick) after a sharp yield, not Menegotto-Pinto's
``x/(1+|x|^R)^(1/R)`` transitions with an excursion-dependent R; it has no Bouc-Wen hysteretic
variable, no degradation of stiffness and no pinching, so it is neither BWBN nor Menegotto-
Pinto (any variant).

Law (one dimension; force f, displacement d, plastic displacement e_p, accumulated plastic
displacement p, back-forces X_1..X_3, memory range q):

* ``f = k0 (d - e_p)``; elastic while ``|f - X| <= fy + R`` with
  ``X = X_1 + X_2 + X_3 + kh e_p``;
* flow in direction ``s = sign(f - X)``: ``de_p = s dp``, ``dX_i = C_i de_p - gamma_i X_i dp``;
* ``R = Q (1 - exp(-b p)) + Qe (1 - exp(-be m)) + hm q``: Voce change of the elastic range
  with accumulated plastic deformation (``Q < 0`` shrinks it: a sharp virgin yield, softer
  later yields, the Bauschinger effect); a change with ``m = max(previous branch, this
  branch)``, the plastic length of the last excursions (a branch: plastic flow in one
  direction), so the range shrinks after long excursions and recovers after short ones; an
  isotropic hardening with ``q = (max e_p - min e_p)/2`` over the history (Chaboche's
  plastic-strain memory, linear).

Return mapping: along one step the flow direction is constant, so ``X_i`` and ``R`` have closed
forms in the plastic increment ``dp`` (``X_i = s C_i/gamma_i + (X_i,c - s C_i/gamma_i)
exp(-gamma_i dp)``); the consistency condition is one scalar equation in ``dp``, strictly
decreasing when ``|Q| b + |Qe| be < k0`` (checked), solved by safeguarded Newton to 1e-12 of
fy. A step is therefore exact whatever its size: a monotonic segment gives the same state in
one step or many (what lets an online refit run on a compressed history). The tangent is the
consistent ``k0 H / (k0 + H)``, ``H`` the plastic modulus at the end of the step.

OpenSees semantics: ``set_trial(d)`` from the last commit, ``commit()``; repeated trials never
advance the state. There is no OpenSees material with exactly this law (``UVCuniaxial`` has
Voce isotropic and AF back-stresses with a different isotropic form and no memory term).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from sim_actuator.checks import FINITE, NON_NEGATIVE, POSITIVE
from sim_actuator.models.base import HysteresisBase, ModelParameterError, Param, trial_input_error

__all__ = ["Chaboche", "ChabocheState"]

_TOL = 1e-12
_MAX_ITER = 60


class ChabocheState(NamedTuple):
    """Committed state of a :class:`Chaboche` law."""

    d: float
    f: float
    k: float
    """Tangent stiffness at the committed point."""
    e_p: float
    """Plastic displacement."""
    p: float
    """Accumulated plastic displacement (sum of |de_p|)."""
    x1: float
    x2: float
    x3: float
    """Armstrong-Frederick back-forces."""
    e_max: float
    """Largest plastic displacement so far (>= 0)."""
    e_min: float
    """Smallest plastic displacement so far (<= 0)."""
    flow: float
    """Direction of the last plastic flow (+1, -1; 0 before any)."""
    p_branch: float
    """Plastic displacement accumulated since the flow last changed direction."""
    p_prev: float
    """That of the previous branch (the last completed excursion)."""


class Chaboche(HysteresisBase):
    """Sharp elastic range, AF kinematic + Voce/memory isotropic hardening (module doc)."""

    __slots__ = ("C1", "C2", "C3", "Q", "Qe", "b", "be", "fy", "gamma1", "gamma2", "gamma3",
                 "hm", "k0", "kh")  # fmt: skip

    name = "chaboche"
    PARAMS = (
        Param("k0", "elastic stiffness", "force/displacement (e.g. kN/mm)", POSITIVE),
        Param("fy", "radius of the virgin elastic range (virgin yield force)", "force (e.g. kN)",
              POSITIVE),
        Param("C1", "initial modulus of back-force 1", "force/displacement", NON_NEGATIVE, 0.0),
        Param("gamma1", "recall rate of back-force 1 (saturates at C1/gamma1)",
              "1/displacement", POSITIVE, 1.0),
        Param("C2", "initial modulus of back-force 2", "force/displacement", NON_NEGATIVE, 0.0),
        Param("gamma2", "recall rate of back-force 2", "1/displacement", POSITIVE, 1.0),
        Param("C3", "initial modulus of back-force 3", "force/displacement", NON_NEGATIVE, 0.0),
        Param("gamma3", "recall rate of back-force 3", "1/displacement", POSITIVE, 1.0),
        Param("kh", "linear kinematic hardening modulus", "force/displacement", NON_NEGATIVE,
              0.0),
        Param("Q", "Voce change of the elastic range at saturation (< 0 shrinks it)",
              "force (e.g. kN)", FINITE, 0.0),
        Param("b", "Voce rate per accumulated plastic displacement", "1/displacement",
              POSITIVE, 1.0),
        Param("hm", "isotropic hardening per half plastic range (memory)",
              "force/displacement", NON_NEGATIVE, 0.0),
        Param("Qe", "change of the elastic range after a long previous excursion (< 0 shrinks)",
              "force (e.g. kN)", FINITE, 0.0),
        Param("be", "its rate per plastic displacement of the previous excursion",
              "1/displacement", POSITIVE, 1.0),
    )
    STATE = ChabocheState

    k0: float
    fy: float
    C1: float
    gamma1: float
    C2: float
    gamma2: float
    C3: float
    gamma3: float
    kh: float
    Q: float
    b: float
    hm: float
    Qe: float
    be: float

    def __init__(self, *, k0: float, fy: float, C1: float = 0.0, gamma1: float = 1.0,
                 C2: float = 0.0, gamma2: float = 1.0, C3: float = 0.0, gamma3: float = 1.0,
                 kh: float = 0.0, Q: float = 0.0, b: float = 1.0, hm: float = 0.0,
                 Qe: float = 0.0, be: float = 1.0) -> None:
        self._init_params(k0=k0, fy=fy, C1=C1, gamma1=gamma1, C2=C2, gamma2=gamma2, C3=C3,
                          gamma3=gamma3, kh=kh, Q=Q, b=b, hm=hm, Qe=Qe, be=be)  # fmt: skip
        self._start()

    def _check_relations(self) -> None:
        if self.fy + min(self.Q, 0.0) + min(self.Qe, 0.0) <= 0.0:
            raise ModelParameterError(self.name, f"the elastic range fy + Q + Qe must stay "
                                      f"positive (fy={self.fy!r}, Q={self.Q!r}, "
                                      f"Qe={self.Qe!r})", "Q")  # fmt: skip
        if -min(self.Q * self.b, 0.0) - min(self.Qe * self.be, 0.0) >= self.k0:
            raise ModelParameterError(self.name, f"the softening |Q|*b + |Qe|*be must be below "
                                      f"k0 (Q={self.Q!r}, b={self.b!r}, Qe={self.Qe!r}, "
                                      f"be={self.be!r}, k0={self.k0!r})", "b")  # fmt: skip

    def _virgin(self) -> tuple[float, ...]:
        return (0.0, 0.0, self.k0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def initial_tangent(self) -> float:
        return self.k0

    def set_trial(self, d: float) -> tuple[float, float]:
        c = self._committed
        if not math.isfinite(d):
            raise trial_input_error(self.name, d)
        _, _, _, e_p, p, x1, x2, x3, e_max, e_min, flow, p_branch, p_prev = c
        k0 = self.k0
        f_tr = k0 * (d - e_p)
        back = x1 + x2 + x3 + self.kh * e_p
        s = 1.0 if f_tr > back else -1.0
        if s != flow:  # a new branch: the excursion just completed is the previous one
            p_prev = 0.0 if flow == 0.0 else p_branch
            p_branch = 0.0
        q = 0.5 * (e_max - e_min)
        g0 = abs(f_tr - back) - (self.fy + self.Qe * (1.0 - math.exp(-self.be * max(p_prev,
                                 p_branch))) + self.Q * (1.0 - math.exp(-self.b * p)) + self.hm * q)
        if g0 <= _TOL * self.fy:
            self._trial = (d, f_tr, k0, *c[3:])
            return f_tr, k0
        dp, h = self._solve(g0, s, f_tr, c, (p_prev, p_branch))
        e_new = e_p + s * dp
        x1n, x2n, x3n = (s * ci / gi + (xi - s * ci / gi) * math.exp(-gi * dp)
                         for ci, gi, xi in ((self.C1, self.gamma1, x1), (self.C2, self.gamma2, x2),
                                            (self.C3, self.gamma3, x3)))  # fmt: skip
        force = k0 * (d - e_new)
        tangent = k0 * h / (k0 + h)
        self._trial = (d, force, tangent, e_new, p + dp, x1n, x2n, x3n, max(e_max, e_new),
                       min(e_min, e_new), s, p_branch + dp, p_prev)  # fmt: skip
        return force, tangent

    def _residual(self, dp: float, s: float, f_tr: float, c: tuple[float, ...],
                  branch: tuple[float, float]) -> tuple[float, float]:  # fmt: skip
        """Consistency function g(dp) and the plastic modulus H = -g'(dp) - k0; ``branch``:
        the previous excursion's and this branch's plastic length at the start of the step."""
        _, _, _, e_p, p, x1, x2, x3, e_max, e_min = c[:10]
        k0, kh = self.k0, self.kh
        e_new = e_p + s * dp
        back = kh * e_new
        h = kh
        for ci, gi, xi in ((self.C1, self.gamma1, x1), (self.C2, self.gamma2, x2),
                           (self.C3, self.gamma3, x3)):  # fmt: skip
            if ci == 0.0 and xi == 0.0:
                continue
            a = ci / gi
            decay = math.exp(-gi * dp)
            back += s * a + (xi - s * a) * decay
            h += gi * (a - s * xi) * decay
        voce = math.exp(-self.b * (p + dp))
        radius = self.fy + self.Q * (1.0 - voce)
        p_prev, p_branch = branch
        if p_branch + dp > p_prev:
            recall = math.exp(-self.be * (p_branch + dp))
            h += self.Qe * self.be * recall
        else:
            recall = math.exp(-self.be * p_prev)
        radius += self.Qe * (1.0 - recall)
        h += self.Q * self.b * voce
        q = 0.5 * (max(e_max, e_new) - min(e_min, e_new))
        radius += self.hm * q
        if (s > 0.0 and e_new > e_max) or (s < 0.0 and e_new < e_min):
            h += 0.5 * self.hm
        return s * (f_tr - k0 * s * dp - back) - radius, h

    def _solve(self, g0: float, s: float, f_tr: float, c: tuple[float, ...],
               branch: tuple[float, float]) -> tuple[float, float]:  # fmt: skip
        """Plastic increment dp > 0 with g(dp) = 0 (safeguarded Newton) and H there."""
        k0 = self.k0
        lo, hi = 0.0, g0 / (k0 + min(self.Q * self.b, 0.0) + min(self.Qe * self.be, 0.0))
        dp = g0 / (k0 + self._residual(0.0, s, f_tr, c, branch)[1])
        dp = min(max(dp, lo), hi)
        g, h = self._residual(dp, s, f_tr, c, branch)
        scale = _TOL * self.fy
        for _ in range(_MAX_ITER):
            if abs(g) <= scale:
                break
            if g > 0.0:
                lo = dp
            else:
                hi = dp
            step = dp + g / (k0 + h)
            dp = step if lo < step < hi else 0.5 * (lo + hi)
            g, h = self._residual(dp, s, f_tr, c, branch)
        return dp, h
