"""``online_improved``: material semantics, bad input, learning on a known law, bounded noise,
the mixture of experts and its pieces (branch memory, first-loading stiffness)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fresco_bridge.updating.base import Updater, UpdaterError, UpdaterInputError
from fresco_bridge.updating.branch import BranchMemory, BranchRls, initial_stiffness
from fresco_bridge.updating.improved import EXPERTS, OnlineImproved
from sim_actuator.models import make_model
from tests.support.material import assert_material_semantics

LAW = {"k0": 8.0, "fy": 12.0, "alpha": 0.03, "R0": 12.0, "a1": 0.03, "a3": 0.03}


def drive(path: np.ndarray) -> np.ndarray:
    model = make_model("menegotto-pinto", **LAW)
    out = []
    for d in path.tolist():
        out.append(model.set_trial(d)[0])
        model.commit()
    return np.array(out)


def cyclic(n: int, amplitude: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    envelope = np.minimum(1.0, t / 4.0)
    phase = rng.uniform(0.0, 6.0)
    return np.asarray(amplitude * envelope * (np.sin(2.3 * t) + 0.4 * np.sin(5.1 * t + phase)))


@pytest.fixture()
def updater() -> OnlineImproved:
    d = cyclic(1500, 10.0, 1)
    return OnlineImproved(offline=(d, drive(d)))


def test_it_is_an_updater_with_material_semantics(updater: OnlineImproved) -> None:
    assert isinstance(updater, Updater)
    assert_material_semantics(updater.twin)
    assert 4.0 < updater.twin.initial_tangent < 12.0  # learned: the law's k0 is 8


@pytest.mark.parametrize("bad", [(math.nan, 1.0), (1.0, math.inf), (-math.inf, 0.0)])
def test_non_finite_measurements_are_refused_and_change_nothing(
    updater: OnlineImproved, bad: tuple[float, float]
) -> None:
    updater.observe(1.0, 7.0)
    scores = updater.scores.copy()
    residual = updater.experts[2].residual  # type: ignore[attr-defined]
    weights = [e.weights.copy() for e in (updater.experts[0], updater.experts[1], residual)]
    law_state = updater.experts[2]._source.committed  # type: ignore[attr-defined]
    twin = updater.twin.set_trial(2.0)
    with pytest.raises(UpdaterInputError, match="finite"):
        updater.observe(*bad)
    assert np.array_equal(updater.scores, scores)
    after = [e.weights for e in (updater.experts[0], updater.experts[1], residual)]
    assert all(np.array_equal(a, b) for a, b in zip(after, weights, strict=True))
    assert updater.experts[2]._source.committed == law_state  # type: ignore[attr-defined]
    assert updater.twin.set_trial(2.0) == twin
    updater.observe(1.5, 9.0)  # still usable


def test_bad_offline_data_is_a_clear_error() -> None:
    with pytest.raises(UpdaterError, match="equal 1-D"):
        OnlineImproved(offline=(np.zeros(30), np.zeros(29)))
    with pytest.raises(UpdaterError, match="NaN"):
        OnlineImproved(offline=(np.full(30, np.nan), np.zeros(30)))
    with pytest.raises(UpdaterError, match="move"):
        OnlineImproved(offline=(np.zeros(30), np.zeros(30)))


def test_the_twin_learns_the_law_on_another_history(updater: OnlineImproved) -> None:
    """Tested and twin see different histories of one law; the twin's error shrinks."""
    tested = cyclic(2000, 12.0, 2)
    force = drive(tested)
    twin_path = 0.6 * cyclic(2000, 12.0, 3)
    truth = drive(twin_path)
    errors = []
    for d, f, dw in zip(tested.tolist(), force.tolist(), twin_path.tolist(), strict=True):
        updater.observe(d, f)
        errors.append(updater.twin.set_trial(dw)[0])
        updater.twin.commit()
    err = np.abs(np.array(errors) - truth)
    peak = float(np.max(np.abs(truth)))
    first, second = float(np.max(err[:1000])), float(np.max(err[1000:]))
    assert first < 0.3 * peak  # the twin's first loading, before much is learned
    assert second < 0.15 * peak and second < 0.5 * first
    assert updater.last_update_seconds >= 0.0


def test_noise_and_spikes_keep_the_twin_bounded(updater: OnlineImproved) -> None:
    rng = np.random.default_rng(7)
    tested = cyclic(3000, 12.0, 4)
    force = drive(tested) + rng.normal(0.0, 0.5, tested.size)
    force[::97] += 40.0  # load-cell spikes
    peak = 0.0
    for d, f in zip(tested.tolist(), force.tolist(), strict=True):
        updater.observe(d, f)
        peak = max(peak, abs(updater.twin.set_trial(0.5 * d)[0]))
        updater.twin.commit()
    assert math.isfinite(peak) and peak < 30.0


def test_unknown_or_repeated_experts_are_a_clear_error() -> None:
    d = cyclic(300, 10.0, 1)
    for bad in ("reversal,plays", "", "reversal,reversal"):
        with pytest.raises(UpdaterError, match="experts must be distinct names"):
            OnlineImproved(offline=(d, drive(d)), experts=bad)
    with pytest.raises(UpdaterError, match="mixing"):
        OnlineImproved(offline=(d, drive(d)), experts="reversal", mixing=1.0)


def test_the_mixture_weights_the_expert_that_predicts_the_tested_element_better() -> None:
    """A basis without memory terms against one with them, on a law whose branches depend on
    the previous excursion: weights sum to 1 and follow the one-step innovations."""
    d = cyclic(1500, 10.0, 1)
    updater = OnlineImproved(offline=(d, drive(d)), experts="reversal,reversal+memory")
    w0 = updater.mixture_weights()
    assert w0.sum() == pytest.approx(1.0) and np.allclose(w0, 0.5)
    tested = cyclic(1500, 12.0, 2)
    for x, f in zip(tested.tolist(), drive(tested).tolist(), strict=True):
        updater.observe(x, f)
    w = updater.mixture_weights()
    assert w.sum() == pytest.approx(1.0)
    best = int(np.argmin(updater.scores))
    assert w[best] == w.max() and w[best] > 0.5
    expected = updater.scores**-2.0 / np.sum(updater.scores**-2.0)
    np.testing.assert_allclose(w, expected)


def test_a_single_expert_mixture_is_that_expert_or_the_offline_start() -> None:
    """The twin serves the one expert, or the offline start (the calibrated Bilinear) while
    the expert's accumulated free-run error is the larger (do no harm), each on the twin's
    whole history."""
    d = cyclic(600, 10.0, 1)
    mixture = OnlineImproved(offline=(d, drive(d)), experts="reversal")
    alone = BranchRls(offline=(d, drive(d)))
    start = make_model("bilinear", **mixture.start_params)
    tested = cyclic(400, 12.0, 2)
    served = []
    for x, f in zip(tested.tolist(), drive(tested).tolist(), strict=True):
        mixture.observe(x, f)
        alone.observe(x, f)
        expected = (start if mixture.serving_start else alone.twin).set_trial(0.5 * x)[0]
        (alone.twin if mixture.serving_start else start).set_trial(0.5 * x)
        assert mixture.twin.set_trial(0.5 * x)[0] == pytest.approx(expected)
        served.append(mixture.serving_start)
        for twin in (mixture.twin, alone.twin, start):
            twin.commit()
    assert not served[-1]  # the expert learned this law far better than a Bilinear


def test_branch_memory_remembers_the_previous_branch() -> None:
    m = BranchMemory()
    for d, f in ((1.0, 8.0), (2.0, 10.0), (1.5, 6.0)):
        m = m.advanced(d, f)
    # the branch 0 -> 2 ended at the reversal (2, 10); the current one started there
    assert (m.d_r, m.f_r, m.prev_dd, m.prev_df) == (2.0, 10.0, 2.0, 10.0)
    assert m.reversal(3.0) and not m.reversal(1.0) and not m.reversal(1.5)
    assert m.previous_branch(3.0) == (1.5 - 2.0, 6.0 - 10.0)  # a trial that reverses again
    assert m.previous_branch(1.0) == (2.0, 10.0)
    assert (m.d_max, m.d_min, m.travel) == (2.0, 0.0, 2.5)


def test_initial_stiffness_is_the_first_loading_slope() -> None:
    d = np.concatenate([np.linspace(0.0, 1.0, 11), np.linspace(1.0, 10.0, 10)])
    f = np.where(d <= 1.0, 8.0 * d, 8.0 + 0.5 * (d - 1.0))  # elastic 8, then hardening
    assert initial_stiffness(d, f) == pytest.approx(8.0)


def test_every_expert_is_available() -> None:
    assert EXPERTS == ("reversal", "reversal+memory", "bouc-wen+memory", "reversal+stops",
                       "baber-wen", "bilinear")
    d = cyclic(300, 10.0, 1)
    optional = OnlineImproved(offline=(d, drive(d)), experts="reversal+memory+stops")
    assert optional.expert_names == ("reversal+memory+stops",)
