"""Bilinear (Steel01) model: closed forms and trial/commit semantics, pure Python."""

from __future__ import annotations

import math
import random

import pytest

from sim_actuator.models import Bilinear, ModelInputError

K0, FY, ALPHA = 10.0, 10.0, 0.05  # dy = 1
DY = FY / K0


def bounds(d: float) -> tuple[float, float]:
    """Lower and upper kinematic-hardening lines at displacement d."""
    return ALPHA * K0 * d - (1.0 - ALPHA) * FY, ALPHA * K0 * d + (1.0 - ALPHA) * FY


def test_virgin_monotonic_curve_is_elastic_then_hardening() -> None:
    model = Bilinear(k0=K0, fy=FY, alpha=ALPHA)
    for i in range(1, 61):
        d = 0.05 * i
        force, tangent = model.set_trial(d)
        model.commit()
        if d < DY:
            assert force == pytest.approx(K0 * d, rel=1e-12)
            assert tangent == K0
        elif d > DY:
            assert force == pytest.approx(bounds(d)[1], rel=1e-12)
            assert tangent == ALPHA * K0


def test_jump_from_elastic_through_yield_in_one_step() -> None:
    model = Bilinear(k0=K0, fy=FY, alpha=ALPHA)
    force, tangent = model.set_trial(3.0 * DY)
    assert force == pytest.approx(ALPHA * K0 * 3.0 * DY + (1.0 - ALPHA) * FY, rel=1e-12)
    assert tangent == ALPHA * K0
    model.commit()
    # a reversal jump crosses the whole elastic range 2*dy and yields on the other side
    force, tangent = model.set_trial(-2.0 * DY)
    assert force == pytest.approx(bounds(-2.0 * DY)[0], rel=1e-12)
    assert tangent == ALPHA * K0


def test_unloading_is_elastic_until_the_opposite_bound() -> None:
    model = Bilinear(k0=K0, fy=FY, alpha=ALPHA)
    peak = 3.0 * DY
    model.set_trial(peak)
    model.commit()
    f_peak = model.committed[1]
    reyield = peak - 2.0 * DY  # closed form: the elastic range after reversal is 2*dy
    for i in range(1, 40):
        d = peak - 0.1 * i
        force, tangent = model.set_trial(d)  # each trial from the committed peak
        if d > reyield + 1e-9:
            assert force == pytest.approx(f_peak - K0 * (peak - d), rel=1e-12)
            assert tangent == K0
        elif d < reyield - 1e-9:
            assert force == pytest.approx(bounds(d)[0], rel=1e-12)
            assert tangent == ALPHA * K0


def test_dissipated_energy_per_stabilised_cycle_matches_closed_form() -> None:
    """Kinematic bilinear loop area is 4*(1 - alpha)*fy*(D - dy) for amplitude D."""
    model = Bilinear(k0=K0, fy=FY, alpha=ALPHA)
    amplitude, per_quarter = 3.0 * DY, 300
    path = [amplitude * i / per_quarter for i in range(per_quarter + 1)]
    down = [amplitude - 2.0 * amplitude * i / (2 * per_quarter) for i in range(1, 2 * per_quarter)]
    cycle = down + [-amplitude] + [-x for x in down] + [amplitude]
    for d in path + cycle:  # first cycle from the virgin state
        model.set_trial(d)
        model.commit()
    energy, d_prev, f_prev = 0.0, amplitude, model.committed[1]
    for d in cycle:
        force, _ = model.set_trial(d)
        model.commit()
        energy += 0.5 * (force + f_prev) * (d - d_prev)
        d_prev, f_prev = d, force
    assert energy == pytest.approx(4.0 * (1.0 - ALPHA) * FY * (amplitude - DY), rel=1e-9)


def test_trial_always_starts_from_the_committed_state() -> None:
    rng = random.Random(7)
    steps = [rng.uniform(-4.0, 4.0) * DY for _ in range(200)]
    reference = Bilinear(k0=K0, fy=FY, alpha=ALPHA)
    tried = Bilinear(k0=K0, fy=FY, alpha=ALPHA)
    for d in steps:
        expected = reference.set_trial(d)
        reference.commit()
        for _ in range(3):  # Newton-like trials that must leave no trace
            tried.set_trial(d + rng.uniform(-3.0, 3.0) * DY)
        tried.revert_to_last_commit()
        tried.set_trial(rng.uniform(-5.0, 5.0) * DY)
        assert tried.set_trial(d) == expected
        tried.commit()
        assert tried.committed == reference.committed


def test_revert_discards_the_trial_and_commit_after_revert_is_a_no_op() -> None:
    model = Bilinear(k0=K0, fy=FY, alpha=ALPHA)
    model.set_trial(2.0 * DY)
    model.commit()
    before = model.committed
    model.set_trial(-5.0 * DY)
    model.revert_to_last_commit()
    model.commit()
    assert model.committed == before
    assert model.set_trial(2.0 * DY) == (before[1], ALPHA * K0)  # zero step keeps the tangent


def test_step_below_machine_epsilon_keeps_committed_state() -> None:
    model = Bilinear(k0=K0, fy=FY, alpha=ALPHA)
    model.set_trial(0.0)
    model.commit()
    assert model.set_trial(1e-17) == (0.0, K0)
    model.commit()
    assert model.committed == (0.0, 0.0)  # like Steel01, the tiny step is not taken


def test_revert_to_start_and_clone_are_independent() -> None:
    model = Bilinear(k0=K0, fy=FY, alpha=ALPHA)
    model.set_trial(3.0 * DY)
    model.commit()
    model.set_trial(2.5 * DY)  # pending trial, copied by clone
    twin = model.clone()
    twin.commit()
    assert twin.committed[0] == 2.5 * DY
    assert model.committed[0] == 3.0 * DY
    model.revert_to_start()
    assert model.committed == (0.0, 0.0)
    assert model.set_trial(0.5 * DY) == (K0 * 0.5 * DY, K0)
    assert twin.committed[0] == 2.5 * DY


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_trial_is_refused(bad: float) -> None:
    model = Bilinear(k0=K0, fy=FY, alpha=ALPHA)
    with pytest.raises(ModelInputError, match="bilinear: trial displacement must be finite"):
        model.set_trial(bad)
