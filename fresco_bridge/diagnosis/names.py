"""The names a user types: baselines and candidate effects (light: the CLI imports it at start)."""

from __future__ import annotations

__all__ = ["BASELINES", "EFFECT_NAMES"]

BASELINES = ("bilinear", "bouc-wen", "bwbn")
EFFECT_NAMES = ("actuator_delay", "actuator_amplitude", "backlash", "friction", "pinching",
                "degradation", "rate_dependence", "sensor_bias", "sensor_noise")
"""The candidate effects, in the order they are reported (``none`` is the baseline alone)."""
