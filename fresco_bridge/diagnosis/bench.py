"""``diagnose-bench``: records with known effects from the simulated rig, diagnosed blind.

Record i of a bench with seed S carries effect ``CLASSES[i % len(CLASSES)]`` (``none`` twice
per cycle, so false alarms are measured on enough records) and is generated from the seed
``S * 100003 + i``: any record can be regenerated alone. The diagnosis sees only time,
command, measured displacement and force — never the effect, its magnitude or the specimen.
Records run through ``fresco_bridge.sweeps.run_sweep`` (serial, local pool, or Dask). With
``realism`` the records come from ``realism.realistic_record`` (effects in the rig's physical
forms, not the candidates' shapes) instead of ``synth.synthetic_record``; same seeds.
"""

from __future__ import annotations

import math
import os
import pickle
import time
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..numbers import pct
from .model import EFFECT_NAMES
from .synth import SyntheticRecord, synthetic_record
from .verdict import diagnose

__all__ = ["CLASSES", "MAGNITUDE_OF", "bench_items", "diagnose_one", "effect_magnitude",
           "format_bench", "generate", "summarise_bench"]

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


BenchItem = tuple[int, str, int, int, bool, str | None]
"""(index, effect, record seed, steps, realism, record cache directory or None) of a record."""


def bench_items(n: int, seed: int, steps: int, realism: bool = False,
                cache: str | None = None) -> list[BenchItem]:
    """(index, effect, record seed, steps, realism, cache) of every record of the bench."""
    return [(i, CLASSES[i % len(CLASSES)], seed * 100_003 + i, steps, realism, cache)
            for i in range(n)]


def generate(item: BenchItem) -> SyntheticRecord:
    """Record ``item`` as the generator makes it; with a cache directory, read from there when
    it was generated before (a compliant-frame realism record takes minutes on the rig's
    substep solver, its diagnosis seconds), written there otherwise. The cache is keyed by
    bench, seed, effect and steps and is only ever written by this function (pickle: trusted,
    local)."""
    _index, effect, record_seed, steps, realism, cache = item
    path = None
    if cache is not None:
        path = Path(cache) / (f"{'realism' if realism else 'plain'}-{record_seed}-{effect}-"
                              f"{steps}.pickle")
        if path.exists():
            loaded = pickle.loads(path.read_bytes())
            if isinstance(loaded, SyntheticRecord):
                return loaded
    if realism:
        from .realism import realistic_record

        synthetic = realistic_record(effect, record_seed, steps=steps)
    else:
        synthetic = synthetic_record(effect, record_seed, steps=steps)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_bytes(pickle.dumps(synthetic))
        tmp.replace(path)
    return synthetic


def diagnose_one(item: BenchItem) -> dict[str, Any]:
    """Generate record ``item`` and diagnose it blind (a sweep task: top level, picklable)."""
    index, effect, record_seed, _steps, _realism, _cache = item
    started = time.perf_counter()
    synthetic = generate(item)
    generated = time.perf_counter()
    result = diagnose(synthetic.record)
    verdict = result["verdict"]
    true_candidate = next((e for e in result["effects"] if e["name"] == effect), None)
    estimates = {} if true_candidate is None else {
        name: p["value"] for name, p in true_candidate["params"].items()}
    errors = {name: abs(estimates[name] - value) / abs(value)
              for name, value in synthetic.truth.items() if name in estimates and value}
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
        "index": index, "effect": effect, "seed": record_seed, "predicted": verdict["effect"],
        "baseline": result["baseline"]["kind"],
        "confidence": verdict["confidence"], "truth": synthetic.truth, "estimates": estimates,
        "relative_errors": errors, "specimen": synthetic.specimen, "law": synthetic.law,
        "gap_before_pct": result["baseline"]["gap_withheld"]["total_pct"],
        "shrink_pct": None if true_candidate is None else true_candidate["shrink_pct"],
        "verdict_shrink_pct": verdict["shrink_pct"],
        "generate_seconds": generated - started, "diagnose_seconds": result["seconds"],
    }


def summarise_bench(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Confusion matrix, top-1, false alarms, magnitude errors and shrink statistics."""
    labels = [*EFFECT_NAMES, "none"]
    predicted_labels = sorted({r["predicted"] for r in rows} - set(labels))
    matrix = {t: Counter(r["predicted"] for r in rows if r["effect"] == t) for t in labels}
    correct = [r for r in rows if r["predicted"] == r["effect"]]
    none_rows = [r for r in rows if r["effect"] == "none"]
    effect_rows = [r for r in rows if r["effect"] != "none"]
    magnitude: dict[str, list[float]] = {}
    for r in correct:
        if "magnitude" in r["relative_errors"]:
            magnitude.setdefault(r["effect"], []).append(r["relative_errors"]["magnitude"])
    all_mag = [e for errs in magnitude.values() for e in errs]
    shrink = [r["shrink_pct"] for r in correct if r["effect"] != "none"
              and r["shrink_pct"] is not None]
    return {
        "records": len(rows),
        "top1_pct": 100.0 * len(correct) / len(rows) if rows else math.nan,
        "effects_top1_pct": 100.0 * sum(r in correct for r in effect_rows) / len(effect_rows)
        if effect_rows else math.nan,
        "none_false_alarm_pct": 100.0 * sum(r["predicted"] != "none" for r in none_rows)
        / len(none_rows) if none_rows else math.nan,
        "missed_as_none_pct": 100.0 * sum(r["predicted"] == "none" for r in effect_rows)
        / len(effect_rows) if effect_rows else math.nan,
        "labels": labels, "extra_predictions": predicted_labels,
        "confusion": {t: dict(matrix[t]) for t in labels},
        "magnitude_within_20pct": 100.0 * sum(e <= MAGNITUDE_TOLERANCE for e in all_mag)
        / len(all_mag) if all_mag else math.nan,
        "magnitude_error_median_pct": {k: 100.0 * float(np.median(v))
                                       for k, v in magnitude.items()},
        "magnitude_error_max_pct": {k: 100.0 * float(np.max(v)) for k, v in magnitude.items()},
        "shrink_pct": {"mean": float(np.mean(shrink)), "median": float(np.median(shrink)),
                       "min": float(np.min(shrink))} if shrink else {},
        "diagnose_seconds": {"median": float(np.median([r["diagnose_seconds"] for r in rows])),
                             "max": float(np.max([r["diagnose_seconds"] for r in rows]))}
        if rows else {},
        "by_law": {law: {"records": len(sub), "top1_pct": 100.0 * sum(
            r["predicted"] == r["effect"] for r in sub) / len(sub)}
            for law in sorted({r.get("law", "bouc-wen") for r in rows})
            for sub in [[r for r in rows if r.get("law", "bouc-wen") == law]]},
        "failures": [{k: r.get(k) for k in ("index", "seed", "effect", "predicted",
                                            "confidence", "gap_before_pct", "truth", "law",
                                            "baseline")}
                     for r in rows if r["predicted"] != r["effect"]],
    }


def format_bench(summary: dict[str, Any], seed: int, wall: float, *,
                 realism: bool = False) -> str:
    """The bench's printout: headline numbers, confusion matrix, magnitudes, failures."""
    labels = summary["labels"]
    columns = [*labels, *summary["extra_predictions"]]
    short = {name: name.replace("actuator_", "act_").replace("rate_dependence", "rate")
             .replace("sensor_", "sens_").replace("degradation", "degrad")[:10]
             for name in columns}
    width = max(len(x) for x in labels) + 1
    lines = [
        f"diagnose-bench{' --realism' if realism else ''}: {summary['records']} records, "
        f"seed {seed}, {wall:.1f} s wall",
        f"top-1 {pct(summary['top1_pct'], 1)} (effects {pct(summary['effects_top1_pct'], 1)}); "
        f"none false alarms {pct(summary['none_false_alarm_pct'], 1)}; effects missed as none "
        f"{pct(summary['missed_as_none_pct'], 1)}",
        f"magnitude within 20 %: {pct(summary['magnitude_within_20pct'], 1)} of correctly "
        "named records",
        "confusion (rows: true effect, columns: verdict):",
        " " * width + " ".join(f"{short[c]:>10}" for c in columns),
    ]
    for t in labels:
        row = summary["confusion"][t]
        lines.append(f"{t:<{width}}" + " ".join(f"{row.get(c, 0):>10}" for c in columns))
    if len(summary["by_law"]) > 1:
        lines.append("top-1 by specimen law: " + ", ".join(
            f"{law} {pct(v['top1_pct'], 1)} of {v['records']}"
            for law, v in summary["by_law"].items()))
    lines.append("magnitude error (median / max, % of the true value):")
    for effect, median in summary["magnitude_error_median_pct"].items():
        lines.append(f"  {effect:<20} {MAGNITUDE_OF[effect]:<16} {median:7.2f} / "
                     f"{summary['magnitude_error_max_pct'][effect]:7.2f}")
    if summary["shrink_pct"]:
        s = summary["shrink_pct"]
        lines.append(f"gap shrink of the true effect (correct records): mean "
                     f"{pct(s['mean'], 1)}, median {pct(s['median'], 1)}, min {pct(s['min'], 1)}")
    if summary["diagnose_seconds"]:
        d = summary["diagnose_seconds"]
        lines.append(f"diagnosis time per record: median {d['median']:.1f} s, max {d['max']:.1f} s")
    for f in summary["failures"]:
        lines.append(f"  failure: record {f['index']} (seed {f['seed']}, {f['law']}, baseline "
                     f"{f.get('baseline')}) "
                     f"{f['effect']} -> {f['predicted']} (confidence {f['confidence']:.2f}, "
                     f"gap {pct(f['gap_before_pct'])})")
    return "\n".join(lines)
