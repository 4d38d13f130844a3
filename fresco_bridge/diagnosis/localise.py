"""Where the gap lies: in which layer, when, at which amplitude and in which loop phase.

Every NRMS here is over the whole record's RMS force (a quiet part cannot inflate its own).

Layers (force gap = measured − sim, the sim driven by the command)::

    F − L(c) = [L(m) − L(c)]   interface: the actuator did not put the specimen where commanded
             + [F − L(m)]      specimen + sensor: the law misses the specimen, or the sensors lie

and the sensor layer is the part of F − L(m) a sensor explains: its offset (mean) and its
white noise (``indicators.white_noise_std``). Shares are of the sum of the three layers'
squared gaps, so they add to 100 % (layers can partly cancel each other: their squares need
not add to the total squared gap, and a share of the total could exceed 100 %).

Loop phases of every sample, from the measured force and the command's motion: ``reversal``
(within ±2 samples of a change of direction),
``near_zero_force`` (|F| < 10 % of the peak), ``peak`` (|c| > 80 % of the peak command),
``loading`` (moving so that |F| grows), ``unloading`` (the rest). The first that applies wins.
All indicator math is in ``fresco_bridge.indicators``.
"""

from __future__ import annotations

import math
from itertools import pairwise
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import indicators as ind
from .load import Record

__all__ = ["PHASES", "localise", "loop_phase", "phase_angle"]

FloatArray = npt.NDArray[np.float64]

PHASES = ("loading", "unloading", "reversal", "near_zero_force", "peak")
TIME_WINDOWS = 10
AMPLITUDE_BINS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0000001)


def _rms(x: FloatArray) -> float:
    return float(np.sqrt(np.mean(x * x))) if x.size else math.nan


def _maybe(fn: Any, *args: Any) -> Any:
    try:
        return fn(*args)
    except ind.IndicatorError:
        return None


def loop_phase(cmd: FloatArray, force: FloatArray) -> npt.NDArray[np.str_]:
    """The loop phase of every sample (see the module docstring)."""
    v = np.zeros_like(cmd)
    v[1:] = np.diff(cmd)
    direction = np.sign(v)
    idx = np.where(direction != 0.0, np.arange(v.size), 0)
    np.maximum.accumulate(idx, out=idx)
    direction = direction[idx]
    turns = np.flatnonzero(np.diff(direction) != 0.0) + 1
    reversal = np.zeros(cmd.size, dtype=bool)
    for k in (-2, -1, 0, 1, 2):
        reversal[np.clip(turns + k, 0, cmd.size - 1)] = True
    f_peak = float(np.max(np.abs(force))) or 1.0
    c_peak = float(np.max(np.abs(cmd))) or 1.0
    phase = np.where(direction * np.sign(force) > 0.0, "loading", "unloading").astype("<U16")
    phase[np.abs(cmd) > 0.8 * c_peak] = "peak"
    phase[np.abs(force) < 0.1 * f_peak] = "near_zero_force"
    phase[reversal] = "reversal"
    return phase


def phase_angle(cmd: FloatArray) -> FloatArray:
    """Loop phase angle of the command (degrees, 0 at a positive peak, analytic signal)."""
    c = cmd - cmd.mean()
    n = c.size
    spectrum = np.fft.fft(c)
    h = np.zeros(n)
    h[0] = 1.0
    if n % 2 == 0:
        h[n // 2] = 1.0
        h[1 : n // 2] = 2.0
    else:
        h[1 : (n + 1) // 2] = 2.0
    analytic = np.fft.ifft(spectrum * h)
    return np.asarray(np.degrees(np.angle(analytic)), dtype=np.float64)


def _gap_share(residual: FloatArray, groups: dict[str, npt.NDArray[np.bool_]],
               scale: float) -> dict[str, dict[str, float]]:
    total = float(np.sum(residual * residual)) or 1.0
    out = {}
    for name, mask in groups.items():
        r = residual[mask]
        out[name] = {
            "samples": int(mask.sum()),
            "nrms_pct": 100.0 * _rms(r) / scale if r.size else math.nan,
            "share_pct": 100.0 * float(np.sum(r * r)) / total,
        }
    return out


def localise(record: Record, sim_cmd: FloatArray, sim_meas: FloatArray | None,
             stop: int) -> dict[str, Any]:
    """The localisation block of the diagnosis (JSON-ready).

    ``sim_cmd`` is the baseline force driven by the command, ``sim_meas`` the same law driven
    by the measured displacement (None without a displacement channel); ``stop`` is the first
    withheld sample.
    """
    t, c, f, m = record.time, record.cmd, record.force, record.meas_disp
    dt = float(np.median(np.diff(t)))
    f_scale = _rms(f) or 1.0
    residual = f - sim_cmd
    out: dict[str, Any] = {}

    interface: dict[str, Any] = {"measured": m is not None}
    if m is not None:
        e_dm, e_md = ind.peak_errors(c, m)
        fei = _maybe(ind.fei, c, m, dt)
        max_lag = min(50, c.size - 3)
        interface.update(
            nrms_pct=100.0 * ind.nrms_error(c, m), peak_amplitude_error=e_dm,
            peak_error=e_md, tracking_indicator=float(ind.tracking_indicator(c, m)[-1]),
            fei_amplitude=None if fei is None else fei[0],
            fei_delay_s=None if fei is None else fei[1],
            xcorr_delay_s=_maybe(ind.xcorr_delay, c, m, dt, max_lag),
            mean_offset=float(np.mean(m - c)),
        )
    specimen_residual = residual if sim_meas is None else f - sim_meas
    interface_part = np.zeros_like(residual) if sim_meas is None else sim_meas - sim_cmd
    offset = float(np.mean(specimen_residual))
    noise = ind.white_noise_std(specimen_residual)
    structured = specimen_residual - offset
    n = residual.size
    sensor2 = n * (offset * offset + noise * noise)
    specimen2 = max(float(np.sum(structured * structured)) - n * noise * noise, 0.0)
    interface2 = float(np.sum(interface_part**2))
    total2 = (interface2 + specimen2 + sensor2) or 1.0
    out["layers"] = {
        "interface": {"nrms_pct": 100.0 * _rms(interface_part) / f_scale,
                      "share_pct": 100.0 * interface2 / total2,
                      **interface},
        "specimen": {"nrms_pct": 100.0 * math.sqrt(specimen2 / n) / f_scale,
                     "share_pct": 100.0 * specimen2 / total2},
        "sensor": {"nrms_pct": 100.0 * math.sqrt(sensor2 / n) / f_scale,
                   "share_pct": 100.0 * sensor2 / total2,
                   "force_offset": offset, "force_noise_std": noise,
                   "disp_noise_std": None if m is None else ind.white_noise_std(m - c)},
    }
    e_dm_f, e_md_f = ind.peak_errors(sim_cmd, f)
    out["force"] = {
        "nrms_pct": 100.0 * _rms(residual) / f_scale,
        "nrms_withheld_pct": 100.0 * _rms(residual[stop:]) / f_scale,
        "peak_amplitude_error": e_dm_f, "peak_error": e_md_f,
        "energy_error_pct": _maybe(lambda: 100.0 * ind.energy_error(
            m if m is not None else c, f, sim_cmd)),
    }
    edges = np.linspace(0, n, TIME_WINDOWS + 1).astype(int)
    out["time"] = [
        {"t_start": float(t[a]), "t_end": float(t[b - 1]),
         "nrms_pct": 100.0 * _rms(residual[a:b]) / f_scale,
         "part": "calibration" if b <= stop else ("withheld" if a >= stop else "both")}
        for a, b in pairwise(edges) if b > a
    ]
    rel = np.abs(c) / (float(np.max(np.abs(c))) or 1.0)
    out["amplitude"] = [
        {"from_pct": 100.0 * lo, "to_pct": min(100.0 * hi, 100.0),
         **_gap_share(residual, {"bin": (rel >= lo) & (rel < hi)}, f_scale)["bin"]}
        for lo, hi in pairwise(AMPLITUDE_BINS)
    ]
    phase = loop_phase(c, f)
    out["phase"] = _gap_share(residual, {p: phase == p for p in PHASES}, f_scale)
    worst = max(PHASES, key=lambda p: out["phase"][p]["nrms_pct"]
                if out["phase"][p]["samples"] else -1.0)
    out["worst_phase"] = worst
    return out
