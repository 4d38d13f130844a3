"""Specimen laws of the independent bench, written from the published equations.

None of this shares code with ``sim_actuator`` (whose laws the diagnosis fits): a bench whose
records come from the very code the tool fits measures identifiability, not whether the tool is
right on a specimen it was not built around. Each law is a displacement-driven force law with
trial/commit semantics (``trial(u)`` evaluates from the committed state without changing it,
``commit()`` accepts the last trial), so an effect can solve equilibrium with it (the pin gap).
Units: mm, kN. Plain Python floats in the per-step loops (the laws are path-dependent, one step
at a time; numpy has nothing to vectorise there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["BoucWenBaberNoori", "GiuffreMenegottoPinto", "IsotropicBilinear", "SpecimenLaw"]


class SpecimenLaw:
    """A displacement-driven hysteresis law: ``trial`` from the committed state, ``commit``."""

    def trial(self, u: float) -> float:
        raise NotImplementedError

    def commit(self) -> None:
        raise NotImplementedError

    def step(self, u: float) -> float:
        """Trial and commit at once (a drive without an interface to solve)."""
        f = self.trial(u)
        self.commit()
        return f


@dataclass
class _GmpState:
    u: float = 0.0
    f: float = 0.0
    direction: int = 0
    """+1 loading towards positive, -1 towards negative, 0 virgin."""
    ur: float = 0.0
    fr: float = 0.0
    u0: float = 0.0
    f0: float = 0.0
    u_max: float = 0.0
    u_min: float = 0.0
    u_plastic: float = 0.0
    """The previous extreme in the current direction (the excursion xi is measured from it)."""


class GiuffreMenegottoPinto(SpecimenLaw):
    """Giuffré-Menegotto-Pinto steel, curvature decaying with the plastic excursion.

    Menegotto & Pinto (1973), with Filippou, Popov & Bertero (1983): between the last reversal
    (u_r, F_r) and the intersection (u_0, F_0) of the elastic line through it with the
    post-yield asymptote of slope b*k0,

        F* = b u* + (1 - b) u* / (1 + |u*|^R)^(1/R),  u* = (u - u_r)/(u_0 - u_r),
        F* = (F - F_r)/(F_0 - F_r),  R = R0 - a1 xi / (a2 + xi),

    xi = |u_m - u_0| / u_y the plastic excursion of the previous half cycle (R falls as the
    excursions grow: the Bauschinger effect). Kinematic hardening only (asymptotes fixed).
    """

    def __init__(self, k0: float, fy: float, b: float, r0: float, a1: float, a2: float) -> None:
        self.k0, self.fy, self.b, self.r0, self.a1, self.a2 = k0, fy, b, r0, a1, a2
        self.uy = fy / k0
        self._c = _GmpState()
        self._t = _GmpState()

    def _asymptote(self, s: _GmpState, direction: int) -> None:
        """Reversal into ``direction``: the target point (u0, f0) on that asymptote."""
        k0, b, fy, uy = self.k0, self.b, self.fy, self.uy
        sign = float(direction)
        # asymptote F = sign*fy + b*k0*(u - sign*uy); elastic line F = fr + k0*(u - ur)
        s.u0 = (sign * fy * (1.0 - b) - s.fr + k0 * s.ur) / (k0 * (1.0 - b))
        s.f0 = sign * fy + b * k0 * (s.u0 - sign * uy)

    def trial(self, u: float) -> float:
        c = self._c
        s = _GmpState(**vars(c))
        du = u - c.u
        if s.direction == 0:  # the virgin curve starts at the origin (u_r = 0, u_0 = +-u_y)
            if u == 0.0:
                self._t = s
                return 0.0
            s.direction = 1 if u > 0.0 else -1
            s.ur, s.fr = 0.0, 0.0
            self._asymptote(s, s.direction)
            s.u_plastic = s.u0
        elif du != 0.0 and (du > 0.0) != (s.direction > 0):
            s.direction = -s.direction
            s.ur, s.fr = c.u, c.f
            if c.u > s.u_max:
                s.u_max = c.u
            if c.u < s.u_min:
                s.u_min = c.u
            self._asymptote(s, s.direction)
            s.u_plastic = s.u_min if s.direction < 0 else s.u_max
        xi = abs(s.u_plastic - s.u0) / self.uy
        r = max(self.r0 - self.a1 * xi / (self.a2 + xi), 1.0)
        span = s.u0 - s.ur
        us = (u - s.ur) / span if span != 0.0 else 0.0
        fs = self.b * us + (1.0 - self.b) * us / (1.0 + abs(us) ** r) ** (1.0 / r)
        s.u, s.f = u, fs * (s.f0 - s.fr) + s.fr
        self._t = s
        return s.f

    def commit(self) -> None:
        self._c = self._t


class IsotropicBilinear(SpecimenLaw):
    """Elastic-plastic law with saturating isotropic and a little linear kinematic hardening.

    Rate-independent plasticity (Simo & Hughes, ch. 1) in force-displacement form: yield
    function |F - X| - (fy + Q(kappa)) <= 0, Voce isotropic hardening Q = Q_inf (1 -
    exp(-kappa / kappa_s)) on the accumulated plastic displacement kappa, back force X = H u_p
    (linear kinematic), elastic stiffness k0; closest-point return mapping with a scalar Newton
    solve for the plastic increment. Mostly isotropic: the yield surface grows and saturates, it
    barely translates (unlike Steel01, whose hardening is purely kinematic).
    """

    def __init__(self, k0: float, fy: float, q_inf: float, kappa_s: float, h_kin: float) -> None:
        self.k0, self.fy, self.q_inf, self.kappa_s, self.h_kin = k0, fy, q_inf, kappa_s, h_kin
        self._c = (0.0, 0.0)  # plastic displacement, accumulated plastic displacement
        self._t = self._c

    def _radius(self, kappa: float) -> float:
        return self.fy + self.q_inf * (1.0 - math.exp(-kappa / self.kappa_s))

    def trial(self, u: float) -> float:
        up, kappa = self._c
        f_trial = self.k0 * (u - up)
        rel = f_trial - self.h_kin * up
        excess = abs(rel) - self._radius(kappa)
        if excess <= 0.0:
            self._t = (up, kappa)
            return f_trial
        sign = 1.0 if rel > 0.0 else -1.0
        dg = excess / (self.k0 + self.h_kin)
        for _ in range(50):  # Newton on the consistency condition (Voce: smooth, monotone)
            r = abs(rel) - (self.k0 + self.h_kin) * dg - self._radius(kappa + dg)
            slope = -(self.k0 + self.h_kin) - (self.q_inf / self.kappa_s
                                              * math.exp(-(kappa + dg) / self.kappa_s))
            step = r / slope
            dg -= step
            if abs(step) < 1e-13 * (1.0 + abs(dg)):
                break
        up_new = up + sign * dg
        self._t = (up_new, kappa + dg)
        return self.k0 * (u - up_new)

    def commit(self) -> None:
        self._c = self._t


class BoucWenBaberNoori(SpecimenLaw):
    """Bouc-Wen-Baber-Noori law with energy-driven degradation and pinching.

    Baber & Noori (1985, 1986), with Foliente (1995)'s pinching function; F = alpha k0 u +
    (1 - alpha) fy z, z dimensionless, u_y = fy/k0, s = sign(du):

        dz/du = h(z, e) [A - nu (beta s |z|^(n-1) z + gamma |z|^n)] / (eta u_y)
        de/du = (1 - alpha) z / u_y          (hysteretic energy / (fy u_y))
        A = 1 - dA e,  nu = 1 + dnu e,  eta = 1 + deta e
        h = 1 - zeta1 exp(-(z s - q z_u)^2 / zeta2^2),  z_u = (A / (nu (beta + gamma)))^(1/n)
        zeta1 = zeta_s (1 - exp(-p e)),  zeta2 = (psi0 + dpsi e)(lam + zeta1)

    integrated with classical RK4 on equal substeps of at most :data:`SUBSTEP` u_y.
    """

    SUBSTEP = 0.02

    def __init__(self, k0: float, fy: float, alpha: float, n: float, beta: float, gamma: float,
                 *, d_a: float = 0.0, d_nu: float = 0.0, d_eta: float = 0.0,
                 zeta_s: float = 0.0, psi0: float = 0.2, q: float = 0.0, p: float = 1.0,
                 lam: float = 0.5, d_psi: float = 0.0) -> None:
        self.k0, self.fy, self.alpha, self.n = k0, fy, alpha, n
        self.beta, self.gamma = beta, gamma
        self.d_a, self.d_nu, self.d_eta = d_a, d_nu, d_eta
        self.zeta_s, self.psi0, self.q, self.p, self.lam, self.d_psi = (
            zeta_s, psi0, q, p, lam, d_psi)
        self.uy = fy / k0
        self._c = (0.0, 0.0, 0.0)  # u, z, e
        self._t = self._c

    def _rates(self, z: float, e: float, s: float) -> tuple[float, float]:
        a = max(1.0 - self.d_a * e, 1e-3)
        nu = 1.0 + self.d_nu * e
        eta = 1.0 + self.d_eta * e
        az = abs(z)
        core = a - nu * (self.beta * s * az ** (self.n - 1.0) * z + self.gamma * az ** self.n)
        h = 1.0
        if self.zeta_s > 0.0:
            zeta1 = self.zeta_s * (1.0 - math.exp(-self.p * e))
            zeta2 = (self.psi0 + self.d_psi * e) * (self.lam + zeta1)
            zu = (a / (nu * (self.beta + self.gamma))) ** (1.0 / self.n)
            h = 1.0 - zeta1 * math.exp(-((z * s - self.q * zu) ** 2) / (zeta2 * zeta2))
        return h * core / (eta * self.uy), (1.0 - self.alpha) * z / self.uy

    def trial(self, u: float) -> float:
        u0, z, e = self._c
        du = u - u0
        if du != 0.0:
            s = 1.0 if du > 0.0 else -1.0
            m = max(1, math.ceil(abs(du) / (self.SUBSTEP * self.uy)))
            h = du / m
            for _ in range(m):
                k1z, k1e = self._rates(z, e, s)
                k2z, k2e = self._rates(z + 0.5 * h * k1z, e + 0.5 * h * k1e, s)
                k3z, k3e = self._rates(z + 0.5 * h * k2z, e + 0.5 * h * k2e, s)
                k4z, k4e = self._rates(z + h * k3z, e + h * k3e, s)
                z += h * (k1z + 2.0 * k2z + 2.0 * k3z + k4z) / 6.0
                e += h * (k1e + 2.0 * k2e + 2.0 * k3e + k4e) / 6.0
        self._t = (u, z, e)
        return self.alpha * self.k0 * u + (1.0 - self.alpha) * self.fy * z

    def commit(self) -> None:
        self._c = self._t

    @property
    def energy(self) -> float:
        """Committed normalised hysteretic energy e."""
        return self._c[2]
