"""Giuffrè-Menegotto-Pinto (Steel02): closed forms, limit cases, OpenSees bit-equality."""

from __future__ import annotations

import math
import random

import pytest

from sim_actuator.models import Bilinear, MenegottoPinto, ModelInputError, make_model
from tests.support.opensees_materials import close, cyclic_history, run_materials

K0, FY, ALPHA = 8.0, 12.0, 0.03
DY = FY / K0


def drive(model: MenegottoPinto | Bilinear, path: list[float]) -> list[float]:
    forces = []
    for d in path:
        force, _ = model.set_trial(d)
        model.commit()
        forces.append(force)
    return forces


@pytest.mark.parametrize("r0", [2.0, 8.0, 20.0])
def test_virgin_loading_is_the_closed_form_gmp_curve(r0: float) -> None:
    model = MenegottoPinto(k0=K0, fy=FY, alpha=ALPHA, R0=r0)
    for d in [0.1 * DY * i for i in range(1, 80)]:
        x = d / DY
        expected = FY * (ALPHA * x + (1.0 - ALPHA) * x / (1.0 + abs(x) ** r0) ** (1.0 / r0))
        force, tangent = model.set_trial(d)
        model.commit()
        assert force == pytest.approx(expected, rel=1e-13)
        slope = K0 * (ALPHA + (1.0 - ALPHA) / (1.0 + abs(x) ** r0) ** (1.0 + 1.0 / r0))
        assert tangent == pytest.approx(slope, rel=1e-12)


def test_virgin_loading_is_odd_symmetric() -> None:
    up, down = MenegottoPinto(k0=K0, fy=FY, alpha=ALPHA), MenegottoPinto(k0=K0, fy=FY, alpha=ALPHA)
    path = [0.3 * DY * i for i in range(1, 30)]
    assert drive(up, path) == [-f for f in drive(down, [-d for d in path])]


def test_sharp_transition_without_isotropic_hardening_is_the_bilinear_law() -> None:
    rng = random.Random(7)
    path = cyclic_history(rng, DY, 400)
    gmp = drive(MenegottoPinto(k0=K0, fy=FY, alpha=ALPHA, R0=2000.0, cR1=0.0), path)
    bilinear = drive(Bilinear(k0=K0, fy=FY, alpha=ALPHA), path)
    worst = max(abs(a - b) for a, b in zip(gmp, bilinear, strict=True))
    assert worst < 5e-3 * FY


def test_isotropic_hardening_shifts_the_reverse_yield_force_by_the_closed_form() -> None:
    """Elastic-perfectly plastic, sharp: after loading to +d_m, reverse yield is at -fy*shift."""
    a1, a2, d_m = 0.05, 1.0, 6.0 * DY
    model = MenegottoPinto(k0=K0, fy=FY, alpha=0.0, R0=5000.0, cR1=0.0, a1=a1, a2=a2)
    drive(model, [d_m * i / 20 for i in range(1, 21)])
    forces = drive(model, [d_m - 12.0 * DY * i / 200 for i in range(1, 201)])
    shift = 1.0 + a1 * ((d_m + DY) / (2.0 * a2 * DY)) ** 0.8
    assert min(forces) == pytest.approx(-FY * shift, rel=1e-3)
    without = MenegottoPinto(k0=K0, fy=FY, alpha=0.0, R0=5000.0, cR1=0.0)
    drive(without, [d_m * i / 20 for i in range(1, 21)])
    assert min(drive(without, [d_m - 12.0 * DY * i / 200 for i in range(1, 201)])) == (
        pytest.approx(-FY, rel=1e-3)
    )


def test_trials_never_advance_the_committed_state() -> None:
    model = MenegottoPinto(k0=K0, fy=FY, alpha=ALPHA, a1=0.02, a3=0.02)
    drive(model, [2.0, 5.0, 1.0, -3.0])
    reference = model.clone()
    for d in (10.0, -10.0, 0.3, 4.0):
        model.set_trial(d)
    first = model.set_trial(2.5)
    model.revert_to_last_commit()
    assert model.committed == reference.committed
    assert reference.set_trial(2.5) == first
    model.commit()
    assert model.committed == reference.committed  # reverted: the commit keeps the old state
    with pytest.raises(ModelInputError):
        model.set_trial(math.nan)
    model.revert_to_start()
    assert model.committed == (0.0, 0.0)


def test_make_model_builds_it_with_steel02_defaults() -> None:
    model = make_model("menegotto-pinto", k0=K0, fy=FY, alpha=ALPHA)
    assert isinstance(model, MenegottoPinto)
    assert (model.R0, model.cR1, model.cR2) == (15.0, 0.925, 0.15)
    assert (model.a1, model.a2, model.a3, model.a4) == (0.0, 1.0, 0.0, 1.0)


STEEL02_CASES = [
    {"k0": 8.0, "fy": 12.0, "alpha": 0.03, "R0": 15.0, "cR1": 0.925, "cR2": 0.15},
    {"k0": 8.0, "fy": 12.0, "alpha": 0.03, "R0": 10.0, "cR1": 0.9, "cR2": 0.2,
     "a1": 0.04, "a2": 1.0, "a3": 0.02, "a4": 2.0},
    {"k0": 2.0e5, "fy": 350.0, "alpha": 0.01, "R0": 20.0, "cR1": 0.925, "cR2": 0.15,
     "a1": 0.1, "a2": 3.0, "a3": 0.1, "a4": 3.0},
]  # fmt: skip


@pytest.mark.opensees
def test_reproduces_opensees_steel02_on_random_cyclic_histories() -> None:
    rng = random.Random(20261124)
    order = ("fy", "k0", "alpha", "R0", "cR1", "cR2", "a1", "a2", "a3", "a4")
    defaults = {"a1": 0.0, "a2": 1.0, "a3": 0.0, "a4": 1.0}
    jobs: list[tuple[list[object], list[float]]] = [
        (["Steel02", *({**defaults, **case}[k] for k in order)],
         cyclic_history(rng, case["fy"] / case["k0"], 300))
        for case in STEEL02_CASES
    ]  # fmt: skip
    results = run_materials(jobs)
    mismatches = 0
    for case, (_, strains), rows in zip(STEEL02_CASES, jobs, results, strict=True):
        model = MenegottoPinto(**case)
        for d, (_, os_stress, os_tangent) in zip(strains, rows, strict=True):
            force, tangent = model.set_trial(d)
            model.commit()
            mismatches += not (close(force, os_stress) and close(tangent, os_tangent))
    assert mismatches == 0
