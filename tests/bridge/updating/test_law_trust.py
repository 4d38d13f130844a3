"""``online_improved``'s ``law_trust``: a law expert that explains the tested element's whole
history takes all the weight; one that does not is weighed by the mixture as before; the twin
stays a material either way."""

from __future__ import annotations

import numpy as np
import pytest

from fresco_bridge.lawfit import law_forces
from fresco_bridge.updating.base import UpdaterError
from fresco_bridge.updating.degrading import BABER_WEN
from fresco_bridge.updating.improved import LAW_TRUST, OnlineImproved
from fresco_bridge.updating.refit import RefitUpdater, compress
from sim_actuator.models import make_model
from tests.support.histories import ramped_sines as path
from tests.support.material import assert_material_semantics

BABER_WEN_LAW = {"k0": 7.5, "fy": 11.0, "alpha": 0.05, "n": 1.3, "beta": 0.6,
                 "delta_nu": 0.003, "delta_eta": 0.005}  # fmt: skip
SHARP_LAW = {"k0": 8.0, "fy": 12.0, "alpha": 0.03, "R0": 12.0, "a1": 0.03, "a3": 0.03}
"""Menegotto-Pinto with a sharp yield and isotropic hardening: outside the Baber-Wen family."""


def _forces(exact: bool, d: np.ndarray) -> np.ndarray:
    if exact:
        return law_forces(BABER_WEN.build(BABER_WEN_LAW), d)
    return law_forces(make_model("menegotto-pinto", **SHARP_LAW), d)


def _run(exact: bool, law_trust: float = LAW_TRUST) -> OnlineImproved:
    """Offline database and 400 tested steps (a refit at 50 and 350) of one law."""
    d = path(600, 12.0, 5)
    mix = OnlineImproved(offline=(d, _forces(exact, d)), experts="reversal,baber-wen",
                         law_trust=law_trust)  # fmt: skip
    tested = path(400, 14.0, 6)
    for x, f in zip(tested.tolist(), _forces(exact, tested).tolist(), strict=True):
        mix.observe(x, f)
    return mix


def test_an_exact_law_takes_all_the_weight_and_the_twin_is_the_laws() -> None:
    mix = _run(exact=True)
    law = mix.experts[1]
    assert isinstance(law, RefitUpdater) and law.refits == 2
    assert law.misfit < 1e-3 * law.force_peak  # the family contains this law
    assert mix.trusted == 1
    np.testing.assert_array_equal(mix.mixture_weights(), [0.0, 1.0])
    assert_material_semantics(mix.twin)
    for x in (3.0, -5.0, 8.0):
        assert mix.twin.set_trial(x) == law.twin.set_trial(x)
        mix.twin.commit()
        law.twin.commit()


def test_a_wrong_law_leaves_the_mixture_as_it_was() -> None:
    mix = _run(exact=False)
    law = mix.experts[1]
    assert isinstance(law, RefitUpdater)
    assert law.misfit > LAW_TRUST * law.force_peak  # a sharp yield the family cannot make
    assert mix.trusted is None
    expected = mix.scores**-2.0 / np.sum(mix.scores**-2.0)
    np.testing.assert_allclose(mix.mixture_weights(), expected)
    assert_material_semantics(mix.twin)


def test_law_trust_zero_is_the_plain_mixture() -> None:
    mix = _run(exact=True, law_trust=0.0)
    assert mix.trusted is None
    expected = mix.scores**-2.0 / np.sum(mix.scores**-2.0)
    np.testing.assert_allclose(mix.mixture_weights(), expected)


def test_the_misfit_is_measured_over_the_whole_history_fitted() -> None:
    """After the offline fit, ``misfit`` is the rms error on the offline data; after refits,
    on the offline and online data together (equal weights)."""
    d = path(600, 12.0, 5)
    f = _forces(False, d)
    mix = OnlineImproved(offline=(d, f), experts="baber-wen")
    law = mix.experts[0]
    assert isinstance(law, RefitUpdater) and law.refits == 0
    assert law.force_peak == pytest.approx(np.max(np.abs(f)))
    keep = compress(d, law.stride)
    assert BABER_WEN.forces is not None
    error = BABER_WEN.forces(law.parameters, d[keep]) - f[keep]
    assert law.misfit == pytest.approx(float(np.sqrt(np.mean(error**2))), rel=1e-9)
    tested = path(400, 14.0, 6)
    for x, y in zip(tested.tolist(), _forces(False, tested).tolist(), strict=True):
        mix.observe(x, y)
    assert law.refits == 2  # at 50 and 350 steps: the misfit is the last refit's
    seen = tested[:350]
    online_keep = compress(seen, law.stride)
    seen_f = _forces(False, seen)
    assert law.force_peak == pytest.approx(max(np.max(np.abs(f)), np.max(np.abs(seen_f))))
    fitted = np.concatenate([BABER_WEN.forces(law.parameters, d[keep]),
                             BABER_WEN.forces(law.parameters, seen[online_keep])])
    error = fitted - np.concatenate([f[keep], seen_f[online_keep]])
    assert law.misfit == pytest.approx(float(np.sqrt(np.mean(error**2))), rel=1e-6)


@pytest.mark.parametrize("bad", [-0.1, 1.0, float("nan")])
def test_a_bad_law_trust_is_a_clear_error(bad: float) -> None:
    d = path(300, 12.0, 5)
    with pytest.raises(UpdaterError, match="law_trust"):
        OnlineImproved(offline=(d, _forces(True, d)), experts="reversal", law_trust=bad)
