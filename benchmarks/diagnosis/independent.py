"""Independent bench records (``diagnose-bench --independent``): own specimens, own effect forms.

``synth`` and ``realism`` generate on ``sim_actuator``'s rig, the very code whose laws the
diagnosis fits; a tool can score well there and still be wrong on a lab's specimen. Everything
here is written anew from the physics and shares no code with ``sim_actuator``, ``synth`` or
``realism`` (only the diagnosis' ``Record`` container and effect names):

* command: the displacement of a linear oscillator (period 0.3-1.5 s, damping 2-5 %) under a
  Kanai-Tajimi filtered white noise with a Jennings build-up/strong/decay envelope (a quiet
  tail of 10-40 % of the strong phase), peak 3-8 yield displacements; 1,500-6,000 samples at
  0.01-0.02 s, the actuator ramping linearly between samples;
* specimen (``independent_laws``): Giuffré-Menegotto-Pinto steel whose R decays with the plastic
  excursion, an elastic-plastic law with mostly isotropic saturating (Voce) hardening, or
  Bouc-Wen(-Baber-Noori), a third each; BWBN when pinching or degradation is the effect;
* base noise: white, 0.2-2 % of each channel's peak, drawn per channel;
* effects (:data:`INDEPENDENT` lists the draws): transport delay plus a first-order servo lag;
  gain error; OpenFresco's ``ErrorSimUndershoot`` (a constant against the direction of the
  command's motion); a pin gap with smooth contact solved in equilibrium with the specimen;
  Coulomb friction behind a compliant spring (a Jenkins element beside the specimen);
  power-law viscosity with a low-velocity hump; coloured (first-order low-pass) sensor noise;
  a load-cell offset with warm-up and linear drift; BWBN pinching and degradation;
* cases: :data:`CYCLE` per 15 records, three of them pairs of two different effects (a fifth).

The truth is labelled with the diagnosis' effect names (a pair: both, alphabetical, joined by
``+``) and parameters in its units, so ``bench`` scores these records like its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from fresco_bridge.diagnosis.load import Record, record_from_arrays

from .independent_laws import (
    BoucWenBaberNoori,
    GiuffreMenegottoPinto,
    IsotropicBilinear,
    SpecimenLaw,
)

__all__ = ["CYCLE", "EFFECTS", "INDEPENDENT", "PAIR", "IndependentRecord", "case_label",
           "coloured_noise", "contact_force", "draw_specimen", "drive_with_gap",
           "ground_motion_command", "independent_record", "jenkins", "servo_path", "signed",
           "specimen_law", "uniform"]

FloatArray = npt.NDArray[np.float64]

UNDERSHOOT = "actuator_undershoot"
"""The undershoot candidate's name in the diagnosis (being added by issue 29)."""
EFFECTS = ("actuator_delay", "actuator_amplitude", UNDERSHOOT, "backlash", "friction",
           "rate_dependence", "sensor_bias", "sensor_noise", "pinching", "degradation")
PAIR = "pair"
CYCLE = (*EFFECTS, "none", "none", PAIR, PAIR, PAIR)
"""What record i carries: ``CYCLE[i % 15]``; a ``pair`` slot draws two different effects."""
SUBSTEPS = 10
"""Fine grid of the actuator's path per sample (the servo lag and delay act on the ramp)."""

INDEPENDENT: dict[str, str] = {
    "command": "linear oscillator T 0.3-1.5 s, zeta 2-5 %, Kanai-Tajimi input (1.5-5 Hz, "
               "zeta_g 0.3-0.7), Jennings envelope with a tail at 10-40 %; peak 3-8 u_y",
    "samples": "1,500-6,000 at 0.01-0.02 s",
    "specimen": "GMP (b 0.5-5 %, R0 10-25, a1 0.85-0.95 R0, a2 0.05-0.3), bilinear with Voce "
                "isotropic hardening (Q 0.2-0.6 fy, kappa_s 3-15 u_y, H_kin 0.2-2 % k0), "
                "Bouc-Wen (alpha 2-15 %, n 1-3, beta+gamma 0.7-1.4): a third each",
    "noise": "white, 0.2-2 % of each channel's peak",
    "actuator_delay": "transport delay 0-15 ms + first-order lag 5-30 ms; truth = their sum",
    "actuator_amplitude": "gain error ±(3-10) %",
    UNDERSHOOT: "1-4 % of the peak against the command's direction of motion",
    "backlash": "pin gap 2-8 % of the peak each side, C1 penalty contact 10-50 k0 (reached "
                "over 5-20 % of the gap), in equilibrium with the specimen",
    "friction": "Coulomb 3-10 % of fy behind a spring of 0.5-5 k0 (Jenkins element)",
    "rate_dependence": "c |v|^a (a 0.2-1), 3-10 % of fy at the RMS velocity, + hump 20-60 % "
                       "of that at 5-30 % of the RMS velocity; truth = power-equivalent c",
    "sensor_bias": "load cell ±(2-8) % fy + warm-up ±(1-4) % fy + linear drift 0-2 % fy; "
                   "truth = the mean offset",
    "sensor_noise": "first-order low-pass noise (2-10 Hz), load cell 1.5-5 % fy, LVDT "
                    "0.5-2 % of the peak (std)",
    "pinching": "BWBN zeta_s 0.3-0.8, psi0 0.1-0.3, q 0-0.2, p 0.3-3, lambda 0.2-0.9, "
                "delta_psi 0-0.02",
    "degradation": "BWBN delta_nu, delta_eta (ratio 1/3-3), mean 0.2-0.6 over the normalised "
                   "path; delta_a up to half the mean",
}
"""What the independent records draw (the bench's definition)."""


@dataclass(frozen=True)
class IndependentRecord:
    """A generated record and what the generator put in it (the bench's ground truth)."""

    record: Record
    effect: str
    """The truth's label: ``none``, an effect name, or two joined by ``+`` (alphabetical)."""
    truth: dict[str, float]
    """True effect parameters in the diagnosis' names and units."""
    specimen: dict[str, float]
    law: str
    """The specimen law: ``menegotto-pinto``, ``bilinear-isotropic``, ``bouc-wen``, ``bwbn``."""
    forms: dict[str, float] = field(default_factory=dict)
    """The physical parameters of the effect forms (beyond what the truth can name)."""


def case_label(seed: int, index: int) -> str:
    """The truth label of record ``index`` of a bench with ``seed``."""
    slot = CYCLE[index % len(CYCLE)]
    if slot != PAIR:
        return slot
    rng = np.random.default_rng([seed, index, 2])
    a, b = rng.choice(len(EFFECTS), size=2, replace=False)
    return "+".join(sorted((EFFECTS[int(a)], EFFECTS[int(b)])))


def uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


def signed(rng: np.random.Generator, lo: float, hi: float) -> float:
    return (1.0 if rng.uniform() < 0.5 else -1.0) * uniform(rng, lo, hi)


def ground_motion_command(rng: np.random.Generator, steps: int, dt: float,
                          peak: float) -> FloatArray:
    """A pseudo-dynamic displacement history: a linear oscillator's response to a
    Kanai-Tajimi filtered, Jennings-enveloped white noise (Kanai 1957, Tajimi 1960; Jennings,
    Housner & Tsai 1968), scaled to ``peak``; zero at the start."""
    duration = steps * dt
    t = np.arange(steps) * dt
    n_fft = 1 << math.ceil(math.log2(2 * steps))
    w = 2.0 * math.pi * np.fft.rfftfreq(n_fft, dt)
    wg, zg = 2.0 * math.pi * uniform(rng, 1.5, 5.0), uniform(rng, 0.3, 0.7)
    kanai_tajimi = (wg**2 + 2j * zg * wg * w) / (wg**2 - w**2 + 2j * zg * wg * w)
    noise = np.fft.rfft(rng.standard_normal(steps), n_fft)
    ground = np.fft.irfft(noise * kanai_tajimi, n_fft)[:steps]
    t1, t2 = uniform(rng, 0.05, 0.15) * duration, uniform(rng, 0.4, 0.7) * duration
    tail = uniform(rng, 0.1, 0.4)
    decay = -math.log(tail) / (duration - t2)
    envelope = np.where(t < t1, (t / t1) ** 2,
                        np.where(t < t2, 1.0, np.exp(-decay * (t - t2))))
    wn, zn = 2.0 * math.pi / uniform(rng, 0.3, 1.5), uniform(rng, 0.02, 0.05)
    wd = wn * math.sqrt(1.0 - zn * zn)
    impulse = np.exp(-zn * wn * t) * np.sin(wd * t) / wd  # u'' + 2 z w u' + w^2 u = -a_g
    response = -np.fft.irfft(np.fft.rfft(ground * envelope, n_fft)
                             * np.fft.rfft(impulse, n_fft), n_fft)[:steps] * dt
    return np.asarray(response / np.max(np.abs(response)) * peak, dtype=np.float64)


def draw_specimen(rng: np.random.Generator, bwbn: bool) -> tuple[str, dict[str, float]]:
    """Every family's parameters are drawn in one fixed order, whichever is used: a record
    with an effect and one without, from the same seed, share the specimen (and the command
    and base noise: independent streams) unless the effect needs BWBN."""
    k0, fy = uniform(rng, 5.0, 50.0), uniform(rng, 10.0, 100.0)
    uy = fy / k0
    family = ("menegotto-pinto", "bilinear-isotropic", "bouc-wen")[int(rng.integers(3))]
    r0 = uniform(rng, 10.0, 25.0)
    steel = {"k0": k0, "fy": fy, "b": uniform(rng, 0.005, 0.05), "R0": r0,
             "a1": uniform(rng, 0.85, 0.95) * r0, "a2": uniform(rng, 0.05, 0.3)}
    isotropic = {"k0": k0, "fy": fy, "q_inf": uniform(rng, 0.2, 0.6) * fy,
                 "kappa_s": uniform(rng, 3.0, 15.0) * uy, "h_kin": uniform(rng, 0.002, 0.02) * k0}
    total, share = uniform(rng, 0.7, 1.4), uniform(rng, 0.2, 0.8)
    bouc_wen = {"k0": k0, "fy": fy, "alpha": uniform(rng, 0.02, 0.15), "n": uniform(rng, 1.0, 3.0),
                "beta": share * total, "gamma": (1.0 - share) * total}
    if bwbn:
        return "bwbn", bouc_wen
    return family, {"menegotto-pinto": steel, "bilinear-isotropic": isotropic,
                    "bouc-wen": bouc_wen}[family]


def specimen_law(family: str, p: dict[str, float]) -> SpecimenLaw:
    if family == "menegotto-pinto":
        return GiuffreMenegottoPinto(p["k0"], p["fy"], p["b"], p["R0"], p["a1"], p["a2"])
    if family == "bilinear-isotropic":
        return IsotropicBilinear(p["k0"], p["fy"], p["q_inf"], p["kappa_s"], p["h_kin"])
    return BoucWenBaberNoori(
        p["k0"], p["fy"], p["alpha"], p["n"], p["beta"], p["gamma"],
        d_a=p.get("delta_a", 0.0), d_nu=p.get("delta_nu", 0.0), d_eta=p.get("delta_eta", 0.0),
        zeta_s=p.get("zeta_s", 0.0), psi0=p.get("psi0", 0.2), q=p.get("q", 0.0),
        p=p.get("p", 1.0), lam=p.get("lam", 0.5), d_psi=p.get("delta_psi", 0.0))


def servo_path(target: FloatArray, dt: float, delay: float, lag: float) -> FloatArray:
    """The piston on a fine grid (:data:`SUBSTEPS` per sample): the reference ramps linearly
    between samples, arrives ``delay`` late (transport delay) and passes a first-order lag
    ``lag`` (y' = (r - y)/lag), integrated exactly for a piecewise-linear input."""
    steps = target.size
    t = np.arange(steps) * dt
    h = dt / SUBSTEPS
    tf = np.arange((steps - 1) * SUBSTEPS + 1) * h
    r = np.interp(tf - delay, t, target, left=float(target[0]))
    if lag <= 0.0:
        return np.asarray(r, dtype=np.float64)
    a = math.exp(-h / lag)
    y = np.empty_like(r)
    y[0] = r[0]
    prev_y, prev_r = float(r[0]), float(r[0])
    for k in range(1, r.size):
        rk = float(r[k])
        slope = (rk - prev_r) / h
        prev_y = rk - lag * slope + (prev_y - prev_r + lag * slope) * a
        prev_r = rk
        y[k] = prev_y
    return np.asarray(y, dtype=np.float64)


def contact_force(r: float, gap: float, k_c: float, width: float) -> float:
    """Pin force for a relative displacement ``r`` (piston minus specimen): none within the
    clearance ``gap`` each side; beyond it a penalty contact whose stiffness grows linearly
    from 0 to ``k_c`` over ``width`` (the pin bedding in), then stays: force and stiffness
    continuous (C1), exactly zero inside the clearance, so ``gap`` is the clearance."""
    depth = abs(r) - gap
    if depth <= 0.0:
        return 0.0
    f = k_c * depth * depth / (2.0 * width) if depth < width else k_c * (depth - 0.5 * width)
    return f if r > 0.0 else -f


def drive_with_gap(law: SpecimenLaw, x: FloatArray, gap: float, k_c: float, width: float,
                    fy: float, uy: float) -> FloatArray:
    """Connection force when the piston ``x`` drives the specimen through a pin gap: at each
    sample, the specimen displacement u where the pin force equals the specimen's resistance
    (bracketed, then Illinois regula falsi; the residual falls as u grows: every specimen law
    here has a positive tangent)."""
    out = np.empty(x.size)
    u = 0.0
    tol = 1e-9 * fy
    for i, xi in enumerate(map(float, x)):
        def residual(v: float, xi: float = xi) -> float:
            return contact_force(xi - v, gap, k_c, width) - law.trial(v)
        a, fa = u, residual(u)
        if abs(fa) <= tol:
            out[i], u = contact_force(xi - a, gap, k_c, width), a
            law.commit()
            continue
        step = max(abs(xi - u), 1e-6 * uy) * (1.0 if fa > 0.0 else -1.0)
        b, fb = a + step, residual(a + step)
        while (fb > 0.0) == (fa > 0.0):
            a, fa = b, fb
            step *= 2.0
            b, fb = a + step, residual(a + step)
        side = 0
        c, fc = b, fb
        for _ in range(200):
            c = (a * fb - b * fa) / (fb - fa)
            fc = residual(c)
            if abs(fc) <= tol or abs(b - a) <= 1e-13 * (abs(c) + uy):
                break
            if (fc > 0.0) == (fb > 0.0):
                b, fb = c, fc
                if side == -1:
                    fa *= 0.5
                side = -1
            else:
                a, fa = c, fc
                if side == 1:
                    fb *= 0.5
                side = 1
        law.commit()  # the last trial was at c: the solution
        u = c
        out[i] = contact_force(xi - c, gap, k_c, width)
    return out


def jenkins(x: FloatArray, coulomb: float, k_s: float) -> FloatArray:
    """Coulomb friction behind a spring: F = k_s (x - y), the slider y moving only when
    |F| would exceed the Coulomb force (Jenkins element; Iwan 1966)."""
    out = np.empty(x.size)
    y = 0.0
    for i, xi in enumerate(map(float, x)):
        f = k_s * (xi - y)
        if abs(f) > coulomb:
            f = math.copysign(coulomb, f)
            y = xi - f / k_s
        out[i] = f
    return out


def coloured_noise(rng: np.random.Generator, n: int, std: float, corner: float,
              dt: float) -> FloatArray:
    """Stationary first-order low-pass (AR(1)) noise of standard deviation ``std``."""
    phi = math.exp(-2.0 * math.pi * corner * dt)
    e = rng.standard_normal(n) * std * math.sqrt(1.0 - phi * phi)
    out = np.empty(n)
    prev = float(rng.standard_normal()) * std
    for i in range(n):
        prev = phi * prev + float(e[i])
        out[i] = prev
    return out


def _check_label(label: str) -> list[str]:
    parts = label.split("+")
    bad = [p for p in parts if p not in (*EFFECTS, "none")]
    if bad or len(parts) > 2 or len(set(parts)) != len(parts) or (
            "none" in parts and len(parts) > 1):
        raise ValueError(f"independent record: unknown or invalid effect label {label!r}; "
                         f"use none, one of {', '.join(EFFECTS)}, or two joined by '+'")
    return [p for p in parts if p != "none"]


def independent_record(label: str, seed: int, *, steps: int | None = None) -> IndependentRecord:
    """Generate one record carrying ``label``'s effects (``none``, one, or ``a+b``) from
    ``seed``; ``steps`` overrides the drawn length (short records for tests)."""
    effects = set(_check_label(label))
    rng = np.random.default_rng([seed, 0])  # the test: length, specimen, command
    draw = np.random.default_rng([seed, 1])  # the effects' magnitudes and forms
    noise = np.random.default_rng([seed, 2])  # the base noise
    drawn_steps, dt = int(rng.integers(1500, 6001)), uniform(rng, 0.01, 0.02)
    n = steps or drawn_steps
    law_name, specimen = draw_specimen(rng, bool(effects & {"pinching", "degradation"}))
    k0, fy = specimen["k0"], specimen["fy"]
    uy = fy / k0
    peak = uniform(rng, 3.0, 8.0) * uy
    cmd = ground_motion_command(rng, n, dt, peak)
    truth: dict[str, float] = {}
    forms: dict[str, float] = {}

    target = cmd.copy()
    if UNDERSHOOT in effects:  # ErrorSimUndershoot: short of each target against the motion
        forms["undershoot"] = truth["undershoot"] = uniform(draw, 0.01, 0.04) * peak
        direction = np.sign(np.diff(cmd, prepend=cmd[0]))
        idx = np.where(direction != 0.0, np.arange(n), 0)
        np.maximum.accumulate(idx, out=idx)
        target = cmd - truth["undershoot"] * direction[idx]
    if "actuator_amplitude" in effects:
        truth["amplitude_error"] = signed(draw, 0.03, 0.10)
        target = target * (1.0 + truth["amplitude_error"])
    delay = lag = 0.0
    if "actuator_delay" in effects:
        delay, lag = uniform(draw, 0.0, 0.015), uniform(draw, 0.005, 0.030)
        truth["tau"] = delay + lag
        forms.update(transport_delay=delay, lag=lag)
    fine = servo_path(target, dt, delay, lag)
    x = fine[::SUBSTEPS]
    v = np.zeros(n)
    v[1:] = (fine[SUBSTEPS::SUBSTEPS] - fine[SUBSTEPS - 1::SUBSTEPS]) / (dt / SUBSTEPS)

    if "pinching" in effects:
        pinch = {"zeta_s": uniform(draw, 0.3, 0.8), "psi0": uniform(draw, 0.1, 0.3),
                 "q": uniform(draw, 0.0, 0.2)}
        truth.update(pinch)
        specimen.update(pinch, p=uniform(draw, 0.3, 3.0), lam=uniform(draw, 0.2, 0.9),
                        delta_psi=uniform(draw, 0.0, 0.02))
    if "degradation" in effects:
        path_u = float(np.sum(np.abs(np.diff(x)))) / uy
        mean = uniform(draw, 0.2, 0.6) / path_u
        ratio = math.exp(uniform(draw, -math.log(3.0), math.log(3.0)))
        nu = 2.0 * mean * ratio / (1.0 + ratio)
        truth.update(delta_nu=nu, delta_eta=2.0 * mean - nu)
        specimen.update(delta_nu=nu, delta_eta=2.0 * mean - nu,
                        delta_a=uniform(draw, 0.0, 0.5) * mean)
    law = specimen_law(law_name, specimen)
    if "backlash" in effects:
        gap = truth["gap"] = uniform(draw, 0.02, 0.08) * peak
        k_c, width = uniform(draw, 10.0, 50.0) * k0, uniform(draw, 0.05, 0.2) * gap
        forms.update(gap=gap, contact_stiffness=k_c, contact_width=width)
        force = drive_with_gap(law, x, gap, k_c, width, fy, uy)
    else:
        force = np.array([law.step(float(xi)) for xi in x])
    if "friction" in effects:
        truth["coulomb"] = uniform(draw, 0.03, 0.10) * fy
        forms.update(coulomb=truth["coulomb"], spring=uniform(draw, 0.5, 5.0) * k0)
        force = force + jenkins(x, truth["coulomb"], forms["spring"])
    if "rate_dependence" in effects:
        v_rms = float(np.sqrt(np.mean(v * v)))
        exponent, at_rms = uniform(draw, 0.2, 1.0), uniform(draw, 0.03, 0.10) * fy
        hump, v_hump = uniform(draw, 0.2, 0.6) * at_rms, uniform(draw, 0.05, 0.3) * v_rms
        ratio_v = v / v_hump
        viscous = (at_rms * np.sign(v) * np.abs(v / v_rms) ** exponent
                   + hump * ratio_v * np.exp(0.5 * (1.0 - ratio_v**2)))
        force = force + viscous
        truth["viscous"] = float(np.sum(viscous * v) / np.sum(v * v))
        forms.update(exponent=exponent, force_at_rms=at_rms, hump=hump, hump_velocity=v_hump)

    t = np.arange(n, dtype=np.float64) * dt
    disp_level, force_level = uniform(noise, 0.002, 0.02), uniform(noise, 0.002, 0.02)
    meas_disp = x + noise.standard_normal(n) * disp_level * float(np.max(np.abs(x)))
    meas_force = force + noise.standard_normal(n) * force_level * float(np.max(np.abs(force)))
    if "sensor_noise" in effects:
        corner = uniform(draw, 2.0, 10.0)
        truth.update(force_noise_std=uniform(draw, 0.015, 0.05) * fy,
                     disp_noise_std=uniform(draw, 0.005, 0.02) * peak)
        forms["noise_corner_hz"] = corner
        meas_force = meas_force + coloured_noise(draw, n, truth["force_noise_std"], corner, dt)
        meas_disp = meas_disp + coloured_noise(draw, n, truth["disp_noise_std"], corner, dt)
    if "sensor_bias" in effects:
        offset, warm, drift = signed(draw, 0.02, 0.08) * fy, signed(draw, 0.01, 0.04) * fy, signed(
            draw, 0.0, 0.02) * fy
        warm_time = uniform(draw, 0.2, 1.0) * t[-1]
        bias = offset + warm * (1.0 - np.exp(-t / warm_time)) + drift * t / t[-1]
        meas_force = meas_force + bias
        truth["force_bias"] = float(np.mean(bias))
        forms.update(offset=offset, warm_up=warm, warm_up_time=warm_time, drift=drift)
    source = f"independent record seed {seed} ({label})"
    record = record_from_arrays(t, cmd, meas_force, meas_disp, source=source)
    return IndependentRecord(record, label, truth, specimen, law_name, forms)
