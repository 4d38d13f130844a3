"""The form matrix: each effect in the forms a lab meets, diagnosed blind.

A candidate effect of the diagnosis has one form (friction: Coulomb behind a spring; rate
dependence: a power law; pinching: BWBN's slip...). A lab's specimen does not know that: dry
friction is regularised by ``tanh(v/v0)`` in many models, pinching can be a slip spring in
series, a delay can be a servo lag. This bench draws each effect in several forms, on the
independent generator's specimens, commands and base noise (``independent``: no code shared
with the rig or the candidates), and scores the verdict per form with the bench's one rule
(:func:`.bench.credit`: a pair or a two-story answer that contains the truth is half right).

Run it (a checkout, from the repository root)::

    python -m benchmarks.diagnosis.forms --per-form 4 --seed 7 --workers 1 [--json OUT]

:data:`FORMS` lists every form with what it draws. The truth is the effect's name; the
parameters the diagnosis' units can name are kept (Coulomb force, tau, gap, ...), a form the
candidates cannot express keeps its own (``forms``).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from fresco_bridge.diagnosis.load import Record, record_from_arrays
from fresco_bridge.numbers import pct

from .independent import (
    SUBSTEPS,
    coloured_noise,
    draw_specimen,
    drive_with_gap,
    ground_motion_command,
    jenkins,
    servo_path,
    specimen_law,
    uniform,
)
from .independent_laws import SpecimenLaw

__all__ = ["FORMS", "FormRecord", "form_items", "form_one", "form_record", "main",
           "summarise_forms"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Form:
    """One form of one effect: the effect's name and what the form draws."""

    effect: str
    draws: str


FORMS: dict[str, Form] = {
    "friction/sign": Form("friction", "Coulomb 3-10 % fy, F_c sign(v) (held through holds)"),
    "friction/tanh-0.5": Form("friction", "F_c tanh(v/v0), v0 0.5 % of the peak velocity"),
    "friction/tanh-2": Form("friction", "F_c tanh(v/v0), v0 2 % of the peak velocity"),
    "friction/tanh-5": Form("friction", "F_c tanh(v/v0), v0 5 % of the peak velocity"),
    "friction/spring": Form("friction", "Coulomb behind a spring of 0.5-5 k0 (Jenkins)"),
    "friction/stribeck": Form("friction", "(F_c + (F_s - F_c) exp(-(v/v_s)^2)) sign(v), F_s "
                                          "1.3-2 F_c, v_s 2-10 % of the peak velocity"),
    "rate_dependence/linear": Form("rate_dependence", "c v, 3-10 % fy at the RMS velocity"),
    "rate_dependence/power-low": Form("rate_dependence", "c sign(v)|v|^a, a 0.3-0.6"),
    "rate_dependence/power-high": Form("rate_dependence", "c sign(v)|v|^a, a 1.2-1.5"),
    "rate_dependence/maxwell": Form("rate_dependence", "viscous dashpot in series with a "
                                                       "spring, relaxation time 5-30 ms"),
    "pinching/bwbn": Form("pinching", "BWBN slip: zeta_s 0.3-0.8, psi0 0.1-0.3, q 0-0.2"),
    "pinching/slip-spring": Form("pinching", "an elastic slip in series, delta tanh(F/F_p): "
                                             "delta 2-6 % of the peak, F_p 5-15 % fy"),
    "pinching/near-zero": Form("pinching", "force reduced near zero displacement, "
                                           "1 - r exp(-(x/x_p)^2): r 0.4-0.8, x_p 10-25 % "
                                           "of the peak"),
    "backlash/sharp": Form("backlash", "pin gap 2-8 % of the peak, contact 200-1000 k0 "
                                       "reached over 0.5 % of the gap"),
    "backlash/smooth": Form("backlash", "pin gap 2-8 % of the peak, contact 10-50 k0 reached "
                                        "over 5-20 % of the gap"),
    "actuator_delay/pure": Form("actuator_delay", "transport delay 5-30 ms"),
    "actuator_delay/lag": Form("actuator_delay", "first-order servo lag 5-30 ms"),
    "actuator_delay/both": Form("actuator_delay", "transport delay 0-15 ms + lag 5-30 ms"),
    "degradation/stiffness": Form("degradation", "BWBN delta_eta alone, 0.2-0.6 over the "
                                                 "normalised path"),
    "degradation/strength": Form("degradation", "BWBN delta_nu alone, 0.2-0.6 over the "
                                                "normalised path"),
    "degradation/energy": Form("degradation", "the independent laws' force times (1 - D), D "
                                              "growing with the dissipated energy to 0.2-0.5"),
    "sensor_noise/white": Form("sensor_noise", "white, load cell 1.5-5 % fy, LVDT 0.5-2 % of "
                                               "the peak (std)"),
    "sensor_noise/ar1": Form("sensor_noise", "first-order low-pass (AR(1), corner 2-10 Hz), "
                                             "same levels"),
    "actuator_undershoot/constant": Form("actuator_undershoot", "1-4 % of the peak against "
                                                                "the direction of motion"),
    "none/floor": Form("none", "the base noise alone: white, 0.2-2 % of each channel's peak"),
}
"""Every form of the matrix (``effect/form``) and what it draws."""


@dataclass(frozen=True)
class FormRecord:
    """A generated record, its effect, its form and what the generator put in."""

    record: Record
    effect: str
    form: str
    truth: dict[str, float]
    specimen: dict[str, float]
    law: str
    forms: dict[str, float] = field(default_factory=dict)


def _held_sign(v: FloatArray) -> FloatArray:
    """sign(v), the last non-zero sign held through holds (written here, not imported from the
    candidates: the generator shares no code with what it tests)."""
    s = np.sign(v)
    idx = np.where(s != 0.0, np.arange(s.size), 0)
    np.maximum.accumulate(idx, out=idx)
    out: FloatArray = s[idx]
    return out


def _series_slip(law: SpecimenLaw, x: FloatArray, delta: float, f_p: float,
                 uy: float) -> FloatArray:
    """Force of the specimen behind an elastic slip ``delta tanh(F/f_p)`` in series: at each
    sample the specimen displacement u with x = u + slip(law(u)) (bisection on a bracket; the
    residual falls as u grows: the law's tangent and the slip's compliance are positive)."""
    out = np.empty(x.size)
    u = 0.0
    for i, xi in enumerate(map(float, x)):
        def residual(v: float, xi: float = xi) -> float:
            return xi - v - delta * math.tanh(law.trial(v) / f_p)
        lo = hi = u
        step = max(abs(xi - u), 1e-3 * uy)
        while residual(hi) > 0.0:
            hi += step
            step *= 2.0
        step = max(abs(xi - u), 1e-3 * uy)
        while residual(lo) < 0.0:
            lo -= step
            step *= 2.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if residual(mid) > 0.0:
                lo = mid
            else:
                hi = mid
            if hi - lo <= 1e-10 * (abs(mid) + uy):
                break
        u = 0.5 * (lo + hi)
        out[i] = law.trial(u)
        law.commit()
    return out


def _maxwell(v: FloatArray, c: float, relax: float, dt: float) -> FloatArray:
    """A dashpot ``c`` in series with a spring ``c / relax``: F' = (c v - F) / relax, exact for
    a velocity held over each step."""
    a = math.exp(-dt / relax)
    out = np.empty(v.size)
    f = 0.0
    for i, vi in enumerate(map(float, v)):
        f = c * vi + (f - c * vi) * a
        out[i] = f
    return out


def form_record(form: str, seed: int, *, steps: int = 3000) -> FormRecord:
    """One record of ``form`` (a key of :data:`FORMS`) from ``seed``."""
    if form not in FORMS:
        raise ValueError(f"unknown form {form!r}; known: {', '.join(FORMS)}")
    effect, variant = FORMS[form].effect, form.split("/", 1)[1]
    rng = np.random.default_rng([seed, 0])
    draw = np.random.default_rng([seed, 1])
    noise = np.random.default_rng([seed, 2])
    dt = uniform(rng, 0.01, 0.02)
    bwbn = form in ("pinching/bwbn", "degradation/stiffness", "degradation/strength")
    law_name, specimen = draw_specimen(rng, bwbn)
    k0, fy = specimen["k0"], specimen["fy"]
    uy = fy / k0
    peak = uniform(rng, 3.0, 8.0) * uy
    cmd = ground_motion_command(rng, steps, dt, peak)
    truth: dict[str, float] = {}
    extra: dict[str, float] = {}

    target = cmd.copy()
    if effect == "actuator_undershoot":
        truth["undershoot"] = uniform(draw, 0.01, 0.04) * peak
        target = cmd - truth["undershoot"] * _held_sign(np.diff(cmd, prepend=cmd[0]))
    delay = lag = 0.0
    if effect == "actuator_delay":
        if variant == "pure":
            delay = uniform(draw, 0.005, 0.030)
        elif variant == "lag":
            lag = uniform(draw, 0.005, 0.030)
        else:
            delay, lag = uniform(draw, 0.0, 0.015), uniform(draw, 0.005, 0.030)
        truth["tau"] = delay + lag
        extra.update(transport_delay=delay, lag=lag)
    fine = servo_path(target, dt, delay, lag)
    x = fine[::SUBSTEPS]
    v = np.zeros(steps)
    v[1:] = (fine[SUBSTEPS::SUBSTEPS] - fine[SUBSTEPS - 1::SUBSTEPS]) / (dt / SUBSTEPS)
    v_peak = float(np.max(np.abs(v))) or 1.0
    v_rms = float(np.sqrt(np.mean(v * v))) or 1.0

    if form == "pinching/bwbn":
        pinch = {"zeta_s": uniform(draw, 0.3, 0.8), "psi0": uniform(draw, 0.1, 0.3),
                 "q": uniform(draw, 0.0, 0.2)}
        truth.update(pinch)
        specimen.update(pinch, p=uniform(draw, 0.3, 3.0), lam=uniform(draw, 0.2, 0.9),
                        delta_psi=uniform(draw, 0.0, 0.02))
    if form in ("degradation/stiffness", "degradation/strength"):
        rate = uniform(draw, 0.2, 0.6) / (float(np.sum(np.abs(np.diff(x)))) / uy)
        key = "delta_eta" if variant == "stiffness" else "delta_nu"
        specimen[key] = rate
        extra[key] = rate
    law = specimen_law(law_name, specimen)
    if effect == "backlash":
        gap = truth["gap"] = uniform(draw, 0.02, 0.08) * peak
        if variant == "sharp":
            k_c, width = uniform(draw, 200.0, 1000.0) * k0, 0.005 * gap
        else:
            k_c, width = uniform(draw, 10.0, 50.0) * k0, uniform(draw, 0.05, 0.2) * gap
        extra.update(contact_stiffness=k_c, contact_width=width)
        force = drive_with_gap(law, x, gap, k_c, width, fy, uy)
    elif form == "pinching/slip-spring":
        delta, f_p = uniform(draw, 0.02, 0.06) * peak, uniform(draw, 0.05, 0.15) * fy
        extra.update(slip=delta, slip_force=f_p)
        force = _series_slip(law, x, delta, f_p, uy)
    else:
        force = np.array([law.step(float(xi)) for xi in x])
    if form == "pinching/near-zero":
        r, x_p = uniform(draw, 0.4, 0.8), uniform(draw, 0.10, 0.25) * peak
        extra.update(reduction=r, width=x_p)
        force = force * (1.0 - r * np.exp(-((x / x_p) ** 2)))
    if form == "degradation/energy":
        dissipated = np.concatenate([[0.0], np.cumsum(0.5 * (force[1:] + force[:-1])
                                                      * np.diff(x))])
        final = uniform(draw, 0.2, 0.5)
        damage = final * np.maximum(dissipated, 0.0) / (max(float(dissipated[-1]), 1e-12))
        extra["final_damage"] = final
        force = force * (1.0 - damage)
    if effect == "friction":
        fc = truth["coulomb"] = uniform(draw, 0.03, 0.10) * fy
        if variant == "sign":
            friction = fc * _held_sign(v)
        elif variant.startswith("tanh"):
            v0 = float(variant.split("-")[1]) / 100.0 * v_peak
            extra["v0"] = v0
            friction = fc * np.tanh(v / v0)
        elif variant == "spring":
            extra["spring"] = uniform(draw, 0.5, 5.0) * k0
            friction = jenkins(x, fc, extra["spring"])
        else:
            f_s, v_s = uniform(draw, 1.3, 2.0) * fc, uniform(draw, 0.02, 0.10) * v_peak
            extra.update(static=f_s, stribeck_velocity=v_s)
            friction = (fc + (f_s - fc) * np.exp(-((v / v_s) ** 2))) * _held_sign(v)
        force = force + friction
    if effect == "rate_dependence":
        at_rms = uniform(draw, 0.03, 0.10) * fy
        if variant == "maxwell":
            relax = uniform(draw, 0.005, 0.03)
            extra["relaxation_time"] = relax
            viscous = _maxwell(v, at_rms / v_rms, relax, dt)
        else:
            exponent = {"linear": 1.0, "power-low": uniform(draw, 0.3, 0.6),
                        "power-high": uniform(draw, 1.2, 1.5)}[variant]
            extra["exponent"] = exponent
            viscous = at_rms * np.sign(v) * np.abs(v / v_rms) ** exponent
        force = force + viscous
        truth["viscous"] = float(np.sum(viscous * v) / np.sum(v * v))

    t = np.arange(steps, dtype=np.float64) * dt
    disp_level, force_level = uniform(noise, 0.002, 0.02), uniform(noise, 0.002, 0.02)
    meas_disp = x + noise.standard_normal(steps) * disp_level * float(np.max(np.abs(x)))
    meas_force = force + noise.standard_normal(steps) * force_level * float(
        np.max(np.abs(force)))
    if effect == "sensor_noise":
        truth.update(force_noise_std=uniform(draw, 0.015, 0.05) * fy,
                     disp_noise_std=uniform(draw, 0.005, 0.02) * peak)
        if variant == "white":
            meas_force = meas_force + draw.standard_normal(steps) * truth["force_noise_std"]
            meas_disp = meas_disp + draw.standard_normal(steps) * truth["disp_noise_std"]
        else:
            corner = extra["noise_corner_hz"] = uniform(draw, 2.0, 10.0)
            meas_force = meas_force + coloured_noise(draw, steps, truth["force_noise_std"],
                                                     corner, dt)
            meas_disp = meas_disp + coloured_noise(draw, steps, truth["disp_noise_std"],
                                                   corner, dt)
    record = record_from_arrays(t, cmd, meas_force, meas_disp,
                                source=f"form record {form} seed {seed}")
    return FormRecord(record, effect, form, truth, specimen, law_name, extra)


FormItem = tuple[str, int, int]
"""(form, record seed, steps)."""


def form_items(per_form: int, seed: int, steps: int,
               forms: list[str] | None = None) -> list[FormItem]:
    """``per_form`` records of every form (or of ``forms``), seeds derived from ``seed`` and the
    form's place in the matrix (``--only`` draws the same records as the whole matrix)."""
    names = list(FORMS) if forms is None else forms
    place = {form: i for i, form in enumerate(FORMS)}
    return [(form, seed * 100_003 + 1_000 * place[form] + k, steps)
            for form in names for k in range(per_form)]


def form_one(item: FormItem) -> dict[str, Any]:
    """Generate record ``item`` and diagnose it blind (a sweep task: top level, picklable)."""
    from fresco_bridge.diagnosis.verdict import diagnose

    from .bench import contains_truth, credit, verdict_label

    form, seed, steps = item
    started = time.perf_counter()
    rec = form_record(form, seed, steps=steps)
    result = diagnose(rec.record).to_json()
    verdict = result["verdict"]
    return {"form": form, "effect": rec.effect, "seed": seed, "law": rec.law,
            "predicted": verdict_label(verdict), "confidence": verdict["confidence"],
            "credit": credit(rec.effect, verdict_label(verdict)),
            "contains": contains_truth(rec.effect, verdict_label(verdict)),
            "gap_before_pct": result["baseline"]["gap_withheld"]["total_pct"],
            "diagnose_seconds": result["seconds"],
            "seconds": time.perf_counter() - started}


def summarise_forms(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Per form and per effect: records, credit share, and the verdicts given."""
    per_form: dict[str, dict[str, Any]] = {}
    for r in rows:
        entry = per_form.setdefault(r["form"], {"records": 0, "credit": 0.0, "contains": 0,
                                                "verdicts": {}})
        entry["records"] += 1
        entry["contains"] += int(r.get("contains", r["credit"] == 1.0))
        entry["credit"] += r["credit"]
        entry["verdicts"][r["predicted"]] = entry["verdicts"].get(r["predicted"], 0) + 1
    per_effect: dict[str, dict[str, float]] = {}
    for form, entry in per_form.items():
        e = per_effect.setdefault(FORMS[form].effect, {"records": 0, "credit": 0.0,
                                                       "contains": 0})
        e["records"] += entry["records"]
        e["contains"] += entry["contains"]
        e["credit"] += entry["credit"]
    seconds = [r["diagnose_seconds"] for r in rows]
    return {
        "records": len(rows),
        "per_form": per_form,
        "per_effect": {k: {**v, "credit_pct": 100.0 * v["credit"] / v["records"],
                           "contains_pct": 100.0 * v["contains"] / v["records"]}
                       for k, v in per_effect.items()},
        "overall_credit_pct": 100.0 * sum(r["credit"] for r in rows) / max(len(rows), 1),
        "diagnose_seconds": {"median": float(np.median(seconds)), "max": float(np.max(seconds))}
        if seconds else {},
    }


def format_forms(summary: dict[str, Any], seed: int, wall: float) -> str:
    lines = [f"form matrix: {summary['records']} records, seed {seed}, {wall:.1f} s wall; "
             f"overall credit {pct(summary['overall_credit_pct'], 1)}"]
    for effect, e in summary["per_effect"].items():
        lines.append(f"{effect:<20} {pct(e['credit_pct'], 1):>8} of {e['records']:g}; right "
                     f"or in two stories {pct(e['contains_pct'], 1)}")
        for form, f in summary["per_form"].items():
            if FORMS[form].effect == effect:
                verdicts = ", ".join(f"{k} {n}" for k, n in sorted(
                    f["verdicts"].items(), key=lambda kv: -kv[1]))
                lines.append(f"    {form:<30} {f['credit']:g}/{f['records']}  ({verdicts})")
    d = summary["diagnose_seconds"]
    if d:
        lines.append(f"diagnosis time per record: median {d['median']:.1f} s, max "
                     f"{d['max']:.1f} s")
    return "\n".join(lines)


def main(argv: list[str] | None = None,
         run: Callable[..., list[dict[str, Any]]] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.diagnosis.forms",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--per-form", type=int, default=4)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--only", default=None, help="comma-separated forms or effects")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    from fresco_bridge.sweeps import run_sweep

    forms = None
    if args.only:
        wanted = args.only.split(",")
        forms = [f for f in FORMS if f in wanted or FORMS[f].effect in wanted]
    items = form_items(args.per_form, args.seed, args.steps, forms)
    started = time.perf_counter()
    rows = (run or run_sweep)(form_one, items, workers=args.workers)
    wall = time.perf_counter() - started
    summary = summarise_forms(rows)
    print(format_forms(summary, args.seed, wall))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump({"seed": args.seed, "summary": summary, "records": rows}, fh, indent=2,
                      default=float)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
