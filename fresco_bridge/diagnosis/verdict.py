"""The diagnosis: the pipeline of stages, each a module, from a record to a :class:`Diagnosis`.

read (``load``) → split (``split``) → baseline (``baseline``) → candidates (``candidates``,
``noise``) → selection (``decision``) → magnitude and shrink (``scored``) → localisation
(``localise``) → the result (``result``; printed and written by ``outputs``).

Procedure (docs/diagnosis.md, "Diagnosing the sim-to-real gap", states it for users):

1. Split by the command's energy: the calibration part is the first samples that carry
   :data:`CALIBRATION_FRACTION` of the command's signal energy (sum of (c − mean c)²), the rest
   is withheld (``split``). The command is the test's input, known before any
   measurement; fits receive ``Record.part(stop)`` only: the withheld samples never reach them.
2. Baseline: the law driven by the command, every parameter fitted (shape too); with
   ``auto`` (the default) the law family is chosen on the calibration part too (``baseline``).
3. Gap on the withheld part, per channel, as NRMS in % of the *whole record's* scale (force:
   measured − predicted over the record's RMS force; displacement: measured − predicted over
   the record's RMS command), and ``total`` = their root sum of squares: a quiet withheld part
   cannot inflate it.
4. Each candidate: the baseline plus one effect, all refitted on the calibration part,
   predicting the withheld part (``candidates``); a candidate that needs another law family
   (pinching or degradation under a bilinear or Menegotto-Pinto baseline drive BWBN) carries
   that family's extra law parameters; with a named baseline the other families of
   ``AUTO_FAMILIES`` are candidates too. When the best single, scored on the gap with the
   white noise removed, leaves more than the systematic floor, pairs of the top three singles
   are fitted.
5. Nothing systematic: a withheld gap below the policy's floor, or, with the white noise
   removed, below what the record resolves (:func:`.scored.systematic_floor`), names no effect:
   ``sensor_noise`` when a channel's noise is above the ordinary level
   (:class:`.options.Policy`), else ``none`` (``decision.nothing_systematic``).
6. Otherwise the one selection rule (``decision``): the lowest BIC on the withheld part wins
   if it beats the baseline's (a winner at the bound where it is another candidate's form,
   ``model.LIMIT_FORMS``, is named as that one); its weight is the confidence; a rival within
   the policy's ``two_story_delta`` that tells another story is named beside it, with the
   measurement that would separate them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from .baseline import choose_baseline, fit_baseline
from .candidates import (
    TOP_FOR_PAIRS,
    effect_start,
    fit_candidate,
    fit_families,
    noise_candidate,
    with_noise,
)
from .decision import confidence_words, decide, nothing_systematic
from .fit import predict
from .load import DiagnosisInputError, Record
from .localise import localise
from .model import (
    AUTO,
    BASELINES,
    DZ_MAX,
    EFFECT_NAMES,
    Context,
    baseline_report,
    effect_parameters,
    law_vector,
)
from .nocommand import hidden_effects, hidden_summary
from .noise import estimate_noise
from .options import CALIBRATION_FRACTION, MAX_FIT_SAMPLES, NOISE_FLOOR_PCT, Options
from .result import SCHEMA, Diagnosis, Series, Verdict
from .scored import (
    Scored,
    effect_size,
    evidence_samples,
    gap,
    rms,
    systematic_floor,
    without_noise,
)
from .split import split, stop_of

__all__ = ["CALIBRATION_FRACTION", "MAX_FIT_SAMPLES", "NOISE_FLOOR_PCT", "SCHEMA", "Options",
           "diagnose", "stop_of"]

Progress = Callable[[int, int], None]


def _check(opts: Options) -> None:
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


def diagnose(record: Record, options: Options | None = None,
             progress: Progress | None = None) -> Diagnosis:
    """Diagnose ``record`` (module doc: the procedure)."""
    opts = options or Options()
    _check(opts)
    started = time.perf_counter()
    requested = opts.baseline
    parts = split(record, opts)
    stop, n, withheld = parts.stop, record.size, parts.withheld
    cal = Context.of(record.part(stop).thinned(opts.max_fit_samples))
    full = Context.of(record)
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

    # baseline
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
    before = gap(record, f0, d0, withheld)
    # the noise: white (removed from every withheld gap) and what sensor_noise claims
    estimate = estimate_noise(record, f0, d0, stop)
    white = estimate.white
    f_scale, d_scale = rms(record.force) or 1.0, rms(record.cmd) or 1.0
    noise_only = math.hypot(100.0 * white[0] / f_scale, 100.0 * white[1] / d_scale
                            if record.meas_disp is not None else 0.0)
    # candidates: other law families, singles, pairs
    families = fit_families(record, cal, full, opts, requested, fixed, values0, spec0.law_kind,
                            effects, before, withheld)
    references = {f.name: f for f in families}
    eff_params = effect_parameters(cal)
    singles_fitted: list[Scored] = []
    for effect in effects:
        if effect == "sensor_noise":
            singles_fitted.append(noise_candidate(record, eff_params[effect], estimate.claim,
                                                  stop, (f0, d0), before, withheld))
        else:
            singles_fitted.append(fit_candidate(
                record, cal, full, opts, fixed, (effect,),
                {**values0, **effect_start(effect, cal)}, before, withheld, base_fit.cost,
                references))
        tick()
    singles = sorted(singles_fitted, key=lambda s: s.score, reverse=True)
    sys_before = gap(record, f0, d0, withheld, white)
    sys_floor = systematic_floor(opts.noise_floor_pct, noise_only, stop, n - stop)
    by_systematic = sorted((without_noise(s, record, withheld, white, sys_before, {})
                            for s in singles if s.fit is not None),
                           key=lambda s: s.score, reverse=True)
    pairs: list[Scored] = []
    if (opts.pairs and singles and before["total_pct"] is not None
            and before["total_pct"] >= opts.noise_floor_pct and by_systematic
            and (sys_before["total_pct"] or 0.0) >= sys_floor
            and (by_systematic[0].after["total_pct"] or 0.0)
            > max(opts.noise_floor_pct, sys_floor)):
        # the best single by the systematic gap (white noise removed) leaves more than the
        # noise can hide: pairs of the top three singles by that gap
        top = [next(s for s in singles if s.name == f.name)
               for f in by_systematic[:TOP_FOR_PAIRS]]
        noise = next((s for s in singles if s.name == "sensor_noise"), None)
        for i, a in enumerate(top):
            for b in top[i + 1:]:
                pairs.append(fit_candidate(record, cal, full, opts, fixed,
                                           tuple(sorted((*a.effects, *b.effects))),
                                           {**values0, **b.values, **a.values}, before,
                                           withheld, base_fit.cost, references))
                tick()
            if noise is not None and a.force is not None:
                pairs.append(with_noise(a, noise, record, withheld, estimate.claim))
                tick()
    # magnitude and shrink; selection
    for s in [*singles, *pairs]:
        if s.fit is not None:
            s.size = effect_size(record, s, f0, d0, withheld)
    gap_cal = gap(record, f0, d0, parts.calibration)
    systematic_cal = math.sqrt(max(gap_cal["total_pct"] ** 2 - noise_only**2, 0.0)) if (
        gap_cal["total_pct"] is not None and math.isfinite(gap_cal["total_pct"])) else math.inf
    policy = opts.policy
    peak_f = float(np.max(np.abs(record.force))) or 1.0
    peak_d = float(np.max(np.abs(record.cmd))) or 1.0
    noise_pct = max(100.0 * estimate.claim[0] / peak_f, 100.0 * estimate.claim[1] / peak_d)
    noise_named = "sensor_noise" in effects
    raw_gap = before["total_pct"] or 0.0
    if raw_gap < policy.noise_floor_pct:
        decided = nothing_systematic(raw_gap, noise_pct, policy,
                                     f"withheld gap {raw_gap:.2f} % is below the noise floor "
                                     f"{policy.noise_floor_pct:g} %", noise_named)
    elif (sys_before["total_pct"] or 0.0) < sys_floor:
        decided = nothing_systematic(raw_gap, noise_pct, policy,
                                     f"withheld gap {raw_gap:.2f} %; without the white noise "
                                     f"{sys_before['total_pct'] or 0.0:.2f} %, below the "
                                     f"{sys_floor:.2f} % the record resolves: nothing "
                                     "systematic", noise_named)
    else:
        n_eff = (evidence_samples(((record.force - f0) / f_scale)[withheld]),
                 None if record.meas_disp is None else
                 evidence_samples(((record.meas_disp - d0) / d_scale)[withheld]))
        decided = decide(before, singles, pairs, families, policy, systematic_cal,
                         spec0.baseline, n_eff, sys_floor)
        noise_single = next((s for s in singles if s.name == "sensor_noise"), None)
        if (decided["effect"] in ("unexplained", "baseline_misfit") and noise_single is not None
                and noise_pct > policy.ordinary_noise_pct
                and decided["better_family"] is None
                and (noise_single.after["total_pct"] or 0.0)
                < (decided["gap_after_pct"] or raw_gap)):
            # the noise the calibration residual shows (coloured too) accounts for more of the
            # gap than the best candidate does
            decided = nothing_systematic(raw_gap, noise_pct, policy,
                                         "no candidate explains the withheld gap "
                                         f"{raw_gap:.2f} %", noise_named)
    decided.setdefault("gap_basis", "raw")  # the gaps and shrink the verdict quotes
    decided["confidence_words"] = confidence_words(decided, policy)
    verdict = Verdict.from_json(decided)
    if progress is not None:
        progress(total_fits, total_fits)
    # localisation
    sim_meas = None
    if record.meas_disp is not None:
        from sim_actuator.models.paths import drive

        law, vec = law_vector(spec0.law_kind, values0)
        sim_meas = drive(law, vec, record.meas_disp, 0.0, DZ_MAX)
    winner = next((s for s in [*singles, *pairs] if s.name == verdict.effect), None)
    refs = {f.name: gap(record, f.force, f.disp, withheld, white)
            for f in families if f.force is not None}

    def row(s: Scored) -> dict[str, object]:
        return s.as_dict(without_noise(s, record, withheld, white, sys_before,
                                       {} if not s.effects else refs))

    return Diagnosis(
        record={
            "source": record.source, "samples": n,
            "duration_s": float(record.time[-1] - record.time[0]), "dt_s": full.dt,
            "channels": (["meas_disp (no command)"] if record.no_command else ["cmd_disp"])
            + ["meas_force"] + (["meas_disp"] if record.meas_disp is not None else []),
            "command": not record.no_command,
            "notes": [*record.notes, *cal.record.notes[len(record.notes):], parts.note],
            "calibration": {"samples": [0, stop], "t_end": float(record.time[stop - 1])},
            "withheld": {"samples": [stop, n], "t_start": float(record.time[stop])},
        },
        baseline={
            "kind": opts.baseline, "requested": requested, "selection": selection,
            "fitted": opts.fit_baseline,
            "params": baseline_report(spec0.law_kind, values0),
            "std": dict(base_fit.std),
            "gap_calibration": gap_cal,
            "gap_withheld": before,
            "fit": {"converged": base_fit.ok, "evaluations": base_fit.evaluations},
        },
        noise_floor={
            "floor_pct": opts.noise_floor_pct, "force_noise_std": white[0],
            "disp_noise_std": white[1], "noise_only_gap_pct": noise_only,
            "claimed_force_noise_std": estimate.claim[0],
            "claimed_disp_noise_std": estimate.claim[1],
            "systematic_calibration_gap_pct": systematic_cal,
            "systematic_withheld_gap_pct": sys_before["total_pct"] or 0.0,
            "systematic_floor_pct": sys_floor,
            "noise_pct_of_peak": noise_pct,
            "ordinary_noise_pct": policy.ordinary_noise_pct,
        },
        localization=localise(record, f0, sim_meas, stop),
        effects=[row(s) for s in singles],
        pairs=[row(s) for s in sorted(pairs, key=lambda s: s.score, reverse=True)],
        families=[{**row(s), "role": s.role}
                  for s in sorted(families, key=lambda s: s.score, reverse=True)],
        verdict=verdict,
        not_identifiable=hidden,
        hidden=hidden_summary(record, opts.effects),
        seconds=time.perf_counter() - started,
        series=Series(record.time, record.cmd, record.meas_disp, record.force, f0, d0,
                      None if winner is None else winner.force,
                      None if winner is None else winner.disp, stop),
    )
