"""What every setup offers the site, and OpenFresco's per-signal scale factors.

A setup turns *trial* signals (the element's basic DOFs) into *ctrl* signals (actuator
commands) and *daq* signals back into *out* signals. The site calls ``ctrl_disp`` on every
trial, ``out_disp``/``basic_force`` on every answer and ``basic_matrix`` for the stiffness
requests; velocities and accelerations are there for controllers that take them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

Values = tuple[float, ...]


class SetupError(ValueError):
    """The setup cannot serve an element of this size, or its geometry is impossible."""


class Setup(Protocol):
    """The kinematic map between an element's basic DOFs and the actuators."""

    @property
    def kind(self) -> str: ...
    @property
    def n_basic(self) -> int: ...
    @property
    def n_actuators(self) -> int: ...
    @property
    def identity(self) -> bool:
        """ctrl = trial and out = daq: the site may skip every call."""
        ...

    def ctrl_disp(self, trial_disp: Values) -> Values: ...
    def ctrl_vel(self, trial_disp: Values, trial_vel: Values) -> Values: ...
    def ctrl_accel(self, trial_disp: Values, trial_vel: Values,
                   trial_accel: Values) -> Values: ...
    def out_disp(self, trial_disp: Values, ctrl: Values, daq_disp: Values) -> Values: ...
    def out_vel(self, daq_vel: Values) -> Values: ...
    def out_accel(self, daq_accel: Values) -> Values: ...
    def basic_force(self, daq_force: Values, daq_disp: Values | None = None) -> Values: ...
    def basic_matrix(self, k_act: Values) -> Values: ...


SIGNALS = ("Disp", "Vel", "Accel", "Force", "Time")
SIDES = ("trial", "out", "ctrl", "daq")


def factor_keys() -> tuple[str, ...]:
    """``trialDispFact`` … ``daqTimeFact``: OpenFresco's twenty scale-factor options."""
    return tuple(f"{side}{sig}Fact" for side in SIDES for sig in SIGNALS)


@dataclass(frozen=True, slots=True)
class Factors:
    """Scale factors of one setup, by OpenFresco's option name without the dash.

    OpenFresco multiplies trial signals before the transformation and ctrl signals after it;
    daq signals before the way back and out signals after it. One number scales every
    component, a list one factor per component (``-trialDispFact 1 -1 1``).
    """

    given: tuple[tuple[str, tuple[float, ...]], ...] = ()

    @property
    def none(self) -> bool:
        return not self.given

    def get(self, key: str, n: int) -> tuple[float, ...] | None:
        """The factors of ``key`` for an ``n``-component signal (None: all ones)."""
        for name, values in self.given:
            if name == key:
                if len(values) == 1:
                    return values * n
                if len(values) != n:
                    raise SetupError(f"{key}: {len(values)} factors for a signal of {n} "
                                     "components (give one number or one per component)")
                return values
        return None

    def check(self, sizes: dict[str, int]) -> None:
        """Every given factor fits its signal (``sizes``: side → components)."""
        for name, _ in self.given:
            side = next(s for s in SIDES if name.startswith(s))
            n = 1 if name.endswith("TimeFact") else sizes[side]
            self.get(name, n)


def scale(values: Values, factors: Sequence[float] | None) -> Values:
    if factors is None:
        return values
    return tuple(v * f for v, f in zip(values, factors, strict=True))
