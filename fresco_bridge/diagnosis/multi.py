"""One device, one story: several records of one specimen diagnosed against one shared law.

Diagnosed one by one, four records of one device can tell four stories (the friction damper
BRFD: a gap on one earthquake record, an offset on a sine, pinching on another record) because
each record fits its own baseline and each baseline absorbs a different share of the same
physics. ``diagnose A B C --same-device`` therefore:

1. **Joint baseline.** The law is fitted once, on the calibration parts of all records together
   (each record's first ``calibration_fraction``, each run from the virgin state, each record's
   force residual normalised by its RMS force and by √N so every record weighs the same
   whatever its length); under ``auto`` the family is chosen by the same BIC rule as for one
   record (``baseline.select_family``) on the pooled residual. The withheld parts are never
   seen by this fit either.
2. **Joint candidates.** Each effect is fitted over all the calibration parts at once too: the
   law (and a specimen effect's own law parameters: pinching, degradation) shared, the
   parameters of an interface, gap or output effect (delay, gap, friction, offset...) one set
   per record, so a magnitude may differ between tests. Holding the law at the joint baseline
   instead would not do: a law fitted to records that all carry the effect has absorbed what it
   can of it, and the effect alone on top no longer shrinks anything.
3. **Consistent effects.** The single record's selection rule (``decision``), on the device:
   a joint candidate's evidence is its BIC on the withheld parts of the records above the
   noise floor, Σ_records Σ_channel n_eff · ln(gap²) + k · ln(Σ n_eff), with n_eff each
   record's effective withheld samples under the shared law (:func:`.scored.evidence_samples`)
   and k the parameters the records estimate (shared and per record, none at a bound). An
   effect *explains the device* when its BIC is below the shared law's (one effect may matter
   more in one test than in another: a pin gap is a larger share of a small-amplitude test);
   it is *consistent* when every record carries it (one of its per-record parameters more than
   three standard deviations from zero), else *partial*. They are ranked consistent first,
   then by their BIC; the first one is the device's story. Pinching and degradation on a law
   that is not Bouc-Wen are judged against the device's own law too; with a named law, when
   another family's shared law alone has a lower BIC than the shared law and than every
   effect, the story is ``baseline_misfit`` naming it (the single-record rules). Its
   parameters are listed per record with a flag saying whether they agree (within
   :data:`MAGNITUDE_SPREAD` of their median, or within three combined standard deviations).
4. **Departures.** Each record is then diagnosed on its own with the story's law and the story
   effect at that record's magnitude *held* (or the joint baseline, with no story): its verdict
   is what departs from the device's story in that test, and a ``baseline_misfit`` or
   ``unexplained`` there says the shared law misses it. (Pinching or degradation as the story on
   a law that is not Bouc-Wen cannot be held this way: the shared law alone is held then.)
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt
from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

from fresco_bridge.lawfit import (
    Solution,
    bounded_least_squares,
    difference_step,
    multi_start,
    parameter_std,
)
from fresco_bridge.numbers import pct

from .baseline import RESTARTS, SCOUT_EVALUATIONS, fit_baseline, select_family
from .fit import predict
from .load import DiagnosisInputError, Record
from .model import (
    AUTO,
    BASELINES,
    LIMIT_FORMS,
    NOT_BOUC_WEN,
    Context,
    baseline_report,
    effect_parameters,
    make_spec,
)
from .names import AUTO_FAMILIES
from .nocommand import hidden_effects
from .scored import at_bound, evidence_samples, information
from .scored import gap as _gap
from .verdict import Options, diagnose, stop_of

__all__ = ["MAGNITUDE_SPREAD", "SCHEMA", "diagnose_device", "fit_joint",
           "fit_joint_candidate", "summary_device"]

SCHEMA = "fresco-bridge/diagnosis-device/1"
MAGNITUDE_SPREAD = 0.25
"""An effect's parameter agrees across records when every value is within this share of
their median (or within three combined standard deviations of it)."""
AGREE_FLOOR = 0.01
"""A share of a parameter's range below which values count as equal (see ``_agree``)."""
NOT_EFFECTS = frozenset({"none", "baseline_misfit", "unexplained"})
Gaps = dict[str, float | None]
JOINT_CANDIDATE_EVALUATIONS = 30
"""As a single record's candidate fit (``verdict``): from the joint baseline, few steps."""
FloatArray = npt.NDArray[np.float64]


def _calibration(records: Sequence[Record], opts: Options) -> list[Context]:
    """Each record's calibration part, thinned for the fits as it would be alone (a shared,
    smaller budget left an earthquake record at 1 kHz with a window of its quiet start)."""
    return [Context.of(r.part(stop_of(r, opts)).thinned(opts.max_fit_samples))
            for r in records]


def fit_joint(kind: str, cals: Sequence[Context], given: Mapping[str, float] | None = None
              ) -> tuple[dict[str, float], float, int]:
    """(law values, mean over records of the mean squared normalised force residual, number
    of fitted parameters) of law ``kind`` fitted on all of ``cals`` at once (module doc)."""
    ref = max(cals, key=lambda c: c.record.size)
    spec = make_spec(ref, kind, [])
    names = [p.name for p in spec.params]
    lower = np.array([p.lo for p in spec.params])
    upper = np.array([p.hi for p in spec.params])
    specs = [make_spec(c, kind, []) for c in cals]
    weights = [1.0 / ((float(np.sqrt(np.mean(c.record.force**2))) or 1.0)
                      * math.sqrt(c.record.size)) for c in cals]

    def residual(x: np.ndarray) -> np.ndarray:
        values = dict(zip(names, (float(v) for v in x), strict=True))
        parts = []
        for s, c, w in zip(specs, cals, weights, strict=True):
            force, _disp = predict(s, c, values)
            r = w * (force - c.record.force)
            parts.append(np.where(np.isfinite(r), r, 1e3 * w))
        return np.concatenate(parts)

    def run(start: Mapping[str, float], evaluations: int) -> Solution:
        x0 = [start.get(n, p.init) for n, p in zip(names, spec.params, strict=True)]
        with threadpool_limits(1):
            return bounded_least_squares(residual, x0, lower, upper, scale="jac",
                                         max_nfev=evaluations, tolerance=1e-6)

    # the law fitted on the longest calibration part alone is a good start for all of them
    _s, alone = fit_baseline(kind, ref, dict(given or {}), {})
    starts = [alone.values, *({**alone.values, **extra} for extra in RESTARTS.get(kind, ()))]
    best = multi_start(run, starts, cost=lambda s: float(np.dot(s.residual, s.residual)),
                       resume=lambda s: dict(zip(names, (float(v) for v in s.x), strict=True)),
                       scout=SCOUT_EVALUATIONS, final=60)
    values = dict(zip(names, (float(v) for v in best.x), strict=True))
    return values, float(np.dot(best.residual, best.residual)) / len(cals), len(names)


@dataclass
class _Joint:
    """A joint candidate: per record its values, the stds of its own parameters, gaps."""

    effect: str
    own: list[str]
    """The per-record parameters (shared law parameters are not listed)."""
    values: list[dict[str, float]]
    std: list[dict[str, float]]
    before: list[float]
    after: list[float]
    after_gaps: list[Gaps]
    """Each record's withheld gap per channel (``scored.gap``), for the evidence."""
    n_params: int
    """Parameters a single record's candidate would have: shared effect ones plus own."""
    bounds: dict[str, tuple[float, float]]
    """(lower, upper) of every parameter (the first record's context: the flags' tolerance)."""
    shared_effect: list[str]
    """The effect's own parameters shared by the records (pinching's, degradation's)."""

    def at_bound(self, name: str, side: str, i: int) -> bool:
        """Record ``i``'s ``name`` at its ``side`` bound (:func:`.scored.at_bound`)."""
        return at_bound(self.values[i][name], *self.bounds[name], side)

    def n_free(self, active: Sequence[int]) -> int:
        """The parameters the records in ``active`` estimate: the shared effect parameters and
        each record's own, none at a bound (:attr:`.scored.Scored.free`, on the device)."""
        def free(name: str, i: int) -> bool:
            hi = self.bounds[name][1]
            return not (self.at_bound(name, "lower", i)
                        or (math.isfinite(hi) and self.at_bound(name, "upper", i)))
        shared = [n for n in self.shared_effect if free(n, active[0])] if active else []
        return len(shared) + sum(free(n, i) for i in active for n in self.own)

    def shrink(self, i: int) -> float:
        b, a = self.before[i], self.after[i]
        return 100.0 * (1.0 - a / b) if b > 0.0 and math.isfinite(a) else -math.inf


def _jacobian(residual: Callable[..., list[Any]], x: FloatArray,
              lower: FloatArray, upper: FloatArray, owner: list[int]) -> FloatArray:
    """Forward differences; a per-record column (``owner[j] >= 0``) drives its record only."""
    base = residual(x)
    sizes = [b.size for b in base]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    jac = np.zeros((int(offsets[-1]), x.size))
    for j in range(x.size):
        h = difference_step(float(x[j]), float(lower[j]), float(upper[j]))
        xj = x.copy()
        xj[j] += h
        parts = residual(xj, only=owner[j])
        for i, part in enumerate(parts):
            if part is not None:
                jac[offsets[i]:offsets[i + 1], j] = (part - base[i]) / h
    return jac


def fit_joint_candidate(kind: str, effect: str, cals: Sequence[Context],
                        fulls: Sequence[Context], law: Mapping[str, float],
                        withheld: Sequence[slice], before: Sequence[float]) -> _Joint:
    """``effect`` fitted over all of ``cals`` at once: role-``law`` parameters shared, the
    effect's others one set per record (module docstring); scored on each withheld part."""
    specs = [make_spec(c, kind, (effect,)) for c in cals]
    ref = specs[int(np.argmax([c.record.size for c in cals]))]
    shared = [p for p in ref.params if p.role == "law"]
    own = [p for p in ref.params if p.role not in ("law", "noise")]
    weights = [1.0 / ((float(np.sqrt(np.mean(c.record.force**2))) or 1.0)
                      * math.sqrt(c.record.size)) for c in cals]
    n = len(cals)
    lower = np.array([p.lo for p in shared] + [p.lo for s in specs for p in s.params
                                              if p.role not in ("law", "noise")])
    upper = np.array([p.hi for p in shared] + [p.hi for s in specs for p in s.params
                                              if p.role not in ("law", "noise")])
    owner = [-1] * len(shared) + [i for i in range(n) for _p in own]
    x0 = np.array([law.get(p.name, p.init) for p in shared]
                  + [p.init for s in specs for p in s.params if p.role not in ("law", "noise")])

    def values_of(x: FloatArray, i: int) -> dict[str, float]:
        out = dict(law)
        out.update({p.name: float(v) for p, v in zip(shared, x, strict=False)})
        k = len(shared) + i * len(own)
        out.update({p.name: float(x[k + j]) for j, p in enumerate(own)})
        return out

    def parts(x: FloatArray, only: int = -1) -> list[Any]:
        out: list[Any] = []
        for i, (spec, c, w) in enumerate(zip(specs, cals, weights, strict=True)):
            if only >= 0 and i != only:
                out.append(None)
                continue
            force, _d = predict(spec, c, values_of(x, i))
            r = w * (force - c.record.force)
            out.append(np.where(np.isfinite(r), r, 1e3 * w))
        return out

    with threadpool_limits(1):
        sol = bounded_least_squares(
            lambda x: np.concatenate(parts(x)), x0, lower, upper, scale="jac",
            max_nfev=JOINT_CANDIDATE_EVALUATIONS,
            jac=lambda x: _jacobian(parts, x, lower, upper, owner), tolerance=1e-5)
    sd = parameter_std(sol.residual, sol.jacobian)
    values, stds, after, after_gaps = [], [], [], []
    for i in range(n):
        v = values_of(sol.x, i)
        k = len(shared) + i * len(own)
        values.append({p.name: v[p.name] for p in [*shared, *own]})
        stds.append({p.name: float(sd[k + j]) for j, p in enumerate(own)}
                    | {p.name: float(sd[j]) for j, p in enumerate(shared)})
        force, disp = predict(specs[i], fulls[i], v)
        after_gaps.append(_gap(fulls[i].record, force, disp, withheld[i]))
        after.append(_total(after_gaps[-1]))
    effect_shared = [p for p in shared if p.name in {q.name for q in
                                                     effect_parameters(ref_ctx(cals))[effect]}]
    return _Joint(effect, [p.name for p in own], values, stds, list(before), after, after_gaps,
                  len(effect_shared) + len(own),
                  {p.name: (p.lo, p.hi) for p in [*shared, *own]},
                  [p.name for p in effect_shared])


def _better_family(alternatives: Mapping[str, tuple[list[Gaps], int]], before: Sequence[Gaps],
                   story_bic: float | None, evidence: Evidence, floor: float
                   ) -> tuple[str, float] | None:
    """(family, mean shrink %) when another family's shared law alone (``alternatives``: its
    gaps and how many law parameters it has beyond the device's) has a lower BIC on the
    withheld parts than the shared law and than the story's effect (the single-record rule,
    on the device)."""
    active = _active(before, floor)
    if not alternatives or not active:
        return None
    bic = {k: _device_bic(g, evidence, active, extra)
           for k, (g, extra) in alternatives.items()}
    family = min(bic, key=lambda k: bic[k])
    if bic[family] >= _device_bic(before, evidence, active, 0) or (
            story_bic is not None and story_bic <= bic[family]):
        return None

    def mean(gaps: Sequence[Gaps]) -> float:
        return sum(_total(gaps[i]) for i in active) / len(active)

    return family, 100.0 * (1.0 - mean(alternatives[family][0]) / mean(before))


Evidence = list[tuple[float, float | None]]
"""Each record's effective withheld samples per channel (force, displacement)."""


def _active(before: Sequence[Gaps], floor: float) -> list[int]:
    """The records whose withheld gap under the shared law is above the noise floor."""
    return [i for i, b in enumerate(before) if _total(b) >= floor]


def _device_bic(gaps: Sequence[Gaps], evidence: Evidence, active: Sequence[int],
                k: int) -> float:
    """The BIC of a prediction of the ``active`` records' withheld parts: each record's
    likelihood term (:func:`.scored.information` with no parameter) summed, plus k · ln of
    every channel's effective samples (module doc)."""
    total = sum(information(gaps[i], evidence[i], 0) for i in active)
    samples = sum(n for i in active for n in evidence[i] if n)
    return total + k * math.log(max(samples, 2.0))


def _evidence(kind: str, law: Mapping[str, float], cals: Sequence[Context],
              fulls: Sequence[Context], withheld: Sequence[slice]) -> Evidence:
    """Each record's effective withheld samples per channel under the shared law
    (:func:`.scored.evidence_samples` of its withheld residual)."""
    spec = make_spec(ref_ctx(cals), kind, [], law)
    out: Evidence = []
    for full, part in zip(fulls, withheld, strict=True):
        force, disp = predict(spec, full, law)
        rec = full.record
        out.append((evidence_samples((rec.force - force)[part]),
                    None if rec.meas_disp is None else
                    evidence_samples((rec.meas_disp - disp)[part])))
    return out


def _gaps(kind: str, law: Mapping[str, float], cals: Sequence[Context],
          fulls: Sequence[Context], withheld: Sequence[slice]) -> list[Gaps]:
    """Each record's withheld gap (NRMS % per channel, ``scored.gap``) under law ``kind``
    with values ``law``."""
    spec = make_spec(ref_ctx(cals), kind, [], law)
    out = []
    for full, part in zip(fulls, withheld, strict=True):
        force, disp = predict(spec, full, law)
        out.append(_gap(full.record, force, disp, part))
    return out


def _total(gaps: Gaps) -> float:
    """The withheld gap's total NRMS in % (``verdict``'s measure, one home)."""
    total = gaps["total_pct"]
    return math.inf if total is None else float(total)


def ref_ctx(cals: Sequence[Context]) -> Context:
    """The longest calibration part: whose scales bound the shared parameters."""
    return max(cals, key=lambda c: c.record.size)


def _agree(values: list[float], stds: list[float], span: float) -> bool:
    """Within :data:`MAGNITUDE_SPREAD` of the median (of :data:`AGREE_FLOOR` of the
    parameter's range for a median nearer zero: a rigid fixture's 0.0002 and 0.0015 mm of
    slip agree), or within three combined standard deviations."""
    median = float(np.median(values))
    scale = max(abs(median), AGREE_FLOOR * span) if math.isfinite(span) else abs(median)
    for v, s in zip(values, stds, strict=True):
        near = abs(v - median) <= MAGNITUDE_SPREAD * scale
        within = math.isfinite(s) and abs(v - median) <= 3.0 * math.sqrt(
            s * s + float(np.median(stds)) ** 2)
        if not (near or within):
            return False
    return True


def _present(j: _Joint, i: int) -> bool:
    """Whether record ``i`` carries the effect: one of its own parameters the record estimates
    (not at its lower bound, where its std is no measure) is more than three standard
    deviations from zero (an effect with shared parameters only: always)."""
    if not j.own:
        return True
    return any(not j.at_bound(n, "lower", i)
               and abs(j.values[i][n]) > 3.0 * j.std[i].get(n, math.inf) for n in j.own)


def _explaining(joints: Sequence[_Joint], sources: Sequence[str], floor: float,
                units: Mapping[str, str], device_before: Sequence[Gaps], evidence: Evidence
                ) -> list[dict[str, Any]]:
    """The joint candidates that explain the device (module docstring): the consistent ones
    (present in every record) first, then the partial ones, each by its BIC. A candidate
    measured from another family's baseline is judged against the device's own law too (a
    pinching that shrinks Bouc-Wen's gap but not steel02's is a family change, not an
    effect)."""
    active = _active(device_before, floor)
    if not active:
        return []
    base_bic = _device_bic(device_before, evidence, active, 0)
    out = []
    named = {j.effect for j in joints}
    for j in joints:
        if any(effect == j.effect and form in named and any(j.at_bound(param, side, i)
                                                             for i in active)
               for (effect, param, side), form in LIMIT_FORMS.items()):
            continue  # a rate law become Coulomb friction: the friction candidate says it
        shrinks = [j.shrink(i) for i in active]
        mean = sum(shrinks) / len(shrinks)
        bic = _device_bic(j.after_gaps, evidence, active, j.n_free(active))
        if bic >= base_bic:
            continue
        names = [*(k for k in j.values[0] if k not in j.own and k in j.std[0]
                   and k in units), *j.own]
        params = {}
        for name in names:
            values = [j.values[i][name] for i in active]
            stds = [j.std[i].get(name, math.nan) for i in active]
            lo, hi = j.bounds[name]
            params[name] = {"values": values, "std": stds, "unit": units.get(name, ""),
                            "shared": name not in j.own,
                            "agree": _agree(values, stds, hi - lo)}
        present = [_present(j, i) for i in active]
        out.append({"effect": j.effect, "consistent": all(present),
                    "present_in": [sources[i] for i, p in zip(active, present, strict=True)
                                   if p],
                    "absent_from": [sources[i] for i, p in zip(active, present, strict=True)
                                    if not p],
                    "mean_shrink_pct": mean, "shrink_pct": shrinks,
                    "delta_bic": bic - base_bic,
                    "records": [sources[i] for i in active], "params": params,
                    "magnitudes_agree": all(p["agree"] for p in params.values())})
    return sorted(out, key=lambda c: (c["consistent"], -c["delta_bic"]), reverse=True)


def diagnose_device(records: Sequence[Record], options: Options | None = None) -> dict[str, Any]:
    """Diagnose ``records`` of one device against one jointly fitted law (module docstring)."""
    opts = options or Options()
    if len(records) < 2:
        raise DiagnosisInputError("--same-device needs two or more records of the device")
    if opts.baseline not in (AUTO, *BASELINES):
        raise DiagnosisInputError(f"unknown baseline {opts.baseline!r}; choose {AUTO} or "
                                  f"{', '.join(BASELINES)}")
    started = time.perf_counter()
    cals = _calibration(records, opts)
    fulls = [Context.of(r) for r in records]
    withheld = [slice(stop_of(r, opts), r.size) for r in records]
    selection = None
    if not opts.fit_baseline:
        kind, law = opts.baseline, dict(opts.baseline_params)
    else:
        families = AUTO_FAMILIES if opts.baseline == AUTO else (opts.baseline,)
        fitted = {k: fit_joint(k, cals, opts.baseline_params) for k in families}
        kind = families[0]
        if opts.baseline == AUTO:
            kind, selection = select_family(
                {k: (n, mse) for k, (_v, mse, n) in fitted.items()},
                sum(c.record.size for c in cals), families)
            selection["criterion"] = ("BIC on the calibration force residual, all records "
                                      "together")
        law = fitted[kind][0]
    before_gaps = _gaps(kind, law, cals, fulls, withheld)
    before = [_total(g) for g in before_gaps]
    evidence = _evidence(kind, law, cals, fulls, withheld)
    # other families' gaps and extra law parameters (a named baseline)
    alternatives: dict[str, tuple[list[Gaps], int]] = {}
    if opts.fit_baseline and opts.baseline != AUTO:
        n_own = len(make_spec(ref_ctx(cals), kind, []).params)
        for k in AUTO_FAMILIES:
            if k != kind:
                values, _mse, n_k = fit_joint(k, cals)
                alternatives[k] = (_gaps(k, values, cals, fulls, withheld),
                                   max(n_k - n_own, 0))
    family_before = before  # what a candidate driving Bouc-Wen is measured from
    if kind in NOT_BOUC_WEN and {"pinching", "degradation"} & set(opts.effects):
        family_before = [_total(g) for g in (
            alternatives["bouc-wen"][0] if "bouc-wen" in alternatives else _gaps(
                "bouc-wen", (fitted["bouc-wen"][0] if opts.fit_baseline
                             and "bouc-wen" in fitted else fit_joint("bouc-wen", cals)[0]),
                cals, fulls, withheld))]
    no_command = any(r.no_command for r in records)
    hidden = {e for r in records for e in hidden_effects(r, opts.effects)}
    joint_effects = [e for e in opts.effects if e != "sensor_noise" and e not in hidden]
    joints = [fit_joint_candidate(kind, e, cals, fulls, law, withheld,
                                  family_before if e in ("pinching", "degradation")
                                  else before)
              for e in joint_effects]
    units = {p.name: p.unit for ps in effect_parameters(ref_ctx(cals)).values() for p in ps}
    sources = [r.source for r in records]
    explaining = _explaining(joints, sources, opts.noise_floor_pct, units, before_gaps,
                             evidence)
    consistent = [c for c in explaining if c["consistent"]]
    top = explaining[0] if explaining else None
    story_joint = next((j for j in joints if top is not None and j.effect == top["effect"]),
                       None)
    results = []
    for i, r in enumerate(records):
        held_values = dict(law)
        if story_joint is not None and not (kind in NOT_BOUC_WEN and story_joint.effect in
                                            ("pinching", "degradation")):
            held_values = {**law, **story_joint.values[i]}
        held = replace(opts, baseline=kind, baseline_params=held_values, fit_baseline=False)
        results.append(diagnose(r, held))
    names = {c["effect"] for c in consistent}
    per_record = []
    for i, result in enumerate(results):
        verdict = result.verdict.effect
        own = set(verdict.split("+")) - NOT_EFFECTS
        if top is not None and not top["consistent"] and sources[i] in top["present_in"]:
            own.add(top["effect"])  # the story's effect, held here, is this test's own
        departures = sorted(own - names) + ([verdict] if verdict in ("baseline_misfit",
                                                                      "unexplained") else [])
        per_record.append({"source": sources[i], "gap_shared_law_pct": before[i],
                           "verdict": verdict, "confidence": result.verdict.confidence,
                           "confidence_words": result.verdict.confidence_words,
                           "gap_before_pct": result.verdict.gap_before_pct,
                           "gap_after_pct": result.verdict.gap_after_pct,
                           "departures": departures})
    story_bic = None if top is None else top["delta_bic"] + _device_bic(
        before_gaps, evidence, _active(before_gaps, opts.noise_floor_pct), 0)
    story: dict[str, Any]
    if all(b < opts.noise_floor_pct for b in before):
        story = {"effect": "none", "explanation": "every record is within the noise floor of "
                                                  "the shared law"}
    elif (better := _better_family(alternatives, before_gaps, story_bic, evidence,
                                   opts.noise_floor_pct)) is not None:
        family, shrink = better
        story = {"effect": "baseline_misfit", "better_family": family,
                 "explanation": f"only a change of law family closes the gaps: one shared "
                                f"{family} law shrinks them by {shrink:.1f} % on average, its "
                                f"withheld evidence (BIC) better than any effect's on the "
                                f"{kind} law"
                                + ("" if top is None else f" (best: {top['effect']}, "
                                   f"{top['mean_shrink_pct']:.1f} %)")}
    elif top is not None and top["consistent"]:
        story = {"effect": top["effect"], "consistent": True,
                 "magnitudes_agree": top["magnitudes_agree"],
                 "explanation": f"{top['effect']}, present in every record, shrinks their "
                                f"withheld gaps by {top['mean_shrink_pct']:.1f} % on average "
                                f"({_shrinks(top)}) with one shared {kind} law"
                                + ("" if top["magnitudes_agree"] else
                                   "; its magnitudes differ between records")}
    elif top is not None:
        story = {"effect": top["effect"], "consistent": False,
                 "magnitudes_agree": top["magnitudes_agree"],
                 "explanation": f"{top['effect']} with one shared {kind} law shrinks the "
                                f"withheld gaps by {top['mean_shrink_pct']:.1f} % on average "
                                f"({_shrinks(top)}), but only "
                                f"{', '.join(top['present_in'])} carry it (absent from "
                                f"{', '.join(top['absent_from'])}): a departure of those "
                                "records, not of the device"}
    else:
        story = {"effect": "no_consistent_effect",
                 "explanation": "no candidate's withheld evidence (BIC over the records) "
                                f"beats the one shared {kind} law's: each record's verdict "
                                "is its own departure"}
    return {
        "schema": SCHEMA,
        "records": sources,
        "baseline": {"kind": kind, "requested": opts.baseline, "selection": selection,
                     "fitted": opts.fit_baseline, "params": baseline_report(kind, law),
                     "calibration_samples": [c.record.size for c in cals],
                     "gap_withheld_pct": before},
        "story": story,
        "consistent": consistent,
        "partial": [c for c in explaining if not c["consistent"]],
        "candidates": [{"effect": j.effect, "shrink_pct": [j.shrink(i) for i in
                                                           range(len(records))],
                        "n_params": j.n_params, "values": j.values, "std": j.std}
                       for j in joints],
        "per_record": per_record,
        "not_identifiable": sorted(hidden) if no_command else [],
        "results": results,
        "seconds": time.perf_counter() - started,
    }


def _shrinks(c: Mapping[str, Any]) -> str:
    return " / ".join(f"{x:.0f}" for x in c["shrink_pct"]) + " %"


def summary_device(doc: dict[str, Any]) -> str:
    """The terminal summary of a ``--same-device`` diagnosis."""
    base = doc["baseline"]
    lines = [f"device    {len(doc['records'])} records, one shared {base['kind']} law: "
             + ", ".join(f"{k} {v:.4g}" for k, v in base["params"].items())]
    if base["selection"] is not None:
        lines.append(f"          chosen by auto (BIC, all calibration parts): "
                     f"{base['selection']['reason']}")
    story = doc["story"]
    lines.append(f"STORY     {story['effect']}: {story['explanation']}")
    for c in [*doc["consistent"], *doc["partial"]]:
        lines.append(f"  {'consistent' if c['consistent'] else 'partial':<10} {c['effect']:<20} "
                     f"mean shrink {c['mean_shrink_pct']:.1f} % ({_shrinks(c)})"
                     + ("" if c["magnitudes_agree"] else "  (magnitudes differ)")
                     + ("" if c["consistent"] else
                        f"  absent from {', '.join(c['absent_from'])}"))
        for name, p in c["params"].items():
            lines.append(f"    {name}: " + ", ".join(
                f"{v:.4g}" + ("" if not math.isfinite(s) else f" ± {s:.2g}")
                for v, s in zip(p["values"], p["std"], strict=True)) + f" {p['unit']}")
    lines.append("per record (verdict against the shared law; departures):")
    for p in doc["per_record"]:
        lines.append(f"  {p['source']}: {p['verdict']} (confidence {p['confidence']:.2f}, "
                     f"{p['confidence_words']}), gap "
                     f"{pct(p['gap_before_pct'])} → {pct(p['gap_after_pct'])}; departures: "
                     + (", ".join(p["departures"]) or "none"))
    hidden = {line for r in doc["results"] for line in r.hidden}
    if hidden:
        lines.append("hidden    no command channel in some records: " + "; ".join(sorted(hidden)))
    lines.append(f"time      {doc['seconds']:.1f} s")
    return "\n".join(lines)
