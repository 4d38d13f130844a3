"""The learned reversal-state law (``updating.reversal_state``): memory variables against hand
values, the secant targets, material semantics, continuity at a reversal, the tangent, the
ensemble mean, and a fit that recovers a known law."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fresco_bridge.updating import reversal_state as rs
from fresco_bridge.updating.base import UpdaterError, UpdaterInputError
from fresco_bridge.updating.lm import LmOptions
from fresco_bridge.updating.mlp import Mlp
from fresco_bridge.updating.refit import law_forces
from sim_actuator.models import Bilinear
from sim_actuator.models.base import ModelInputError
from tests.support.histories import ramped_sines
from tests.support.material import assert_material_semantics

SC = rs.Scales(disp=4.0, force=10.0, energy=20.0, stiffness=5.0)


def _walk(points: list[tuple[float, float]]) -> rs.Memory:
    mem = rs.Memory()
    for d, f in points:
        mem = mem.branch(d).committed_at(d, f)
    return mem


def test_the_memory_takes_a_reversal_at_the_committed_point_and_keeps_the_one_before() -> None:
    mem = _walk([(1.0, 2.0), (2.0, 3.0), (1.0, 0.0), (-1.0, -3.0)])
    assert (mem.s, mem.d_r, mem.f_r, mem.d_rp, mem.f_rp) == (-1.0, 2.0, 3.0, 0.0, 0.0)
    assert (mem.d_max, mem.d_min) == (2.0, -1.0)
    # work: 0.5*(0+2)*1 + 0.5*(2+3)*1 + 0.5*(3+0)*(-1) + 0.5*(0-3)*(-2)
    assert mem.energy == pytest.approx(1.0 + 2.5 - 1.5 + 3.0)
    again = mem.branch(0.5)  # against s = -1: a reversal at (-1, -3)
    assert (again.s, again.d_r, again.f_r, again.d_rp, again.f_rp) == (1.0, -1.0, -3.0, 2.0, 3.0)
    assert mem.branch(-2.0) == mem and mem.branch(-1.0) == mem  # onwards, or no move


def test_the_inputs_are_scaled_and_mirrored_by_the_direction() -> None:
    mem = _walk([(1.0, 2.0), (2.0, 3.0), (1.0, 0.0), (-1.0, -3.0)])
    z = mem.inputs(-2.0, SC)  # s = -1: ahead is d_min, behind d_max
    want = [-(-2.0 - 2.0) / 4, -2.0 / 4, -3.0 / 10, 0.0, 0.0, 1.0 / 4, -2.0 / 4, 5.0 / 20]
    assert z.tolist() == pytest.approx(want)
    rel = rs.Scales(4.0, 10.0, 20.0, 5.0, variables="relative", drop=("energy",))
    assert rel.names == ("s(d-d_r)", "s(d_ahead-d_r)", "range", "|d_r-d_rp|", "s F_r", "s F_rp")
    assert mem.inputs(-2.0, rel).tolist() == pytest.approx([1.0, 0.75, 0.75, 0.5, -0.3, 0.0])
    with pytest.raises(UpdaterError, match="unknown variables"):
        rs.Scales(1.0, 1.0, 1.0, 1.0, drop=("range",))


def test_the_secant_targets_of_an_elastic_history_are_one_and_weigh_the_force_error() -> None:
    d = np.array([0.0, 1.0, 2.0, 1.0, 0.0])
    k = 5.0
    x, y, w = rs.features(d, k * d, SC)
    assert x.shape == (5, 8)
    assert w[0] == 0.0  # d = d_r: no secant
    assert y[1:].tolist() == pytest.approx([1.0] * 4)
    assert w[3] == pytest.approx(((1.0 - 2.0) * k / 10.0) ** 2)  # from the reversal at 2


def test_scales_come_from_the_data_and_reject_data_that_never_load() -> None:
    d = ramped_sines(600, 3.0, 1)
    sc = rs.scales(d, 4.0 * d)
    assert sc.disp == pytest.approx(float(np.max(np.abs(d))))
    assert sc.stiffness == pytest.approx(4.0)
    assert sc.energy >= sc.disp * sc.force
    with pytest.raises(UpdaterError, match="never load"):
        rs.scales(d, np.zeros_like(d))


def _law(members: int = 1, seed: int = 3) -> rs.ReversalStateLaw:
    net = Mlp((8, 6, 1))
    thetas = np.array([net.init_params(np.random.default_rng(seed + i)) for i in range(members)])
    return rs.ReversalStateLaw(net, thetas, SC)


def test_the_law_has_material_semantics_and_rejects_a_nan_trial_unchanged() -> None:
    law = _law()
    assert_material_semantics(law)
    law.set_trial(1.0)
    law.commit()
    committed = law.committed
    with pytest.raises(ModelInputError):
        law.set_trial(math.nan)
    assert law.committed == committed


def test_the_force_is_continuous_at_a_reversal_and_the_tangent_is_its_derivative() -> None:
    law = _law()
    for d in (1.0, 2.5, 3.0):
        law.set_trial(d)
        law.commit()
    f_r = law.committed[1]
    assert law.set_trial(3.0 - 1e-9)[0] == pytest.approx(f_r, abs=1e-6)
    h = 1e-6
    force, tangent = law.set_trial(2.0)
    ahead = law.set_trial(2.0 - h)[0]
    assert tangent == pytest.approx((force - ahead) / h, rel=1e-4)


def test_an_ensemble_averages_its_members() -> None:
    both, one, two = _law(2), _law(1, 3), _law(1, 4)
    for d in (0.7, 1.9, 0.2, -1.5):
        fb, f1, f2 = (m.set_trial(d)[0] for m in (both, one, two))
        for m in (both, one, two):
            m.commit()
        # the memory differs once the members' forces differ, so compare the first step's g
        if d == 0.7:
            assert fb == pytest.approx(0.5 * (f1 + f2))
    assert both.initial_tangent == pytest.approx(0.5 * (one.initial_tangent
                                                        + two.initial_tangent))


def test_a_fit_recovers_a_bilinear_law_and_its_free_run_on_a_new_history() -> None:
    train = ramped_sines(1200, 6.0, 1)
    law = Bilinear(k0=6.0, fy=10.0, alpha=0.04)
    force = law_forces(law, train)
    sc = rs.scales(train, force)
    net = Mlp((8, 8, 8, 1))  # one hidden layer of 8 fits (rms 2 %) but free-runs at 40 %
    theta, rms = rs.fit_law(net, net.init_params(np.random.default_rng(0)),
                            [(train, force, 1.0)], sc, LmOptions(max_iterations=60, mu=1e-3))
    peak = float(np.max(np.abs(force)))
    assert rms < 0.03 * peak
    other = ramped_sines(1200, 5.0, 2)
    truth = law_forces(Bilinear(k0=6.0, fy=10.0, alpha=0.04), other)
    free = law_forces(rs.ReversalStateLaw(net, theta, sc), other)
    assert float(np.sqrt(np.mean((free - truth) ** 2))) < 0.05 * peak
    start = net.init_params(np.random.default_rng(0))
    untrained = law_forces(rs.ReversalStateLaw(net, start, sc), other)
    assert float(np.sqrt(np.mean((untrained - truth) ** 2))) > 0.2 * peak


def _offline() -> tuple[np.ndarray, np.ndarray]:
    d = ramped_sines(400, 6.0, 5)
    return d, law_forces(Bilinear(k0=6.0, fy=10.0, alpha=0.04), d)


def _updater(hidden: tuple[int, ...] = (4,), **options: int) -> rs.ReversalStateUpdater:
    opts = {"members": 2, "iterations": 8, "refit_iterations": 3, "warmup": 10, "every": 5}
    return rs.ReversalStateUpdater(offline=_offline(), hidden=hidden, **{**opts, **options})


def _feed(updater: rs.ReversalStateUpdater, n: int, seed: int = 6) -> None:
    d = ramped_sines(n, 5.0, seed)
    f = law_forces(Bilinear(k0=6.0, fy=10.0, alpha=0.04), d)
    for di, fi in zip(d.tolist(), f.tolist(), strict=True):
        updater.observe(di, fi)


def test_the_updater_refits_on_schedule_and_its_twin_shares_the_parameters() -> None:
    up = _updater()
    start = up.params.thetas.copy()
    _feed(up, 9)
    assert up.refits == 0 and np.array_equal(up.params.thetas, start)
    _feed(up, 1)
    assert up.refits == 1 and not np.array_equal(up.params.thetas, start)
    _feed(up, 5)
    assert up.refits == 2
    assert up.twin.params is up.params and up.twin.clone().params is up.params
    assert_material_semantics(up.twin)


def test_predict_is_the_measured_memory_s_one_step_force_and_changes_nothing() -> None:
    up = _updater()
    _feed(up, 12)
    before = up.params.thetas.copy()
    force = up.predict(0.3)
    assert up.source_twin().set_trial(0.3)[0] == pytest.approx(force)
    assert up.predict(0.3) == force and np.array_equal(up.params.thetas, before)


def test_a_nan_measurement_is_rejected_and_the_updater_is_unchanged() -> None:
    up = _updater()
    _feed(up, 8)
    state = (up.predict(1.0), up.params.thetas.copy(), up.refits)
    with pytest.raises(UpdaterInputError, match="rejected"):
        up.observe(math.nan, 1.0)
    _feed(up, 0)
    assert (up.predict(1.0), up.refits) == (state[0], state[2])
    assert np.array_equal(up.params.thetas, state[1])


def test_the_refitted_twin_stays_bounded_on_a_long_free_run() -> None:
    """Bounded on a history like the data (not guaranteed: the bound is per branch; an
    under-trained 4-unit law reaches 2.8x the peak on this history, and a trained one 1.7-2x on
    amplitudes beyond the data's, measured while writing this test)."""
    up = _updater((8, 8), iterations=40)
    _feed(up, 60)
    assert up.refits == 11
    forces = law_forces(up.twin, ramped_sines(1500, 6.0, 8))
    assert np.all(np.isfinite(forces))
    assert float(np.max(np.abs(forces))) < 1.2 * up.scales.force


def test_the_updater_rejects_bad_options() -> None:
    with pytest.raises(UpdaterError, match="must be >= 1"):
        _updater(members=0)
    with pytest.raises(UpdaterError, match="must be >= 1"):
        _updater(every=0)
