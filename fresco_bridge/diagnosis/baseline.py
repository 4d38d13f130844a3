"""The baseline law: fitted on the calibration part, or chosen there among the law families.

A diagnosis measures the gap against a law that can represent the specimen; with the wrong
family (a Bouc-Wen law for a steel coupon with Bauschinger-shaped reversals) the gap of a
record with no effect at all is the family's misfit, and every verdict after it is about that.
``--baseline auto`` (the default) therefore fits each family of :data:`AUTO_FAMILIES` on the
calibration part — never the withheld part — and keeps the one with the lowest Bayesian
information criterion on the force residual,

    BIC = N · ln(mean r²) + k · ln(N),

k the number of fitted law parameters, r the force residual over the RMS measured force and N
the calibration samples the fits use. The residual's autocorrelation is deliberately not
discounted (N_eff = N (1 − ρ)/(1 + ρ)): the correlated part of a baseline's residual is the
misfit being compared, not noise — with an effect in the record (pinching, a gap) ρ reaches
0.98-0.99 and the discounted N_eff of 10-20 samples let the 3-parameter bilinear win over a
Bouc-Wen law that fitted clearly better (BENCHMARKS.md, "Diagnosis"). Families within
:data:`BIC_EVIDENCE` of the lowest are not distinguished by the data: the simplest of them
(fewest parameters, then the order of :data:`AUTO_FAMILIES`) is kept.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fresco_bridge.lawfit import multi_start

from .fit import Fit, fit_spec, predict
from .model import Context, Spec, make_spec
from .names import AUTO_FAMILIES

__all__ = ["BIC_EVIDENCE", "RESTARTS", "Baseline", "choose_baseline", "fit_baseline",
           "select_family"]

RESTARTS: Mapping[str, tuple[dict[str, float], ...]] = {
    "bouc-wen": ({"n": 1.2, "beta_share": 0.5}, {"n": 4.0, "beta_share": 0.8}),
    "bwbn": ({"n": 1.2, "beta_share": 0.5}, {"n": 4.0, "beta_share": 0.8}),
    "menegotto-pinto": ({"R0": 6.0, "cR1": 0.5}, {"R0": 30.0, "cR1": 0.95}),
    "steel02": ({"R0": 6.0, "cR1": 0.5}, {"R0": 30.0, "cR1": 0.95, "a1": 0.1}),
    "isotropic-bilinear": ({"q_iso": 0.5, "p_sat": 3.0}, {"q_iso": 1.5, "p_sat": 50.0}),
}
"""Further starts of a baseline fit besides the parameters' own (the best calibration cost
wins): a smooth and a sharp transition, so a record far from the default shape is not left in
a local minimum."""
SCOUT_EVALUATIONS = 15
"""Evaluations each start gets before the best one is fitted to convergence."""
BIC_EVIDENCE = 2.0
"""A BIC difference below this is "not worth more than a bare mention" (Kass & Raftery 1995)."""


@dataclass(frozen=True)
class Baseline:
    """The fitted baseline and, under ``auto``, how it was chosen."""

    spec: Spec
    fit: Fit
    selection: dict[str, Any] | None


def fit_baseline(kind: str, cal: Context, given: Mapping[str, float],
                 fixed: Mapping[str, float]) -> tuple[Spec, Fit]:
    """Fit law ``kind`` on ``cal`` (the calibration part): every start scouted, the best one
    fitted to convergence. ``given`` are start values, ``fixed`` values held."""
    spec = make_spec(cal, kind, [], fixed)
    starts = [dict(given)]
    if not fixed:
        starts += [{**given, **extra} for extra in RESTARTS.get(kind, ())]
    return spec, multi_start(lambda start, n: fit_spec(spec, cal, start, max_evaluations=n),
                             starts, cost=lambda fit: fit.cost, resume=lambda fit: fit.values,
                             scout=SCOUT_EVALUATIONS, final=60)


def choose_baseline(cal: Context, families: Sequence[str] = AUTO_FAMILIES) -> Baseline:
    """Fit every family on ``cal`` and keep the one the criterion prefers (module docstring)."""
    rec = cal.record
    scale = float(np.sqrt(np.mean(rec.force**2))) or 1.0
    fitted: dict[str, tuple[Spec, Fit]] = {}
    mse: dict[str, float] = {}
    for kind in families:
        spec, fit = fit_baseline(kind, cal, {}, {})
        force, _disp = predict(spec, cal, fit.values)
        r = (force - rec.force) / scale
        r = np.where(np.isfinite(r), r, 1e3)
        fitted[kind] = (spec, fit)
        mse[kind] = float(np.mean(r * r))
    chosen, selection = select_family(
        {kind: (len(spec.params), mse[kind]) for kind, (spec, _f) in fitted.items()}, rec.size,
        families)
    spec, fit = fitted[chosen]
    return Baseline(spec, fit, selection)


def select_family(fitted: Mapping[str, tuple[int, float]], n: int,
                  families: Sequence[str]) -> tuple[str, dict[str, Any]]:
    """The family the criterion keeps from ``fitted`` ({kind: (parameters, mean squared
    normalised force residual)} over ``n`` samples) and the ``baseline.selection`` record:
    lowest BIC, the simplest within :data:`BIC_EVIDENCE` (module docstring)."""
    mse = {kind: m for kind, (_k, m) in fitted.items()}
    bic = {kind: n * math.log(max(mse[kind], 1e-300)) + fitted[kind][0] * math.log(n)
           for kind in fitted}
    lowest = min(bic.values())
    plausible = [kind for kind in families if bic[kind] - lowest < BIC_EVIDENCE]
    chosen = min(plausible, key=lambda kind: (fitted[kind][0], families.index(kind)))
    others = sorted((k for k in families if k != chosen), key=lambda k: bic[k])
    reason = (f"{chosen}: calibration force NRMS {100.0 * math.sqrt(mse[chosen]):.2f} % with "
              f"{fitted[chosen][0]} parameters; "
              + "; ".join(f"{k} {100.0 * math.sqrt(mse[k]):.2f} % "
                          f"(BIC {bic[k] - bic[chosen]:+.0f})" for k in others))
    return chosen, {
        "chosen": chosen,
        "criterion": "BIC on the calibration force residual",
        "samples": n,
        "families": {kind: {"n_params": fitted[kind][0],
                            "calibration_force_nrms_pct": 100.0 * math.sqrt(mse[kind]),
                            "bic": bic[kind]} for kind in families},
        "reason": reason,
    }
