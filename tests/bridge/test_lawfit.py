"""The one home of fitting a law (``fresco_bridge.lawfit``): the calibrated Bilinear recovers a
known Bilinear, also from noisy forces; the bounded solver stays inside its bounds; the
multi-start keeps the best scouted start."""

from __future__ import annotations

import numpy as np
import pytest

from fresco_bridge.lawfit import bounded_least_squares, calibrate_bilinear, law_forces, multi_start
from sim_actuator.models import Bilinear

TRUE = {"k0": 8.0, "fy": 12.0, "alpha": 0.05}


@pytest.mark.parametrize("noise", [0.0, 0.15])
def test_the_calibrated_bilinear_recovers_a_known_bilinear(noise: float) -> None:
    t = np.arange(1500) * 0.01
    disp = 12.0 * np.minimum(1.0, t / 5.0) * np.sin(2.0 * t) * (1.0 + 0.3 * np.sin(0.7 * t))
    force = law_forces(Bilinear(**TRUE), disp)
    noisy = force + np.random.default_rng(1).normal(0.0, noise, disp.size)
    fitted = calibrate_bilinear(disp, noisy)
    for name, value in TRUE.items():
        assert fitted[name] == pytest.approx(value, rel=0.03), name


def test_calibration_refuses_mismatched_histories() -> None:
    with pytest.raises(ValueError, match="equal 1-D"):
        calibrate_bilinear(np.zeros(20), np.zeros(19))


def test_the_bounded_solver_starts_clipped_and_stops_at_the_bound() -> None:
    """The unconstrained minimum (3, -2) lies outside; the fit ends on the bound it crosses."""
    target = np.array([3.0, -2.0])
    lower, upper = np.array([0.0, -1.0]), np.array([5.0, 1.0])
    fit = bounded_least_squares(lambda x: x - target, [9.0, 9.0], lower, upper,
                                scale=np.ones(2), max_nfev=50)  # fmt: skip
    assert fit.success
    assert fit.x == pytest.approx([3.0, -1.0], abs=1e-6)
    assert fit.residual == pytest.approx([0.0, 1.0], abs=1e-6)
    assert fit.jacobian.shape == (2, 2)


def test_multi_start_fits_the_best_scouted_start_to_the_end() -> None:
    calls: list[tuple[float, int]] = []

    def fit(start: float, evaluations: int) -> tuple[float, float]:
        calls.append((start, evaluations))
        return start + 0.5, abs(start - 2.0)  # (where it stopped, its cost)

    best = multi_start(fit, [0.0, 2.0, 6.0, 2.0], cost=lambda r: r[1], resume=lambda r: r[0],
                       scout=3, final=40)  # fmt: skip
    assert calls == [(0.0, 3), (2.0, 3), (6.0, 3), (2.0, 3), (2.5, 40)]
    assert best == (3.0, 0.5)
