"""``diagnose-bench``: records with known effects from the simulated rig, diagnosed blind.

Record i of a bench with seed S carries effect ``CLASSES[i % len(CLASSES)]`` (``none`` twice
per cycle, so false alarms are measured on enough records) and is generated from the seed
``S * 100003 + i``: any record can be regenerated alone. The diagnosis sees only time,
command, measured displacement and force — never the effect, its magnitude or the specimen.
Records run through ``fresco_bridge.sweeps.run_sweep`` (serial, local pool, or Dask). With
``realism`` the records come from ``realism.realistic_record`` (effects in the rig's physical
forms, not the candidates' shapes) instead of ``synth.synthetic_record``; same seeds. With
``independent`` they come from ``independent.independent_record`` (specimens and effect forms
written anew, sharing no code with the rig; record i carries ``independent.case_label(S, i)``,
a fifth of them two effects at once), scored as sets: a pair verdict in any order is right, and
the overall score gives half credit when truth and verdict share one member. A realism record
lists the second effects its rig really adds (``also_present``: an amplitude record's
undershoot, an undershoot record's servo lag); the primary named with one of them is right, and
the strict figure (truth = the primary alone) is printed beside it (:func:`credit`).
"""

from __future__ import annotations

import math
import os
import pickle
import time
from collections import Counter
from collections.abc import Collection, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from fresco_bridge.diagnosis.load import Record
from fresco_bridge.diagnosis.model import EFFECT_NAMES, rate_force
from fresco_bridge.diagnosis.result import Verdict
from fresco_bridge.diagnosis.verdict import diagnose
from fresco_bridge.numbers import fmt, pct

from .independent import UNDERSHOOT, IndependentRecord, case_label, independent_record
from .synth import SyntheticRecord, synthetic_record

__all__ = ["CLASSES", "MAGNITUDE_OF", "bench_items", "contains_truth", "credit", "diagnose_one",
           "effect_magnitude", "format_bench", "generate", "row_credit", "summarise_bench",
           "verdict_label"]

CLASSES = (*EFFECT_NAMES, "none", "none")
MAGNITUDE_OF = {
    "actuator_delay": "tau", "actuator_amplitude": "amplitude_error",
    "actuator_undershoot": "undershoot", "backlash": "gap",
    "friction": "coulomb", "pinching": "zeta_s", "degradation": "delta_mean",
    "rate_dependence": "viscous", "sensor_bias": "force_bias", "sensor_noise": "force_noise_std",
}
"""The parameter whose relative error is the effect's "magnitude" error. For degradation it is
the mean of delta_nu and delta_eta: on these records strength and stiffness degradation trade
off against each other (their sum is well determined, each alone is not; both are reported),
per unit *physical* hysteretic energy (kN*mm), i.e. times k0 / fy**2 of the law it belongs to.
Bouc-Wen's fy and beta + gamma are redundant (only (beta + gamma) / fy**n enters the force), so
a fit may land anywhere on that ridge, and a rate per unit energy normalised by the fitted
fy * dy moves with it; the rate per kN*mm does not."""


def effect_magnitude(effect: str, values: Mapping[str, float],
                     law: Mapping[str, float] | None = None) -> float | None:
    """The effect's magnitude from its parameter values (None when absent); ``law`` (k0, fy)
    puts an energy rate in physical units."""
    name = MAGNITUDE_OF.get(effect)
    if name == "delta_mean":
        if "delta_nu" not in values or "delta_eta" not in values:
            return None
        mean = 0.5 * (values["delta_nu"] + values["delta_eta"])
        return mean if law is None else mean * law["k0"] / law["fy"] ** 2
    return None if name is None or name not in values else values[name]


MAGNITUDE_TOLERANCE = 0.20


BenchItem = tuple[int, str, int, int | None, str, str | None]
"""(index, effect, record seed, steps, generator, record cache directory or None) of a record;
the generator is ``plain``, ``realism`` or ``independent`` (steps None: drawn per record)."""
SYSTEMATIC = frozenset(EFFECT_NAMES) - {"sensor_noise"} | {UNDERSHOOT}
"""Effects that claim a systematic departure (a 'none' record must never get one)."""


def bench_items(n: int, seed: int, steps: int | None, realism: bool = False,
                cache: str | None = None, *, independent: bool = False) -> list[BenchItem]:
    """(index, effect, record seed, steps, generator, cache) of every record of the bench."""
    generator = "independent" if independent else "realism" if realism else "plain"
    return [(i, case_label(seed, i) if independent else CLASSES[i % len(CLASSES)],
             seed * 100_003 + i, steps if steps is not None or independent else 3000,
             generator, cache) for i in range(n)]


def generate(item: BenchItem) -> SyntheticRecord | IndependentRecord:
    """Record ``item`` as the generator makes it; with a cache directory, read from there when
    it was generated before (a compliant-frame realism record takes minutes on the rig's
    substep solver, its diagnosis seconds), written there otherwise. The cache is keyed by
    bench, seed, effect and steps and is only ever written by this function (pickle: trusted,
    local)."""
    _index, effect, record_seed, steps, generator, cache = item
    path = None
    if cache is not None:
        path = Path(cache) / f"{generator}-{record_seed}-{effect}-{steps}.pickle"
        if path.exists():
            loaded = pickle.loads(path.read_bytes())
            if isinstance(loaded, IndependentRecord) or (
                    isinstance(loaded, SyntheticRecord) and "also_present" in vars(loaded)):
                # (a record cached before ``also_present`` is generated anew; the Record is
                # rebuilt so fields added since are derived, e.g. ``velocity_scale``)
                return replace(loaded, record=replace(loaded.record))
    synthetic: SyntheticRecord | IndependentRecord
    if generator == "independent":
        synthetic = independent_record(effect, record_seed, steps=steps)
    elif generator == "realism":
        from .realism import realistic_record

        synthetic = realistic_record(effect, record_seed, steps=steps or 3000)
    else:
        synthetic = synthetic_record(effect, record_seed, steps=steps or 3000)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_bytes(pickle.dumps(synthetic))
        tmp.replace(path)
    return synthetic


def diagnose_one(item: BenchItem) -> dict[str, Any]:
    """Generate record ``item`` and diagnose it blind (a sweep task: top level, picklable)."""
    index, effect, record_seed, _steps, _generator, _cache = item
    started = time.perf_counter()
    synthetic = generate(item)
    generated = time.perf_counter()
    result = diagnose(synthetic.record).to_json()
    verdict = result["verdict"]
    label = verdict_label(verdict)
    also = synthetic.also_present if isinstance(synthetic, SyntheticRecord) else {}
    # the candidate the estimates come from: the verdict's when it is right (the primary named
    # with an effect the rig adds: the pair's fit), else the true effect's
    named = (_members(verdict["effect"]) if credit(effect, verdict["effect"], also) == 1.0
             else _members(effect))
    true_candidate = next((e for e in [*result["effects"], *result.get("pairs", [])]
                           if _members(e["name"]) == named), None)
    estimates = {} if true_candidate is None else {
        name: p["value"] for name, p in true_candidate["params"].items()}
    if "rate_exponent" in estimates:
        estimates = {**estimates, **power_equivalent(synthetic.record, estimates)}
    errors = {name: abs(estimates[name] - value) / abs(value)
              for name, value in synthetic.truth.items() if name in estimates and value}
    errors.update({f"{other}.{name}": abs(estimates[name] - value) / abs(value)
                   for other, values in also.items() for name, value in values.items()
                   if name in estimates and value})
    true_size = effect_magnitude(effect, synthetic.truth, synthetic.specimen)
    found = effect_magnitude(effect, estimates,
                             None if true_candidate is None else true_candidate["law"])
    if true_size and found is not None:
        errors["magnitude"] = abs(found - true_size) / abs(true_size)
        plain_truth, plain_found = (effect_magnitude(effect, synthetic.truth),
                                    effect_magnitude(effect, estimates))
        if plain_truth and plain_found is not None and plain_truth != true_size:
            # the earlier definition (per unit energy normalised by each law's own fy * dy)
            errors["magnitude_normalised"] = abs(plain_found - plain_truth) / abs(plain_truth)
    return {
        "index": index, "effect": effect, "seed": record_seed,
        "samples": synthetic.record.size, "predicted": label,
        "baseline": result["baseline"]["kind"],
        "confidence": verdict["confidence"], "truth": synthetic.truth, "also_present": also,
        "estimates": estimates,
        "relative_errors": errors, "specimen": synthetic.specimen, "law": synthetic.law,
        "gap_before_pct": result["baseline"]["gap_withheld"]["total_pct"],
        "shrink_pct": None if true_candidate is None else true_candidate["shrink_pct"],
        "verdict_shrink_pct": verdict["shrink_pct"],
        "generate_seconds": generated - started, "diagnose_seconds": result["seconds"],
    }


def power_equivalent(record: Record, estimates: Mapping[str, float]) -> dict[str, float]:
    """The fitted rate law as the linear coefficient that dissipates the same energy on the
    record's command velocity (how the generators state their truth); the coefficient at the
    RMS velocity stays beside it as ``viscous_at_rms_velocity``."""
    v = np.diff(record.cmd) / np.diff(record.time)
    force = rate_force(v, estimates["viscous"], estimates["rate_exponent"],
                       record.velocity_scale)
    return {"viscous": float(np.sum(force * v) / np.sum(v * v)),
            "viscous_at_rms_velocity": float(estimates["viscous"])}


def _members(label: str) -> frozenset[str]:
    """The effects a label names (``a+b`` in any order: the same pair)."""
    return frozenset(label.split("+"))


def _canonical(label: str) -> str:
    return "+".join(sorted(_members(label)))


def credit(truth: str, predicted: str, also_present: Collection[str] = ()) -> float:
    """The bench's one scoring rule. 1 for the right verdict: the truth's effects (a pair in
    any order), or the truth's effects named with some of ``also_present`` (second effects the
    generator really added, which the record lists beside its primary effect); 0.5 when truth
    or verdict is a pair and they share one member, or when the verdict is two stories
    (``a|b``: :func:`verdict_label`) one of which is right; else 0. Without ``also_present``
    (the plain and independent benches, and every strict figure) the truth is its label
    alone."""
    if "|" in predicted:  # two stories: half right when one of them is right
        return 0.5 if any(credit(truth, story, also_present) == 1.0
                          for story in predicted.split("|")) else 0.0
    t, p = _members(truth), _members(predicted)
    if t == p or (t < p and p - t <= set(also_present)):
        return 1.0
    return 0.5 if (len(t) > 1 or len(p) > 1) and t & p else 0.0


def verdict_label(verdict: Mapping[str, Any]) -> str:
    """The label a bench scores of a verdict's JSON: its effect, or ``a|b`` for two stories
    (``Verdict.label``)."""
    return Verdict.from_json(verdict).label


def contains_truth(truth: str, predicted: str) -> bool:
    """Right, or a two-story answer one of whose stories is right (the form matrix's
    per-effect figure)."""
    return credit(truth, predicted) == 1.0 or any(
        credit(truth, story) == 1.0 for story in predicted.split("|") if "|" in predicted)


def row_credit(row: Mapping[str, Any], *, strict: bool = False) -> float:
    """:func:`credit` of a bench row, counting the effects its record lists as also present
    (``also_present``) unless ``strict``."""
    return credit(row["effect"], row["predicted"], () if strict else row.get("also_present") or ())


def _right(row: Mapping[str, Any], *, strict: bool = False) -> bool:
    return row_credit(row, strict=strict) == 1.0


def _pct(part: float, whole: int) -> float:
    return 100.0 * part / whole if whole else math.nan


def summarise_bench(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Confusion matrix, top-1 (singles, pairs, overall with half credit), false alarms (any,
    and systematic), per-effect hits, magnitude errors and shrink statistics. Every figure
    counts the effects a record lists as also present (:func:`credit`); ``*_strict_pct`` and
    ``rig_added`` (the rows right only through them) say what the strict truth would give."""
    truths = {r["effect"] for r in rows}
    labels = [*EFFECT_NAMES, "none",
              *sorted(t for t in truths if "+" not in t and t not in (*EFFECT_NAMES, "none"))]
    pair_labels = sorted(t for t in truths if "+" in t)
    predicted_labels = sorted({_canonical(r["predicted"]) for r in rows} - set(labels))
    matrix = {t: Counter(_canonical(r["predicted"]) for r in rows if r["effect"] == t)
              for t in (*labels, *pair_labels)}
    correct = [r for r in rows if _right(r)]
    none_rows = [r for r in rows if r["effect"] == "none"]
    effect_rows = [r for r in rows if r["effect"] != "none"]
    single_rows = [r for r in effect_rows if "+" not in r["effect"]]
    pair_rows = [r for r in effect_rows if "+" in r["effect"]]
    magnitude: dict[str, list[float]] = {}
    for r in correct:
        if "magnitude" in r["relative_errors"]:
            magnitude.setdefault(r["effect"], []).append(r["relative_errors"]["magnitude"])
    all_mag = [e for errs in magnitude.values() for e in errs]
    shrink = [r["shrink_pct"] for r in correct if r["effect"] != "none"
              and r["shrink_pct"] is not None]
    return {
        "records": len(rows),
        "top1_pct": _pct(len(correct), len(rows)),
        "top1_strict_pct": _pct(sum(_right(r, strict=True) for r in rows), len(rows)),
        "effects_top1_pct": _pct(sum(_right(r) for r in effect_rows), len(effect_rows)),
        "effects_top1_strict_pct": _pct(sum(_right(r, strict=True) for r in effect_rows),
                                        len(effect_rows)),
        "also_present_records": sum(bool(r.get("also_present")) for r in rows),
        "singles": len(single_rows),
        "singles_top1_pct": _pct(sum(_right(r) for r in single_rows), len(single_rows)),
        "pairs": len(pair_rows),
        "pairs_exact_pct": _pct(sum(_right(r) for r in pair_rows), len(pair_rows)),
        "overall_credit_pct": _pct(sum(row_credit(r) for r in rows), len(rows)),
        "none_false_alarm_pct": _pct(sum(r["predicted"] != "none" for r in none_rows),
                                     len(none_rows)),
        "none_systematic_pct": _pct(sum(bool(_members(r["predicted"]) & SYSTEMATIC)
                                        for r in none_rows), len(none_rows)),
        "missed_as_none_pct": _pct(sum(r["predicted"] == "none" for r in effect_rows),
                                   len(effect_rows)),
        "labels": labels, "pair_labels": pair_labels, "extra_predictions": predicted_labels,
        "confusion": {t: dict(matrix[t]) for t in (*labels, *pair_labels)},
        "per_effect": {t: {"records": len(sub), "correct": sum(_right(r) for r in sub),
                           "correct_strict": sum(_right(r, strict=True) for r in sub),
                           "credit": sum(row_credit(r) for r in sub)}
                       for t in (*labels, *pair_labels)
                       for sub in [[r for r in rows if r["effect"] == t]] if sub},
        "magnitude_within_20pct": _pct(sum(e <= MAGNITUDE_TOLERANCE for e in all_mag),
                                       len(all_mag)),
        "magnitude_error_median_pct": {k: 100.0 * float(np.median(v))
                                       for k, v in magnitude.items()},
        "magnitude_error_max_pct": {k: 100.0 * float(np.max(v)) for k, v in magnitude.items()},
        "shrink_pct": {"mean": float(np.mean(shrink)), "median": float(np.median(shrink)),
                       "min": float(np.min(shrink))} if shrink else {},
        "diagnose_seconds": {"median": float(np.median([r["diagnose_seconds"] for r in rows])),
                             "max": float(np.max([r["diagnose_seconds"] for r in rows]))}
        if rows else {},
        "by_law": {law: {"records": len(sub), "top1_pct": _pct(
            sum(_right(r) for r in sub), len(sub))}
            for law in sorted({r.get("law", "bouc-wen") for r in rows})
            for sub in [[r for r in rows if r.get("law", "bouc-wen") == law]]},
        "failures": [{k: r.get(k) for k in ("index", "seed", "effect", "predicted",
                                            "confidence", "gap_before_pct", "truth",
                                            "also_present", "law",
                                            "baseline", "samples", "diagnose_seconds")}
                     for r in rows if not _right(r)],
        "rig_added": [{k: r.get(k) for k in ("index", "seed", "effect", "predicted",
                                             "also_present", "estimates")}
                      for r in rows if _right(r) and not _right(r, strict=True)],
    }


def format_bench(summary: dict[str, Any], seed: int, wall: float, *,
                 realism: bool = False, independent: bool = False) -> str:
    """The bench's printout: headline numbers, confusion matrix, magnitudes, failures."""
    labels = summary["labels"]
    rows = [*labels, *summary.get("pair_labels", [])]
    columns = [*labels, *summary["extra_predictions"]]
    short = {name: name.replace("actuator_", "act_").replace("rate_dependence", "rate")
             .replace("sensor_", "sens_").replace("degradation", "degrad")[:10]
             for name in columns}
    width = max(len(x) for x in rows) + 1
    mode = " --independent" if independent else " --realism" if realism else ""
    lines = [
        f"diagnose-bench{mode}: {summary['records']} records, seed {seed}, {wall:.1f} s wall",
        f"top-1 {pct(summary['top1_pct'], 1)} (effects {pct(summary['effects_top1_pct'], 1)}); "
        f"none false alarms {pct(summary['none_false_alarm_pct'], 1)}; effects missed as none "
        f"{pct(summary['missed_as_none_pct'], 1)}",
    ]
    if realism or summary.get("also_present_records"):
        lines[1] = (
            f"top-1 {pct(summary['top1_strict_pct'], 1)} strict, {pct(summary['top1_pct'], 1)} "
            "counting effects the rig really adds (effects "
            f"{pct(summary['effects_top1_strict_pct'], 1)} / "
            f"{pct(summary['effects_top1_pct'], 1)}); none false alarms "
            f"{pct(summary['none_false_alarm_pct'], 1)}; effects missed as none "
            f"{pct(summary['missed_as_none_pct'], 1)}")
    if summary.get("pairs"):
        lines.append(
            f"singles top-1 {pct(summary['singles_top1_pct'], 1)} of {summary['singles']}; "
            f"pairs exact {pct(summary['pairs_exact_pct'], 1)} of {summary['pairs']}; overall "
            f"with half credit {pct(summary['overall_credit_pct'], 1)}; none -> systematic "
            f"effect {pct(summary['none_systematic_pct'], 1)}")
    lines += [
        f"magnitude within 20 %: {pct(summary['magnitude_within_20pct'], 1)} of correctly "
        "named records",
        "confusion (rows: true effect, columns: verdict):",
        " " * width + " ".join(f"{short[c]:>10}" for c in columns),
    ]
    for t in rows:
        row = summary["confusion"][t]
        lines.append(f"{t:<{width}}" + " ".join(f"{row.get(c, 0):>10}" for c in columns))
    if summary.get("pairs"):
        lines.append("per truth (right / records): " + ", ".join(
            f"{t} {v['correct']}/{v['records']}" for t, v in summary["per_effect"].items()))
    if len(summary["by_law"]) > 1:
        lines.append("top-1 by specimen law: " + ", ".join(
            f"{law} {pct(v['top1_pct'], 1)} of {v['records']}"
            for law, v in summary["by_law"].items()))
    lines.append("magnitude error (median / max, % of the true value):")
    for effect, median in summary["magnitude_error_median_pct"].items():
        lines.append(f"  {effect:<20} {MAGNITUDE_OF.get(effect, '-'):<16} {median:7.2f} / "
                     f"{summary['magnitude_error_max_pct'][effect]:7.2f}")
    if summary["shrink_pct"]:
        s = summary["shrink_pct"]
        lines.append(f"gap shrink of the true effect (correct records): mean "
                     f"{pct(s['mean'], 1)}, median {pct(s['median'], 1)}, min {pct(s['min'], 1)}")
    if summary["diagnose_seconds"]:
        d = summary["diagnose_seconds"]
        lines.append(f"diagnosis time per record: median {d['median']:.1f} s, max {d['max']:.1f} s")
    for r in summary.get("rig_added", []):
        also = "; ".join(
            f"{name} {fmt(value)} put in, {fmt(r['estimates'].get(name))} found"
            for values in r["also_present"].values() for name, value in values.items())
        lines.append(f"  right with an effect the rig adds: record {r['index']} (seed "
                     f"{r['seed']}) {r['effect']} -> {r['predicted']} ({also})")
    for f in summary["failures"]:
        lines.append(f"  failure: record {f['index']} (seed {f['seed']}, {f['law']}, baseline "
                     f"{f.get('baseline')}) "
                     f"{f['effect']} -> {f['predicted']} (confidence {f['confidence']:.2f}, "
                     f"gap {pct(f['gap_before_pct'])})")
    return "\n".join(lines)
