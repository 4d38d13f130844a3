"""The names a user types: baselines and candidate effects (light: the CLI imports it at start)."""

from __future__ import annotations

__all__ = ["AUTO", "AUTO_FAMILIES", "BASELINES", "EFFECT_NAMES"]

BASELINES = ("bilinear", "bouc-wen", "bwbn", "menegotto-pinto", "steel02", "isotropic-bilinear",
             "elastic")
"""The laws a baseline can be: every kind of the ``sim_actuator.models`` registry (all have a
fast drive; the elastic spring drives as a bilinear with alpha = 1), ``steel02`` (the
``menegotto-pinto`` kind with its symmetric isotropic hardening a1 = a3 fitted) and
``isotropic-bilinear`` (``sim_actuator.models.IsotropicBilinear``: kinematic plus saturating
isotropic hardening)."""
AUTO = "auto"
"""``--baseline auto`` (the default): the tool chooses the law on the calibration part."""
AUTO_FAMILIES = ("bilinear", "bouc-wen", "menegotto-pinto", "isotropic-bilinear", "steel02")
"""What ``auto`` chooses from: the specimen laws without an effect built in (BWBN's pinching and
degradation are candidate effects, so a BWBN baseline would hide them)."""
EFFECT_NAMES = ("actuator_delay", "actuator_amplitude", "actuator_undershoot", "backlash",
                "friction", "pinching", "degradation", "rate_dependence", "sensor_bias",
                "sensor_noise")
"""The candidate effects, in the order they are reported (``none`` is the baseline alone)."""
