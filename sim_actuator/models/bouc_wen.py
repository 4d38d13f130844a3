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
from typing import Any, NamedTuple

from sim_actuator.checks import FINITE, POSITIVE, at_least, within
from sim_actuator.models.base import (
    HysteresisBase,
    ModelInputError,
    ModelParameterError,
    Param,
    trial_input_error,
)

__all__ = [
    "DEFAULT_DZ_MAX",
    "DZ_MAX",
    "MAX_SUBSTEPS",
    "SHAPE_PARAMS",
    "BoucWen",
    "BoucWenFamily",
    "BoucWenState",
]

DEFAULT_DZ_MAX = 0.01
"""Largest change of z (dimensionless) per RK4 substep by default."""

DZ_MAX = Param("dz_max", "largest change of z per RK4 substep", "-", within(1e-9, 1.0),
               DEFAULT_DZ_MAX)
"""The integration setting (not a law parameter) of the Bouc-Wen family."""

MAX_SUBSTEPS = 200_000
"""A trial step needing more substeps is refused (almost surely a unit or sign error)."""

SHAPE_PARAMS = (
    Param("k0", "initial stiffness", "force/displacement (e.g. kN/mm)", POSITIVE),
    Param("fy", "yield force scale: hysteretic force is (1-alpha)*fy*z", "force (e.g. kN)",
          POSITIVE),
    Param("alpha", "post-yield to initial stiffness ratio", "-", within(0.0, 1.0)),
    Param("n", "sharpness of the elastic-plastic transition", "-", at_least(1.0)),
    Param("beta", "weight of the sign(dd*z) term (loading/unloading shape)", "-", POSITIVE),
    Param("gamma", "weight of the constant term (beta + gamma > 0)", "-", FINITE),
)
"""The parameters the Bouc-Wen family shares (``bwbn`` starts with the same six)."""


class BoucWenState(NamedTuple):
    """Committed state of a :class:`BoucWen` specimen."""

    d: float
    f: float
    k: float
    """Tangent stiffness at the committed point."""
    z: float
    """Hysteretic variable (dimensionless)."""


class BoucWenFamily(HysteresisBase):
    """What the Bouc-Wen kinds share: the six shape parameters and their relation, the
    integration setting ``dz_max``, dy and the elastic/hysteretic force split."""

    __slots__ = (
        "_dy", "_f_hyst", "_k_el", "_k_hyst", "alpha", "beta", "dz_max", "fy", "gamma", "k0", "n",
    )  # fmt: skip

    k0: float
    fy: float
    alpha: float
    n: float
    beta: float
    gamma: float

    def _init_family(self, dz_max: float, **params: float) -> None:
        self._init_params(**params)
        self.dz_max = DZ_MAX.check(self.name, dz_max)
        self._dy = self.fy / self.k0
        self._k_el = self.alpha * self.k0
        self._k_hyst = (1.0 - self.alpha) * self.k0
        self._f_hyst = (1.0 - self.alpha) * self.fy

    def _check_relations(self) -> None:
        if self.beta + self.gamma <= 0.0:
            raise ModelParameterError(
                self.name, f"beta + gamma must be > 0, got {self.beta!r} + {self.gamma!r}", "gamma"
            )

    def _settings(self) -> dict[str, Any]:
        return {"dz_max": self.dz_max}

    @property
    def yield_displacement(self) -> float:
        """dy = fy / k0."""
        return self._dy

    @property
    def committed_z(self) -> float:
        """Committed hysteretic variable z (dimensionless)."""
        return self._committed[3]


class BoucWen(BoucWenFamily):
    """Bouc-Wen hysteresis with a dimensionless hysteretic variable z (see module docstring)."""

    __slots__ = ("A", "_bound_coef", "_loading", "_unloading", "z_ultimate")

    name = "bouc-wen"
    PARAMS = (
        *SHAPE_PARAMS,
        Param("A", "initial slope of z against d/dy", "-", POSITIVE, 1.0),
    )
    STATE = BoucWenState

    A: float

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
        self._init_family(dz_max, k0=k0, fy=fy, alpha=alpha, n=n, beta=beta, gamma=gamma, A=A)
        self._loading = self.beta + self.gamma  # coefficient when sign(du*z) = +1
        self._unloading = self.gamma - self.beta  # coefficient when sign(du*z) = -1
        self._bound_coef = self.n * (self.beta + abs(self.gamma))
        self.z_ultimate: float = (self.A / self._loading) ** (1.0 / self.n)
        self._start()

    def _virgin(self) -> tuple[float, ...]:
        return (0.0, 0.0, self.initial_tangent, 0.0)

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
        d_c, f_c, k_c, z_c = self._committed
        du = (d - d_c) / self._dy
        if not math.isfinite(du):
            raise trial_input_error(self.name, d)
        if du == 0.0:
            self._trial = self._committed
            return f_c, k_c
        z = self._advance(z_c, du)
        force = self._k_el * d + self._f_hyst * z
        tangent = self._k_el + self._k_hyst * self._slope(z, 1.0 if du > 0.0 else -1.0)
        self._trial = (d, force, tangent, z)
        return force, tangent

    @property
    def initial_tangent(self) -> float:
        return self._k_el + self._k_hyst * self.A
