"""Bouc-Wen-Baber-Noori hysteresis: Bouc-Wen plus energy-driven degradation and pinching.

Equations (same dimensionless z and normalisation as ``bouc_wen``)::

    dy = fy / k0,  u = d / dy,  f = alpha*k0*d + (1 - alpha)*fy*z
    de/du = (1 - alpha) * z           e = hysteretic energy / (fy*dy), dimensionless
    A   = A0 - delta_a*e              (stiffness/strength decay)
    nu  = 1 + delta_nu*e              (strength degradation)
    eta = 1 + delta_eta*e             (stiffness degradation)
    dz/du = h(z, e) * (A - nu*|z|**n * (beta*sign(du*z) + gamma)) / eta
    h(z, e) = 1 - zeta1 * exp(-((z*sign(du) - q*z_u) / zeta2)**2)        (pinching)
    zeta1 = zeta_s * (1 - exp(-p*e)),  zeta2 = (psi0 + delta_psi*e) * (lam + zeta1)
    z_u = (1 / (nu*(beta + gamma)))**(1/n)

Sources: energy-driven degradation of A, nu, eta after Baber & Wen (1981) and Baber & Noori
(1985, 1986); pinching function h(z) of Foliente (1995, J. Struct. Eng.), including its ``z_u``
without A (bibliographic details from memory). The same 18-parameter form (nu0 = eta0 = 1) is
coded in OpenHySL ``Substructure_BoucWen.c`` (ferranobon/OpenHySL), whose energy is also
normalised by fy*dy; OpenSees ``BWBN`` is the pinching-only special case. Mapping to OpenSees
(z, energy in model units): ``beta_os = beta/dy**n``, ``gamma_os = gamma/dy**n``,
``deltaX_os = delta_x/(fy*dy)``, ``p_os = p/(fy*dy)``, ``Shi = psi0*dy``,
``deltaShi = delta_psi/fy``, ``lamda = lam``, ``zetas = zeta_s``, ``q`` unchanged.

Guards beyond the sources: the pinching terms use ``max(e, 0)`` (e can dip below zero by
round-off on unloading) and h = 1 while zeta1 = 0. With ``zeta_s = 0`` and all deltas 0 the
equations are exactly the classic Bouc-Wen of ``bouc_wen``. A trial that would leave
``A0 - delta_a*e <= 0`` (degradation exhausted, the model no longer means anything) is refused
with ``ModelInputError``.

Integration: as in ``bouc_wen``, RK4 on equal substeps of the state (z, e) along the monotonic
path of a trial, sized from a bound of |dz/du| so z changes by at most ``dz_max`` per substep,
split at z = 0 by one RK4 step in z for (u, e); tangent from dz/du at the trial point. Inside
a pinching bell dz/du is small, so the bound also resolves narrow bells: with zeta2 ~ 0.01-0.05
the force error is ~5e-9 of fy at the default dz_max = 0.01 (fourth-order convergence).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from sim_actuator.checks import NON_NEGATIVE, POSITIVE, within
from sim_actuator.models.base import ModelInputError, Param, trial_input_error
from sim_actuator.models.bouc_wen import (
    DEFAULT_DZ_MAX,
    MAX_SUBSTEPS,
    SHAPE_PARAMS,
    BoucWenFamily,
)

__all__ = ["BoucWenBaberNoori", "BwbnState"]


class BwbnState(NamedTuple):
    """Committed state of a :class:`BoucWenBaberNoori` specimen."""

    d: float
    f: float
    k: float
    """Tangent stiffness at the committed point."""
    z: float
    """Hysteretic variable (dimensionless)."""
    e: float
    """Normalised hysteretic energy e = energy / (fy*dy)."""


class BoucWenBaberNoori(BoucWenFamily):
    """BWBN hysteresis with degradation and pinching (see module docstring for equations)."""

    __slots__ = (
        "A0", "delta_a", "delta_eta", "delta_nu", "delta_psi", "lam", "p", "psi0", "q", "zeta_s",
    )  # fmt: skip

    name = "bwbn"
    PARAMS = (
        *SHAPE_PARAMS,
        Param("A0", "initial slope of z against d/dy", "-", POSITIVE, 1.0),
        Param("delta_a", "decay rate of A per unit normalised energy e", "-", NON_NEGATIVE, 0.0),
        Param("delta_nu", "growth rate of nu (strength degradation) per unit e", "-",
              NON_NEGATIVE, 0.0),
        Param("delta_eta", "growth rate of eta (stiffness degradation) per unit e", "-",
              NON_NEGATIVE, 0.0),
        Param("zeta_s", "pinching severity (0 = no pinching)", "-", within(0.0, 1.0), 0.0),
        Param("p", "rate of pinching build-up with e", "-", NON_NEGATIVE),
        Param("q", "pinching centre as a fraction of z_u", "-", within(0.0, 1.0)),
        Param("psi0", "initial pinching spread", "-", POSITIVE),
        Param("delta_psi", "growth of the pinching spread per unit e", "-", NON_NEGATIVE),
        Param("lam", "coupling of spread and severity (lambda)", "-", POSITIVE),
    )
    STATE = BwbnState

    A0: float
    delta_a: float
    delta_nu: float
    delta_eta: float
    zeta_s: float
    p: float
    q: float
    psi0: float
    delta_psi: float
    lam: float

    def __init__(
        self,
        *,
        k0: float,
        fy: float,
        alpha: float,
        n: float,
        beta: float,
        gamma: float,
        p: float,
        q: float,
        psi0: float,
        delta_psi: float,
        lam: float,
        A0: float = 1.0,
        delta_a: float = 0.0,
        delta_nu: float = 0.0,
        delta_eta: float = 0.0,
        zeta_s: float = 0.0,
        dz_max: float = DEFAULT_DZ_MAX,
    ) -> None:
        self._init_family(
            dz_max, k0=k0, fy=fy, alpha=alpha, n=n, beta=beta, gamma=gamma, A0=A0,
            delta_a=delta_a, delta_nu=delta_nu, delta_eta=delta_eta, zeta_s=zeta_s, p=p, q=q,
            psi0=psi0, delta_psi=delta_psi, lam=lam,
        )  # fmt: skip
        self._start()

    def _virgin(self) -> tuple[float, ...]:
        return (0.0, 0.0, self.initial_tangent, 0.0, 0.0)

    @property
    def committed_energy(self) -> float:
        """Committed normalised hysteretic energy e = energy / (fy*dy)."""
        return self._committed[4]

    def _pinching_spread(self, e: float) -> tuple[float, float]:
        """(zeta1, zeta2) at normalised energy e."""
        e_pos = e if e > 0.0 else 0.0
        zeta1 = self.zeta_s * (1.0 - math.exp(-self.p * e_pos))
        return zeta1, (self.psi0 + self.delta_psi * e_pos) * (self.lam + zeta1)

    def _slope(self, z: float, e: float, direction: float) -> float:
        """dz/du at (z, e) on a path moving in ``direction`` (+1.0 or -1.0)."""
        nu = 1.0 + self.delta_nu * e
        core = self.A0 - self.delta_a * e
        if z != 0.0:
            sign = 1.0 if (z > 0.0) == (direction > 0.0) else -1.0
            core -= nu * abs(z) ** self.n * (self.beta * sign + self.gamma)
        if self.zeta_s > 0.0:
            zeta1, zeta2 = self._pinching_spread(e)
            if zeta1 > 0.0:
                z_u = (1.0 / (nu * (self.beta + self.gamma))) ** (1.0 / self.n)
                x = (z * direction - self.q * z_u) / zeta2
                core *= 1.0 - zeta1 * math.exp(-x * x)
        return core / (1.0 + self.delta_eta * e)

    def _rk4(self, z: float, e: float, h: float, direction: float) -> tuple[float, float]:
        slope = self._slope
        w = 1.0 - self.alpha
        k1 = slope(z, e, direction)
        z2, e2 = z + 0.5 * h * k1, e + 0.5 * h * w * z
        k2 = slope(z2, e2, direction)
        z3, e3 = z + 0.5 * h * k2, e + 0.5 * h * w * z2
        k3 = slope(z3, e3, direction)
        z4, e4 = z + h * k3, e + h * w * z3
        k4 = slope(z4, e4, direction)
        return (
            z + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4),
            e + h / 6.0 * w * (z + 2.0 * z2 + 2.0 * z3 + z4),
        )

    def _to_zero(self, z: float, e: float, direction: float) -> tuple[float, float] | None:
        """(u-distance, e) from z to z = 0 by one RK4 step in z; None if ill-conditioned."""
        w = 1.0 - self.alpha
        dz = -z
        s1 = self._slope(z, e, direction)
        if s1 <= 0.0:
            return None
        z2 = z + 0.5 * dz
        e2 = e + 0.5 * dz * w * z / s1
        s2 = self._slope(z2, e2, direction)
        if s2 <= 0.0:
            return None
        e3 = e + 0.5 * dz * w * z2 / s2
        s3 = self._slope(z2, e3, direction)
        if s3 <= 0.0:
            return None
        e4 = e + dz * w * z2 / s3
        s4 = self._slope(0.0, e4, direction)
        if s4 <= 0.0:
            return None
        du = dz / 6.0 * (1.0 / s1 + 2.0 / s2 + 2.0 / s3 + 1.0 / s4)
        de = dz / 6.0 * w * (z / s1 + 2.0 * z2 / s2 + 2.0 * z2 / s3)
        return du, e + de

    def _substep(self, z: float, e: float, h: float, direction: float) -> tuple[float, float]:
        """One RK4 substep of length h in u, split at z = 0 if it crosses it."""
        z_end, e_end = self._rk4(z, e, h, direction)
        if z * z_end >= 0.0:
            return z_end, e_end
        crossing = self._to_zero(z, e, direction)
        if crossing is None:
            return z_end, e_end
        to_zero, e_zero = crossing
        if not 0.0 < to_zero / h < 1.0:
            return z_end, e_end
        return self._rk4(0.0, e_zero, h - to_zero, direction)

    def _advance(self, z: float, e: float, du: float) -> tuple[float, float]:
        direction = 1.0 if du > 0.0 else -1.0
        nu = 1.0 + self.delta_nu * e
        z_scale = max(abs(z), (self.A0 / (nu * (self.beta + self.gamma))) ** (1.0 / self.n))
        bound = (self.A0 + self.n * nu * (self.beta + abs(self.gamma)) * z_scale**self.n) / (
            1.0 + self.delta_eta * e
        )
        count = int(abs(du) * bound / self.dz_max) + 1
        if count > MAX_SUBSTEPS:
            raise ModelInputError(
                f"{self.name}: trial step of {du * self._dy!r} (= {du!r} yield displacements) "
                f"needs {count} substeps (> {MAX_SUBSTEPS}); check units of the displacement"
            )
        h = du / count
        for _ in range(count):
            z, e = self._substep(z, e, h, direction)
        return z, e

    def set_trial(self, d: float) -> tuple[float, float]:
        d_c, f_c, k_c, z_c, e_c = self._committed
        du = (d - d_c) / self._dy
        if not math.isfinite(du):
            raise trial_input_error(self.name, d)
        if du == 0.0:
            self._trial = self._committed
            return f_c, k_c
        direction = 1.0 if du > 0.0 else -1.0
        z, e = self._advance(z_c, e_c, du)
        if self.A0 - self.delta_a * e <= 0.0:
            raise ModelInputError(
                f"{self.name}: degradation exhausted at d = {d!r}: A = A0 - delta_a*e = "
                f"{self.A0!r} - {self.delta_a!r}*{e!r} <= 0; parameters do not fit this history"
            )
        force = self._k_el * d + self._f_hyst * z
        tangent = self._k_el + self._k_hyst * self._slope(z, e, direction)
        self._trial = (d, force, tangent, z, e)
        return force, tangent

    @property
    def initial_tangent(self) -> float:
        return self._k_el + self._k_hyst * self.A0
