"""Shadow scoring of ``online_improved`` (the state match by hand, the scorer on a known answer,
the updater with the option: material semantics, bad input, source twins) and the force-hinge
basis of the ``reversal+memory+hinges`` expert."""

from __future__ import annotations

import numpy as np
import pytest

from fresco_bridge.updating.base import UpdaterError, UpdaterInputError
from fresco_bridge.updating.branch import BranchRls, ReversalBasis, force_hinges
from fresco_bridge.updating.improved import OnlineImproved
from fresco_bridge.updating.shadow import (
    FreeRun,
    ShadowScorer,
    element_state,
    matched_start,
    stepper,
)
from sim_actuator.models import make_model
from tests.bridge.updating.test_online_improved import cyclic, drive
from tests.support.material import assert_material_semantics


def test_element_state_by_hand() -> None:
    span, amp = element_state(np.array([0.0, 1.0, -2.0, 0.5, 0.25]), 2)
    np.testing.assert_allclose(span, [0.0, 1.0, 3.0, 3.0, 3.0])
    np.testing.assert_allclose(amp, [0.0, 1.0, 2.0, 2.0, 0.5])
    with pytest.raises(UpdaterError, match="window"):
        element_state(np.zeros(3), 0)


def test_matched_start_finds_the_step_in_the_twins_state() -> None:
    """A tested history that grows 0 → 10 mm and a twin that reached 4 mm: the match is where
    the tested element's span and recent amplitude were the twin's, not its recent past."""
    tested = np.linspace(0.0, 10.0, 101)
    twin = np.linspace(0.0, 4.0, 41)
    t = matched_start(tested, twin, length=20, window=5, floor=0.1)
    assert t == 40
    with pytest.raises(UpdaterError, match="more than"):
        matched_start(tested[:10], twin, length=20, window=5, floor=0.1)


def test_the_scorer_prefers_the_model_right_on_the_matched_stretch() -> None:
    """Two candidate models, stored as starters: a Bilinear that is the tested law and one that
    is not; the shadow score of the right one is zero."""
    d = cyclic(400, 10.0, 3)
    law = {"k0": 8.0, "fy": 12.0, "alpha": 0.03}
    true, wrong = make_model("bilinear", **law), make_model("bilinear", k0=4.0, fy=6.0, alpha=0.1)
    scorer = ShadowScorer(2, length=50, window=20, every=10)
    for i, x in enumerate(d.tolist()):
        scorer.before_step([true.clone(), wrong.clone()])
        f = true.set_trial(x)[0]
        true.commit()
        wrong.set_trial(x)
        wrong.commit()
        scorer.twin_committed(0.5 * x)
        scorer.after_step(x, f)
        assert scorer.scores is None or i >= 69
    assert scorer.scores is not None
    assert scorer.scores[0] == pytest.approx(0.0, abs=1e-18)
    assert scorer.scores[1] > 1.0
    with pytest.raises(UpdaterError, match="shadow"):
        ShadowScorer(2, length=100, window=100, keep=150)


@pytest.fixture()
def shadowed() -> OnlineImproved:
    d = cyclic(1500, 10.0, 1)
    return OnlineImproved(offline=(d, drive(d)), shadow=True)


def test_with_shadow_scoring_the_twin_keeps_material_semantics(shadowed: OnlineImproved) -> None:
    assert_material_semantics(shadowed.twin)


def test_shadow_scores_change_the_weights_and_stay_bounded(shadowed: OnlineImproved) -> None:
    """Tested element at 10 mm, twin at 3 mm: after enough steps the shadow scores exist, every
    weight is finite and they sum to one; the twin's force stays within the law's range."""
    d = cyclic(600, 10.0, 2)
    f = drive(d)
    twin = shadowed.twin
    for x, y in zip(d.tolist(), f.tolist(), strict=True):
        shadowed.observe(x, y)
        twin.set_trial(0.3 * x)
        twin.commit()
    assert shadowed.shadow is not None and shadowed.shadow.scores is not None
    w = shadowed.mixture_weights()
    assert np.all(np.isfinite(w)) and w.sum() == pytest.approx(1.0)
    assert abs(twin.committed[1]) < 2.0 * float(np.max(np.abs(f)))


def test_a_rejected_measurement_leaves_the_shadow_history_unchanged(
        shadowed: OnlineImproved) -> None:
    shadowed.observe(1.0, 8.0)
    assert shadowed.shadow is not None
    before = len(shadowed.shadow._d), len(shadowed.shadow._starts)
    with pytest.raises(UpdaterInputError):
        shadowed.observe(float("nan"), 1.0)
    assert (len(shadowed.shadow._d), len(shadowed.shadow._starts)) == before


def _trained(steps: int) -> tuple[OnlineImproved, np.ndarray]:
    """The default updater after ``steps`` tested steps of a cyclic history (and that history)."""
    d = cyclic(300, 10.0, 1)
    f = drive(d)
    updater = OnlineImproved(offline=(d, f))
    for x, y in zip(d[:steps].tolist(), f[:steps].tolist(), strict=True):
        updater.observe(x, y)
    return updater, d


def test_every_expert_gives_a_twin_on_its_tested_memory() -> None:
    """The source twin of each expert starts where the tested element is (its committed point)
    and is a material of its own: moving it leaves the expert unchanged."""
    updater, d = _trained(120)
    for expert in updater.experts:
        twin = expert.source_twin()
        assert twin.committed[0] == pytest.approx(d[119])
        before = expert.predict(float(d[120]))
        twin.set_trial(float(d[120]) + 1.0)
        twin.commit()
        assert expert.predict(float(d[120])) == before


def test_force_hinges_by_hand() -> None:
    """Stiffness 2, levels -5, 5 and 10 kN, a branch from F_r = 3 kN: the -5 level was passed at
    the reversal (the feature is u), 5 kN is reached at u = 1 mm, 10 kN at u = 3.5 mm."""
    levels = np.array([-5.0, 5.0, 10.0])
    np.testing.assert_allclose(force_hinges(3.0, 0.5, levels, 2.0), [0.5, 0.0, 0.0])
    np.testing.assert_allclose(force_hinges(3.0, 2.0, levels, 2.0), [2.0, 1.0, 0.0])
    np.testing.assert_allclose(force_hinges(3.0, 4.0, levels, 2.0), [4.0, 3.0, 0.5])


def test_the_hinge_expert_has_material_semantics_and_learns() -> None:
    d = cyclic(1500, 10.0, 1)
    f = drive(d)
    updater = OnlineImproved(offline=(d, f), experts="reversal+memory+hinges")
    assert_material_semantics(updater.twin)
    expert = updater.experts[0]
    assert isinstance(expert, BranchRls)
    assert expert.basis.size == ReversalBasis(1.0, 1.0, stiffness=1.0).size + 15
    with pytest.raises(UpdaterError, match="positive stiffness"):
        ReversalBasis(1.0, 1.0, hinge_stiffness=0.0)


def test_advance_is_set_trial_then_commit_without_the_tangent() -> None:
    """The free-run step of every expert's twin gives the force and state of set_trial + commit;
    every basis expert has the fast path (a refitted law, ``baber-wen``, steps as a law)."""
    updater, d = _trained(100)
    for name, expert in zip(updater.expert_names, updater.experts, strict=True):
        fast, slow = stepper(expert.source_twin()), expert.source_twin()
        assert isinstance(expert.source_twin(), FreeRun) == (name != "baber-wen")
        for x in d[100:200].tolist():
            force = slow.set_trial(x)[0]
            slow.commit()
            assert fast(x) == force
