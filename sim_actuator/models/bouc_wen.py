"""Classic Bouc-Wen smooth hysteresis (Bouc 1967, Wen 1976), no degradation, no pinching.

Parameterisation (the same as OpenHySL ``Substructure_BoucWen``; z is dimensionless)::

    dy = fy / k0                      yield displacement
    u  = d / dy                       normalised displacement
    f  = alpha*k0*d + (1 - alpha)*fy*z
    dz/du = A - |z|**n * (beta*sign(du*z) + gamma)        (dz/du = A at z = 0)

so ``z`` saturates at ``z_u = (A / (beta + gamma))**(1/n)`` under monotonic loading, where
the force approaches ``alpha*k0*d + (1 - alpha)*fy*z_u`` (the Steel01 post-yield line when
``A = 1`` and ``beta + gamma = 1``). The initial tangent is ``alpha*k0 + (1 - alpha)*k0*A``.
``beta`` multiplies ``sign(du*z)`` as in Wen (1976) and OpenSees ``BoucWen``; ``beta = gamma``
gives unloading at the initial stiffness. Mapping to OpenSees
``uniaxialMaterial BoucWen tag alpha ko n gamma beta Ao 0 0 0`` (z in displacement units):
``ko = k0``, ``Ao = A``, ``beta_os = beta/dy**n``, ``gamma_os = gamma/dy**n``.

Integration: within one trial the path from the committed displacement is monotonic, so
``z(u)`` solves an autonomous ODE. It is integrated with classic RK4 on equal substeps, their
number chosen so that z changes by at most ``dz_max`` per substep (bound from
``A + n*(beta + |gamma|)*max(|z|, z_u)**n``). The right-hand side has a kink where z changes
sign; a substep that crosses z = 0 is split there: the distance in u to the crossing is
the quadrature ``int dz / (dz/du)`` (Simpson, i.e. RK4 in z), then RK4 continues from z = 0.
The tangent ``alpha*k0 + (1 - alpha)*k0*dz/du`` is evaluated at the trial point; for the exact
flow this is the consistent tangent ``d f_trial / d d_trial``. Results converge with
``dz_max`` at fourth order away from z = 0 (error ~1e-9 of fy at the default 0.01).
"""

from __future__ import annotations

import math

from sim_actuator.models.base import (
    ModelInputError,
    ModelParameterError,
    check_at_least,
    check_finite,
    check_positive,
    check_range,
    trial_input_error,
)

__all__ = ["DEFAULT_DZ_MAX", "MAX_SUBSTEPS", "BoucWen"]

DEFAULT_DZ_MAX = 0.01
"""Largest change of z (dimensionless) per RK4 substep by default."""

MAX_SUBSTEPS = 200_000
"""A trial step needing more substeps is refused (almost surely a unit or sign error)."""


class BoucWen:
    """Bouc-Wen hysteresis with a dimensionless hysteretic variable z (see module docstring)."""

    __slots__ = (
        "A",
        "_bound_coef",
        "_d_c",
        "_d_t",
        "_dy",
        "_f_c",
        "_f_hyst",
        "_f_t",
        "_k_c",
        "_k_el",
        "_k_hyst",
        "_k_t",
        "_loading",
        "_unloading",
        "_z_c",
        "_z_t",
        "alpha",
        "beta",
        "dz_max",
        "fy",
        "gamma",
        "k0",
        "n",
        "z_ultimate",
    )

    name = "bouc-wen"

    _d_c: float
    _d_t: float
    _z_c: float
    _z_t: float
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
        A: float = 1.0,
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
        self.A = check_positive(model, "A", A)
        self.dz_max = check_range(model, "dz_max", dz_max, 1e-9, 1.0)
        self._dy = self.fy / self.k0
        self._k_el = self.alpha * self.k0
        self._k_hyst = (1.0 - self.alpha) * self.k0
        self._f_hyst = (1.0 - self.alpha) * self.fy
        self._loading = self.beta + self.gamma  # coefficient when sign(du*z) = +1
        self._unloading = self.gamma - self.beta  # coefficient when sign(du*z) = -1
        self._bound_coef = self.n * (self.beta + abs(self.gamma))
        self.z_ultimate: float = (self.A / self._loading) ** (1.0 / self.n)
        self.revert_to_start()

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={v!r}" for k, v in self.parameters.items())
        return f"BoucWen({inner})"

    @property
    def parameters(self) -> dict[str, float]:
        """The construction parameters (without dz_max), for rebuilding or reporting."""
        return {
            "k0": self.k0,
            "fy": self.fy,
            "alpha": self.alpha,
            "n": self.n,
            "beta": self.beta,
            "gamma": self.gamma,
            "A": self.A,
        }

    @property
    def yield_displacement(self) -> float:
        """dy = fy / k0."""
        return self._dy

    @property
    def committed_z(self) -> float:
        """Committed hysteretic variable z (dimensionless)."""
        return self._z_c

    def _slope(self, z: float, direction: float) -> float:
        """dz/du at z on a path moving in ``direction`` (+1.0 or -1.0)."""
        if z == 0.0:
            return self.A
        coef = self._loading if (z > 0.0) == (direction > 0.0) else self._unloading
        power: float = abs(z) ** self.n
        return self.A - power * coef

    def _rk4(self, z: float, h: float, direction: float) -> float:
        slope = self._slope
        k1 = slope(z, direction)
        k2 = slope(z + 0.5 * h * k1, direction)
        k3 = slope(z + 0.5 * h * k2, direction)
        k4 = slope(z + h * k3, direction)
        return z + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

    def _substep(self, z: float, h: float, direction: float) -> float:
        """One RK4 substep of length h in u, split at z = 0 if it crosses it."""
        z_end = self._rk4(z, h, direction)
        if z * z_end >= 0.0:
            return z_end
        # Crossing from the unloading side: u-distance to z = 0 by Simpson on du/dz.
        s1 = self._slope(z, direction)
        s2 = self._slope(0.5 * z, direction)
        if s1 <= 0.0 or s2 <= 0.0:
            return z_end
        to_zero = -z / 6.0 * (1.0 / s1 + 4.0 / s2 + 1.0 / self.A)
        fraction = to_zero / h
        if not 0.0 < fraction < 1.0:
            return z_end
        return self._rk4(0.0, h - to_zero, direction)

    def _advance(self, z: float, du: float) -> float:
        direction = 1.0 if du > 0.0 else -1.0
        bound = self.A + self._bound_coef * max(abs(z), self.z_ultimate) ** self.n
        count = int(abs(du) * bound / self.dz_max) + 1
        if count > MAX_SUBSTEPS:
            raise ModelInputError(
                f"{self.name}: trial step of {du * self._dy!r} (= {du!r} yield displacements) "
                f"needs {count} substeps (> {MAX_SUBSTEPS}); check units of the displacement"
            )
        h = du / count
        for _ in range(count):
            z = self._substep(z, h, direction)
        return z

    def set_trial(self, d: float) -> tuple[float, float]:
        du = (d - self._d_c) / self._dy
        if not math.isfinite(du):
            raise trial_input_error(self.name, d)
        if du == 0.0:
            self._d_t, self._z_t, self._f_t, self._k_t = self._d_c, self._z_c, self._f_c, self._k_c
            return self._f_c, self._k_c
        z = self._advance(self._z_c, du)
        force = self._k_el * d + self._f_hyst * z
        tangent = self._k_el + self._k_hyst * self._slope(z, 1.0 if du > 0.0 else -1.0)
        self._d_t, self._z_t, self._f_t, self._k_t = d, z, force, tangent
        return force, tangent

    def commit(self) -> None:
        self._d_c, self._z_c, self._f_c, self._k_c = self._d_t, self._z_t, self._f_t, self._k_t

    def revert_to_last_commit(self) -> None:
        self._d_t, self._z_t, self._f_t, self._k_t = self._d_c, self._z_c, self._f_c, self._k_c

    def revert_to_start(self) -> None:
        self._d_c = self._d_t = 0.0
        self._z_c = self._z_t = 0.0
        self._f_c = self._f_t = 0.0
        self._k_c = self._k_t = self.initial_tangent

    @property
    def initial_tangent(self) -> float:
        return self._k_el + self._k_hyst * self.A

    @property
    def committed(self) -> tuple[float, float]:
        return self._d_c, self._f_c

    def clone(self) -> BoucWen:
        twin = BoucWen.__new__(BoucWen)
        for slot in BoucWen.__slots__:
            object.__setattr__(twin, slot, getattr(self, slot))
        return twin
