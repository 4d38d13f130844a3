"""Kinematic plus saturating isotropic hardening: the yield force grows and levels off."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from sim_actuator.models import IsotropicBilinear, ModelInputError, ModelParameterError


def _cycle_peaks(model: IsotropicBilinear, amplitude: float, cycles: int) -> list[float]:
    peaks = []
    cycle = np.concatenate([np.linspace(0.0, amplitude, 50), np.linspace(amplitude, -amplitude,
                                                                         100)[1:],
                            np.linspace(-amplitude, 0.0, 50)[1:]])
    for _ in range(cycles):
        forces = []
        for d in cycle:
            model.set_trial(float(d))
            model.commit()
            forces.append(model.committed[1])
        peaks.append(max(forces))
    return peaks


def test_the_yield_force_grows_to_its_saturated_value() -> None:
    """Elastic-perfectly-plastic kinematically (alpha = 0): the peak force of constant-amplitude
    cycles rises from fy towards fy (1 + q_iso) and the rise slows down."""
    model = IsotropicBilinear(k0=10.0, fy=5.0, alpha=0.0, q_iso=0.6, p_sat=20.0)
    peaks = _cycle_peaks(model, 3.0, 12)
    assert peaks[0] > 5.0
    assert all(b > a for a, b in itertools.pairwise(peaks))
    assert peaks[-1] == pytest.approx(8.0, rel=1e-2)
    assert peaks[1] - peaks[0] > 10.0 * (peaks[-1] - peaks[-2])


def test_elastic_inside_the_yield_surface_and_tangent_after_yield() -> None:
    model = IsotropicBilinear(k0=10.0, fy=5.0, alpha=0.1, q_iso=0.5, p_sat=4.0)
    force, tangent = model.set_trial(0.3)
    assert (force, tangent) == (pytest.approx(3.0), 10.0)  # type: ignore[comparison-overlap]
    force, tangent = model.set_trial(2.0)
    h = 0.1 * 10.0 / 0.9
    assert 5.0 < force < 20.0
    assert 10.0 * h / (10.0 + h) < tangent < 10.0
    eps = 1e-7
    model.revert_to_last_commit()
    f_plus, _ = model.set_trial(2.0 + eps)
    assert (f_plus - force) / eps == pytest.approx(tangent, rel=1e-4)
    model.commit()
    assert model.state()[3] > 0.0  # the accumulated plastic displacement


def test_bad_parameters_and_input_are_refused() -> None:
    with pytest.raises(ModelParameterError, match="q_iso"):
        IsotropicBilinear(k0=10.0, fy=5.0, alpha=0.1, q_iso=-0.1)
    with pytest.raises(ModelParameterError, match="alpha"):
        IsotropicBilinear(k0=10.0, fy=5.0, alpha=1.0)
    with pytest.raises(ModelInputError):
        IsotropicBilinear(k0=10.0, fy=5.0, alpha=0.1).set_trial(math.nan)
