"""The Baber-Wen law refitted online (``updating.degrading``): its fast drive is the law, a fit
recovers a known Baber-Wen law from its own history, the twin is a material whose state is its
own, the family excludes pinching, bad input is refused, and online_improved takes it as an
expert."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fresco_bridge.lawfit import fit_law, law_forces
from fresco_bridge.updating.base import Updater, UpdaterError, UpdaterInputError
from fresco_bridge.updating.degrading import BABER_WEN, baber_wen_refit
from fresco_bridge.updating.improved import OnlineImproved
from tests.support.histories import ramped_sines as path
from tests.support.material import assert_material_semantics

LAW = {"k0": 7.5, "fy": 11.0, "alpha": 0.05, "n": 1.3, "beta": 0.6, "delta_nu": 0.003,
       "delta_eta": 0.005}  # fmt: skip


def test_the_fast_drive_is_the_law() -> None:
    d = path(1500, 12.0, 1)
    slow = law_forces(BABER_WEN.build(LAW), d)
    assert BABER_WEN.forces is not None
    fast = BABER_WEN.forces(LAW, d)
    assert np.max(np.abs(fast - slow)) < 1e-9 * np.max(np.abs(slow))


def test_the_family_has_no_pinching_and_degrades_with_energy() -> None:
    model = BABER_WEN.build(LAW)
    assert model.parameters["zeta_s"] == 0.0  # type: ignore[attr-defined]
    d = path(3000, 15.0, 2)
    f = law_forces(model, d)
    first, last = slice(200, 900), slice(2100, 3000)
    assert np.max(np.abs(f[last])) < np.max(np.abs(f[first]))  # strength lost with energy


def test_a_fit_recovers_a_known_baber_wen_law_from_its_history() -> None:
    d = path(1500, 12.0, 3)
    f = law_forces(BABER_WEN.build(LAW), d)
    x = fit_law(BABER_WEN, [(d, f, 1.0)], BABER_WEN.space(d, f), max_nfev=300)
    fitted = BABER_WEN.params(x)
    other = path(1500, 9.0, 4)  # another history of the same law
    error = law_forces(BABER_WEN.build(fitted), other) - law_forces(BABER_WEN.build(LAW), other)
    assert np.max(np.abs(error)) < 1e-3 * np.max(np.abs(f))
    assert fitted == pytest.approx(LAW, rel=1e-3)


def _updater() -> Updater:
    d = path(600, 12.0, 5)
    return baber_wen_refit((d, law_forces(BABER_WEN.build(LAW), d)), every=100, warmup=100)


def test_the_twin_is_a_material_on_its_own_history() -> None:
    updater = _updater()
    assert isinstance(updater, Updater)
    assert_material_semantics(updater.twin)
    d_src, d_twin = path(400, 12.0, 6), path(400, 7.0, 7)
    f_src = law_forces(BABER_WEN.build(LAW), d_src)
    twin = updater.twin
    for i in range(400):
        updater.observe(float(d_src[i]), float(f_src[i]))
        first = twin.set_trial(float(d_twin[i]))
        twin.set_trial(float(d_twin[i]) + 2.0)  # a second trial advances nothing
        assert twin.set_trial(float(d_twin[i])) == first
        twin.commit()
    truth = law_forces(BABER_WEN.build(LAW), d_twin)
    assert twin.committed[1] == pytest.approx(truth[-1], abs=1e-3 * np.max(np.abs(truth)))


@pytest.mark.parametrize("bad", [(math.nan, 1.0), (1.0, -math.inf)])
def test_non_finite_measurements_are_refused(bad: tuple[float, float]) -> None:
    updater = _updater()
    with pytest.raises(UpdaterInputError, match="finite"):
        updater.observe(*bad)


def test_offline_data_that_never_load_are_a_clear_error() -> None:
    with pytest.raises(UpdaterError, match="Baber-Wen"):
        baber_wen_refit((np.zeros(50), np.zeros(50)))


def test_online_improved_takes_it_as_a_fifth_expert() -> None:
    d = path(600, 12.0, 8)
    mix = OnlineImproved(offline=(d, law_forces(BABER_WEN.build(LAW), d)),
                         experts="reversal,baber-wen")  # fmt: skip
    assert mix.expert_names == ("reversal", "baber-wen")
    assert_material_semantics(mix.twin)
