"""Numbers for people: the one formatter of the command line's summaries and the reports.

Significant digits, not fixed decimals nor ``repr``; float dust (``-2.434e-19`` s of a delay
that is zero, ``-0.00``) printed as the zero it is; ``–`` for a value that is missing or
undefined (a ratio over a zero, a NaN). The files a command writes (JSON, CSV) keep every
digit; only what a person reads goes through here. Standard library only.
"""

from __future__ import annotations

import math
from typing import SupportsFloat

__all__ = ["DUST", "UNDEFINED", "fmt", "pct", "rounded"]

UNDEFINED = "–"
"""What stands for a missing or undefined number."""
DUST = 1e-12
"""Below this magnitude a value is rounding noise, not a measurement (units mm, kN, s, %)."""


def _value(v: SupportsFloat | None) -> float | None:
    if v is None:
        return None
    x = float(v)
    return x if math.isfinite(x) else None


def fmt(v: SupportsFloat | None, unit: str = "", digits: int = 4) -> str:
    """``v`` to ``digits`` significant digits (``12.35``, ``0.0001235``, ``1.235e+06``), with
    `` unit`` when given; ``0`` for float dust; :data:`UNDEFINED` for None, NaN, inf."""
    x = _value(v)
    if x is None:
        return UNDEFINED
    if abs(x) < DUST:
        x = 0.0
    text = f"{x:.{digits}g}"
    if float(text) == 0.0:
        text = "0"  # never "-0"
    return f"{text} {unit}" if unit else text


def pct(v: SupportsFloat | None, decimals: int = 2) -> str:
    """A percentage with ``decimals`` decimals (``12.34 %``); never ``-0.00 %``;
    :data:`UNDEFINED` for None, NaN, inf."""
    x = _value(v)
    if x is None:
        return UNDEFINED
    text = f"{x:.{decimals}f}"
    if float(text) == 0.0:
        text = f"{0.0:.{decimals}f}"
    return f"{text} %"


def rounded(v: float, digits: int = 4) -> float:
    """``v`` kept to ``digits`` significant digits, for a number a person reads in JSON
    (``5.887515649000079`` -> ``5.888``); float dust -> ``0.0``."""
    if not math.isfinite(v):
        return v
    return 0.0 if abs(v) < DUST else float(f"{v:.{digits}g}")
