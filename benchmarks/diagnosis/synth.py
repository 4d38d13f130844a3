"""Records with a known effect, generated with the simulated lab (``sim_actuator`` rig).

Each record is one specimen on the rig driven by a pseudo-dynamic-like displacement history
(band-limited random response, 0.3-2 Hz, peak 3-8 yield displacements), one move per step,
ramped over the step and measured at its end (continuous testing: ``settle_time = 0``). The
specimen's Bouc-Wen shape (alpha, n, beta, gamma) and scale (k0, fy) are drawn per record;
every record carries the instrument's own noise (0.1 % of the peak displacement on the LVDT,
0.2 % of fy on the load cell), below the diagnosis noise floor. The effect, if any, is set
where the rig has it, at a random magnitude in the ranges of :data:`MAGNITUDES`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from fresco_bridge.diagnosis.load import Record, record_from_arrays
from sim_actuator.config import build_rig, parse_rig_config

__all__ = [
    "MAGNITUDES",
    "SyntheticRecord",
    "command_history",
    "rig_record",
    "run_rig",
    "sensor_effect",
    "signed",
    "synthetic_record",
    "uniform",
]

FloatArray = npt.NDArray[np.float64]

MAGNITUDES: dict[str, str] = {
    "actuator_delay": "tau 5-40 ms",
    "actuator_amplitude": "amplitude error ±(3-10) %",
    "actuator_undershoot": "end point short by 1-4 % of the peak displacement against the motion",
    "backlash": "gap 2-8 % of the peak displacement, each side",
    "friction": "Coulomb 3-10 % of fy",
    "pinching": "zeta_s 0.3-0.8, psi0 0.1-0.3, q 0-0.2",
    "degradation": "delta_nu = delta_eta, 0.2-0.6 over the record's normalised path length",
    "rate_dependence": "viscous force 3-10 % of fy at the RMS velocity",
    "sensor_bias": "load cell ±(2-8) % of fy, LVDT ±(1-4) % of the peak displacement",
    "sensor_noise": "load cell 1.5-5 % of fy, LVDT 0.5-2 % of the peak displacement (std)",
    "none": "instrument noise only",
}
"""What each effect's random magnitude is drawn from (the bench's definition)."""

PLAIN_PINCHING = {"p": 1.0, "lam": 0.5, "delta_psi": 0.0}
"""The plain bench's pinching build-up: within the first cycle (p = 1 per unit normalised
energy), Foliente's coupling 0.5, a constant spread."""

NOMINAL_LVDT_NOISE = 0.001
"""Instrument noise of every record: LVDT std as a fraction of the peak displacement."""
NOMINAL_LOAD_CELL_NOISE = 0.002
"""Instrument noise of every record: load-cell std as a fraction of fy."""


@dataclass(frozen=True)
class SyntheticRecord:
    """A generated record and what the generator put in it (the bench's ground truth)."""

    record: Record
    effect: str
    truth: dict[str, float]
    """True effect parameters in the diagnosis' names and units."""
    specimen: dict[str, float] = field(default_factory=dict)
    law: str = "bouc-wen"
    """The specimen's hysteresis law (a ``sim_actuator.models`` kind)."""
    also_present: dict[str, dict[str, float]] = field(default_factory=dict)
    """Secondary effects the generator really added beside ``effect`` (effect name ->
    parameters in the diagnosis' names and units): a verdict naming one of them beside the
    primary effect is right (``bench.credit``). Empty on the plain bench."""


def command_history(rng: np.random.Generator, steps: int, dt: float, peak: float) -> FloatArray:
    """Band-limited (0.3-2 Hz) random displacement with a 2 s build-up, scaled to ``peak``."""
    n_fft = 1 << math.ceil(math.log2(steps * 2))
    freqs = np.fft.rfftfreq(n_fft, dt)
    band = (freqs >= 0.3) & (freqs <= 2.0)
    spectrum = np.zeros(freqs.size, dtype=np.complex128)
    spectrum[band] = rng.standard_normal(band.sum()) + 1j * rng.standard_normal(band.sum())
    signal = np.fft.irfft(spectrum, n_fft)[:steps]
    t = np.arange(steps) * dt
    signal *= np.minimum(1.0, t / 2.0)
    return np.asarray(signal / np.max(np.abs(signal)) * peak, dtype=np.float64)


def uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    """A draw from [lo, hi)."""
    return float(rng.uniform(lo, hi))


def signed(rng: np.random.Generator, lo: float, hi: float) -> float:
    """A draw from [lo, hi) with a random sign."""
    return float(rng.choice((-1.0, 1.0))) * uniform(rng, lo, hi)


def synthetic_record(effect: str, seed: int, *, steps: int = 3000,
                     dt: float = 0.01) -> SyntheticRecord:
    """Generate one record with ``effect`` (or ``none``) from ``seed``, through the rig."""
    rng = np.random.default_rng(seed)
    k0 = uniform(rng, 5.0, 50.0)
    fy = uniform(rng, 10.0, 100.0)
    beta = uniform(rng, 0.3, 0.8)
    specimen: dict[str, float] = {
        "k0": k0, "fy": fy, "alpha": uniform(rng, 0.02, 0.15), "n": uniform(rng, 1.0, 3.0),
        "beta": beta, "gamma": 1.0 - beta,
    }
    dy = fy / k0
    peak = uniform(rng, 3.0, 8.0) * dy
    cmd = command_history(rng, steps, dt, peak)
    path_u = float(np.sum(np.abs(np.diff(cmd)))) / dy
    v_rms = float(np.sqrt(np.mean((np.diff(cmd) / dt) ** 2)))
    kind = "bouc-wen"
    actuator: dict[str, Any] = {"stroke": 10.0 * peak + 10.0, "force_capacity": 1e6}
    effects: dict[str, Any] = {}
    lvdt: dict[str, Any] = {"noise_std": NOMINAL_LVDT_NOISE * peak}
    load_cell: dict[str, Any] = {"noise_std": NOMINAL_LOAD_CELL_NOISE * fy}
    truth: dict[str, float] = {}
    if effect == "actuator_delay":
        truth["tau"] = uniform(rng, 0.005, 0.040)
        actuator["delay"] = truth["tau"]
    elif effect == "actuator_amplitude":
        truth["amplitude_error"] = signed(rng, 0.03, 0.10)
        actuator["amplitude"] = 1.0 + truth["amplitude_error"]
    elif effect == "actuator_undershoot":
        truth["undershoot"] = uniform(rng, 0.01, 0.04) * peak
        actuator["undershoot"] = truth["undershoot"]
    elif effect == "backlash":
        truth["gap"] = uniform(rng, 0.02, 0.08) * peak
        effects["backlash"] = {"gap": truth["gap"]}
    elif effect == "friction":
        truth["coulomb"] = uniform(rng, 0.03, 0.10) * fy
        effects["friction"] = {"coulomb": truth["coulomb"]}
    elif effect == "rate_dependence":
        truth["viscous"] = uniform(rng, 0.03, 0.10) * fy / v_rms
        effects["friction"] = {"viscous": truth["viscous"]}
    elif effect == "pinching":
        kind = "bwbn"
        truth.update(zeta_s=uniform(rng, 0.3, 0.8), psi0=uniform(rng, 0.1, 0.3),
                     q=uniform(rng, 0.0, 0.2))
        specimen.update(truth, **PLAIN_PINCHING)
    elif effect == "degradation":
        kind = "bwbn"
        delta = uniform(rng, 0.2, 0.6) / path_u
        truth.update(delta_nu=delta, delta_eta=delta)
        specimen.update(truth, p=0.0, q=0.0, psi0=1.0, delta_psi=0.0, lam=1.0)
    elif effect in ("sensor_bias", "sensor_noise"):
        truth.update(sensor_effect(effect, rng, fy, peak, lvdt, load_cell))
    elif effect != "none":
        raise ValueError(f"unknown effect {effect!r}")
    return rig_record("bench", effect, seed, kind, specimen, actuator, effects,
                      {"lvdt": lvdt, "load_cell": load_cell}, truth, cmd, dt)


def sensor_effect(effect: str, rng: np.random.Generator, fy: float, peak: float,
                  lvdt: dict[str, Any], load_cell: dict[str, Any]) -> dict[str, float]:
    """Put ``sensor_bias`` or ``sensor_noise`` on the two channels; its truth."""
    if effect == "sensor_bias":
        truth = {"force_bias": signed(rng, 0.02, 0.08) * fy,
                 "disp_bias": signed(rng, 0.01, 0.04) * peak}
        lvdt["bias"], load_cell["bias"] = truth["disp_bias"], truth["force_bias"]
    else:
        truth = {"force_noise_std": uniform(rng, 0.015, 0.05) * fy,
                 "disp_noise_std": uniform(rng, 0.005, 0.02) * peak}
        lvdt["noise_std"] = truth["disp_noise_std"]
        load_cell["noise_std"] = truth["force_noise_std"]
    return truth


def rig_record(bench: str, effect: str, seed: int, kind: str, specimen: dict[str, float],
               actuator: dict[str, Any], effects: dict[str, Any],
               sensors: dict[str, dict[str, Any]], truth: dict[str, float], cmd: FloatArray,
               dt: float, also_present: dict[str, dict[str, float]] | None = None,
               ) -> SyntheticRecord:
    """The generated record with what the generator put in it (``also_present``: secondary
    effects beside ``effect``, see :class:`SyntheticRecord`)."""
    record = run_rig({
        "name": f"{bench}-{effect}-{seed}", "seed": seed % (2**32),
        "specimen": {"kind": kind, "params": specimen},
        "actuator": actuator, "effects": effects, "sensors": sensors,
    }, cmd, dt, f"{bench} record seed {seed} ({effect})")
    return SyntheticRecord(record, effect, truth, specimen, kind, dict(also_present or {}))


def run_rig(rig: dict[str, Any], cmd: FloatArray, dt: float, source: str) -> Record:
    """Drive a rig (``sim_actuator`` config keys; clock keys added here) one move per step,
    ramped over the step at 1 kHz substeps and measured at its end (``settle_time = 0``)."""
    config = parse_rig_config({
        **rig, "substep_rate": 1000.0, "settle_time": 0.0, "default_ramp_time": dt,
        "max_ramp_time": 1.0,
    }, source=source)
    built = build_rig(config)
    steps = cmd.size
    disp = np.empty(steps)
    force = np.empty(steps)
    for i, target in enumerate(cmd):
        m = built.execute(float(target), dt)
        disp[i], force[i] = m.displacement, m.force
    return record_from_arrays(np.arange(steps, dtype=np.float64) * dt, cmd, force, disp,
                              source=source)
