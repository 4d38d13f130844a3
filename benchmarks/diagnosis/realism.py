"""Harder bench records (``diagnose-bench --realism``): effects in the rig's own physical forms.

The plain bench (``synth``) puts each effect into the rig in the very form the candidate fits
(a pure delay, a rigid fixture with Coulomb friction, BWBN pinching with the candidate's fixed
build-up, equal strength and stiffness degradation), so it measures identifiability, not
robustness to a wrong form. Here every effect comes from ``sim_actuator``'s models in a form
the candidates do *not* have, the specimen's law and shape vary wider, and so does the noise:

* specimen: Bouc-Wen with n 1-4, beta/(beta+gamma) 0.1-0.9 and beta+gamma 0.6-1.6 (two
  records in three), or Menegotto-Pinto (Steel02, Bauschinger curve, R0 10-20) — a law the
  Bouc-Wen baseline cannot reproduce exactly, even with no effect;
* instrument noise per record: LVDT 0.05-0.2 % of the peak displacement, load cell
  0.1-0.4 % of fy;
* ``actuator_delay``: servo dynamics instead of a transport delay — a first-order lag
  (5-30 ms) or a second-order servo (4-12 Hz, damping 0.6-1.0), plus 0-5 ms transport delay.
  The truth is the low-frequency equivalent delay (delay + tau, or delay + 2 zeta / omega_n);
* ``actuator_amplitude``: the gain error ±(3-10) % (truth: the gain error); a gain short of 1
  also gets OpenFresco's end-point undershoot of 0-1 % of the peak, in the same sense. The
  undershoot is a candidate of its own (``actuator_undershoot``), so the record carries a
  second effect: listed in ``also_present`` (undershoot in mm);
* ``actuator_undershoot``: OpenFresco's end-point undershoot (1-4 % of the peak; truth: the
  undershoot) on a servo that has not quite settled when the step is measured, a first-order
  lag of 1-3 ms: a small delay, listed in ``also_present`` as ``actuator_delay`` with ``tau``
  the lag's time constant (what a delay candidate sees of it, to first order);
* ``backlash``, ``friction``, ``rate_dependence``: the effect behind a compliant reaction frame
  (stiffness 5-20 k0): the fixture sticks and slips on the frame's spring instead of following
  the piston (truth: gap, Coulomb force, viscous coefficient);
* ``pinching``: BWBN with its own build-up p 0.3-3 and coupling lambda 0.2-0.9, and a
  pinching spread growing with energy (delta_psi 0-0.02) — the candidate holds p = 1,
  lambda = 0.5, delta_psi = 0 (truth: zeta_s);
* ``degradation``: BWBN with independent strength and stiffness rates (ratio 1/3-3) and a
  degrading A (delta_a up to half their mean), which the candidate does not fit (truth: the
  mean of delta_nu and delta_eta);
* ``sensor_bias`` / ``sensor_noise``: as in the plain bench (the rig's sensors are offset and
  white noise only), on top of the varied instrument noise.

Ground truth: ``truth`` holds the primary effect's parameters, ``also_present`` every
secondary effect the rig really adds (the two above; the servo forms of a delay, the frame
behind friction and the like are the primary effect's own form, not a second effect). The
bench gives full credit to the primary alone or paired with one of them and prints the strict
figure (primary only) beside it (``bench.credit``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .synth import (
    SyntheticRecord,
    command_history,
    rig_record,
    sensor_effect,
    signed,
    uniform,
)

__all__ = ["REALISM", "realistic_record"]

REALISM: dict[str, str] = {
    "specimen": "Bouc-Wen (n 1-4, beta share 0.1-0.9, beta+gamma 0.6-1.6) 2/3, "
                "Menegotto-Pinto (R0 10-20) 1/3",
    "noise": "LVDT 0.05-0.2 % of the peak, load cell 0.1-0.4 % of fy",
    "actuator_delay": "first-order lag 5-30 ms or second-order servo 4-12 Hz (zeta 0.6-1.0), "
                      "+ 0-5 ms transport delay; truth = equivalent delay",
    "actuator_amplitude": "gain ±(3-10) %; a gain below 1 also gets an undershoot 0-1 % of "
                          "the peak (also present: actuator_undershoot, mm)",
    "actuator_undershoot": "undershoot 1-4 % of the peak + first-order servo lag 1-3 ms "
                           "(also present: actuator_delay, tau = the lag)",
    "backlash": "gap 2-8 % of the peak behind a compliant frame (5-20 k0)",
    "friction": "Coulomb 3-10 % of fy behind a compliant frame (5-20 k0)",
    "pinching": "BWBN zeta_s 0.3-0.8, psi0 0.1-0.3, q 0-0.2, p 0.3-3, lambda 0.2-0.9, "
                "delta_psi 0-0.02",
    "degradation": "delta_nu, delta_eta independent (ratio 1/3-3), mean 0.2-0.6 over the "
                   "normalised path; delta_a up to half their mean",
    "rate_dependence": "viscous 3-10 % of fy at the RMS velocity, compliant frame (5-20 k0)",
    "sensor_bias": "as the plain bench",
    "sensor_noise": "as the plain bench",
}
"""What the realism records draw (the bench's definition, printed in BENCHMARKS.md, "Diagnosis");
"also present" names a second effect the rig really adds, which the truth lists."""


def _specimen(rng: np.random.Generator) -> tuple[str, dict[str, float]]:
    k0 = uniform(rng, 5.0, 50.0)
    fy = uniform(rng, 10.0, 100.0)
    alpha = uniform(rng, 0.02, 0.15)
    if rng.uniform() < 2.0 / 3.0:
        total, share = uniform(rng, 0.6, 1.6), uniform(rng, 0.1, 0.9)
        return "bouc-wen", {"k0": k0, "fy": fy, "alpha": alpha, "n": uniform(rng, 1.0, 4.0),
                            "beta": share * total, "gamma": (1.0 - share) * total}
    return "menegotto-pinto", {"k0": k0, "fy": fy, "alpha": alpha,
                               "R0": uniform(rng, 10.0, 20.0)}


def realistic_record(effect: str, seed: int, *, steps: int = 3000,
                     dt: float = 0.01) -> SyntheticRecord:
    """Generate one realism record with ``effect`` (or ``none``) from ``seed``."""
    rng = np.random.default_rng(seed)
    kind, specimen = _specimen(rng)
    k0, fy = specimen["k0"], specimen["fy"]
    dy = fy / k0
    peak = uniform(rng, 3.0, 8.0) * dy
    cmd = command_history(rng, steps, dt, peak)
    path_u = float(np.sum(np.abs(np.diff(cmd)))) / dy
    v_rms = float(np.sqrt(np.mean((np.diff(cmd) / dt) ** 2)))
    actuator: dict[str, Any] = {"stroke": 10.0 * peak + 10.0, "force_capacity": 1e6}
    effects: dict[str, Any] = {}
    lvdt: dict[str, Any] = {"noise_std": uniform(rng, 0.0005, 0.002) * peak}
    load_cell: dict[str, Any] = {"noise_std": uniform(rng, 0.001, 0.004) * fy}
    truth: dict[str, float] = {}
    also: dict[str, dict[str, float]] = {}
    frame = {"stiffness": uniform(rng, 5.0, 20.0) * k0}
    if effect in ("pinching", "degradation") and kind != "bouc-wen":
        kind, specimen = "bouc-wen", {**specimen, "n": uniform(rng, 1.0, 4.0),
                                      "beta": 0.5, "gamma": 0.5}
        specimen.pop("R0")
    if effect == "actuator_delay":
        delay = uniform(rng, 0.0, 0.005)
        actuator["delay"] = delay
        if rng.uniform() < 0.5:
            tau = uniform(rng, 0.005, 0.030)
            actuator["servo"] = {"kind": "first_order", "tau": tau}
            truth["tau"] = delay + tau
        else:
            fn, zeta = uniform(rng, 4.0, 12.0), uniform(rng, 0.6, 1.0)
            actuator["servo"] = {"kind": "second_order", "natural_frequency": fn,
                                 "damping": zeta}
            truth["tau"] = delay + 2.0 * zeta / (2.0 * math.pi * fn)
    elif effect == "actuator_amplitude":
        truth["amplitude_error"] = signed(rng, 0.03, 0.10)
        actuator["amplitude"] = 1.0 + truth["amplitude_error"]
        if truth["amplitude_error"] < 0.0:
            actuator["undershoot"] = uniform(rng, 0.0, 0.01) * peak
            # the rig's undershoot acts on the reference before the gain, as the candidate's
            also["actuator_undershoot"] = {"undershoot": actuator["undershoot"]}
    elif effect == "actuator_undershoot":
        truth["undershoot"] = uniform(rng, 0.01, 0.04) * peak
        actuator["undershoot"] = truth["undershoot"]
        lag = uniform(rng, 0.001, 0.003)
        actuator["servo"] = {"kind": "first_order", "tau": lag}
        also["actuator_delay"] = {"tau": lag}
    elif effect == "backlash":
        truth["gap"] = uniform(rng, 0.02, 0.08) * peak
        effects.update(backlash={"gap": truth["gap"]}, frame=frame)
    elif effect == "friction":
        truth["coulomb"] = uniform(rng, 0.03, 0.10) * fy
        effects.update(friction={"coulomb": truth["coulomb"]}, frame=frame)
    elif effect == "rate_dependence":
        truth["viscous"] = uniform(rng, 0.03, 0.10) * fy / v_rms
        effects.update(friction={"viscous": truth["viscous"]}, frame=frame)
    elif effect == "pinching":
        kind = "bwbn"
        truth.update(zeta_s=uniform(rng, 0.3, 0.8), psi0=uniform(rng, 0.1, 0.3),
                     q=uniform(rng, 0.0, 0.2))
        specimen.update(truth, p=uniform(rng, 0.3, 3.0), lam=uniform(rng, 0.2, 0.9),
                        delta_psi=uniform(rng, 0.0, 0.02))
    elif effect == "degradation":
        kind = "bwbn"
        mean = uniform(rng, 0.2, 0.6) / path_u
        ratio = math.exp(uniform(rng, -math.log(3.0), math.log(3.0)))
        nu = 2.0 * mean * ratio / (1.0 + ratio)
        truth.update(delta_nu=nu, delta_eta=2.0 * mean - nu)
        specimen.update(truth, delta_a=uniform(rng, 0.0, 0.5) * mean, p=0.0, q=0.0,
                        psi0=1.0, delta_psi=0.0, lam=1.0)
    elif effect in ("sensor_bias", "sensor_noise"):
        truth.update(sensor_effect(effect, rng, fy, peak, lvdt, load_cell))
    elif effect != "none":
        raise ValueError(f"unknown effect {effect!r}")
    return rig_record("realism", effect, seed, kind, specimen, actuator, effects,
                      {"lvdt": lvdt, "load_cell": load_cell}, truth, cmd, dt, also)
