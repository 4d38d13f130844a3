"""The Bouc-Wen expert of ``online_improved``: the fit recovers a known law, the expert is an
updater with material semantics, and bad input changes nothing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fresco_bridge.updating.base import Updater, UpdaterError, UpdaterInputError
from fresco_bridge.updating.physics import PhysicsResidual, bouc_wen_forces, fit_bouc_wen
from tests.support.histories import ramped_sines
from tests.support.material import assert_material_semantics

LAW = {"k0": 6.0, "fy": 10.0, "alpha": 0.04, "n": 2.0, "beta": 0.6, "gamma": 0.4}


path = ramped_sines


def test_the_fit_recovers_a_bouc_wen_law_from_its_own_history() -> None:
    d = path(600, 8.0, 1)
    f = bouc_wen_forces(LAW, d)
    fitted = fit_bouc_wen(d, f)
    rms = float(np.sqrt(np.mean((bouc_wen_forces(fitted, d) - f) ** 2)))
    assert rms < 0.02 * float(np.max(np.abs(f)))
    # the law, not just the curve: another history is predicted as well
    other = path(600, 6.0, 2)
    err = np.max(np.abs(bouc_wen_forces(fitted, other) - bouc_wen_forces(LAW, other)))
    assert err < 0.05 * float(np.max(np.abs(f)))


def test_offline_data_that_never_loads_is_a_clear_error() -> None:
    with pytest.raises(UpdaterError, match="Bouc-Wen"):
        fit_bouc_wen(np.linspace(0.0, 1.0, 50), np.zeros(50))


@pytest.fixture()
def expert() -> PhysicsResidual:
    d = path(400, 8.0, 1)
    return PhysicsResidual(offline=(d, bouc_wen_forces(LAW, d)), law=LAW)


def test_trial_and_commit_semantics(expert: PhysicsResidual) -> None:
    assert isinstance(expert, Updater)
    assert_material_semantics(expert.twin)


def test_the_prediction_commits_nothing_and_the_law_alone_is_exact(
    expert: PhysicsResidual,
) -> None:
    """With the true law, the residual basis has nothing to learn: predictions are the law's."""
    d = path(300, 7.0, 3)
    f = bouc_wen_forces(LAW, d)
    for x, y in zip(d.tolist(), f.tolist(), strict=True):
        assert expert.predict(x) == pytest.approx(expert.predict(x))
        assert expert.predict(x) == pytest.approx(y, abs=0.05)
        expert.observe(x, y)


@pytest.mark.parametrize("bad", [(math.nan, 1.0), (1.0, math.inf)])
def test_non_finite_measurements_are_refused_and_change_nothing(
    expert: PhysicsResidual, bad: tuple[float, float]
) -> None:
    expert.observe(1.0, 5.0)
    weights = expert.residual.weights.copy()
    state = expert._source.committed
    with pytest.raises(UpdaterInputError, match="finite"):
        expert.observe(*bad)
    assert np.array_equal(expert.residual.weights, weights)
    assert expert._source.committed == state
