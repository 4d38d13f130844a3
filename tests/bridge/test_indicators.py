"""Error indicators against closed forms, and the online monitor against the offline functions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fresco_bridge.indicators import (
    IndicatorError,
    OnlineMonitor,
    fei,
    nrms_error,
    peak_errors,
    tracking_indicator,
    xcorr_delay,
)


def sine_pair(
    *, amp: float, ratio: float, freq: float, tau: float, dt: float, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """x_c = A sin ωt and x_m = (ratio·A) sin ω(t − τ): a pure gain and a pure delay."""
    t = np.arange(n) * dt
    w = 2.0 * math.pi * freq
    return amp * np.sin(w * t), ratio * amp * np.sin(w * (t - tau))


@pytest.mark.parametrize(
    ("ratio", "tau", "freq"),
    [(1.0, 0.012, 2.0), (0.93, 0.0315, 1.0), (1.07, -0.008, 5.0), (0.5, 0.0, 2.5)],
)
def test_fei_returns_gain_and_delay_of_a_delayed_scaled_sine(
    ratio: float, tau: float, freq: float
) -> None:
    dt = 0.001
    n = round(4.0 / freq / dt)  # a whole number of periods: one spectral line, no leakage
    cmd, meas = sine_pair(amp=3.0, ratio=ratio, freq=freq, tau=tau, dt=dt, n=n)
    amplitude, delay = fei(cmd, meas, dt)
    assert amplitude == pytest.approx(ratio, rel=1e-9)
    assert delay == pytest.approx(tau, abs=1e-9)


def test_fei_with_taper_tolerates_a_partial_period_window() -> None:
    dt = 0.01
    cmd, meas = sine_pair(amp=2.0, ratio=0.95, freq=1.0, tau=0.02, dt=dt, n=512)  # 5.12 periods
    amplitude, delay = fei(cmd, meas, dt, taper=True)
    assert amplitude == pytest.approx(0.95, rel=1e-3)
    assert delay == pytest.approx(0.02, rel=1e-2)


@pytest.mark.parametrize(("tau", "ratio"), [(0.02, 0.95), (0.005, 1.0), (-0.01, 1.05)])
def test_tracking_indicator_changes_by_minus_pi_ab_sin_wtau_per_cycle(
    tau: float, ratio: float
) -> None:
    dt, freq, amp, cycles = 0.001, 1.0, 2.0, 10
    cmd, meas = sine_pair(amp=amp, ratio=ratio, freq=freq, tau=tau, dt=dt,
                          n=int(cycles / freq / dt) + 1)
    ti = tracking_indicator(cmd, meas)
    w = 2.0 * math.pi * freq
    per_cycle = -math.pi * amp * (ratio * amp) * math.sin(w * tau)
    assert ti[0] == 0.0
    assert ti[-1] == pytest.approx(cycles * per_cycle, rel=(w * dt) ** 2)
    if tau > 0:  # lag: TI decreases
        assert ti[-1] < ti[len(ti) // 2] < 0.0
    else:
        assert ti[-1] > ti[len(ti) // 2] > 0.0


def test_tracking_indicator_matches_the_express_cumtrapz_formula() -> None:
    rng = np.random.default_rng(7)
    u = np.cumsum(rng.normal(size=200))
    um = u + rng.normal(scale=0.1, size=200)

    def cumtrapz(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        out = np.zeros_like(x)
        out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(x))
        return out

    expected = 0.5 * (cumtrapz(u, um) - cumtrapz(um, u))
    np.testing.assert_allclose(tracking_indicator(u, um), expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("lag_samples", [0, 3, 17, -5])
def test_xcorr_delay_finds_an_integer_sample_delay_in_broadband_signal(lag_samples: int) -> None:
    rng = np.random.default_rng(3)
    dt, n, pad = 0.002, 4000, 40
    base = np.convolve(rng.normal(size=n + 2 * pad), np.ones(8) / 8, mode="same")
    cmd = base[pad : pad + n]
    meas = 0.8 * base[pad - lag_samples : pad - lag_samples + n]  # meas(t) = 0.8 cmd(t − lag)
    assert xcorr_delay(cmd, meas, dt, max_lag=30) == pytest.approx(lag_samples * dt, abs=0.1 * dt)


def test_xcorr_delay_resolves_a_sub_sample_delay_of_a_sine() -> None:
    dt = 0.001
    cmd, meas = sine_pair(amp=1.0, ratio=0.9, freq=2.0, tau=0.0123, dt=dt, n=3000)
    assert xcorr_delay(cmd, meas, dt, max_lag=49) == pytest.approx(0.0123, abs=0.05 * dt)


@pytest.mark.parametrize("gain", [1.0, 1.1, 0.75, -1.0])
def test_nrms_and_peak_errors_of_a_scaled_signal(gain: float) -> None:
    cmd, _ = sine_pair(amp=1.5, ratio=1.0, freq=1.0, tau=0.0, dt=0.01, n=250)
    meas = gain * cmd
    peak = float(np.max(np.abs(cmd)))
    assert nrms_error(cmd, meas) == pytest.approx(abs(gain - 1.0), abs=1e-12)
    e_dm, e_md = peak_errors(cmd, meas)
    assert e_dm == pytest.approx((abs(gain) - 1.0) * peak, abs=1e-12)
    assert e_md == pytest.approx(abs(gain - 1.0) * peak, abs=1e-12)


def test_peak_errors_see_a_single_spike_the_nrms_hides() -> None:
    cmd = np.sin(np.linspace(0.0, 20.0, 2000))
    meas = cmd.copy()
    meas[1234] += 0.3
    _, e_md = peak_errors(cmd, meas)
    assert e_md == pytest.approx(0.3)
    assert nrms_error(cmd, meas) < 0.02


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: nrms_error([1.0, 2.0], [1.0]), "same length"),
        (lambda: nrms_error([0.0, 0.0], [1.0, 1.0]), "identically zero"),
        (lambda: peak_errors([1.0, math.nan], [1.0, 1.0]), "finite"),
        (lambda: tracking_indicator([[1.0]], [[1.0]]), "1-D"),  # type: ignore[list-item]
        (lambda: fei([1.0] * 16, [1.0] * 16, 0.01), "no non-DC spectral content"),
        (lambda: fei([1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 4.0], 0.0),
         "fei: dt must be > 0, got 0.0"),
        (lambda: xcorr_delay([1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 4.0], 0.01, 0.5), "int"),  # type: ignore[arg-type]
        (lambda: xcorr_delay([1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 4.0], 0.01, 9), r"\[0, 1\]"),
        (lambda: OnlineMonitor(0.01, window=4), "window"),
        (lambda: OnlineMonitor(0.01, warn_tracking_error=-1.0), "warn_tracking_error"),
    ],
)
def test_bad_input_is_refused_with_a_specific_error(call: object, match: str) -> None:
    with pytest.raises(IndicatorError, match=match):
        call()  # type: ignore[operator]


def test_online_monitor_matches_the_offline_functions() -> None:
    dt, window = 0.01, 256
    cmd, meas = sine_pair(amp=2.0, ratio=0.95, freq=1.0, tau=0.02, dt=dt, n=1000)
    monitor = OnlineMonitor(dt, window=window, fei_every=50)
    samples = [monitor.update(float(c), float(m)) for c, m in zip(cmd, meas, strict=True)]

    ti = tracking_indicator(cmd, meas)
    for k in (1, 99, 500, 999):
        assert samples[k].tracking_error == pytest.approx(meas[k] - cmd[k], abs=1e-15)
        assert samples[k].ti == pytest.approx(ti[k], rel=1e-9, abs=1e-12)
        assert samples[k].nrms == pytest.approx(nrms_error(cmd[: k + 1], meas[: k + 1]), rel=1e-9)
    assert samples[0].nrms is None  # the command is still all zero
    assert samples[window - 2].fei_amplitude is None  # window not yet full
    # recomputed at steps window-1, window-1+50, ...: held in between
    last = window - 1 + 50 * ((len(cmd) - window) // 50)
    expected = fei(cmd[last - window + 1 : last + 1], meas[last - window + 1 : last + 1], dt,
                   taper=True)
    assert (samples[-1].fei_amplitude, samples[-1].fei_delay) == pytest.approx(expected, rel=1e-9)
    assert samples[-1].fei_delay == pytest.approx(0.02, rel=0.05)
    assert samples[-1].fei_amplitude == pytest.approx(0.95, rel=0.01)
    assert all(s.warning is None for s in samples)


def test_online_monitor_keeps_fixed_memory() -> None:
    monitor = OnlineMonitor(0.01, window=64)
    for k in range(5000):
        monitor.update(math.sin(0.1 * k), math.sin(0.1 * k - 0.05))
    cmd, meas = monitor.window_arrays()
    assert cmd.shape == meas.shape == (64,)
    assert cmd[-1] == pytest.approx(math.sin(0.1 * 4999))  # newest last


def test_tracking_error_warning_is_edge_triggered_and_rearms_after_a_clean_window() -> None:
    dt, window = 0.01, 32
    monitor = OnlineMonitor(dt, window=window, warn_tracking_error=0.5)
    errors = [0.1] * 10 + [0.6] * 5 + [0.1] * 10 + [0.7] + [0.1] * (window + 5) + [0.8]
    warnings = [(k, monitor.update(1.0, 1.0 + e).warning) for k, e in enumerate(errors)]
    fired = [(k, w) for k, w in warnings if w is not None]
    # first crossing, no repeat inside the window, re-armed after `window` clean steps
    assert [k for k, _ in fired] == [10, len(errors) - 1]
    assert "0.6 > 0.5" in fired[0][1]
    assert fired[0][1].startswith("|tracking error| 0.6")


def test_ti_rate_warning_fires_for_lag_and_not_for_lead() -> None:
    dt, window = 0.01, 100
    per_second = math.pi * 1.0 * 1.0 * math.sin(2 * math.pi * 0.03)  # |dTI/dt| at 1 Hz, 30 ms
    for tau, should_warn in ((0.03, True), (-0.03, False)):
        cmd, meas = sine_pair(amp=1.0, ratio=1.0, freq=1.0, tau=tau, dt=dt, n=400)
        monitor = OnlineMonitor(dt, window=window, warn_ti_rate=0.5 * per_second)
        fired = [k for k, (c, m) in enumerate(zip(cmd, meas, strict=True))
                 if monitor.update(float(c), float(m)).warning]
        assert bool(fired) is should_warn
        if should_warn:
            assert fired[0] == window  # first step with a full window of TI history


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-5, 5), st.floats(-5, 5)), min_size=1, max_size=90),
       st.integers(1, 40), st.sampled_from([None, 0.5]), st.sampled_from([None, 2.0]))
def test_update_many_is_update_in_a_loop(pairs: list[tuple[float, float]], cut: int,
                                         warn_error: float | None,
                                         warn_rate: float | None) -> None:
    """The batch form (``MonitorBatch``) gives the very samples, warnings and state of one
    ``update`` a pair, whatever the batches (cut anywhere), FEI updates and checks included."""
    one = OnlineMonitor(0.01, window=8, warn_tracking_error=warn_error, warn_ti_rate=warn_rate,
                        fei_every=3)
    many = OnlineMonitor(0.01, window=8, warn_tracking_error=warn_error, warn_ti_rate=warn_rate,
                         fei_every=3)
    want = [one.update(c, m) for c, m in pairs]
    got_values, got_warnings = many.update_many(pairs[:cut])
    rest_values, rest_warnings = many.update_many(pairs[cut:])
    got_values += rest_values
    got_warnings += [(cut + i, w) for i, w in rest_warnings]
    assert repr(got_values) == repr([tuple(s[:5]) for s in want])  # bit for bit, NaN-proof
    assert got_warnings == [(i, s.warning) for i, s in enumerate(want) if s.warning]
    assert repr(many.__dict__) == repr(one.__dict__)


def test_update_many_stops_at_a_non_finite_pair_after_the_pairs_before_it() -> None:
    one, many = OnlineMonitor(0.01, window=8), OnlineMonitor(0.01, window=8)
    one.update(1.0, 1.5)
    with pytest.raises(IndicatorError, match="step 1: cmd=nan"):
        many.update_many([(1.0, 1.5), (math.nan, 0.0), (2.0, 2.0)])
    assert repr(many.__dict__) == repr(one.__dict__)


def test_the_taper_is_made_once_per_length_and_cannot_be_changed() -> None:
    from fresco_bridge.indicators import _hann

    assert np.array_equal(_hann(512), np.hanning(512)) and _hann(512) is _hann(512)
    with pytest.raises(ValueError, match="read-only"):
        _hann(512)[0] = 1.0


@settings(max_examples=60, deadline=None)
@given(st.integers(8, 80), st.sampled_from([0.01, 0.003, 0.5]), st.integers(0, 200),
       st.lists(st.tuples(st.floats(-1e3, 1e3), st.floats(0.5, 1.5)), min_size=80,
                max_size=300), st.booleans())
def test_the_monitors_fei_is_fei_of_its_window_bit_for_bit(
        window: int, dt: float, shift: int, samples: list[tuple[float, float]],
        constant: bool) -> None:
    """``OnlineMonitor``'s own FEI (both signals in one array, one rfft) gives exactly what
    ``fei`` gives for the window it holds, wherever the ring starts, and None where ``fei``
    finds no content."""
    monitor = OnlineMonitor(dt, window=window)
    for cmd, gain in samples[: window + shift]:
        cmd = 2.5 if constant else cmd
        monitor.update(cmd, cmd * gain)
    cmd_window, meas_window = monitor.window_arrays()
    try:
        want: tuple[float, float] | None = fei(cmd_window, meas_window, dt, taper=True)
    except IndicatorError:
        want = None
    assert repr(monitor._window_fei()) == repr(want)
