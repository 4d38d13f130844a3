"""BWBN model: reduction to Bouc-Wen, degradation and pinching effects, integration accuracy."""

from __future__ import annotations

import itertools
import math
import random

import pytest

from sim_actuator.models import BoucWen, BoucWenBaberNoori, ModelInputError

K0, FY, ALPHA = 40.0, 8.0, 0.05
DY = FY / K0
PER_CYCLE = 200
BASE = {"k0": K0, "fy": FY, "alpha": ALPHA, "n": 1.5, "beta": 0.6, "gamma": 0.4}
SHAPE = {"p": 1.0, "q": 0.1, "psi0": 0.3, "delta_psi": 0.005, "lam": 0.5}


def drive(model: BoucWen | BoucWenBaberNoori, path: list[float]) -> list[tuple[float, float]]:
    out = []
    for d in path:
        out.append(model.set_trial(d))
        model.commit()
    return out


def sine_cycles(cycles: int, amplitude: float = 5.0 * DY) -> list[float]:
    return [
        amplitude * math.sin(2.0 * math.pi * i / PER_CYCLE)
        for i in range(1, cycles * PER_CYCLE + 1)
    ]


def random_path(seed: int, count: int = 200) -> list[float]:
    rng = random.Random(seed)
    path, d = [], 0.0
    for _ in range(count):
        d = max(-7.0 * DY, min(7.0 * DY, d + rng.uniform(-2.0, 2.0) * DY))
        path.append(d)
    return path


def peaks(forces: list[tuple[float, float]]) -> list[float]:
    """Force at the positive displacement peak of each cycle."""
    return [forces[c * PER_CYCLE + PER_CYCLE // 4 - 1][0] for c in range(len(forces) // PER_CYCLE)]


@pytest.mark.parametrize(
    "bw",
    [
        {"n": 1.0, "beta": 0.5, "gamma": 0.5, "A": 1.0},
        {"n": 2.5, "beta": 0.8, "gamma": -0.2, "A": 1.3},
        {"n": 1.2, "beta": 0.2, "gamma": 0.6, "A": 0.8},
    ],
)
def test_without_pinching_and_degradation_it_is_bouc_wen(bw: dict[str, float]) -> None:
    path = random_path(5, 120)
    reference = drive(BoucWen(k0=K0, fy=FY, alpha=ALPHA, **bw), path)
    params = {k: v for k, v in bw.items() if k != "A"}
    model = BoucWenBaberNoori(k0=K0, fy=FY, alpha=ALPHA, A0=bw["A"], **params, **SHAPE)
    result = drive(model, path)
    for (f, k), (f_ref, k_ref) in zip(result, reference, strict=True):
        assert f == pytest.approx(f_ref, abs=1e-10 * FY)
        assert k == pytest.approx(k_ref, abs=1e-10 * K0)


def test_strength_degradation_lowers_later_equal_amplitude_peaks() -> None:
    plain = peaks(drive(BoucWenBaberNoori(**BASE, **SHAPE), sine_cycles(4)))
    for degradation in ({"delta_nu": 0.02}, {"delta_a": 0.02}):
        degraded = peaks(drive(BoucWenBaberNoori(**BASE, **SHAPE, **degradation), sine_cycles(4)))
        assert all(later < 0.97 * earlier for earlier, later in itertools.pairwise(degraded))
        assert degraded[-1] < 0.9 * plain[-1]
    assert max(plain[1:]) - min(plain[1:]) < 1e-3 * FY  # no degradation: steady peaks


def test_stiffness_degradation_softens_unloading() -> None:
    """delta_eta divides dz/du by eta = 1 + delta_eta*e, so unloading gets softer each cycle."""

    def unloading_tangents(delta_eta: float) -> list[float]:
        forces = drive(BoucWenBaberNoori(**BASE, **SHAPE, delta_eta=delta_eta), sine_cycles(4))
        return [forces[c * PER_CYCLE + PER_CYCLE // 4][1] for c in range(4)]

    plain, degraded = unloading_tangents(0.0), unloading_tangents(0.02)
    assert degraded[3] < 0.8 * degraded[0]
    assert plain[3] == pytest.approx(plain[1], rel=1e-3)


def reload_to_z_zero(model: BoucWenBaberNoori) -> tuple[float, float, float]:
    """Reload in small committed steps; (|z|, tangent, e) at the step where |z| is smallest."""
    start = model.committed[0]
    best = (math.inf, 0.0, 0.0)
    for i in range(1, 301):
        _, tangent = model.set_trial(start + 0.02 * DY * i)
        model.commit()
        if abs(model.committed_z) < best[0]:
            best = (abs(model.committed_z), tangent, model.committed_energy)
    return best


def test_pinching_lowers_force_and_tangent_near_zero() -> None:
    path = sine_cycles(4)
    zero_on_unloading = 3 * PER_CYCLE + PER_CYCLE // 2
    negative_peak = 3 * PER_CYCLE + 3 * PER_CYCLE // 4
    assert path[zero_on_unloading - 1] == pytest.approx(0.0, abs=1e-12)
    assert path[negative_peak - 1] == pytest.approx(-5.0 * DY, rel=1e-12)
    shape = {**SHAPE, "q": 0.0}  # pinching centred on z = 0
    plain = BoucWenBaberNoori(**BASE, **shape)
    pinched = BoucWenBaberNoori(**BASE, **shape, zeta_s=0.8)
    f_plain = drive(plain, path[:zero_on_unloading])[-1][0]
    f_pinched = drive(pinched, path[:zero_on_unloading])[-1][0]
    assert abs(f_pinched) < 0.85 * abs(f_plain)  # pinched loop: small force at d = 0

    drive(plain, path[zero_on_unloading:negative_peak])
    drive(pinched, path[zero_on_unloading:negative_peak])
    z_plain, k_plain, _ = reload_to_z_zero(plain)
    z_pinched, k_pinched, energy = reload_to_z_zero(pinched)
    assert z_plain < 0.02 and z_pinched < 0.02
    assert k_pinched < 0.6 * k_plain
    # closed form at z = 0 with q = 0: dz/du = (1 - zeta1) * A0, zeta1 = zeta_s*(1 - exp(-p*e))
    zeta1 = 0.8 * (1.0 - math.exp(-SHAPE["p"] * energy))
    assert k_pinched == pytest.approx(ALPHA * K0 + (1 - ALPHA) * K0 * (1 - zeta1), rel=0.05)
    assert k_plain == pytest.approx(K0, rel=0.05)


def test_energy_grows_cycle_by_cycle_and_loops_are_antisymmetric() -> None:
    params = {**BASE, **SHAPE, "zeta_s": 0.6, "delta_nu": 0.01, "delta_eta": 0.01}
    model = BoucWenBaberNoori(**params)
    energies = []
    path = sine_cycles(3)
    plus = []
    for cycle in range(3):
        plus += drive(model, path[cycle * PER_CYCLE : (cycle + 1) * PER_CYCLE])
        energies.append(model.committed_energy)
    assert 0.0 < energies[0] < energies[1] < energies[2]
    minus = drive(BoucWenBaberNoori(**params), [-d for d in path])
    assert all(fp == -fm and kp == km for (fp, kp), (fm, km) in zip(plus, minus, strict=True))


def test_results_converge_as_substeps_shrink_with_pinching_and_degradation() -> None:
    path = random_path(9, 60)
    params = {**BASE, **SHAPE, "zeta_s": 0.7, "delta_a": 0.005, "delta_nu": 0.01}
    reference = drive(BoucWenBaberNoori(**params, dz_max=2e-3), path)
    errors = []
    for dz_max in (0.2, 0.04, 0.008):
        forces = drive(BoucWenBaberNoori(**params, dz_max=dz_max), path)
        errors.append(max(abs(f - r) for (f, _), (r, _) in zip(forces, reference, strict=True)))
    assert errors[0] > 10.0 * errors[1] > 100.0 * errors[2]
    assert errors[2] < 1e-8 * FY


def test_tangent_is_consistent_and_big_steps_equal_small_steps() -> None:
    params = {**BASE, **SHAPE, "zeta_s": 0.7, "delta_a": 0.005, "delta_nu": 0.01}
    model = BoucWenBaberNoori(**params)
    drive(model, sine_cycles(2)[:-30])
    start = model.committed[0]
    target = start - 3.0 * DY
    h = 1e-5 * DY
    _, tangent = model.set_trial(target)
    f_plus, _ = model.set_trial(target + h)
    f_minus, _ = model.set_trial(target - h)
    assert tangent == pytest.approx((f_plus - f_minus) / (2.0 * h), rel=1e-5)
    f_big, k_big = model.set_trial(target)
    small = model.clone()
    small.revert_to_last_commit()
    for i in range(1, 31):
        f_small, k_small = small.set_trial(start - 0.1 * DY * i)
        small.commit()
    assert f_small == pytest.approx(f_big, abs=1e-8 * FY)
    assert k_small == pytest.approx(k_big, abs=1e-8 * K0)


def test_exhausted_degradation_is_refused_and_leaves_the_state_unchanged() -> None:
    model = BoucWenBaberNoori(**BASE, **SHAPE, delta_a=0.5)
    with pytest.raises(ModelInputError, match="bwbn: degradation exhausted"):
        drive(model, sine_cycles(10))
    committed = model.committed
    assert model.A0 - model.delta_a * model.committed_energy > 0.0
    with pytest.raises(ModelInputError, match="bwbn: trial displacement must be finite"):
        model.set_trial(math.nan)
    assert model.committed == committed
