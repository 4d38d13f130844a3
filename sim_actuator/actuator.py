"""Servo-hydraulic actuator stages, discretised exactly on the rig's fixed substep.

Sampling convention (shared by every stage): ``step(u)`` is called once per substep with the
reference sample ``u_k`` at time ``t_k = k*dt``; that sample is held over the interval
``(t_{k-1}, t_k]`` (zero-order hold) and ``step`` returns the stage output at ``t_k``.
With it an ideal stage is the identity (``y_k = u_k``), a pure delay of ``n*dt`` returns
``u_{k-n}`` exactly, and the lags reproduce their continuous step responses exactly at the
sample times (``1 - exp(-t/tau)`` for a step that starts acting at ``t = 0``).

The chain of an :class:`Actuator` is: reference -> amplitude factor -> pure delay -> servo
dynamics -> piston position (measured by the actuator's LVDT). Undershoot, after OpenFresco's
``ErrorSimUndershoot`` filter, shortens each move's end point against its direction of motion.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Protocol

from sim_actuator.checks import NON_NEGATIVE, POSITIVE, checked

__all__ = [
    "Actuator",
    "ActuatorParameterError",
    "FirstOrderLag",
    "IdealServo",
    "PureDelay",
    "SecondOrderServo",
    "ServoStage",
]


class ActuatorParameterError(ValueError):
    """An actuator stage parameter is out of range (names the stage and the parameter)."""


def _positive(stage: str, name: str, value: float) -> float:
    return checked(POSITIVE, name, value, ActuatorParameterError, stage)


def _non_negative(stage: str, name: str, value: float) -> float:
    return checked(NON_NEGATIVE, name, value, ActuatorParameterError, stage)


class ServoStage(Protocol):
    """A single-input single-output discrete stage advanced once per substep."""

    def step(self, u: float) -> float:
        """Advance one substep with input sample ``u``; return the output at the new time."""
        ...

    def reset(self, value: float) -> None:
        """Put the stage at rest with input and output equal to ``value``."""
        ...

    @property
    def is_identity(self) -> bool:
        """True when the stage passes its input through unchanged."""
        ...


class IdealServo:
    """Perfect position tracking: the piston is where the reference says."""

    @property
    def is_identity(self) -> bool:
        return True

    def step(self, u: float) -> float:
        return u

    def reset(self, value: float) -> None:
        del value


class PureDelay:
    """Transport delay ``y(t) = u(t - delay)``; fractional delays interpolate linearly."""

    def __init__(self, delay: float, dt: float, initial: float = 0.0) -> None:
        self.delay = _non_negative("pure delay", "delay", delay)
        self.dt = _positive("pure delay", "dt", dt)
        ratio = self.delay / self.dt
        whole = round(ratio)
        if abs(ratio - whole) <= 1e-9 * max(1.0, ratio):
            self._n, self._frac = int(whole), 0.0
        else:
            self._n, self._frac = math.floor(ratio), ratio - math.floor(ratio)
        self._history: deque[float] = deque()
        self.reset(initial)

    @property
    def samples(self) -> float:
        """The delay in substeps (may be fractional)."""
        return self._n + self._frac

    @property
    def is_identity(self) -> bool:
        return self._n == 0 and self._frac == 0.0

    def reset(self, value: float) -> None:
        # history[i] is u_{k-i} after the current sample is appended; keep n+2 samples.
        self._history = deque([float(value)] * (self._n + 2), maxlen=self._n + 2)

    def step(self, u: float) -> float:
        self._history.appendleft(u)
        if self._frac == 0.0:
            return self._history[self._n]
        newer, older = self._history[self._n], self._history[self._n + 1]
        return newer + self._frac * (older - newer)


class FirstOrderLag:
    """``tau*y' + y = u``, exact for a zero-order-held input: step response 1 - e^(-t/tau)."""

    def __init__(self, tau: float, dt: float, initial: float = 0.0) -> None:
        self.tau = _positive("first-order servo", "tau", tau)
        self.dt = _positive("first-order servo", "dt", dt)
        self._decay = math.exp(-self.dt / self.tau)
        self._y = float(initial)

    @property
    def is_identity(self) -> bool:
        return False

    def reset(self, value: float) -> None:
        self._y = float(value)

    def step(self, u: float) -> float:
        self._y = u + (self._y - u) * self._decay
        return self._y


class SecondOrderServo:
    """``y'' + 2*zeta*wn*y' + wn^2*y = wn^2*u`` (wn = 2*pi*fn), exact ZOH discretisation.

    The transition matrix is ``exp(A*dt) = e^(mu*dt) * (C*I + S*(A - mu*I))`` with ``mu`` half
    the trace of ``A`` and ``C, S = cosh(d*dt), sinh(d*dt)/d`` for ``d^2 = mu^2 - det(A)``
    (cos/sin when the system is underdamped, their limits when it is critically damped).
    """

    def __init__(self, natural_frequency: float, damping: float, dt: float,
                 initial: float = 0.0) -> None:
        stage = "second-order servo"
        self.natural_frequency = _positive(stage, "natural_frequency", natural_frequency)
        self.damping = _positive(stage, "damping", damping)
        self.dt = _positive(stage, "dt", dt)
        wn = 2.0 * math.pi * self.natural_frequency
        zeta = self.damping
        mu = -zeta * wn
        disc = mu * mu - wn * wn  # d^2, negative when underdamped
        h = self.dt
        if disc < 0.0:
            wd = math.sqrt(-disc)
            c, s = math.cos(wd * h), math.sin(wd * h) / wd
        elif disc > 0.0:
            d = math.sqrt(disc)
            c, s = math.cosh(d * h), math.sinh(d * h) / d
        else:
            c, s = 1.0, h
        e = math.exp(mu * h)
        # A = [[0, 1], [-wn^2, -2 zeta wn]], A - mu I = [[-mu, 1], [-wn^2, -2 zeta wn - mu]]
        self._p11 = e * (c - s * mu)
        self._p12 = e * s
        self._p21 = -e * s * wn * wn
        self._p22 = e * (c + s * (-2.0 * zeta * wn - mu))
        # Gamma = A^-1 (Phi - I) B with B = [0, wn^2]
        self._g1 = 1.0 - self._p22 - 2.0 * zeta * wn * self._p12
        self._g2 = wn * wn * self._p12
        self._y = float(initial)
        self._v = 0.0

    @property
    def is_identity(self) -> bool:
        return False

    def reset(self, value: float) -> None:
        self._y = float(value)
        self._v = 0.0

    def step(self, u: float) -> float:
        y, v = self._y, self._v
        self._y = self._p11 * y + self._p12 * v + self._g1 * u
        self._v = self._p21 * y + self._p22 * v + self._g2 * u
        return self._y


class Actuator:
    """Reference -> amplitude -> delay -> servo dynamics; plus stroke and force capacity."""

    def __init__(
        self,
        *,
        dt: float,
        stroke: float,
        force_capacity: float,
        amplitude: float = 1.0,
        undershoot: float = 0.0,
        delay: float = 0.0,
        servo: ServoStage | None = None,
    ) -> None:
        self.dt = _positive("actuator", "dt", dt)
        self.stroke = _positive("actuator", "stroke", stroke)
        self.force_capacity = _positive("actuator", "force_capacity", force_capacity)
        self.amplitude = _positive("actuator", "amplitude", amplitude)
        self.undershoot = _non_negative("actuator", "undershoot", undershoot)
        self.delay = PureDelay(delay, dt)
        self.servo: ServoStage = servo if servo is not None else IdealServo()
        self._last_direction = 0.0

    @property
    def is_ideal(self) -> bool:
        """True when the piston follows the reference exactly (no stage changes it)."""
        return (
            self.amplitude == 1.0
            and self.undershoot == 0.0
            and self.delay.is_identity
            and self.servo.is_identity
        )

    def end_point(self, target: float, start: float) -> float:
        """Where the reference of a move from ``start`` to ``target`` ends, after undershoot.

        ErrorSimUndershoot semantics: the end point falls short by ``undershoot`` against the
        direction of motion; a move of zero length keeps the previous move's direction.
        """
        if self.undershoot == 0.0:
            return target
        if target > start:
            self._last_direction = 1.0
        elif target < start:
            self._last_direction = -1.0
        return target - self.undershoot * self._last_direction

    def step(self, reference: float) -> float:
        """Advance one substep; return the piston position."""
        return self.servo.step(self.delay.step(self.amplitude * reference))

    def reset(self, position: float) -> None:
        """Re-initialise every stage at rest at ``position`` (bumpless transfer after a trip)."""
        self.delay.reset(position)
        self.servo.reset(position)
