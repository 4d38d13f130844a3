"""The one set of parameter checks: a real, finite number within a range.

A :class:`Bound` says what a parameter may be, both as a check (``bound.check(name, value)``
returns the value as a float or raises :class:`ParameterRangeError` with the reason) and as text
for documentation (``bound.describe(name)`` → ``"> 0"``, ``"0 <= alpha < 1"``). Callers wrap the
reason in their own error type, which names the model, stage or effect (``"bilinear: fy must be
> 0, got -3"``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "FINITE",
    "NON_NEGATIVE",
    "POSITIVE",
    "Bound",
    "ParameterRangeError",
    "at_least",
    "checked",
    "within",
]


class ParameterRangeError(ValueError):
    """A parameter is not a real number, not finite, or out of its range (the reason)."""


@dataclass(frozen=True, slots=True)
class Bound:
    """Allowed values of a real parameter: finite, and ``low <(=) value <(=) high`` when set."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    """True: the value must be strictly greater than ``low``."""
    high_open: bool = True
    """True: the value must be strictly less than ``high``."""

    def describe(self, name: str) -> str:
        """The range as text: ``> 0``, ``>= 1``, ``0 <= alpha < 1``, or ``finite``."""
        low_op = "<" if self.low_open else "<="
        high_op = "<" if self.high_open else "<="
        if self.low is not None and self.high is not None:
            return f"{self.low:g} {low_op} {name} {high_op} {self.high:g}"
        if self.low is not None:
            return f"{'>' if self.low_open else '>='} {self.low:g}"
        if self.high is not None:
            return f"{high_op} {self.high:g}"
        return "finite"

    def check(self, name: str, value: object) -> float:
        """``value`` as a float, or :class:`ParameterRangeError` saying why it is refused."""
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ParameterRangeError(
                f"{name} must be a real number, got {value!r} ({type(value).__name__})"
            )
        result = float(value)
        if not math.isfinite(result):
            raise ParameterRangeError(f"{name} must be finite, got {value!r}")
        low, high = self.low, self.high
        too_low = low is not None and (result <= low if self.low_open else result < low)
        too_high = high is not None and (result >= high if self.high_open else result > high)
        if too_low or too_high:
            text = self.describe(name)
            verb = "satisfy" if low is not None and high is not None else "be"
            raise ParameterRangeError(f"{name} must {verb} {text}, got {value!r}")
        return result


FINITE = Bound()
POSITIVE = Bound(low=0.0, low_open=True)
NON_NEGATIVE = Bound(low=0.0)


def at_least(low: float) -> Bound:
    """``value >= low``."""
    return Bound(low=low)


def within(low: float, high: float) -> Bound:
    """``low <= value < high``."""
    return Bound(low=low, high=high)


def checked(bound: Bound, name: str, value: object, error: type[Exception], where: str) -> float:
    """``bound.check`` with the reason raised as ``error("<where>: <reason>")`` (the caller's
    error type, naming its stage, effect or indicator)."""
    try:
        return bound.check(name, value)
    except ParameterRangeError as exc:
        raise error(f"{where}: {exc}") from None
