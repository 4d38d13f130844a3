"""Actuator stages against closed forms: delay, first/second-order lags, amplitude, undershoot."""

from __future__ import annotations

import math
import random

import pytest

from sim_actuator.actuator import (
    Actuator,
    ActuatorParameterError,
    FirstOrderLag,
    IdealServo,
    PureDelay,
    SecondOrderServo,
)

DT = 1e-3


def _signal(n: int, seed: int = 3) -> list[float]:
    rnd = random.Random(seed)
    return [rnd.uniform(-5.0, 5.0) for _ in range(n)]


@pytest.mark.parametrize("n_delay", [0, 1, 7, 40])
def test_pure_delay_shifts_exactly_by_whole_substeps(n_delay: int) -> None:
    u = _signal(200)
    stage = PureDelay(n_delay * DT, DT, initial=0.25)
    y = [stage.step(v) for v in u]
    expected = [0.25] * n_delay + u[: len(u) - n_delay]
    assert y == expected  # bit-exact, not approximate
    assert stage.samples == n_delay
    assert stage.is_identity is (n_delay == 0)


def test_pure_delay_fractional_interpolates_a_ramp_exactly() -> None:
    delay = 2.5 * DT
    stage = PureDelay(delay, DT)
    for k in range(1, 50):
        y = stage.step(k * DT)  # unit-slope ramp sampled at t_k
        if k >= 4:
            assert y == pytest.approx(k * DT - delay, abs=1e-15)


def test_pure_delay_reset_refills_history() -> None:
    stage = PureDelay(3 * DT, DT)
    for v in (1.0, 2.0, 3.0, 4.0):
        stage.step(v)
    stage.reset(-1.0)
    assert [stage.step(9.0) for _ in range(4)] == [-1.0, -1.0, -1.0, 9.0]


@pytest.mark.parametrize("tau", [0.005, 0.02, 0.1])
def test_first_order_step_response_is_one_minus_exp(tau: float) -> None:
    stage = FirstOrderLag(tau, DT)
    for k in range(1, int(6 * tau / DT)):
        y = stage.step(1.0)
        assert y == pytest.approx(1.0 - math.exp(-k * DT / tau), abs=1e-13)


def _second_order_step(t: float, wn: float, zeta: float) -> float:
    """Closed-form unit-step response of x'' + 2 zeta wn x' + wn^2 x = wn^2 u, at rest at 0."""
    if zeta < 1.0:
        wd = wn * math.sqrt(1.0 - zeta * zeta)
        return 1.0 - math.exp(-zeta * wn * t) * (
            math.cos(wd * t) + zeta / math.sqrt(1.0 - zeta * zeta) * math.sin(wd * t)
        )
    if zeta == 1.0:
        return 1.0 - math.exp(-wn * t) * (1.0 + wn * t)
    s1 = -wn * (zeta - math.sqrt(zeta * zeta - 1.0))
    s2 = -wn * (zeta + math.sqrt(zeta * zeta - 1.0))
    return 1.0 + (s2 * math.exp(s1 * t) - s1 * math.exp(s2 * t)) / (s1 - s2)


@pytest.mark.parametrize(("fn", "zeta"), [(10.0, 0.2), (25.0, 0.7), (15.0, 1.0), (8.0, 2.5)])
def test_second_order_step_response_matches_closed_form(fn: float, zeta: float) -> None:
    stage = SecondOrderServo(fn, zeta, DT)
    wn = 2.0 * math.pi * fn
    for k in range(1, 400):
        assert stage.step(1.0) == pytest.approx(_second_order_step(k * DT, wn, zeta), abs=1e-12)


def test_second_order_natural_frequency_and_damping_from_free_decay() -> None:
    """Logarithmic decrement and period of the sampled response give back fn and zeta."""
    fn, zeta, dt = 5.0, 0.05, 1e-4
    stage = SecondOrderServo(fn, zeta, dt)
    y = [stage.step(1.0) - 1.0 for _ in range(20000)]
    peaks = [k for k in range(1, len(y) - 1) if y[k - 1] < y[k] > y[k + 1]]
    assert len(peaks) >= 5
    period = (peaks[4] - peaks[0]) * dt / 4
    decrement = math.log(y[peaks[0]] / y[peaks[1]])
    zeta_est = decrement / math.sqrt(4 * math.pi**2 + decrement**2)
    fd = 1.0 / period
    fn_est = fd / math.sqrt(1.0 - zeta_est**2)
    assert zeta_est == pytest.approx(zeta, rel=1e-3)
    assert fn_est == pytest.approx(fn, rel=2e-3)  # peak timing is quantised to dt


def test_amplitude_factor_scales_piston_position() -> None:
    act = Actuator(dt=DT, stroke=100.0, force_capacity=1e3, amplitude=0.95)
    assert not act.is_ideal
    assert act.step(4.0) == 0.95 * 4.0


def test_actuator_chain_delay_then_lag() -> None:
    """Delay of 5 substeps then a first-order lag: the lag's step response, shifted."""
    tau = 0.01
    act = Actuator(dt=DT, stroke=100.0, force_capacity=1e3, delay=5 * DT,
                   servo=FirstOrderLag(tau, DT))
    out = [act.step(2.0) for _ in range(30)]
    assert out[:5] == [0.0] * 5
    for k in range(6, 31):
        assert out[k - 1] == pytest.approx(2.0 * (1.0 - math.exp(-(k - 5) * DT / tau)), abs=1e-13)


def test_undershoot_falls_short_against_the_direction_of_motion() -> None:
    act = Actuator(dt=DT, stroke=100.0, force_capacity=1e3, undershoot=0.01)
    assert act.end_point(2.0, 0.0) == 2.0 - 0.01
    assert act.end_point(1.0, 2.0) == 1.0 + 0.01
    assert act.end_point(1.0, 1.0) == 1.0 + 0.01  # zero-length move keeps the last direction


def test_reset_puts_every_stage_at_rest() -> None:
    act = Actuator(dt=DT, stroke=100.0, force_capacity=1e3, delay=3 * DT,
                   servo=SecondOrderServo(20.0, 0.3, DT))
    for _ in range(10):
        act.step(5.0)
    act.reset(1.5)
    assert [act.step(1.5) for _ in range(20)] == pytest.approx([1.5] * 20, abs=1e-12)


def test_ideal_actuator_is_identity() -> None:
    act = Actuator(dt=DT, stroke=100.0, force_capacity=1e3, servo=IdealServo())
    assert act.is_ideal
    assert [act.step(v) for v in (0.1, -3.0, 7.25)] == [0.1, -3.0, 7.25]


@pytest.mark.parametrize(
    ("build", "fragment"),
    [
        (lambda: PureDelay(-0.1, DT), "delay must be >= 0"),
        (lambda: FirstOrderLag(0.0, DT), "tau must be > 0"),
        (lambda: SecondOrderServo(10.0, math.nan, DT), "damping must be finite"),
        (lambda: Actuator(dt=DT, stroke=-1.0, force_capacity=1.0), "stroke must be > 0"),
        (lambda: Actuator(dt=DT, stroke=1.0, force_capacity=1.0, undershoot=-1e-3),
         "undershoot must be >= 0"),
    ],
)
def test_bad_parameters_are_named(build: object, fragment: str) -> None:
    assert callable(build)
    with pytest.raises(ActuatorParameterError, match=fragment):
        build()
