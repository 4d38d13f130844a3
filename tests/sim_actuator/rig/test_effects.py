"""Load-path effects and sensors against closed forms: friction, backlash, compliance, noise."""

from __future__ import annotations

import statistics

import numpy as np
import pytest

from sim_actuator.effects import EffectParameterError, LoadPath, Sensor
from sim_actuator.models import make_model

DT = 1e-3
K = 10.0  # kN/mm


def _sweep(path: LoadPath, points: list[float], steps_per_mm: int = 1000) -> list[tuple]:
    """Drive the fixture piecewise-linearly through ``points``; return (x, state) per substep."""
    out = []
    x0 = points[0]
    for x1 in points[1:]:
        n = max(1, round(abs(x1 - x0) * steps_per_mm))
        for i in range(1, n + 1):
            x = x0 + (x1 - x0) * i / n
            out.append((x, path.step(x)))
        x0 = x1
    return out


def test_coulomb_friction_adds_fc_with_the_sign_of_velocity() -> None:
    fc = 0.7
    path = LoadPath(make_model("elastic", k=K), dt=DT, coulomb=fc)
    up = _sweep(path, [0.0, 2.0])
    for x, s in up:
        assert s.load_cell_force == pytest.approx(K * x + fc, abs=1e-12)
    hold = path.step(2.0)  # no motion: the fixture sticks with its last slip force
    assert hold.friction_force == fc
    down = _sweep(path, [2.0, -1.0])
    for x, s in down:
        assert s.load_cell_force == pytest.approx(K * x - fc, abs=1e-12)
        assert s.connection_force == pytest.approx(K * x, abs=1e-12)


def test_viscous_friction_is_proportional_to_velocity() -> None:
    c = 0.05  # kN*s/mm
    path = LoadPath(make_model("elastic", k=K), dt=DT, viscous=c)
    x_prev = 0.0
    for k in range(1, 100):
        x = 0.3 * k**1.5 * DT  # varying velocity
        s = path.step(x)
        assert s.friction_force == pytest.approx(c * (x - x_prev) / DT, rel=1e-12)
        assert s.load_cell_force == pytest.approx(K * x + c * (x - x_prev) / DT, rel=1e-12)
        x_prev = x


def _zero_force_span(trace: list[tuple]) -> float:
    zero = [x for x, s in trace if s.connection_force == 0.0]
    return max(zero) - min(zero)


@pytest.mark.parametrize("gap", [0.05, 0.2])
def test_gap_gives_zero_force_over_two_gaps_after_reversal_elastic(gap: float) -> None:
    path = LoadPath(make_model("elastic", k=K), dt=DT, gap=gap)
    _sweep(path, [0.0, 3.0])
    back = _sweep(path, [3.0, -3.0])
    assert _zero_force_span(back) == pytest.approx(2 * gap, abs=2.5e-3)  # 1 um sampling
    for x, s in back:
        if x > gap + 1e-9:
            assert s.connection_force == pytest.approx(K * (x - gap), abs=1e-9)
            assert s.specimen_displacement == pytest.approx(x - gap, abs=1e-12)
        elif x < -gap - 1e-9:
            assert s.connection_force == pytest.approx(K * (x + gap), abs=1e-9)
        elif abs(x) < gap - 1e-9:
            assert s.connection_force == 0.0  # exactly: the pin is free
            assert s.in_gap


def test_gap_after_yielding_starts_where_the_force_returns_to_zero() -> None:
    """Bilinear specimen: unload elastically to zero force, then 2g of free travel."""
    gap, k0, fy, alpha = 0.1, 20.0, 10.0, 0.05
    path = LoadPath(make_model("bilinear", k0=k0, fy=fy, alpha=alpha), dt=DT, gap=gap)
    up = _sweep(path, [0.0, 3.0])
    f_top = up[-1][1].connection_force
    u_top = up[-1][1].specimen_displacement
    u_rest = u_top - f_top / k0  # elastic unloading to zero force
    back = _sweep(path, [3.0, -3.0])
    zero = [x for x, s in back if s.connection_force == 0.0]
    assert max(zero) == pytest.approx(u_rest + gap, abs=1.5e-3)
    assert min(zero) == pytest.approx(u_rest - gap, abs=1.5e-3)
    for _, s in back:
        if s.in_gap:
            assert s.specimen_displacement == pytest.approx(u_rest, abs=1e-9)


@pytest.mark.parametrize("kf", [5.0, 40.0, 1000.0])
def test_frame_compliance_gives_series_stiffness(kf: float) -> None:
    path = LoadPath(make_model("elastic", k=K), dt=DT, frame_stiffness=kf)
    for x, s in _sweep(path, [0.0, 2.0, -1.0], steps_per_mm=50):
        assert s.load_cell_force == pytest.approx(x * K * kf / (K + kf), rel=1e-10, abs=1e-12)
        assert s.specimen_displacement == pytest.approx(x * kf / (K + kf), rel=1e-10, abs=1e-12)


def test_compliant_frame_with_friction_sticks_over_two_fc_over_kf_after_reversal() -> None:
    """While the fixture sticks only the frame deflects: dF/dx = kf for 2*Fc/kf of travel."""
    kf, fc = 50.0, 1.0
    path = LoadPath(make_model("elastic", k=K), dt=DT, frame_stiffness=kf, coulomb=fc)
    up = _sweep(path, [0.0, 2.0], steps_per_mm=2000)
    x_top, s_top = up[-1]
    assert s_top.load_cell_force == pytest.approx((K * x_top + fc) * kf / (K + kf), rel=1e-10)
    back = _sweep(path, [2.0, 0.0], steps_per_mm=2000)
    stick_end = x_top - 2 * fc / kf
    for x, s in back:
        if x > stick_end + 1e-6:
            assert s.fixture == pytest.approx(s_top.fixture, abs=1e-12)
            assert s.load_cell_force == pytest.approx(
                s_top.load_cell_force - kf * (x_top - x), abs=1e-9
            )
        elif x < stick_end - 1e-3:
            assert s.load_cell_force == pytest.approx((K * x - fc) * kf / (K + kf), abs=1e-9)


def test_all_effects_together_stay_in_equilibrium() -> None:
    kf, fc, c, gap = 80.0, 0.5, 0.01, 0.05
    path = LoadPath(make_model("bilinear", k0=20.0, fy=10.0, alpha=0.05), dt=DT,
                    frame_stiffness=kf, coulomb=fc, viscous=c, gap=gap)
    for x, s in _sweep(path, [0.0, 2.0, -2.0, 1.0], steps_per_mm=500):
        # frame: the load cell force is what the frame spring carries
        assert s.load_cell_force == pytest.approx(kf * (x - s.fixture), abs=1e-8)
        assert abs(s.specimen_displacement - s.fixture) <= gap + 1e-12
        assert abs(s.friction_force) <= fc + c * 1e3  # bounded (velocities are small)


def test_sensor_noise_has_configured_std_and_is_seed_deterministic() -> None:
    std = 0.05

    def readings(seed: int) -> list[float]:
        sensor = Sensor(noise_std=std, rng=np.random.default_rng(seed))
        return [sensor.read(3.0) for _ in range(20000)]

    a, b, c = readings(7), readings(7), readings(8)
    assert a == b
    assert a != c
    # the sample std of 20000 normals is within ~0.5 % (1 sigma) of the true std
    assert statistics.stdev(a) == pytest.approx(std, rel=0.03)
    assert statistics.fmean(a) == pytest.approx(3.0, abs=5 * std / 20000**0.5)


def test_sensor_bias_offsets_exactly() -> None:
    sensor = Sensor(bias=-0.125)
    assert [sensor.read(v) for v in (0.0, 1.5, -2.0)] == [-0.125, 1.375, -2.125]


@pytest.mark.parametrize(
    ("kwargs", "fragment"),
    [
        ({"gap": -0.1}, "gap must be >= 0"),
        ({"coulomb": float("nan")}, "coulomb must be finite"),
        ({"frame_stiffness": 0.0}, "stiffness must be > 0"),
    ],
)
def test_bad_effect_parameters_are_named(kwargs: dict[str, float], fragment: str) -> None:
    with pytest.raises(EffectParameterError, match=fragment):
        LoadPath(make_model("elastic", k=K), dt=DT, **kwargs)


def test_noisy_sensor_without_generator_is_refused() -> None:
    with pytest.raises(EffectParameterError, match="seeded random generator"):
        Sensor(noise_std=0.1)
