"""Hybrid-simulation error indicators: one home for online monitors and offline diagnosis.

Every function compares a *command* displacement history ``cmd`` (x_c, what the integrator
asked for, i.e. ctrl) with the *measured* one ``meas`` (x_m, daq). Conventions:

- NRMS error = sqrt(Σ(x_m − x_c)² / Σx_c²) (HSCAM).
- Peak errors: eDM = max|x_m| − max|x_c| (amplitude error of the peaks), eMD = max|x_m − x_c|
  (worst instant). Both in the units of the inputs.
- Tracking indicator, OpenFresco Express convention (GUI/Integrator_AlphaOS.m):
  TI = 0.5·(cumtrapz(U, Um) − cumtrapz(Um, U)) with U = command and Um = measured.
  A *decreasing* TI means the measurement lags the command (energy is added: destabilising);
  for x_c = A sin ωt, x_m = B sin ω(t − τ) it changes by −πAB·sin(ωτ) per cycle.
- FEI (frequency evaluation index, HSCAM): FEI = Σ_j (X_m/X_c)(f_j)·w_j with spectral weights
  w_j = |X_c(f_j)|^l / Σ|X_c|^l; amplitude ratio A0 = |FEI|, equivalent frequency
  f_eq = Σ|X_c|^l f_j / Σ|X_c|^l and equivalent delay δ = −arg(FEI)/(2π f_eq). The weights use
  the *command* spectrum so that a pure gain B/A returns A0 = B/A exactly (HSCAM's page writes
  |X_m|^l in the numerator, which would return (B/A)^(l+1)).
- Cross-correlation delay: the lag maximising corr(x_m(t + k), x_c(t)) (RTHS benchmark J1),
  refined to a fraction of a sample by a parabola through the peak.
- Energy error (after Mosqueda et al.'s energy monitors): the hysteretic work ∫F dd of the
  measured force against that of a simulated force along the same displacement, relative.
- White-noise level: the robust std of first differences / √2 (MAD-based), which sees the
  white part of a residual and not its smooth or sparse-jump parts.

Positive delays mean the measurement lags the command. All functions are pure numpy.

Model-updating indicators (source paper, Table 3 and Fig. 14) compare a *true* force history
``true`` (the tested element's measurement, or in simulation the twin's true force) with the
force ``pred`` an updatable numerical element predicted:

- peak values PV = (max F, −min F) of each history (both reported as magnitudes, as in Table 3);
  AEPV = |PV_true − PV_pred| per sign;
- MAETH = max |true − pred| over the time history (paper eq. 9 maximised);
- MAESD = max |u − u_ref| per story of the story (floor) displacement against the reference;
- one-step RMSE = RMS of the twin's force predicted *before* the updater saw the step, against
  the truth: what the model knew, not what it re-fitted.
"""

from __future__ import annotations

import functools
import math
from array import array
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from sim_actuator.checks import POSITIVE, checked

FloatArray = npt.NDArray[np.float64]
Signal = Sequence[float] | npt.NDArray[np.floating]

__all__ = [
    "IndicatorError",
    "MonitorSample",
    "OnlineMonitor",
    "PeakValues",
    "energy_error",
    "fei",
    "hysteretic_work",
    "maesd",
    "maeth",
    "nrms_error",
    "one_step_rmse",
    "peak_errors",
    "peak_values",
    "rmseth",
    "state_unexplained",
    "tracking_indicator",
    "white_noise_std",
    "xcorr_delay",
]


class IndicatorError(ValueError):
    """An indicator cannot be computed from the given signals (shape, NaN, no content)."""


def _pair(
    cmd: Signal, meas: Signal, *, where: str, min_len: int = 1
) -> tuple[FloatArray, FloatArray]:
    """Validate a command/measurement pair: 1-D, equal length, finite, long enough."""
    c = np.asarray(cmd, dtype=np.float64)
    m = np.asarray(meas, dtype=np.float64)
    if c.ndim != 1 or m.ndim != 1:
        raise IndicatorError(
            f"{where}: cmd and meas must be 1-D, got shapes {c.shape} and {m.shape}"
        )
    if c.shape != m.shape:
        raise IndicatorError(
            f"{where}: cmd and meas must have the same length, got {c.size} and {m.size}"
        )
    if c.size < min_len:
        raise IndicatorError(f"{where}: needs at least {min_len} samples, got {c.size}")
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(m))):
        raise IndicatorError(f"{where}: cmd and meas must be finite (found NaN or inf)")
    return c, m


def _positive(value: float, name: str, where: str) -> float:
    return checked(POSITIVE, name, value, IndicatorError, where)


def nrms_error(cmd: Signal, meas: Signal) -> float:
    """Normalised RMS tracking error sqrt(Σ(x_m − x_c)² / Σx_c²); 0 is perfect tracking."""
    c, m = _pair(cmd, meas, where="nrms_error")
    energy = float(np.dot(c, c))
    if energy == 0.0:
        raise IndicatorError("nrms_error: the command is identically zero, NRMS is undefined")
    e = m - c
    return math.sqrt(float(np.dot(e, e)) / energy)


def peak_errors(cmd: Signal, meas: Signal) -> tuple[float, float]:
    """(eDM, eMD): peak-amplitude error max|x_m| − max|x_c| and worst error max|x_m − x_c|."""
    c, m = _pair(cmd, meas, where="peak_errors")
    e_dm = float(np.max(np.abs(m)) - np.max(np.abs(c)))
    e_md = float(np.max(np.abs(m - c)))
    return e_dm, e_md


@dataclass(frozen=True, slots=True)
class PeakValues:
    """Table 3 of the source paper for one element: peak forces and their absolute errors."""

    pv_es_pos: float
    """max of the true (experimental-substructure) force."""
    pv_es_neg: float
    """−min of the true force (a magnitude)."""
    pv_ums_pos: float
    """max of the predicted (updatable-numerical-substructure) force."""
    pv_ums_neg: float
    """−min of the predicted force (a magnitude)."""

    @property
    def aepv_pos(self) -> float:
        return abs(self.pv_es_pos - self.pv_ums_pos)

    @property
    def aepv_neg(self) -> float:
        return abs(self.pv_es_neg - self.pv_ums_neg)


def peak_values(true: Signal, pred: Signal) -> PeakValues:
    """Positive and negative peak values of a true and a predicted force history."""
    t, p = _pair(true, pred, where="peak_values")
    return PeakValues(float(t.max()), float(-t.min()), float(p.max()), float(-p.min()))


def maeth(true: Signal, pred: Signal) -> float:
    """Maximum absolute error in the time history, max |true − pred| (paper eq. 9)."""
    t, p = _pair(true, pred, where="maeth")
    return float(np.max(np.abs(t - p)))


def one_step_rmse(true: Signal, pred_ahead: Signal) -> float:
    """RMS of one-step-ahead prediction errors sqrt(mean((true − pred_ahead)²))."""
    return _rms_error(true, pred_ahead, "one_step_rmse")


def rmseth(true: Signal, pred: Signal) -> float:
    """RMS error over the time history sqrt(mean((true − pred)²)) of a twin's served force:
    beside MAETH, an error no single step decides (on a measured friction damper MAETH can be
    set by force chatter no hysteresis law follows: ``BENCHMARKS.md``, "Online updating")."""
    return _rms_error(true, pred, "rmseth")


def _rms_error(true: Signal, pred: Signal, where: str) -> float:
    t, p = _pair(true, pred, where=where)
    return math.sqrt(float(np.mean((t - p) ** 2)))


def maesd(disp: npt.ArrayLike, disp_ref: npt.ArrayLike) -> list[float]:
    """Per story (column) max |u − u_ref| of two (steps, stories) displacement histories."""
    u = np.asarray(disp, dtype=np.float64)
    r = np.asarray(disp_ref, dtype=np.float64)
    if u.ndim != 2 or u.shape != r.shape or u.shape[0] == 0:
        raise IndicatorError(
            f"maesd: need two equal (steps, stories) histories, got shapes {u.shape} and {r.shape}"
        )
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(r))):
        raise IndicatorError("maesd: displacements must be finite (found NaN or inf)")
    return [float(v) for v in np.max(np.abs(u - r), axis=0)]


def tracking_indicator(cmd: Signal, meas: Signal) -> FloatArray:
    """TI history, same length as the inputs and starting at 0; decreasing TI means lag.

    Trapezoidal TI reduces per increment to 0.5·(U_i·Um_{i−1} − U_{i−1}·Um_i), which is what
    the online monitor accumulates.
    """
    c, m = _pair(cmd, meas, where="tracking_indicator")
    ti = np.zeros_like(c)
    if c.size > 1:
        np.cumsum(0.5 * (c[1:] * m[:-1] - c[:-1] * m[1:]), out=ti[1:])
    return ti


def fei(
    cmd: Signal, meas: Signal, dt: float, l: int = 2, *, taper: bool = False  # noqa: E741
) -> tuple[float, float]:
    """(A0, δ): amplitude ratio |FEI| and equivalent delay in seconds (positive = lag).

    Means are removed and the DC bin is skipped. ``taper=True`` applies a Hann window to both
    signals first, which limits leakage when the record is not a whole number of periods
    (the online monitor's sliding window). ``l`` is the spectral weight exponent.
    """
    c, m = _pair(cmd, meas, where="fei", min_len=4)
    step = _positive(dt, "dt", "fei")
    if l < 1:
        raise IndicatorError(f"fei: weight exponent l must be >= 1, got {l}")
    both = np.stack((c, m))
    result = _fei_of_rows(both, step, l, taper=taper)
    if result is None:
        raise IndicatorError("fei: the command has no non-DC spectral content, FEI is undefined")
    return result


def _fei_of_rows(both: FloatArray, step: float, l: int, *, taper: bool  # noqa: E741
                 ) -> tuple[float, float] | None:
    """FEI's arithmetic on a (2, n) array of (command, measurement), overwritten in place
    (means removed, tapered), checks left to the caller; None when the command has no non-DC
    content. One home for ``fei`` and the online monitor (which fills the array from its rings
    and skips the checks: they hold finite values only)."""
    both -= both.mean(axis=1, keepdims=True)
    if taper:
        both *= _hann(both.shape[1])
    spectra = np.fft.rfft(both)
    xc, xm = spectra[0, 1:], spectra[1, 1:]
    mag = np.abs(xc)
    weight = mag**l
    total = float(weight.sum())
    if not (math.isfinite(total) and total > 0.0):
        return None
    # (X_m / X_c)·|X_c|^l written without the division, so empty bins contribute 0.
    safe = np.where(mag > 0.0, mag, 1.0)
    index = complex(np.sum(xm * np.conj(xc) * (weight / (safe * safe)))) / total
    f_eq = float(np.dot(weight, _rfft_freqs(both.shape[1], step))) / total
    return abs(index), -math.atan2(index.imag, index.real) / (2.0 * math.pi * f_eq)


@functools.lru_cache(maxsize=8)
def _hann(n: int) -> FloatArray:
    """``np.hanning(n)``, made once per length (read-only): making it was a quarter of a
    ``fei`` (the online monitor's, every ``window/4`` steps)."""
    window = np.hanning(n)
    window.flags.writeable = False
    return window


@functools.lru_cache(maxsize=8)
def _rfft_freqs(n: int, dt: float) -> FloatArray:
    """``np.fft.rfftfreq(n, d=dt)[1:]`` (no DC bin), made once per length and step
    (read-only)."""
    freqs: FloatArray = np.fft.rfftfreq(n, d=dt)[1:].astype(np.float64, copy=False)
    freqs.flags.writeable = False
    return freqs


def xcorr_delay(cmd: Signal, meas: Signal, dt: float, max_lag: int) -> float:
    """Delay (s) maximising the correlation of meas(t + k) with cmd(t), |k| <= max_lag samples.

    Each lag uses the Pearson coefficient over the overlapping samples, so short overlaps are
    not penalised; a parabola through the peak and its neighbours gives sub-sample resolution.
    """
    c, m = _pair(cmd, meas, where="xcorr_delay", min_len=3)
    step = _positive(dt, "dt", "xcorr_delay")
    if isinstance(max_lag, bool) or not isinstance(max_lag, int | np.integer):
        raise IndicatorError(f"xcorr_delay: max_lag is a sample count (int), got {max_lag!r}")
    if not 0 <= max_lag <= c.size - 3:
        raise IndicatorError(
            f"xcorr_delay: max_lag must be in [0, {c.size - 3}] for {c.size} samples, got {max_lag}"
        )
    lags = np.arange(-max_lag, max_lag + 1)
    corr = np.array([_pearson(c, m, int(k)) for k in lags])
    if not np.any(np.isfinite(corr)):
        raise IndicatorError("xcorr_delay: a signal is constant, correlation is undefined")
    best = int(np.nanargmax(corr))
    shift = 0.0
    if 0 < best < corr.size - 1 and np.all(np.isfinite(corr[best - 1 : best + 2])):
        left, mid, right = (float(v) for v in corr[best - 1 : best + 2])
        curvature = left - 2.0 * mid + right
        if curvature < 0.0:
            shift = 0.5 * (left - right) / curvature
    return (float(lags[best]) + shift) * step


def hysteretic_work(disp: Signal, force: Signal) -> float:
    """Work of the force along the displacement, trapezoidal Σ ½(F_i + F_{i−1})(d_i − d_{i−1})."""
    d, f = _pair(disp, force, where="hysteretic_work", min_len=2)
    return float(np.dot(0.5 * (f[1:] + f[:-1]), np.diff(d)))


def energy_error(disp: Signal, force_meas: Signal, force_sim: Signal) -> float:
    """(W_meas − W_sim) / |W_meas| along the same displacement; positive: the specimen
    dissipated more than the simulation says."""
    measured = hysteretic_work(disp, force_meas)
    simulated = hysteretic_work(disp, force_sim)
    if measured == 0.0:
        raise IndicatorError("energy_error: the measured force does no work, undefined")
    return (measured - simulated) / abs(measured)


def white_noise_std(signal: Signal) -> float:
    """Std of the white part of ``signal``: 1.4826·MAD(Δx)/√2 (smooth drift and rare jumps,
    such as friction reversals, barely move the median)."""
    x = np.asarray(signal, dtype=np.float64)
    if x.ndim != 1 or x.size < 3 or not np.all(np.isfinite(x)):
        raise IndicatorError("white_noise_std: needs a finite 1-D signal of >= 3 samples")
    dx = np.diff(x)
    return float(1.4826 * np.median(np.abs(dx - np.median(dx))) / math.sqrt(2.0))


def state_unexplained(residual: Signal, state: npt.NDArray[np.float64]
                      ) -> tuple[float, npt.NDArray[np.float64]] | None:
    """(R², the part left) of ``residual`` after a least-squares fit on the columns of
    ``state``: R² is near 0 for noise that has nothing to do with the loop, large for a residual
    the loop's state drives (a law's misfit, an interface error). None for a residual without
    variance or too short for the fit."""
    r = np.asarray(residual, dtype=np.float64)
    if r.ndim != 1 or state.shape[0] != r.size or r.size <= 2 * state.shape[1]:
        return None
    variance = float(np.var(r))
    if variance <= 0.0 or not math.isfinite(variance):
        return None
    rest: npt.NDArray[np.float64] = r - state @ np.linalg.lstsq(state, r, rcond=None)[0]
    return float(1.0 - np.var(rest) / variance), rest


def _pearson(c: FloatArray, m: FloatArray, k: int) -> float:
    """corr(m[t + k], c[t]) over the overlap; NaN when either slice is constant."""
    a, b = (c[: c.size - k], m[k:]) if k >= 0 else (c[-k:], m[: m.size + k])
    a = a - a.mean()
    b = b - b.mean()
    denom = math.sqrt(float(np.dot(a, a)) * float(np.dot(b, b)))
    return float(np.dot(a, b)) / denom if denom > 0.0 else math.nan


class MonitorSample(NamedTuple):
    """The online indicators after one step (a named tuple: made once per committed step, it
    costs a fifth of a frozen dataclass).

    ``nrms`` is cumulative since the start (None while the command is still all zero);
    ``fei_amplitude``/``fei_delay`` are recomputed every ``fei_every`` steps over the sliding
    window (None until the window is full). ``warning`` is edge-triggered: non-None only on
    the step a threshold is first crossed, so publishing it as an event cannot flood.
    """

    tracking_error: float
    ti: float
    nrms: float | None
    fei_amplitude: float | None
    fei_delay: float | None
    warning: str | None = None


class OnlineMonitor:
    """Per-site online error monitor: O(1) work per step and fixed memory.

    The FEI over the last ``window`` steps is recomputed every ``fei_every`` steps (an rfft of
    ``window`` points, a few tens of µs at 512) and held in between. ``dt`` is the integration
    time step, so frequencies and delays are in simulated time.

    Warnings: ``warn_tracking_error`` trips when |x_m − x_c| exceeds it; ``warn_ti_rate``
    (TI units per second) trips when TI *falls* faster than that over the window (lag adding
    energy). A tripped condition re-arms after ``window`` steps without it.
    """

    def __init__(
        self,
        dt: float,
        window: int = 512,
        warn_tracking_error: float | None = None,
        warn_ti_rate: float | None = None,
        *,
        fei_every: int | None = None,
    ) -> None:
        self.dt = _positive(dt, "dt", "OnlineMonitor")
        if window < 8:
            raise IndicatorError(f"OnlineMonitor: window must be >= 8 samples, got {window}")
        for name, value in (("warn_tracking_error", warn_tracking_error),
                            ("warn_ti_rate", warn_ti_rate)):
            if value is not None:
                _positive(value, name, "OnlineMonitor")
        self.window = window
        self.fei_every = window // 4 if fei_every is None else fei_every
        if self.fei_every < 1:
            raise IndicatorError(f"OnlineMonitor: fei_every must be >= 1, got {self.fei_every}")
        self.warn_tracking_error = warn_tracking_error
        self.warn_ti_rate = warn_ti_rate
        # rings of C doubles: a store is far cheaper than a numpy scalar store (once a step),
        # no float object is kept alive per slot, and the FEI reads them without a copy
        self._cmd = array("d", bytes(8 * window))
        self._meas = array("d", bytes(8 * window))
        self._ti_ring = array("d", bytes(8 * window))
        self._checks = warn_tracking_error is not None or warn_ti_rate is not None
        self._steps = 0
        self._prev: tuple[float, float] | None = None
        self._ti = 0.0
        self._sum_err2 = 0.0
        self._sum_cmd2 = 0.0
        self._fei: tuple[float, float] | None = None
        self._last_seen: dict[str, int] = {}

    @property
    def steps(self) -> int:
        """Number of samples seen so far."""
        return self._steps

    def update(self, cmd: float, meas: float) -> MonitorSample:
        """Add one (command, measurement) pair and return the indicators after it."""
        if not (math.isfinite(cmd) and math.isfinite(meas)):
            raise IndicatorError(
                f"OnlineMonitor.update: step {self._steps}: cmd={cmd!r}, meas={meas!r} not finite"
            )
        err = meas - cmd
        if self._prev is not None:
            prev_cmd, prev_meas = self._prev
            self._ti += 0.5 * (cmd * prev_meas - prev_cmd * meas)
        self._prev = (cmd, meas)
        self._sum_err2 += err * err
        self._sum_cmd2 += cmd * cmd
        slot = self._steps % self.window
        ti_window_ago = self._ti_ring[slot]  # TI `window` steps ago, once full
        self._cmd[slot] = cmd
        self._meas[slot] = meas
        self._ti_ring[slot] = self._ti
        self._steps += 1
        full = self._steps >= self.window
        if full and (self._steps - self.window) % self.fei_every == 0:
            self._fei = self._window_fei()
        nrms = math.sqrt(self._sum_err2 / self._sum_cmd2) if self._sum_cmd2 > 0.0 else None
        warning = (self._check(err, ti_window_ago if self._steps > self.window else None)
                   if self._checks else None)
        fei_a, fei_d = self._fei if self._fei is not None else (None, None)
        return MonitorSample(err, self._ti, nrms, fei_a, fei_d, warning)

    def update_many(self, pairs: Sequence[tuple[float, float]]
                    ) -> tuple[list[tuple[float, float, float | None, float | None, float | None]],
                               list[tuple[int, str]]]:
        """``update`` for each (command, measurement) pair in order, in one loop (a batch:
        ``telemetry.taps.MonitorBatch``): the same state after it and the same samples — the
        same arithmetic in the same order —, returned as each sample's values
        (``tracking_error, ti, nrms, fei_amplitude, fei_delay``) and the warnings as (index
        in ``pairs``, text). IndicatorError at a non-finite pair, after the pairs before it."""
        values: list[tuple[float, float, float | None, float | None, float | None]] = []
        warnings: list[tuple[int, str]] = []
        window, fei_every, checks = self.window, self.fei_every, self._checks
        cmd_ring, meas_ring, ti_ring = self._cmd, self._meas, self._ti_ring
        ti, prev, sum_err2, sum_cmd2 = self._ti, self._prev, self._sum_err2, self._sum_cmd2
        steps = self._steps
        fei_a, fei_d = self._fei if self._fei is not None else (None, None)
        isfinite, sqrt = math.isfinite, math.sqrt
        try:
            for index, (cmd, meas) in enumerate(pairs):
                if not (isfinite(cmd) and isfinite(meas)):
                    raise IndicatorError(f"OnlineMonitor.update: step {steps}: cmd={cmd!r}, "
                                         f"meas={meas!r} not finite")
                err = meas - cmd
                if prev is not None:
                    ti += 0.5 * (cmd * prev[1] - prev[0] * meas)
                prev = (cmd, meas)
                sum_err2 += err * err
                sum_cmd2 += cmd * cmd
                slot = steps % window
                ti_window_ago = ti_ring[slot]
                cmd_ring[slot] = cmd
                meas_ring[slot] = meas
                ti_ring[slot] = ti
                steps += 1
                if steps >= window and (steps - window) % fei_every == 0:
                    self._steps = steps  # what the window is read with
                    self._fei = self._window_fei()
                    fei_a, fei_d = self._fei if self._fei is not None else (None, None)
                nrms = sqrt(sum_err2 / sum_cmd2) if sum_cmd2 > 0.0 else None
                if checks:
                    self._ti, self._steps = ti, steps
                    warning = self._check(err, ti_window_ago if steps > window else None)
                    if warning:
                        warnings.append((index, warning))
                values.append((err, ti, nrms, fei_a, fei_d))
        finally:
            self._ti, self._prev, self._sum_err2, self._sum_cmd2 = ti, prev, sum_err2, sum_cmd2
            self._steps = steps
        return values, warnings

    def window_arrays(self) -> tuple[FloatArray, FloatArray]:
        """The last ``min(steps, window)`` commands and measurements, oldest first."""
        if self._steps < self.window:
            n = self._steps
            return (np.frombuffer(self._cmd, count=n).copy(),
                    np.frombuffer(self._meas, count=n).copy())
        start = self._steps % self.window
        cmd, meas = np.frombuffer(self._cmd), np.frombuffer(self._meas)
        return (np.concatenate((cmd[start:], cmd[:start])),
                np.concatenate((meas[start:], meas[:start])))

    def _window_fei(self) -> tuple[float, float] | None:
        """``fei(*self.window_arrays(), self.dt, taper=True)`` of the full window, or None
        when the command has no content (HOLD, a quasi-static plateau): ``fei``'s own core
        (``_fei_of_rows``) on the window read straight from the rings, without ``fei``'s
        checks — the rings hold only finite values (``update`` refuses the others)."""
        n = self.window
        start = self._steps % n
        both = np.empty((2, n))
        for row, ring in ((0, self._cmd), (1, self._meas)):
            values = np.frombuffer(ring)
            both[row, : n - start] = values[start:]
            both[row, n - start:] = values[:start]
        return _fei_of_rows(both, self.dt, 2, taper=True)

    def _check(self, err: float, ti_window_ago: float | None) -> str | None:
        messages: list[str] = []
        limit = self.warn_tracking_error
        if limit is not None and abs(err) > limit:
            messages += self._trip("tracking_error", f"|tracking error| {abs(err):.6g} > {limit:g}")
        rate_limit = self.warn_ti_rate
        if rate_limit is not None and ti_window_ago is not None:
            rate = (self._ti - ti_window_ago) / (self.window * self.dt)
            if rate < -rate_limit:
                messages += self._trip(
                    "ti_rate", f"TI falling at {-rate:.6g}/s > {rate_limit:g}/s (lag)"
                )
        return "; ".join(messages) if messages else None

    def _trip(self, condition: str, message: str) -> list[str]:
        """Record that ``condition`` holds now; return the message only on its rising edge."""
        last = self._last_seen.get(condition)
        self._last_seen[condition] = self._steps
        if last is not None and self._steps - last <= self.window:
            return []
        return [message]  # the caller knows which step this is (the site adds its own number)
