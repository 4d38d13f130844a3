"""The candidates: the baseline plus one effect (or two), each refitted on the calibration part
and scored on the withheld part; and the other law families, scored alike.

Each candidate's parameters start where the interface indicators say something directly
(:func:`effect_start`), its shrink is measured from the gap it is compared with (the baseline's,
or the best baseline of the law family it drives: :func:`fit_families`), and on a long record it
is fitted in two stages (:data:`STAGED_JOINT_EVALUATIONS`). Fitting only: which candidate the
record names is ``decision``'s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
import numpy.typing as npt

from .. import indicators as ind
from .baseline import fit_baseline
from .fit import Fit, fit_spec, predict
from .load import Record
from .model import AUTO, Context, Param, held_sign, make_spec
from .names import AUTO_FAMILIES
from .options import Options
from .scored import Scored, gap
from .split import stop_of

__all__ = ["HOPELESS_COST_SHARE", "RESTARTED", "RESTART_IF_COST_ABOVE",
           "STAGED_JOINT_EVALUATIONS", "TOP_FOR_PAIRS", "effect_start", "fit_candidate",
           "fit_families", "noise_candidate", "reference_family", "with_noise"]

FloatArray = npt.NDArray[np.float64]

TOP_FOR_PAIRS = 3
"""Pairs are fitted among the best this many singles (by the systematic gap)."""
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


def effect_start(effect: str, cal: Context) -> dict[str, float]:
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


def fit_families(record: Record, cal: Context, full: Context, opts: Options, requested: str,
                 fixed: Mapping[str, float], values0: Mapping[str, float], law_kind: str,
                 effects: Sequence[str], before: dict[str, float | None],
                 withheld: slice) -> list[Scored]:
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
            reference = reference_family(spec.law_kind)
            if reference not in kinds:
                kinds[reference] = "reference"
    out: list[Scored] = []
    for kind, role in kinds.items():
        held = {k: v for k, v in fixed.items()
                if k in {p.name for p in make_spec(cal, kind, []).params}}
        given = {k: values0[k] for k in ("k0", "fy", "alpha") if k in values0}
        spec, fit = fit_baseline(kind, cal, {k: v for k, v in given.items() if k not in held},
                                 held)
        force, disp = predict(spec, full, fit.values)
        out.append(Scored(kind, (), [], fit, {}, {}, before, gap(record, force, disp, withheld),
                           force, disp, extra_law_params=len(spec.params) - n_base, role=role))
    return out


def reference_family(law_kind: str) -> str:
    """The baseline family an effect candidate driving ``law_kind`` is compared with: BWBN
    without pinching and degradation is Bouc-Wen."""
    return "bouc-wen" if law_kind == "bwbn" else law_kind


def fit_candidate(record: Record, cal: Context, full: Context, opts: Options,
                  fixed: Mapping[str, float], effects: tuple[str, ...],
                  start: Mapping[str, float], before: dict[str, float | None],
                  withheld: slice, base_cost: float,
                  references: Mapping[str, Scored] | None = None) -> Scored:
    """The baseline plus ``effects`` fitted on the calibration part (``cal``) from ``start`` and
    scored on the ``withheld`` part of the whole record (``full``); ``references``: the best
    baselines of other families, by name, that a candidate driving one is measured from."""
    spec = make_spec(cal, opts.baseline, effects, fixed)
    law_names = {p.name for p in make_spec(cal, opts.baseline, [], fixed).params}
    params = [p for p in spec.params if p.name not in law_names and p.role != "noise"]
    compared_with = None
    reference = (references or {}).get(reference_family(spec.law_kind))
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
    after = gap(record, force, disp, withheld)
    return Scored("+".join(sorted(effects)), effects, params, result,
                  {p.name: result.values[p.name] for p in params},
                  {p.name: result.std.get(p.name, math.nan) for p in params},
                  before, after, force, disp, compared_with,
                  extra_law_params=0 if compared_with is None or reference is None
                  else reference.extra_law_params)


def noise_candidate(record: Record, params: Sequence[Param], claim: tuple[float, float],
                    stop: int, base: tuple[FloatArray, FloatArray],
                    before: dict[str, float | None], withheld: slice) -> Scored:
    """``sensor_noise``: the baseline's prediction, claiming ``claim`` (force, displacement std
    from the calibration residual, ``noise.estimate_noise``) of the withheld gap's variance;
    its std is a sample std's (N − 1 degrees of freedom)."""
    claim_f, claim_d = claim
    kept = list(params) if record.meas_disp is not None else list(params)[:1]
    values = {"force_noise_std": claim_f, "disp_noise_std": claim_d}
    stds = {"force_noise_std": claim_f / math.sqrt(2.0 * (stop - 1)),
            "disp_noise_std": claim_d / math.sqrt(2.0 * stop)}
    after = gap(record, base[0], base[1], withheld, claim)
    return Scored("sensor_noise", ("sensor_noise",), kept, None, values, stds, before, after,
                  base[0], base[1])


def with_noise(a: Scored, noise: Scored, record: Record, withheld: slice,
               claim: tuple[float, float]) -> Scored:
    """The pair of ``a`` and ``sensor_noise``: ``a``'s prediction, claiming the noise."""
    members = tuple(sorted((*a.effects, "sensor_noise")))
    assert a.force is not None
    return Scored("+".join(members), members, [*a.params, *noise.params], a.fit,
                  {**a.values, **noise.values}, {**a.std, **noise.std}, a.before,
                  gap(record, a.force, a.disp, withheld, claim), a.force, a.disp,
                  a.compared_with)
