"""Unmodelled effects between the actuator and the specimen, and the sensors that measure them.

The load path, from the reaction frame to the specimen, quasi-static (no inertia)::

    frame (stiffness kf) -- actuator piston x -- load cell -- fixture p (friction)
        -- connection with play (gap g each side) -- specimen u (hysteresis model)

* Frame compliance: the actuator body moves back under load, so the fixture sits at
  ``p = x - F/kf`` where ``x`` is the piston stroke the servo controls and ``F`` the load-cell
  force. With an elastic specimen ``k`` the load cell therefore sees ``F = x*k*kf/(k + kf)``.
* Fixture friction (Coulomb ``Fc`` and viscous ``c``) acts on the fixture between load cell and
  specimen, so the load cell measures it: ``F = F_connection + Fc*sign(p') + c*p'``. While the
  fixture sticks the friction force is whatever equilibrium needs, within ``[-Fc, Fc]``; with a
  rigid frame it keeps its last slip value (the limit of a stiff frame).
* Backlash: the pin has a clearance of ``g`` on each side. The connection carries force only in
  contact; after the specimen force returns to zero the fixture travels ``2g`` with zero
  connection force before it picks the specimen up on the other side. Requires a specimen whose
  tangent is never negative (true for every model in ``sim_actuator.models``).

Every substep is solved for the fixture position by a safeguarded Newton iteration on a
residual that is monotone with slope >= 1 (so the bracket is known a priori), and the specimen
is then committed at its displacement: the specimen follows the physical path.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from sim_actuator.checks import NON_NEGATIVE, POSITIVE, checked

__all__ = [
    "EffectParameterError",
    "LoadPath",
    "LoadPathSolveError",
    "LoadPathState",
    "Sensor",
    "SpecimenModel",
]

_TOL_D = 1e-12  # relative displacement tolerance of the substep solves
_MAX_ITER = 200


class EffectParameterError(ValueError):
    """An effect parameter is out of range (names the effect and the parameter)."""


class LoadPathSolveError(RuntimeError):
    """The substep equilibrium did not converge (reports the fixture bracket and residual)."""


class SpecimenModel(Protocol):
    """What the load path needs from a hysteresis model (``sim_actuator.models``)."""

    def set_trial(self, d: float) -> tuple[float, float]: ...

    def commit(self) -> None: ...

    @property
    def committed(self) -> tuple[float, float]: ...


def _check(effect: str, name: str, value: float, *, positive: bool = False) -> float:
    return checked(POSITIVE if positive else NON_NEGATIVE, name, value, EffectParameterError,
                   effect)


@dataclass(frozen=True, slots=True)
class LoadPathState:
    """The solved state of one substep (all true values, before any sensor)."""

    fixture: float
    """Fixture (piston rod end) position p, mm."""
    specimen_displacement: float
    """Specimen displacement u, mm."""
    connection_force: float
    """Force through the pin into the specimen, kN (exactly 0 inside the gap)."""
    friction_force: float
    """Fixture friction force, kN."""
    in_gap: bool
    """True when the pin is free inside its clearance."""

    @property
    def load_cell_force(self) -> float:
        """What the load cell carries: connection plus friction, kN."""
        return self.connection_force + self.friction_force


class LoadPath:
    """Frame compliance, fixture friction and backlash around a specimen model."""

    def __init__(
        self,
        specimen: SpecimenModel,
        *,
        dt: float,
        gap: float = 0.0,
        coulomb: float = 0.0,
        viscous: float = 0.0,
        frame_stiffness: float | None = None,
    ) -> None:
        self.specimen = specimen
        self.dt = _check("load path", "dt", dt, positive=True)
        self.gap = _check("backlash", "gap", gap)
        self.coulomb = _check("friction", "coulomb", coulomb)
        self.viscous = _check("friction", "viscous", viscous)
        self.frame_stiffness = (
            None if frame_stiffness is None
            else _check("frame compliance", "stiffness", frame_stiffness, positive=True)
        )
        d0, f0 = specimen.committed
        self._p = d0
        self._sign = 0.0  # sign of the last fixture slip (Coulomb memory)
        self._free = self.gap > 0.0 and f0 == 0.0
        self.state = LoadPathState(d0, d0, 0.0 if self._free else f0, 0.0, self._free)

    @property
    def is_kinematic(self) -> bool:
        """True when the specimen is driven exactly by the piston (no effect active)."""
        return (
            self.gap == 0.0 and self.coulomb == 0.0 and self.viscous == 0.0
            and self.frame_stiffness is None
        )

    # -- one substep ------------------------------------------------------------------------

    def impose(self, x: float) -> LoadPathState:
        """Kinematic shortcut (no effect active): one specimen increment straight to ``x``."""
        if not self.is_kinematic:
            raise RuntimeError("LoadPath.impose is only valid when no effect is active")
        force, _ = self.specimen.set_trial(x)
        self.specimen.commit()
        self._p = x
        self.state = LoadPathState(x, x, force, 0.0, False)
        return self.state

    def step(self, x: float) -> LoadPathState:
        """Solve equilibrium for piston position ``x`` at the next substep, then commit it."""
        if self.frame_stiffness is None:
            p = x
            velocity = (p - self._p) / self.dt
            if velocity > 0.0:
                self._sign = 1.0
            elif velocity < 0.0:
                self._sign = -1.0
            friction = self.coulomb * self._sign + self.viscous * velocity
        else:
            p, friction = self._solve_compliant(x, self.frame_stiffness)
        self._finish(p, friction)
        return self.state

    def settle_at_rest(self) -> None:
        """Forget the fixture velocity (after a trip the fixture is held where it is)."""
        self._p = self.state.fixture

    # -- internals --------------------------------------------------------------------------

    def _connection(self, p: float) -> tuple[float, float, int]:
        """Connection force, its slope dF/dp, and contact side (+1, -1, or 0 = free)."""
        g = self.gap
        if g == 0.0:
            force, tangent = self.specimen.set_trial(p)
            return force, tangent, 1
        f_lo, k_lo = self.specimen.set_trial(p - g)
        if f_lo > 0.0:
            return f_lo, k_lo, 1
        f_hi, k_hi = self.specimen.set_trial(p + g)
        if f_hi < 0.0:
            return f_hi, k_hi, -1
        return 0.0, 0.0, 0

    def _solve_compliant(self, x: float, kf: float) -> tuple[float, float]:
        """Fixture position and friction force with a compliant frame (stick or slip)."""
        p0, fc, c, dt = self._p, self.coulomb, self.viscous, self.dt
        phi0, _, _ = self._connection(p0)
        r0 = p0 - x + phi0 / kf  # residual without friction at the old position
        if r0 - fc / kf <= 0.0 <= r0 + fc / kf:  # static friction holds the fixture
            return p0, kf * (x - p0) - phi0
        sign = 1.0 if r0 + fc / kf < 0.0 else -1.0

        def residual(p: float) -> tuple[float, float]:
            phi, slope, _ = self._connection(p)
            value = p - x + (phi + sign * fc + c * (p - p0) / dt) / kf
            return value, 1.0 + (slope + c / dt) / kf

        # residual(p0 +- 0) has the slip sign's value and the slope is >= 1, so one residual
        # length away on the slip side brackets the root.
        start = r0 + sign * fc / kf
        lo, hi = (p0, p0 - start) if sign > 0.0 else (p0 - start, p0)
        p = _solve_monotone(residual, lo, hi, guess=x, scale=1.0 + abs(x), what="fixture")
        self._sign = sign
        return p, sign * fc + c * (p - p0) / dt

    def _finish(self, p: float, friction: float) -> None:
        """Place the specimen for fixture position ``p``, commit it, record the state."""
        g = self.gap
        force, _, side = self._connection(p)
        if g == 0.0:
            u = p
        elif side > 0:
            u = p - g
        elif side < 0:
            u = p + g
        else:
            u = self._free_position(p)
        self.specimen.set_trial(u)
        self.specimen.commit()
        self._free = side == 0 and g > 0.0
        self._p = p
        self.state = LoadPathState(p, u, force if side != 0 else 0.0, friction, self._free)

    def _free_position(self, p: float) -> float:
        """Where the unloaded specimen rests while the pin is inside its clearance."""
        g = self.gap
        d_c, _ = self.specimen.committed
        if self._free and p - g <= d_c <= p + g:
            return d_c  # already at zero force, and still inside the clearance

        def force(u: float) -> tuple[float, float]:
            return self.specimen.set_trial(u)

        guess = min(max(d_c, p - g), p + g)
        return _solve_monotone(force, p - g, p + g, guess=guess, scale=1.0 + abs(p),
                               what="free specimen")


def _solve_monotone(
    fun: Callable[[float], tuple[float, float]],
    lo: float,
    hi: float,
    *,
    guess: float,
    scale: float,
    what: str,
) -> float:
    """Root of a non-decreasing ``fun`` (value, slope) with ``fun(lo) <= 0 <= fun(hi)``.

    Newton steps, replaced by bisection whenever they leave the bracket.
    """
    tol = _TOL_D * scale
    p = min(max(guess, lo), hi)
    value = 0.0
    for _ in range(_MAX_ITER):
        value, slope = fun(p)
        if value == 0.0:
            return float(p)
        if value > 0.0:
            hi = p
        else:
            lo = p
        if hi - lo <= tol:
            return float(p)
        step_to = p - value / slope if slope > 0.0 else math.nan
        if not lo < step_to < hi:
            step_to = 0.5 * (lo + hi)
        if abs(step_to - p) <= tol:
            return float(step_to)
        p = step_to
    raise LoadPathSolveError(
        f"{what} equilibrium did not converge in {_MAX_ITER} iterations: "
        f"bracket [{lo!r}, {hi!r}], residual {value!r}"
    )


class Sensor:
    """A transducer channel: true value + bias + Gaussian noise from its own seeded stream."""

    def __init__(self, *, noise_std: float = 0.0, bias: float = 0.0,
                 rng: np.random.Generator | None = None) -> None:
        self.noise_std = _check("sensor", "noise_std", noise_std)
        bias_value = float(bias)
        if not math.isfinite(bias_value):
            raise EffectParameterError(f"sensor: bias must be finite, got {bias!r}")
        self.bias = bias_value
        if self.noise_std > 0.0 and rng is None:
            raise EffectParameterError("sensor: noise_std > 0 needs a seeded random generator")
        self._rng = rng

    def read(self, true_value: float, *, noisy: bool = True) -> float:
        """One sample; draws from the stream only when the channel is noisy and ``noisy``."""
        noise = 0.0
        if noisy and self.noise_std > 0.0 and self._rng is not None:
            noise = self.noise_std * float(self._rng.standard_normal())
        return true_value + self.bias + noise
