"""Bouc-Wen with beta = gamma and an excursion-scheduled exponent: limits, the JIT drive, the
unloading tangent, the exponent schedule, trial/commit semantics, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_actuator.models import BoucWen, HysteresisModel, ModelInputError, ModelParameterError
from sim_actuator.models.excursion_bw import ExcursionBoucWen, drive
from tests.support.histories import ramped_sines
from tests.support.material import assert_material_semantics

LAW = {"k0": 8.0, "fy": 12.0, "alpha": 0.03, "n0": 10.0, "n_min": 1.5, "xi0": 0.5, "a": 0.03,
       "p": 0.8}  # fmt: skip


def run(model: HysteresisModel, disp: np.ndarray) -> np.ndarray:
    out = np.empty(disp.size)
    for i, d in enumerate(disp.tolist()):
        out[i] = model.set_trial(d)[0]
        model.commit()
    return out


@pytest.mark.parametrize("c", [0.0, 0.6, 1.0])
def test_the_jit_drive_is_the_law(c: float) -> None:
    model = ExcursionBoucWen(**LAW, c=c)
    d = ramped_sines(600, 9.0, 2)
    np.testing.assert_allclose(drive(model.vector(), d), run(model, d), rtol=0, atol=1e-12)


def test_a_constant_exponent_without_hardening_is_classic_bouc_wen() -> None:
    """c = 0, n0 = n_min, a = 0: Bouc-Wen with A = 1, beta = gamma = 1/2."""
    d = ramped_sines(500, 8.0, 1)
    ours = run(ExcursionBoucWen(k0=8.0, fy=12.0, alpha=0.03, n0=3.0, n_min=3.0, xi0=1.0), d)
    classic = run(BoucWen(k0=8.0, fy=12.0, alpha=0.03, n=3.0, beta=0.5, gamma=0.5), d)
    np.testing.assert_allclose(ours, classic, rtol=0, atol=1e-5)


@pytest.mark.parametrize("c", [0.0, 1.0])
def test_every_reversal_leaves_with_the_initial_stiffness(c: float) -> None:
    model = ExcursionBoucWen(**LAW, c=c)
    run(model, np.linspace(0.0, 6.0, 61))
    assert model.set_trial(5.999)[1] == pytest.approx(8.0, rel=1e-3)
    # c = 0: the whole unloading side (down to w = 0) is elastic; c = 1: it softens at once
    tangent = model.set_trial(5.0)[1]
    assert (tangent == pytest.approx(8.0)) if c == 0.0 else (tangent < 7.9)


def test_a_long_previous_excursion_rounds_the_next_transition() -> None:
    """The tangent on the next branch, at the same force change after the reversal, is lower
    after a long excursion (small n) than after a short one (n near n0)."""

    def tangent_after(amplitude: float) -> float:
        model = ExcursionBoucWen(**{**LAW, "a": 0.0}, c=1.0)
        run(model, np.linspace(0.0, amplitude, 200))
        top = model.committed[1]
        for d in np.linspace(amplitude, amplitude - 4.0, 4001)[1:].tolist():
            force, tangent = model.set_trial(d)
            if top - force >= 12.0:
                return tangent
            model.commit()
        raise AssertionError("no force change of 12")

    assert tangent_after(12.0) < 0.8 * tangent_after(1.8)


def test_monotonic_loading_tends_to_the_hardened_bound() -> None:
    model = ExcursionBoucWen(**LAW)
    force = run(model, np.linspace(0.0, 30.0, 3001))[-1]
    h = 1.0 + 0.03 * (15.0 / 1.5) ** 0.8
    bound = 0.03 * 8.0 * 30.0 + 0.97 * 12.0 * h  # w lags a little behind the growing h
    assert 0.0 < bound - force < 1e-3 * bound


def test_trial_and_commit_semantics() -> None:
    assert_material_semantics(ExcursionBoucWen(**LAW))
    model = ExcursionBoucWen(**LAW, c=0.5)
    d = ramped_sines(400, 9.0, 3)
    reference = run(ExcursionBoucWen(**LAW, c=0.5), d)
    for i, x in enumerate(d.tolist()):
        model.set_trial(x + 5.0)
        model.set_trial(x - 5.0)
        assert model.set_trial(x)[0] == reference[i]
        model.commit()
    clone = ExcursionBoucWen(**LAW, c=0.5).with_params({}, model.state())
    assert clone.committed == model.committed


@pytest.mark.parametrize(
    ("params", "name"),
    [
        ({"k0": 0.0}, "k0"),
        ({"alpha": 1.0}, "alpha"),
        ({"n_min": 12.0}, "n_min"),
        ({"xi0": 0.0}, "xi0"),
        ({"a": -0.1}, "a"),
        ({"c": 1.5}, "c"),
        ({"p": math.nan}, "p"),
    ],
)
def test_bad_parameters_are_refused_by_name(params: dict[str, float], name: str) -> None:
    with pytest.raises(ModelParameterError) as info:
        ExcursionBoucWen(**{**LAW, **params})
    assert info.value.parameter == name


def test_bad_trials_are_refused() -> None:
    model = ExcursionBoucWen(**LAW)
    with pytest.raises(ModelInputError, match="finite"):
        model.set_trial(math.nan)
    with pytest.raises(ModelInputError, match="substeps"):
        model.set_trial(1e9)
    assert model.committed == (0.0, 0.0)
    assert np.isnan(drive(model.vector(), np.array([1.0, 1e9, 2.0]))[1:]).all()
