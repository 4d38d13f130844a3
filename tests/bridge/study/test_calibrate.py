"""The calibrated Bilinear recovers a known Bilinear, also from noisy forces."""

from __future__ import annotations

import numpy as np
import pytest

from fresco_bridge.study.calibrate import calibrate_bilinear
from sim_actuator.models import Bilinear

TRUE = {"k0": 8.0, "fy": 12.0, "alpha": 0.05}


@pytest.mark.parametrize("noise", [0.0, 0.15])
def test_recovers_a_known_bilinear(noise: float) -> None:
    t = np.arange(1500) * 0.01
    disp = 12.0 * np.minimum(1.0, t / 5.0) * np.sin(2.0 * t) * (1.0 + 0.3 * np.sin(0.7 * t))
    model = Bilinear(**TRUE)
    force = []
    for d in disp.tolist():
        force.append(model.set_trial(d)[0])
        model.commit()
    noisy = np.array(force) + np.random.default_rng(1).normal(0.0, noise, disp.size)
    fitted = calibrate_bilinear(disp, noisy)
    for name, value in TRUE.items():
        assert fitted[name] == pytest.approx(value, rel=0.03), name


def test_refuses_mismatched_histories() -> None:
    with pytest.raises(ValueError, match="equal 1-D"):
        calibrate_bilinear(np.zeros(20), np.zeros(19))
