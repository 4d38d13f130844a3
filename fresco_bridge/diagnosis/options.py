"""How to diagnose: the options a user gives (``diagnose``'s flags) and their defaults."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from .names import AUTO, EFFECT_NAMES

__all__ = ["CALIBRATION_FRACTION", "MAX_FIT_SAMPLES", "NOISE_FLOOR_PCT", "Options"]

CALIBRATION_FRACTION = 0.6
"""The share of the command's signal energy the calibration part carries (``split``)."""
NOISE_FLOOR_PCT = 1.0
"""The withheld gap (NRMS %) below which the verdict is ``none`` (``--noise-floor``)."""
MAX_FIT_SAMPLES = 6000
"""Longer calibration parts are thinned for the fits (every k-th sample and every reversal of
the command: the same path for a rate-independent law); scoring uses every sample."""

@dataclass(frozen=True)
class Options:
    """How to diagnose: baseline law (and optional given parameters), floor, candidates."""

    baseline: str = AUTO
    """A law of ``BASELINES``, or ``auto``: chosen on the calibration part (``baseline``)."""
    baseline_params: Mapping[str, float] = field(default_factory=dict)
    fit_baseline: bool = True
    """False: the given ``baseline_params`` are the sim, held (a PARAMS.toml with fit = false)."""
    noise_floor_pct: float = NOISE_FLOOR_PCT
    calibration_fraction: float = CALIBRATION_FRACTION
    effects: Sequence[str] = EFFECT_NAMES
    pairs: bool = True
    max_fit_samples: int = MAX_FIT_SAMPLES
