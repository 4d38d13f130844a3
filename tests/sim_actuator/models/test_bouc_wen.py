"""Bouc-Wen model against closed-form solutions of its ODE and basic hysteresis properties."""

from __future__ import annotations

import math
import random

import pytest

from sim_actuator.models import BoucWen, ModelInputError

K0, FY, ALPHA = 40.0, 8.0, 0.05
DY = FY / K0


def force_from_z(d: float, z: float) -> float:
    return ALPHA * K0 * d + (1.0 - ALPHA) * FY * z


def drive(model: BoucWen, path: list[float]) -> list[tuple[float, float]]:
    out = []
    for d in path:
        out.append(model.set_trial(d))
        model.commit()
    return out


def z_monotonic(u: float, n: float, a: float, c: float) -> float:
    """Closed-form z(u) from z = 0 for dz/du = a - c*z**n, n = 1 or 2."""
    if n == 1.0:
        return a / c * (1.0 - math.exp(-c * u))
    return math.sqrt(a / c) * math.tanh(math.sqrt(a * c) * u)


@pytest.mark.parametrize(("n", "a", "beta", "gamma"), [(1.0, 1.0, 0.5, 0.5), (2.0, 1.3, 0.7, 0.2)])
@pytest.mark.parametrize("step", [0.01, 0.3, 2.5])  # in units of dy
def test_monotonic_loading_matches_closed_form(
    n: float, a: float, beta: float, gamma: float, step: float
) -> None:
    model = BoucWen(k0=K0, fy=FY, alpha=ALPHA, n=n, beta=beta, gamma=gamma, A=a)
    count = round(10.0 / step)
    for i in range(1, count + 1):
        d = i * step * DY
        force, tangent = model.set_trial(d)
        model.commit()
        z = z_monotonic(d / DY, n, a, beta + gamma)
        assert force == pytest.approx(force_from_z(d, z), abs=1e-9 * FY)
        slope = a - (beta + gamma) * z**n
        assert tangent == pytest.approx(ALPHA * K0 + (1.0 - ALPHA) * K0 * slope, abs=1e-9 * K0)


@pytest.mark.parametrize(("beta", "gamma"), [(0.5, 0.5), (0.8, 0.2), (0.3, 0.7)])
def test_unloading_through_zero_matches_piecewise_closed_form(beta: float, gamma: float) -> None:
    """n = 1: dz/du = A - (gamma - beta)*z while z > 0, then A + (beta + gamma)*z (du < 0)."""
    a, c, g = 1.0, beta + gamma, gamma - beta
    model = BoucWen(k0=K0, fy=FY, alpha=ALPHA, n=1.0, beta=beta, gamma=gamma, A=a)
    u0 = 4.0
    model.set_trial(u0 * DY)
    model.commit()
    z0 = model.committed_z

    def z_pos(u: float) -> float:
        if g == 0.0:
            return z0 + a * (u - u0)
        return a / g + (z0 - a / g) * math.exp(-g * (u - u0))

    u_cross = u0 - z0 / a if g == 0.0 else u0 - math.log((a / g) / (a / g - z0)) / g
    for i in range(1, 81):  # steps of 0.1 dy, several straddle the zero crossing of z
        u = u0 - 0.1 * i
        force, _ = model.set_trial(u * DY)
        model.commit()
        z = z_pos(u) if u >= u_cross else -a / c + a / c * math.exp(c * (u - u_cross))
        assert force == pytest.approx(force_from_z(u * DY, z), abs=1e-9 * FY)
    assert model.committed_z < 0.0


@pytest.mark.parametrize("n", [1.0, 1.7, 3.0, 12.0])
def test_monotonic_loading_saturates_at_z_ultimate(n: float) -> None:
    a, beta, gamma = 1.2, 0.45, 0.35
    model = BoucWen(k0=K0, fy=FY, alpha=ALPHA, n=n, beta=beta, gamma=gamma, A=a)
    z_u = (a / (beta + gamma)) ** (1.0 / n)
    assert model.z_ultimate == pytest.approx(z_u, rel=1e-15)
    drive(model, [i * 0.5 * DY for i in range(1, 81)])
    assert model.committed_z == pytest.approx(z_u, rel=1e-9)
    force, tangent = model.set_trial(41.0 * DY)
    assert force == pytest.approx(force_from_z(41.0 * DY, z_u), rel=1e-9)
    assert tangent == pytest.approx(ALPHA * K0, rel=1e-6)


def test_initial_tangent_is_k0_when_a_is_one() -> None:
    model = BoucWen(k0=K0, fy=FY, alpha=ALPHA, n=2.0, beta=0.5, gamma=0.5)
    assert model.initial_tangent == K0
    force, tangent = model.set_trial(1e-6 * DY)
    assert tangent == pytest.approx(K0, rel=1e-9)
    assert force == pytest.approx(K0 * 1e-6 * DY, rel=1e-6)


def test_tangent_is_consistent_with_the_trial_force() -> None:
    rng = random.Random(3)
    model = BoucWen(k0=K0, fy=FY, alpha=ALPHA, n=1.6, beta=0.6, gamma=0.3)
    for d in [rng.uniform(-5.0, 5.0) * DY for _ in range(30)]:
        d_c = model.committed[0]
        target = d + 0.4 * DY * (1.0 if d > d_c else -1.0)  # keeps the trial direction
        h = 1e-5 * DY
        _, tangent = model.set_trial(target)
        f_plus, _ = model.set_trial(target + h)
        f_minus, _ = model.set_trial(target - h)
        assert tangent == pytest.approx((f_plus - f_minus) / (2.0 * h), rel=1e-5, abs=1e-6 * K0)
        model.set_trial(d)
        model.commit()


def test_loops_are_antisymmetric_and_dissipate_energy() -> None:
    path = [5.0 * DY * math.sin(2.0 * math.pi * i / 200) for i in range(1, 601)]
    params = {"k0": K0, "fy": FY, "alpha": ALPHA, "n": 1.5, "beta": 0.55, "gamma": 0.45}
    plus = drive(BoucWen(**params), path)
    minus = drive(BoucWen(**params), [-d for d in path])
    assert all(fp == -fm and kp == km for (fp, kp), (fm, km) in zip(plus, minus, strict=True))
    energies = []
    for cycle in range(3):
        seg = range(cycle * 200, (cycle + 1) * 200)
        energies.append(
            sum(0.5 * (plus[i][0] + plus[i - 1][0]) * (path[i] - path[i - 1]) for i in seg if i > 0)
        )
    assert all(e > 0.5 * FY * DY for e in energies)
    assert energies[2] == pytest.approx(energies[1], rel=1e-3)  # steady loop, no degradation


def test_one_big_step_equals_many_committed_small_steps() -> None:
    params = {"k0": K0, "fy": FY, "alpha": ALPHA, "n": 1.4, "beta": 0.7, "gamma": 0.1}
    big, small = BoucWen(**params), BoucWen(**params)
    for model in (big, small):
        model.set_trial(3.0 * DY)
        model.commit()
    f_big, k_big = big.set_trial(-4.0 * DY)
    for i in range(1, 71):
        f_small, k_small = small.set_trial(3.0 * DY - 0.1 * i * DY)
        small.commit()
    assert f_small == pytest.approx(f_big, abs=1e-9 * FY)
    assert k_small == pytest.approx(k_big, abs=1e-9 * K0)


def test_results_converge_as_substeps_shrink() -> None:
    rng = random.Random(11)
    path, d = [], 0.0
    for _ in range(150):
        d = max(-6.0 * DY, min(6.0 * DY, d + rng.uniform(-1.5, 1.5) * DY))
        path.append(d)
    params = {"k0": K0, "fy": FY, "alpha": ALPHA, "n": 1.5, "beta": 0.6, "gamma": 0.4}
    reference = drive(BoucWen(**params, dz_max=1e-3), path)
    errors = []
    for dz_max in (0.2, 0.05, 0.01):
        forces = drive(BoucWen(**params, dz_max=dz_max), path)
        errors.append(max(abs(f - r) for (f, _), (r, _) in zip(forces, reference, strict=True)))
    assert errors[0] > 10.0 * errors[1] > 100.0 * errors[2]  # at least ~2nd order, n = 1.5
    assert errors[2] < 1e-8 * FY


def test_trial_revert_and_clone_semantics() -> None:
    model = BoucWen(k0=K0, fy=FY, alpha=ALPHA, n=2.0, beta=0.5, gamma=0.5)
    at_commit = model.set_trial(2.0 * DY)
    model.commit()
    expected = model.clone().set_trial(-1.0 * DY)
    model.set_trial(5.0 * DY)
    model.set_trial(-3.0 * DY)
    assert model.set_trial(-1.0 * DY) == expected
    model.revert_to_last_commit()
    assert model.committed[0] == 2.0 * DY
    assert model.set_trial(2.0 * DY) == at_commit  # a zero step returns the committed state
    twin = model.clone()
    twin.set_trial(4.0 * DY)
    twin.commit()
    assert model.committed[0] == 2.0 * DY
    model.revert_to_start()
    assert model.committed == (0.0, 0.0) and model.committed_z == 0.0


def test_bad_trials_are_refused_with_a_reason() -> None:
    model = BoucWen(k0=K0, fy=FY, alpha=ALPHA, n=2.0, beta=0.5, gamma=0.5)
    with pytest.raises(ModelInputError, match="bouc-wen: trial displacement must be finite"):
        model.set_trial(math.nan)
    with pytest.raises(ModelInputError, match="check units"):
        model.set_trial(1e6 * DY)
    assert model.committed == (0.0, 0.0)
