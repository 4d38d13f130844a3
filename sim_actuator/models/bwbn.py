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

from sim_actuator.models.base import (
    ModelInputError,
    ModelParameterError,
    check_at_least,
    check_finite,
    check_non_negative,
    check_positive,
    check_range,
    trial_input_error,
)
from sim_actuator.models.bouc_wen import DEFAULT_DZ_MAX, MAX_SUBSTEPS

__all__ = ["BoucWenBaberNoori"]

_PARAMETER_NAMES = (
    "k0", "fy", "alpha", "n", "beta", "gamma", "A0", "delta_a", "delta_nu", "delta_eta",
    "zeta_s", "p", "q", "psi0", "delta_psi", "lam",
)  # fmt: skip


class BoucWenBaberNoori:
    """BWBN hysteresis with degradation and pinching (see module docstring for equations)."""

    __slots__ = (
        "A0",
        "_d_c",
        "_d_t",
        "_dy",
        "_e_c",
        "_e_t",
        "_f_c",
        "_f_hyst",
        "_f_t",
        "_k_c",
        "_k_el",
        "_k_hyst",
        "_k_t",
        "_z_c",
        "_z_t",
        "alpha",
        "beta",
        "delta_a",
        "delta_eta",
        "delta_nu",
        "delta_psi",
        "dz_max",
        "fy",
        "gamma",
        "k0",
        "lam",
        "n",
        "p",
        "psi0",
        "q",
        "zeta_s",
    )

    name = "bwbn"

    _d_c: float
    _d_t: float
    _z_c: float
    _z_t: float
    _e_c: float
    _e_t: float
    _f_c: float
    _f_t: float
    _k_c: float
    _k_t: float

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
        model = self.name
        self.k0 = check_positive(model, "k0", k0)
        self.fy = check_positive(model, "fy", fy)
        self.alpha = check_range(model, "alpha", alpha, 0.0, 1.0)
        self.n = check_at_least(model, "n", n, 1.0)
        self.beta = check_positive(model, "beta", beta)
        self.gamma = check_finite(model, "gamma", gamma)
        if self.beta + self.gamma <= 0.0:
            raise ModelParameterError(
                model, f"beta + gamma must be > 0, got {beta!r} + {gamma!r}", "gamma"
            )
        self.A0 = check_positive(model, "A0", A0)
        self.delta_a = check_non_negative(model, "delta_a", delta_a)
        self.delta_nu = check_non_negative(model, "delta_nu", delta_nu)
        self.delta_eta = check_non_negative(model, "delta_eta", delta_eta)
        self.zeta_s = check_range(model, "zeta_s", zeta_s, 0.0, 1.0)
        self.p = check_non_negative(model, "p", p)
        self.q = check_range(model, "q", q, 0.0, 1.0)
        self.psi0 = check_positive(model, "psi0", psi0)
        self.delta_psi = check_non_negative(model, "delta_psi", delta_psi)
        self.lam = check_positive(model, "lam", lam)
        self.dz_max = check_range(model, "dz_max", dz_max, 1e-9, 1.0)
        self._dy = self.fy / self.k0
        self._k_el = self.alpha * self.k0
        self._k_hyst = (1.0 - self.alpha) * self.k0
        self._f_hyst = (1.0 - self.alpha) * self.fy
        self.revert_to_start()

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={v!r}" for k, v in self.parameters.items())
        return f"BoucWenBaberNoori({inner})"

    @property
    def parameters(self) -> dict[str, float]:
        """The construction parameters (without dz_max), for rebuilding or reporting."""
        return {name: float(getattr(self, name)) for name in _PARAMETER_NAMES}

    @property
    def yield_displacement(self) -> float:
        """dy = fy / k0."""
        return self._dy

    @property
    def committed_z(self) -> float:
        """Committed hysteretic variable z (dimensionless)."""
        return self._z_c

    @property
    def committed_energy(self) -> float:
        """Committed normalised hysteretic energy e = energy / (fy*dy)."""
        return self._e_c

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
        du = (d - self._d_c) / self._dy
        if not math.isfinite(du):
            raise trial_input_error(self.name, d)
        if du == 0.0:
            self.revert_to_last_commit()
            return self._f_c, self._k_c
        direction = 1.0 if du > 0.0 else -1.0
        z, e = self._advance(self._z_c, self._e_c, du)
        if self.A0 - self.delta_a * e <= 0.0:
            raise ModelInputError(
                f"{self.name}: degradation exhausted at d = {d!r}: A = A0 - delta_a*e = "
                f"{self.A0!r} - {self.delta_a!r}*{e!r} <= 0; parameters do not fit this history"
            )
        force = self._k_el * d + self._f_hyst * z
        tangent = self._k_el + self._k_hyst * self._slope(z, e, direction)
        self._d_t, self._z_t, self._e_t, self._f_t, self._k_t = d, z, e, force, tangent
        return force, tangent

    def commit(self) -> None:
        self._d_c, self._z_c, self._e_c = self._d_t, self._z_t, self._e_t
        self._f_c, self._k_c = self._f_t, self._k_t

    def revert_to_last_commit(self) -> None:
        self._d_t, self._z_t, self._e_t = self._d_c, self._z_c, self._e_c
        self._f_t, self._k_t = self._f_c, self._k_c

    def revert_to_start(self) -> None:
        self._d_c = self._d_t = 0.0
        self._z_c = self._z_t = 0.0
        self._e_c = self._e_t = 0.0
        self._f_c = self._f_t = 0.0
        self._k_c = self._k_t = self.initial_tangent

    @property
    def initial_tangent(self) -> float:
        return self._k_el + self._k_hyst * self.A0

    @property
    def committed(self) -> tuple[float, float]:
        return self._d_c, self._f_c

    def clone(self) -> BoucWenBaberNoori:
        twin = BoucWenBaberNoori.__new__(BoucWenBaberNoori)
        for slot in BoucWenBaberNoori.__slots__:
            object.__setattr__(twin, slot, getattr(self, slot))
        return twin
