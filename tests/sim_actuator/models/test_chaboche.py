"""Chaboche-type law: closed-form limits, exact steps, trial/commit semantics, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_actuator.models import Bilinear, HysteresisModel, ModelInputError, ModelParameterError
from sim_actuator.models.chaboche import Chaboche
from tests.support.histories import ramped_sines
from tests.support.material import assert_material_semantics

LAW = {"k0": 8.0, "fy": 12.0, "C1": 6.0, "gamma1": 1.5, "C2": 1.0, "gamma2": 0.1, "C3": 0.2,
       "gamma3": 0.01, "kh": 0.2, "Q": -6.0, "b": 0.3, "hm": 0.2}  # fmt: skip


path = ramped_sines


def run(model: HysteresisModel, disp: np.ndarray) -> np.ndarray:
    out = np.empty(disp.size)
    for i, d in enumerate(disp.tolist()):
        out[i] = model.set_trial(d)[0]
        model.commit()
    return out


def test_virgin_yield_is_sharp_at_fy() -> None:
    model = Chaboche(**LAW)
    dy = LAW["fy"] / LAW["k0"]
    assert model.set_trial(0.999 * dy) == pytest.approx((0.999 * LAW["fy"], LAW["k0"]))
    force, tangent = model.set_trial(1.001 * dy)
    assert force == pytest.approx(LAW["fy"], rel=1e-3) and tangent < 0.7 * LAW["k0"]


def test_linear_kinematic_hardening_alone_is_the_bilinear_law() -> None:
    k0, fy, kh = 8.0, 12.0, 0.4
    d = path(3000, 9.0, 1)
    bilinear = Bilinear(k0=k0, fy=fy, alpha=kh / (k0 + kh))
    expected = run(bilinear, d)
    assert np.allclose(run(Chaboche(k0=k0, fy=fy, kh=kh), d), expected, rtol=0.0, atol=1e-9)


def test_a_step_is_exact_whatever_its_size() -> None:
    """A monotonic segment in one step or in a hundred gives the same state."""
    fine, coarse = Chaboche(**LAW), Chaboche(**LAW)
    run(fine, np.linspace(0.0, 9.0, 101)[1:])
    run(coarse, np.array([9.0]))
    assert fine.state() == pytest.approx(coarse.state(), rel=1e-9, abs=1e-9)
    run(fine, np.linspace(9.0, -7.0, 101)[1:])
    run(coarse, np.array([-7.0]))
    assert fine.state() == pytest.approx(coarse.state(), rel=1e-9, abs=1e-9)


def test_the_tangent_is_the_consistent_one() -> None:
    model = Chaboche(**LAW)
    run(model, path(700, 9.0, 2))
    for d in (model.committed[0] + 0.3, model.committed[0] - 0.3, model.committed[0] + 4.0):
        force, tangent = model.set_trial(d)
        ahead = model.set_trial(d + 1e-7)[0]
        assert tangent == pytest.approx((ahead - force) / 1e-7, rel=1e-4, abs=1e-6)


def test_a_shrinking_elastic_range_yields_earlier_after_plastic_flow() -> None:
    model = Chaboche(k0=8.0, fy=12.0, Q=-9.0, b=0.5)  # no hardening: the range is 2 (fy + R)
    run(model, np.linspace(0.0, 20.0, 50))
    f_top = model.committed[1]
    assert f_top == pytest.approx(3.0, rel=1e-3)  # 12 - 9 (1 - exp(-0.5 p)), p ~ 18.5
    force, tangent = model.set_trial(model.committed[0] - 0.5)  # elastic unloading
    assert tangent == 8.0 and force == pytest.approx(f_top - 4.0)


def test_trial_and_commit_semantics() -> None:
    assert_material_semantics(Chaboche(**LAW))
    model = Chaboche(**LAW)
    d = path(400, 9.0, 3)
    reference = run(Chaboche(**LAW), d)
    for i, x in enumerate(d.tolist()):
        model.set_trial(x + 5.0)
        model.set_trial(x - 5.0)
        assert model.set_trial(x)[0] == reference[i]
        model.commit()
    assert Chaboche(**LAW).with_params({}, model.state()).committed == model.committed


@pytest.mark.parametrize(
    ("params", "name"),
    [
        ({"k0": 0.0}, "k0"),
        ({"C1": -1.0}, "C1"),
        ({"gamma2": 0.0}, "gamma2"),
        ({"Q": -12.0}, "Q"),
        ({"Q": -6.0, "b": 2.0}, "b"),
        ({"hm": math.nan}, "hm"),
    ],
)
def test_bad_parameters_are_refused_by_name(params: dict[str, float], name: str) -> None:
    with pytest.raises(ModelParameterError) as info:
        Chaboche(**{**LAW, **params})
    assert info.value.parameter == name


def test_non_finite_trials_are_refused() -> None:
    model = Chaboche(**LAW)
    with pytest.raises(ModelInputError, match="finite"):
        model.set_trial(math.inf)
    assert model.committed == (0.0, 0.0)


def test_the_elastic_range_follows_the_length_of_the_previous_excursion() -> None:
    """Qe: the range shrinks along a long excursion and stays shrunk (symmetric about the
    back-force) for the reversal; after a short one the next branch yields late."""

    def reverse_yield(amplitude: float) -> tuple[float, float]:
        model = Chaboche(k0=8.0, fy=12.0, Qe=-8.0, be=0.5)  # no hardening: back-force 0
        run(model, np.array([amplitude]))
        top = model.committed[1]
        for d in np.linspace(amplitude, amplitude - 4.0, 4001)[1:].tolist():
            if model.set_trial(d)[1] < 8.0:
                return top, top - model.committed[1]
            model.commit()
        return top, math.inf

    top, drop = reverse_yield(10.0)
    p = 10.0 - top / 8.0
    assert top == pytest.approx(12.0 - 8.0 * (1.0 - math.exp(-0.5 * p)), rel=1e-9)
    assert drop == pytest.approx(2.0 * top, abs=0.01) and top < 4.2
    top, drop = reverse_yield(1.6)
    assert drop == pytest.approx(2.0 * top, abs=0.01) and top > 11.0
