"""The online-refit infrastructure (``updating.refit``): compression keeps a rate-independent
law's states, the fit recovers a known law, the updater refits on schedule with material
semantics for its twin and its clones, and bad input changes nothing."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import pytest

from fresco_bridge.lawfit import FitSpace, LawFamily, fit_law, law_forces
from fresco_bridge.updating.base import Updater, UpdaterError, UpdaterInputError
from fresco_bridge.updating.refit import RefitUpdater, compress
from sim_actuator.models import Bilinear, HysteresisModel
from tests.support.histories import ramped_sines
from tests.support.material import assert_material_semantics

LAW = {"k0": 6.0, "fy": 10.0, "alpha": 0.04}


def _build(p: Mapping[str, float]) -> HysteresisModel:
    return Bilinear(**p)


def _space(disp: np.ndarray, force: np.ndarray) -> FitSpace:
    return FitSpace(start=(4.0, 6.0, 0.1), lower=(1.0, 1.0, 0.0), upper=(20.0, 30.0, 0.5),
                    scale=(1.0, 1.0, 0.01))  # fmt: skip


BILINEAR = LawFamily("bilinear", ("k0", "fy", "alpha"), _build, _space)


path = ramped_sines


def test_compression_keeps_every_reversal_and_the_last_sample() -> None:
    d = np.array([0.0, 1.0, 2.0, 2.0, 1.0, 0.0, -1.0, 0.5, 0.7, 0.8])
    keep = compress(d, 4).tolist()
    assert keep == [0, 3, 4, 6, 8, 9]  # stride 0, 4, 8; reversals at 3 (after a flat step), 6
    assert compress(np.zeros(0), 3).size == 0


def test_a_compressed_history_gives_a_rate_independent_law_the_same_state() -> None:
    d = path(2000, 5.0, 1)
    full = law_forces(Bilinear(**LAW), d)
    keep = compress(d, 7)
    assert keep.size < d.size / 3
    assert np.allclose(law_forces(Bilinear(**LAW), d[keep]), full[keep], rtol=0, atol=1e-9)


def test_the_fit_recovers_a_known_law_from_its_history() -> None:
    d = path(800, 8.0, 2)
    f = law_forces(Bilinear(**LAW), d)
    x = fit_law(BILINEAR, [(d, f, 1.0)], _space(d, f), max_nfev=100)
    assert BILINEAR.params(x) == pytest.approx(LAW, rel=1e-3)


def test_a_law_that_rejects_a_parameter_set_scores_the_penalty() -> None:
    d = path(100, 8.0, 2)
    f = law_forces(Bilinear(**LAW), d)
    bad = FitSpace(start=(6.0, 10.0, 2.0), lower=(1.0, 1.0, 1.5), upper=(20.0, 30.0, 3.0),
                   scale=(1.0, 1.0, 0.1))  # fmt: skip
    x = fit_law(BILINEAR, [(d, f, 1.0)], bad, max_nfev=3, penalty=1e3)
    assert np.all(np.isfinite(x))  # alpha >= 1 is refused by Bilinear: no crash, a penalty


@pytest.fixture()
def updater() -> RefitUpdater:
    d = path(300, 8.0, 1)
    off = {"k0": 5.0, "fy": 8.0, "alpha": 0.1}  # the offline law differs from the online one
    return RefitUpdater(BILINEAR, offline=(d, law_forces(Bilinear(**off), d)), every=100,
                        warmup=100, max_nfev=30, offline_weight=0.0)  # fmt: skip


def test_the_updater_is_an_updater_and_its_twin_a_material(updater: RefitUpdater) -> None:
    assert isinstance(updater, Updater)
    assert_material_semantics(updater.twin)


def test_refits_move_the_law_and_the_twin_and_its_clones_follow(updater: RefitUpdater) -> None:
    assert updater.parameters == pytest.approx({"k0": 5.0, "fy": 8.0, "alpha": 0.1}, rel=1e-2)
    d_src, d_twin = path(300, 8.0, 3), path(300, 6.0, 4)
    f_src = law_forces(Bilinear(**LAW), d_src)
    twin = updater.twin
    shadow = twin.clone()
    for i in range(299):
        updater.observe(float(d_src[i]), float(f_src[i]))
        twin.set_trial(float(d_twin[i]))
        twin.set_trial(float(d_twin[i]) + 1.0)  # a second trial advances nothing
        twin.set_trial(float(d_twin[i]))
        twin.commit()
        shadow.set_trial(float(d_twin[i]))
        shadow.commit()
    assert updater.refits == 2
    assert updater.parameters == pytest.approx(LAW, rel=1e-3)
    truth = law_forces(Bilinear(**LAW), d_twin[:299])
    assert twin.committed[1] == pytest.approx(truth[-1], abs=1e-6)
    assert shadow.committed[1] == pytest.approx(truth[-1], abs=1e-6)
    assert updater.predict(float(d_src[299])) == pytest.approx(f_src[299], abs=1e-6)
    assert updater.last_update_seconds >= 0.0


@pytest.mark.parametrize("bad", [(math.nan, 1.0), (1.0, math.inf)])
def test_non_finite_measurements_are_refused_and_change_nothing(
    updater: RefitUpdater, bad: tuple[float, float]
) -> None:
    updater.observe(1.0, 5.0)
    state = updater.source_twin().committed
    with pytest.raises(UpdaterInputError, match="finite"):
        updater.observe(*bad)
    assert updater.source_twin().committed == state


@pytest.mark.parametrize(
    ("offline", "options", "match"),
    [
        ((np.zeros(5), np.zeros(5)), {}, "20 samples"),
        ((np.full(30, math.nan), np.zeros(30)), {}, "NaN"),
        ((np.zeros(30), np.zeros(30)), {"every": 0}, ">= 1"),
        ((np.zeros(30), np.zeros(30)), {"offline_weight": -1.0}, "offline_weight"),
        ((np.zeros(30), np.zeros(30)), {"every": 300, "window": 200}, "window must be >= every"),
    ],
)
def test_bad_construction_is_a_clear_error(offline: tuple[np.ndarray, np.ndarray],
                                           options: dict[str, float], match: str) -> None:
    with pytest.raises(UpdaterError, match=match):
        RefitUpdater(BILINEAR, offline=offline, **options)  # type: ignore[arg-type]



def test_a_windowed_refit_learns_from_the_window_start_state_and_keeps_bounded_memory() -> None:
    """A window shorter than the run: each refit replays only the last ``window`` steps, from
    the law's state before them (not from rest), so it still identifies the law after yield;
    the windows hold at most ``window`` samples; shorter than the window, the run is fitted
    exactly as with an unbounded one."""
    d = path(1200, 8.0, 5)
    f = law_forces(Bilinear(**LAW), d)
    off = path(300, 8.0, 1)
    offline = (off, law_forces(Bilinear(k0=5.0, fy=8.0, alpha=0.1), off))
    options = {"every": 100, "warmup": 100, "max_nfev": 30, "offline_weight": 0.0}
    short = RefitUpdater(BILINEAR, offline=offline, window=200, **options)  # type: ignore[arg-type]
    unbounded = RefitUpdater(BILINEAR, offline=offline, window=10**6, **options)  # type: ignore[arg-type]
    for i in range(d.size):
        short.observe(float(d[i]), float(f[i]))
        unbounded.observe(float(d[i]), float(f[i]))
        short.twin.set_trial(0.7 * float(d[i]))
        short.twin.commit()
        if i == 150:  # before the window fills: the same fit as on the whole history
            assert short.parameters == unbounded.parameters
    assert short.parameters == pytest.approx(LAW, rel=1e-3)
    assert len(short._history) == 200 and len(short._twin._window) == 200  # type: ignore[attr-defined]
    truth = law_forces(Bilinear(**LAW), 0.7 * d)
    assert short.twin.committed[1] == pytest.approx(truth[-1], abs=1e-6)


def test_the_fast_window_forces_are_the_laws_own() -> None:
    """``forces_from`` (the JIT kernel from a committed state) gives the objects' forces to the
    bit, for both online laws, from a state after yield."""
    from fresco_bridge.updating.bilinear import _build as bilinear_law
    from fresco_bridge.updating.bilinear import _forces_from as bilinear_from
    from fresco_bridge.updating.degrading import _build as baber_wen_law
    from fresco_bridge.updating.degrading import _forces_from as baber_wen_from

    d = path(1500, 10.0, 6)
    baber_wen = {"k0": 8.0, "fy": 12.0, "alpha": 0.05, "n": 2.0, "beta": 0.5,
                 "delta_nu": 1e-3, "delta_eta": 1e-3}  # fmt: skip
    for build, fast, params in ((bilinear_law, bilinear_from, LAW),
                                (baber_wen_law, baber_wen_from, baber_wen)):
        model = build(params)
        law_forces(model, d[:700])
        state = model.state()  # type: ignore[attr-defined]
        np.testing.assert_array_equal(fast(params, d[700:], state), law_forces(model, d[700:]))
