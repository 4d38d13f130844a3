"""The diagnosis: baseline on the calibration part, every candidate scored on the withheld part.

Procedure (docs/diagnosis.md, "Diagnosing the sim-to-real gap", states it for users):

1. Split by the command's energy: the calibration part is the first samples that carry
   :data:`CALIBRATION_FRACTION` of the command's signal energy (sum of (c − mean c)²), the rest
   is withheld, so a quiet tail never becomes the whole withheld part (on a stationary record
   this is the first ~60 % of the samples). The command is the test's input, known before any
   measurement; fits receive ``Record.part(stop)`` only: the withheld samples never reach them.
2. Baseline: the law driven by the command, every parameter fitted (shape too); with
   ``auto`` (the default) the law family is chosen on the calibration part too (``baseline``).
3. Gap on the withheld part, per channel, as NRMS in % of the *whole record's* scale (force:
   measured − predicted over the record's RMS force; displacement: measured − predicted over
   the record's RMS command), and ``total`` = their root sum of squares: a quiet withheld part
   cannot inflate it. Below :data:`NOISE_FLOOR_PCT` the verdict is ``none``.
4. Each candidate: the baseline plus one effect, all refitted on the calibration part,
   predicting the withheld part; ``sensor_noise`` claims the white part of the baseline's gap
   (its std estimated on the calibration residual, never on the withheld one). ``shrink_pct`` =
   100 (1 − after/before); ``score`` = shrink − :data:`PARSIMONY_PCT` per parameter. A
   candidate is named only if it moves the baseline's prediction by at least the floor
   (``scored.effect_size``: a 0.4 % "offset" absorbing a small law misfit is not an effect) and
   leaves less than the baseline's gap. A candidate that needs another law family (pinching or
   degradation under a bilinear or Menegotto-Pinto baseline drive BWBN) is compared with the
   best baseline *of that family* (Bouc-Wen, fitted on the calibration part), never credited
   with the family change. With a named baseline (not ``auto``) the other families of
   ``AUTO_FAMILIES`` are fitted too; when a family change alone beats every effect (it shrinks
   the gap by at least :data:`MIN_SHRINK_PCT` and scores higher, the extra law parameters
   counted), the verdict is ``baseline_misfit`` naming that family. The best score wins if it
   shrinks the gap by at least :data:`MIN_SHRINK_PCT`; otherwise the verdict is
   ``baseline_misfit`` when the baseline misses even its calibration part by more than the
   floor beyond the white noise (the law family is the first suspect), else ``unexplained``.
5. Pairs: when the best single by the systematic gap (item 7) leaves more than the systematic
   floor (and more than the floor), pairs of the top three singles are fitted (and each top
   single with sensor noise).
   A pair wins when both of its effects matter by the rule a single passes against the
   baseline (each shrinks the gap the other leaves alone by :data:`MIN_SHRINK_PCT`) and its
   score beats the best single's by :data:`PAIR_MARGIN_PCT`. A pair is named in alphabetical
   order (``friction+sensor_bias``), whatever the ranking of its members.
6. Confidence: the share of the winner's gap reduction that the runner-up does not achieve,
   (after_second − after_best) / (before − after_best); for ``none``, 1 − gap/floor. Every
   parameter of the winning effect at a bound (other than a zero lower bound: "absent") or with
   a relative std above :data:`MAX_RELATIVE_STD` is flagged and halves it
   (:data:`FLAG_CONFIDENCE_FACTOR`); below :data:`LOW_CONFIDENCE` the verdict names the
   runner-up it could not separate (``not_separated_from``). A winner at a bound where its
   form becomes the runner-up's (``model.LIMIT_FORMS``: a rate law at its smallest exponent
   is Coulomb friction) that the record cannot separate from it gives way to the runner-up.
7. White noise is no rival: unless the verdict is ``none``, the candidates are scored again on
   the *systematic* gap (the white noise estimated on the calibration residual removed from
   each withheld variance); ``sensor_noise`` wins only when that gap is below what the record
   resolves (:func:`systematic_floor`). Items 3-7 are applied in :mod:`.decision`
   (:func:`.decision.systematic_verdict`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import indicators as ind
from .baseline import choose_baseline, fit_baseline
from .decision import (
    FLAG_CONFIDENCE_FACTOR,
    LOW_CONFIDENCE,
    PAIR_MARGIN_PCT,
    confidence_words,
    decide,
    systematic_verdict,
)
from .fit import Fit, fit_spec, predict
from .load import DiagnosisInputError, Record
from .localise import localise
from .model import (
    AUTO,
    BASELINES,
    EFFECT_NAMES,
    Context,
    baseline_report,
    effect_parameters,
    held_sign,
    make_spec,
)
from .names import AUTO_FAMILIES
from .nocommand import hidden_effects, hidden_summary
from .noise import estimate_noise
from .scored import (
    MAX_RELATIVE_STD,
    MIN_SHRINK_PCT,
    PARSIMONY_PCT,
    effect_size,
    systematic_floor,
    without_noise,
)
from .scored import Scored as _Scored
from .scored import gap as _gap
from .scored import rms as _rms

__all__ = [
    "CALIBRATION_FRACTION",
    "FLAG_CONFIDENCE_FACTOR",
    "HOPELESS_COST_SHARE",
    "LOW_CONFIDENCE",
    "MAX_RELATIVE_STD",
    "MIN_SHRINK_PCT",
    "NOISE_FLOOR_PCT",
    "PAIR_MARGIN_PCT",
    "PARSIMONY_PCT",
    "SCHEMA",
    "Options",
    "diagnose",
    "stop_of",
]

FloatArray = npt.NDArray[np.float64]
Progress = Callable[[int, int], None]

SCHEMA = "fresco-bridge/diagnosis/1"
CALIBRATION_FRACTION = 0.6
NOISE_FLOOR_PCT = 1.0
TOP_FOR_PAIRS = 3
MAX_FIT_SAMPLES = 6000
"""Longer calibration parts are thinned for the fits (every k-th sample and every reversal of
the command: the same path for a rate-independent law); scoring uses every sample."""
RESTART_IF_COST_ABOVE = 0.5
"""A shape-changing candidate (:data:`RESTARTED`) fitted from the baseline's values that keeps
more than this share of the baseline's calibration cost, with its effect parameters stuck at
their lower bounds, is fitted again from the generic start (the better one is kept): a baseline
bent to mimic a gap or pinching is a trap for them."""
RESTARTED = frozenset({"backlash", "pinching"})
STAGED_JOINT_EVALUATIONS = 10
"""On a long record (a calibration part over ``max_fit_samples``, thinned for the fits) a
candidate is fitted in two stages: its effect parameters alone with the law held at the
baseline's values (a Jacobian of one to three drives instead of seven to ten), then everything
together from there for at most this many evaluations. A long random record makes every drive
a long path of a stiff law (thousands of yield displacements per drive), and a joint refit from
a good start needs few steps: the same calibration cost for a fraction of the drives
(``BENCHMARKS.md``, "Diagnosis")."""
HOPELESS_COST_SHARE = 0.98
"""Early rejection in that staged fit: a candidate whose first stage (its effect parameters
alone, on the law it is compared with) leaves more than this share of that law's calibration
cost (mean squared normalised residual) is not refitted jointly. It removed under 2 % of the
misfit it was meant to explain; the joint stage (a Jacobian of seven to twelve long drives per
step) did not turn such a candidate into a 20 % shrink of the withheld gap on the measured
records (``BENCHMARKS.md``, "Diagnosis": the MR damper). Records whose calibration part fits
the budget are fitted in one stage and never take this path."""


@dataclass(frozen=True)
class Options:
    """How to diagnose: baseline law (and optional given parameters), floor, candidates."""

    baseline: str = AUTO
    """A law of ``BASELINES``, or ``auto``: chosen on the calibration part (``baseline``)."""
    baseline_params: Mapping[str, float] = field(default_factory=dict)
    fit_baseline: bool = True
    """False: the given ``baseline_params`` are the sim, held (a PARAMS.toml with fit = false)."""
    noise_floor_pct: float = NOISE_FLOOR_PCT
    calibration_fraction: float = CALIBRATION_FRACTION
    effects: Sequence[str] = EFFECT_NAMES
    pairs: bool = True
    max_fit_samples: int = MAX_FIT_SAMPLES


def _effect_start(effect: str, cal: Context) -> dict[str, float]:
    """Start values from the interface indicators where they say something directly."""
    rec = cal.record
    if rec.meas_disp is None:
        return {}
    if effect == "actuator_delay":
        max_lag = min(50, rec.size - 3)
        try:
            tau = ind.xcorr_delay(rec.cmd, rec.meas_disp, cal.dt, max_lag)
        except ind.IndicatorError:
            return {}
        return {"tau": max(tau, 0.1 * cal.dt)}
    if effect == "actuator_amplitude":
        c = rec.cmd
        return {"amplitude_error": float(np.dot(c, rec.meas_disp) / np.dot(c, c)) - 1.0}
    if effect == "sensor_bias":
        return {"disp_bias": float(np.mean(rec.meas_disp - rec.cmd))}
    if effect == "actuator_undershoot":
        step = np.zeros_like(rec.cmd)
        step[1:] = np.diff(rec.cmd)
        direction = held_sign(step)
        moving = direction != 0.0
        if not np.any(moving):
            return {}
        short = -float(np.mean((rec.meas_disp - rec.cmd)[moving] * direction[moving]))
        return {"undershoot": max(short, 1e-3 * cal.d_peak)}
    return {}


def diagnose(record: Record, options: Options | None = None,
             progress: Progress | None = None) -> dict[str, Any]:
    """Diagnose ``record``; the JSON-ready result (schema in docs/diagnosis.md)."""
    opts = options or Options()
    if opts.baseline not in (AUTO, *BASELINES):
        raise DiagnosisInputError(
            f"unknown baseline {opts.baseline!r}; choose {AUTO}, {', '.join(BASELINES)} or a "
            "PARAMS.toml")
    if opts.baseline == AUTO and (opts.baseline_params or not opts.fit_baseline):
        raise DiagnosisInputError("baseline auto chooses and fits the law itself: give no "
                                  "parameters (or name the law)")
    unknown = [e for e in opts.effects if e not in EFFECT_NAMES]
    if unknown:
        raise DiagnosisInputError(f"unknown effect(s) {', '.join(unknown)}; candidates: "
                                  f"{', '.join(EFFECT_NAMES)}")
    started = time.perf_counter()
    requested = opts.baseline
    n = record.size
    stop = stop_of(record, opts)
    if stop < 60 or n - stop < 40:
        raise DiagnosisInputError(
            f"{record.source}: record too short to split: {n} samples give {stop} to calibrate "
            f"and {n - stop} to withhold (need >= 60 and >= 40)")
    split_note = (f"split by the command's energy: calibration samples 0-{stop} "
                  f"({100.0 * stop / n:.0f} % of the samples, "
                  f"{100.0 * opts.calibration_fraction:.0f} % of the energy)")
    calibration = record.part(stop)
    cal = Context.of(calibration.thinned(opts.max_fit_samples))
    full = Context.of(record)
    withheld = slice(stop, n)
    hidden = hidden_effects(record, opts.effects)  # no command channel: the interface layer
    effects = [e for e in opts.effects if e not in hidden]
    total_fits = 1 + len(effects) + (TOP_FOR_PAIRS * 2 if opts.pairs else 0)
    done = 0
    if progress is not None:
        progress(0, total_fits)  # the total before the baseline's fits (seconds)

    def tick() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(min(done, total_fits), total_fits)

    fixed = {} if opts.fit_baseline else dict(opts.baseline_params)
    if opts.baseline == AUTO:
        chosen = choose_baseline(cal)
        spec0, base_fit, selection = chosen.spec, chosen.fit, chosen.selection
        opts = replace(opts, baseline=spec0.baseline)
    else:
        spec0, base_fit = fit_baseline(opts.baseline, cal, opts.baseline_params, fixed)
        selection = None
    tick()
    values0 = base_fit.values
    f0, d0 = predict(spec0, full, values0)
    before = _gap(record, f0, d0, withheld)
    f_scale, d_scale = _rms(record.force) or 1.0, _rms(record.cmd) or 1.0
    estimate = estimate_noise(record, f0, d0, stop)
    noise_f, noise_d = estimate.white
    claim_f, claim_d = estimate.claim
    noise_only = math.hypot(100.0 * noise_f / f_scale, 100.0 * noise_d / d_scale
                            if record.meas_disp is not None else 0.0)
    noise_gap = {"force_noise_std": noise_f, "disp_noise_std": noise_d,
                 "noise_only_gap_pct": noise_only, "claimed_force_noise_std": claim_f,
                 "claimed_disp_noise_std": claim_d}
    families = _families(record, cal, full, opts, requested, fixed, values0, spec0.law_kind,
                         effects, before, withheld)
    references = {f.name: f for f in families}
    eff_params = effect_parameters(cal)
    scored: list[_Scored] = []
    for effect in effects:
        if effect == "sensor_noise":
            params = list(eff_params[effect])
            if record.meas_disp is None:
                params = params[:1]
            std_f = claim_f / math.sqrt(2.0 * (stop - 1))
            values = {"force_noise_std": claim_f, "disp_noise_std": claim_d}
            stds = {"force_noise_std": std_f, "disp_noise_std": claim_d / math.sqrt(2.0 * stop)}
            after = _gap(record, f0, d0, withheld, estimate.claim)
            scored.append(_Scored(effect, (effect,), params, None, values, stds, before, after,
                                  f0, d0))
            tick()
            continue
        scored.append(_fit_candidate(record, cal, full, opts, fixed, (effect,),
                                     {**values0, **_effect_start(effect, cal)}, before,
                                     withheld, base_fit.cost, references))
        tick()
    singles = sorted(scored, key=lambda s: s.score, reverse=True)
    pairs: list[_Scored] = []
    best = singles[0] if singles else None
    white = (noise_f, noise_d)
    sys_before = _gap(record, f0, d0, withheld, white)
    sys_floor = systematic_floor(opts.noise_floor_pct, noise_only, stop, n - stop)
    fitted = sorted((without_noise(s, record, withheld, white, sys_before, {})
                     for s in singles if s.fit is not None), key=lambda s: s.score, reverse=True)
    if (opts.pairs and best is not None and before["total_pct"] is not None
            and before["total_pct"] >= opts.noise_floor_pct and fitted
            and (sys_before["total_pct"] or 0.0) >= sys_floor
            and (fitted[0].after["total_pct"] or 0.0) > max(opts.noise_floor_pct, sys_floor)):
        # the best single by the systematic gap (white noise removed) leaves more than the
        # noise can hide: pairs of the top three singles by that gap
        fitted = [next(s for s in singles if s.name == f.name) for f in fitted[:TOP_FOR_PAIRS]]
        for i, a in enumerate(fitted):
            for b in fitted[i + 1:]:
                start = {**values0, **b.values, **a.values}
                pairs.append(_fit_candidate(record, cal, full, opts, fixed,
                                            tuple(sorted((*a.effects, *b.effects))), start,
                                            before, withheld, base_fit.cost, references))
                tick()
            if "sensor_noise" in effects and a.force is not None:
                after = _gap(record, a.force, a.disp, withheld, estimate.claim)
                noise = next(s for s in scored if s.name == "sensor_noise")
                members = tuple(sorted((*a.effects, "sensor_noise")))
                pairs.append(_Scored("+".join(members), members,
                                     [*a.params, *noise.params], a.fit,
                                     {**a.values, **noise.values}, {**a.std, **noise.std},
                                     a.before, after, a.force, a.disp, a.compared_with))
                tick()
    for s in [*singles, *pairs]:
        if s.fit is not None:
            s.size = effect_size(record, s, f0, d0, withheld)
    gap_cal = _gap(record, f0, d0, slice(0, stop))
    systematic_cal = math.sqrt(max(gap_cal["total_pct"] ** 2 - noise_only**2, 0.0)) if (
        gap_cal["total_pct"] is not None and math.isfinite(gap_cal["total_pct"])) else math.inf
    noise_gap["systematic_calibration_gap_pct"] = systematic_cal
    verdict = decide(before, singles, pairs, families, opts.noise_floor_pct, systematic_cal,
                       spec0.baseline)
    if "sensor_noise" in effects and verdict["effect"] != "none":
        verdict = systematic_verdict(record, withheld, white, sys_before, sys_floor, verdict,
                                      singles, pairs, families, opts.noise_floor_pct,
                                      systematic_cal, spec0.baseline)
    verdict.setdefault("gap_basis", "raw")  # the gaps and shrink the verdict quotes
    noise_gap["systematic_withheld_gap_pct"] = sys_before["total_pct"] or 0.0
    noise_gap["systematic_floor_pct"] = sys_floor
    if progress is not None:
        progress(total_fits, total_fits)
    sim_meas = None
    if record.meas_disp is not None:
        from sim_actuator.models.paths import drive

        from .model import DZ_MAX, law_vector

        law, vec = law_vector(spec0.law_kind, values0)
        sim_meas = drive(law, vec, record.meas_disp, 0.0, DZ_MAX)
    winner = next((s for s in [*singles, *pairs] if s.name == verdict["effect"]), None)
    refs = {f.name: _gap(record, f.force, f.disp, withheld, white)
            for f in families if f.force is not None}

    def row(s: _Scored) -> dict[str, Any]:
        return s.as_dict(without_noise(s, record, withheld, white, sys_before,
                                       {} if not s.effects else refs))

    verdict["confidence_words"] = confidence_words(verdict)
    return {
        "schema": SCHEMA,
        "record": {
            "source": record.source, "samples": n, "duration_s": float(record.time[-1]
                                                                       - record.time[0]),
            "dt_s": full.dt, "channels": (["meas_disp (no command)"] if record.no_command
                                          else ["cmd_disp"]) + ["meas_force"]
            + (["meas_disp"] if record.meas_disp is not None else []),
            "command": not record.no_command,
            "notes": [*record.notes, *cal.record.notes[len(record.notes):], split_note],
            "calibration": {"samples": [0, stop], "t_end": float(record.time[stop - 1])},
            "withheld": {"samples": [stop, n], "t_start": float(record.time[stop])},
        },
        "baseline": {
            "kind": opts.baseline, "requested": requested, "selection": selection,
            "fitted": opts.fit_baseline,
            "params": baseline_report(spec0.law_kind, values0),
            "std": {k: v for k, v in base_fit.std.items()},
            "gap_calibration": gap_cal,
            "gap_withheld": before,
            "fit": {"converged": base_fit.ok, "evaluations": base_fit.evaluations},
        },
        "noise_floor": {"floor_pct": opts.noise_floor_pct, **noise_gap},
        "localization": localise(record, f0, sim_meas, stop),
        "effects": [row(s) for s in singles],
        "pairs": [row(s) for s in sorted(pairs, key=lambda s: s.score, reverse=True)],
        "families": [{**row(s), "role": s.role}
                     for s in sorted(families, key=lambda s: s.score, reverse=True)],
        "verdict": verdict,
        "not_identifiable": hidden,
        "hidden": hidden_summary(record, opts.effects),
        "seconds": time.perf_counter() - started,
        "_series": {
            "time": record.time, "cmd": record.cmd, "meas_disp": record.meas_disp,
            "force": record.force, "sim": f0, "sim_disp": d0,
            "best": None if winner is None else winner.force,
            "best_disp": None if winner is None else winner.disp, "stop": stop,
        },
    }


def stop_of(record: Record, opts: Options) -> int:
    """The calibration part's length: the first samples that carry ``calibration_fraction`` of
    the command's signal energy, sum of (c − mean c)² (the time fraction for a constant
    command). The command only: it is the test's input, so the split never depends on a
    measured (possibly withheld) value."""
    c = record.cmd - float(np.mean(record.cmd))
    energy = np.cumsum(c * c)
    if not energy.size or energy[-1] <= 0.0:
        return round(opts.calibration_fraction * record.size)
    return int(np.searchsorted(energy, opts.calibration_fraction * energy[-1])) + 1


def _families(record: Record, cal: Context, full: Context, opts: Options, requested: str,
              fixed: Mapping[str, float], values0: Mapping[str, float], law_kind: str,
              effects: Sequence[str], before: dict[str, float | None],
              withheld: slice) -> list[_Scored]:
    """Baselines of other law families, fitted on the calibration part, scored like effects.

    ``role`` is "alternative" for an alternative to the baseline (a named baseline: every other
    family of ``AUTO_FAMILIES``, when the baseline is fitted), and "reference" for the best
    baseline of a family an effect candidate drives (Bouc-Wen for pinching or degradation under
    a bilinear or Menegotto-Pinto baseline), against which that candidate is measured. Both
    kinds are scored against the baseline: either can be the family that closes the gap."""
    n_base = len(make_spec(cal, opts.baseline, [], fixed).params)
    kinds: dict[str, str] = {}
    if requested != AUTO and opts.fit_baseline:
        kinds.update({k: "alternative" for k in AUTO_FAMILIES if k != opts.baseline})
    for effect in effects:
        if effect == "sensor_noise":
            continue
        spec = make_spec(cal, opts.baseline, [effect], fixed)
        if spec.law_kind != law_kind:
            reference = _reference_family(spec.law_kind)
            if reference not in kinds:
                kinds[reference] = "reference"
    out: list[_Scored] = []
    for kind, role in kinds.items():
        held = {k: v for k, v in fixed.items()
                if k in {p.name for p in make_spec(cal, kind, []).params}}
        given = {k: values0[k] for k in ("k0", "fy", "alpha") if k in values0}
        spec, fit = fit_baseline(kind, cal, {k: v for k, v in given.items() if k not in held},
                                 held)
        force, disp = predict(spec, full, fit.values)
        out.append(_Scored(kind, (), [], fit, {}, {}, before, _gap(record, force, disp, withheld),
                           force, disp, extra_law_params=len(spec.params) - n_base, role=role))
    return out


def _reference_family(law_kind: str) -> str:
    """The baseline family an effect candidate driving ``law_kind`` is compared with: BWBN
    without pinching and degradation is Bouc-Wen."""
    return "bouc-wen" if law_kind == "bwbn" else law_kind


def _fit_candidate(record: Record, cal: Context, full: Context, opts: Options,
                   fixed: Mapping[str, float], effects: tuple[str, ...],
                   start: Mapping[str, float], before: dict[str, float | None],
                   withheld: slice, base_cost: float,
                   references: Mapping[str, _Scored] | None = None) -> _Scored:
    spec = make_spec(cal, opts.baseline, effects, fixed)
    law_names = {p.name for p in make_spec(cal, opts.baseline, [], fixed).params}
    params = [p for p in spec.params if p.name not in law_names and p.role != "noise"]
    compared_with = None
    reference = (references or {}).get(_reference_family(spec.law_kind))
    if reference is not None and reference.fit is not None and spec.law_kind != make_spec(
            cal, opts.baseline, [], fixed).law_kind:
        # another family: the law's own parameters are not the effect's, and the shrink is
        # measured from the best baseline of that family
        own = {p.name for p in reference.fit.spec.params} | {"n"}
        params = [p for p in params if p.name not in own]
        law_names |= own
        before = reference.after
        compared_with = f"{reference.name} baseline"
        start = {**start, **{k: v for k, v in reference.fit.values.items()
                             if k not in {p.name for p in params}}}
    staged = stop_of(record, opts) > opts.max_fit_samples
    compared_cost = (reference.fit.cost if compared_with is not None and reference is not None
                     and reference.fit is not None else base_cost)

    def fit_from(values: Mapping[str, float]) -> Fit:
        if not staged:
            return fit_spec(spec, cal, values, max_evaluations=30, tolerance=1e-5)
        held = {**{p.name: values.get(p.name, p.init) for p in spec.params
                   if p.name in law_names}, **fixed}
        first = fit_spec(make_spec(cal, opts.baseline, effects, held), cal, values,
                         max_evaluations=30, tolerance=1e-5)
        if first.cost > HOPELESS_COST_SHARE * compared_cost:
            return first  # hopeless: the joint stage is not worth its drives
        return fit_spec(spec, cal, first.values, max_evaluations=STAGED_JOINT_EVALUATIONS,
                        tolerance=1e-5)

    result = fit_from(start)
    stuck = all(result.values[p.name] <= p.lo + 0.02 * (p.hi - p.lo) for p in params)
    if (set(effects) & RESTARTED and stuck
            and result.cost > RESTART_IF_COST_ABOVE * base_cost):
        generic = {k: v for k, v in start.items() if k not in law_names}
        again = fit_from(generic)
        if again.cost < result.cost:
            result = again
    force, disp = predict(spec, full, result.values)
    after = _gap(record, force, disp, withheld)
    return _Scored("+".join(sorted(effects)), effects, params, result,
                   {p.name: result.values[p.name] for p in params},
                   {p.name: result.std.get(p.name, math.nan) for p in params},
                   before, after, force, disp, compared_with)
