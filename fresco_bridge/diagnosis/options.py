"""How to diagnose: the options a user gives (``diagnose``'s flags) and their defaults."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from .names import AUTO, EFFECT_NAMES

__all__ = ["CALIBRATION_FRACTION", "MAX_FIT_SAMPLES", "NOISE_FLOOR_PCT", "Options", "Policy"]

CALIBRATION_FRACTION = 0.6
"""The share of the command's signal energy the calibration part carries (``split``)."""
NOISE_FLOOR_PCT = 1.0
"""The withheld gap (NRMS %) below which the verdict is ``none`` (``--noise-floor``)."""
MAX_FIT_SAMPLES = 6000
"""Longer calibration parts are thinned for the fits (every k-th sample and every reversal of
the command: the same path for a rate-independent law); scoring uses every sample."""

@dataclass(frozen=True)
class Policy:
    """What remains of policy once the withheld evidence chooses (``decision``): what is too
    small to hear about, what noise a lab ordinarily has, and how sure is "sure". Every other
    choice is the one selection rule (docs/diagnosis.md, "The selection rule")."""

    noise_floor_pct: float = NOISE_FLOOR_PCT
    """The withheld gap (NRMS % of the record's RMS force and command) below which nothing is
    named, and the smallest change of the prediction an effect must make to be heard
    (``--noise-floor``): the user's resolution, not the record's."""
    ordinary_noise_pct: float = 2.0
    """White noise (std) a lab's channel ordinarily carries, in % of the channel's peak: a
    conditioned strain-gauge load cell or an LVDT reads to about 0.1 % of its full scale, and a
    test uses a third to a tenth of the capacity of its load cell and stroke, with pickup from
    the hydraulics on top. Noise up to this level is a property of the record (``none``);
    above it, ``sensor_noise`` is an effect."""
    two_story_delta: float = 2.0
    """Two stories are both named when their evidence (BIC on the withheld part) differs by at
    most this: a Bayes factor below e (Kass & Raftery: "not worth more than a bare mention")."""
    low_confidence: float = 0.5
    """Below this weight the confidence words say "low" (and the verdict is usually two
    stories)."""
    high_confidence: float = 0.8
    """From this weight on the words say "high" (between the two: "moderate")."""
    flag_factor: float = 0.5
    """The confidence is multiplied by this for each parameter of the winner the record does
    not measure (at a bound, or a relative std above ``scored.MAX_RELATIVE_STD``)."""


@dataclass(frozen=True)
class Options:
    """How to diagnose: baseline law (and optional given parameters), floor, candidates."""

    baseline: str = AUTO
    """A law of ``BASELINES``, or ``auto``: chosen on the calibration part (``baseline``)."""
    baseline_params: Mapping[str, float] = field(default_factory=dict)
    fit_baseline: bool = True
    """False: the given ``baseline_params`` are the sim, held (a PARAMS.toml with fit = false)."""
    policy: Policy = field(default_factory=Policy)
    calibration_fraction: float = CALIBRATION_FRACTION
    effects: Sequence[str] = EFFECT_NAMES
    pairs: bool = True
    max_fit_samples: int = MAX_FIT_SAMPLES

    @property
    def noise_floor_pct(self) -> float:
        return self.policy.noise_floor_pct
