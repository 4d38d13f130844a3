"""The decision: which story the record tells, how sure it is, and what it says.

One selection rule (docs/diagnosis.md, "The selection rule"): every candidate (the baseline
plus one effect or two, or another law family) is fitted on the calibration part and judged by
its Bayesian information criterion on the withheld part,

    BIC = Σ_channel n_eff · ln(gap²) + k · ln(Σ_channel n_eff),

with ``gap`` its withheld NRMS gap per channel, ``n_eff`` the withheld samples' effective count
(:func:`.scored.evidence_samples`) and ``k`` the parameters the record actually estimates
(:attr:`.scored.Scored.n_free`: a parameter at a bound is not estimated, the form at that bound
is a simpler candidate's). The lowest BIC wins when it is below the baseline's; the weights
exp(−ΔBIC/2), normalised, are the confidence. A runner-up within
:attr:`.options.Policy.two_story_delta` that tells another story is named beside the winner
(the verdict's ``stories``), with the measurement that would separate them. Pure: no fitting.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from .model import LIMIT_FORMS
from .options import Policy
from .scored import Scored, at_bound, information
from .scored import finite as _finite

__all__ = ["SEPARATED_BY", "confidence_words", "decide", "explained", "nothing_systematic",
           "pct_text"]

SEPARATED_BY: dict[frozenset[str], str] = {
    frozenset({"friction", "rate_dependence"}):
        "the record's velocities do not separate them: cycles of one amplitude at two rates "
        "(friction's force does not change with velocity, a rate law's does)",
    frozenset({"backlash", "pinching"}):
        "a gap and a slipping pinch look alike at the loop's centre: the relative travel of the "
        "connection (a displacement transducer across it) or cycles of small amplitude",
    frozenset({"actuator_delay", "actuator_amplitude"}):
        "the command's frequencies do not separate a lag from a gain: a slow cycle and a fast "
        "one of the same amplitude",
    frozenset({"actuator_delay", "actuator_undershoot"}):
        "a lag and a short stop look alike on a smooth command: a stepped command with holds",
    frozenset({"actuator_amplitude", "actuator_undershoot"}):
        "a gain and a short stop look alike at one amplitude: cycles at two amplitudes",
    frozenset({"degradation", "pinching"}):
        "cycles repeated at one amplitude (degradation grows with them, pinching does not)",
    frozenset({"sensor_bias", "friction"}):
        "a record that starts and ends at rest (an offset stays, friction does not)",
}
"""What measurement separates two stories the record cannot (by the pair of effects)."""
GENERIC_SEPARATION = ("a longer record, or a command that visits more amplitudes and rates, "
                      "would separate them")


def nothing_systematic(gap: float, noise_pct: float, policy: Policy, reason: str,
                       noise_named: bool = True) -> dict[str, Any]:
    """The verdict when no systematic gap is heard: ``sensor_noise`` if the channels' noise is
    above what a lab ordinarily has (:attr:`.options.Policy.ordinary_noise_pct`), else
    ``none``: noise at the ordinary level is a property of the record, not an effect."""
    ordinary = policy.ordinary_noise_pct
    noisy = noise_pct > ordinary and noise_named
    effect = "sensor_noise" if noisy else "none"
    confidence = 1.0 - ordinary / noise_pct if noisy else 1.0 - noise_pct / ordinary
    return {"effect": effect, "confidence": float(min(max(confidence, 0.0), 1.0)),
            "shrink_pct": 0.0, "gap_before_pct": gap, "gap_after_pct": gap,
            "runner_up": None, "not_separated_from": None, "flags": {}, "better_family": None,
            "stories": [], "separated_by": None,
            "explanation": f"{reason}; the noise is {noise_pct:.2f} % of the channels' peak, "
                           + ("above" if noisy else "within") + f" the {ordinary:g} % a lab's "
                           "load cell and LVDT ordinarily carry"}


def decide(before: dict[str, float | None], singles: list[Scored], pairs: list[Scored],
           families: list[Scored], policy: Policy, systematic_cal: float, law: str,
           n_eff: tuple[float, float | None],
           resolved: float | None = None) -> dict[str, Any]:
    """The verdict on a gap above the floor (module doc: the rule); ``resolved`` is the
    smallest systematic gap the record resolves (:func:`.scored.systematic_floor`; at least
    the policy's floor, which it is when not given)."""
    gap = before["total_pct"] or 0.0
    floor = policy.noise_floor_pct
    resolved = floor if resolved is None else max(resolved, floor)
    base_bic = information(before, n_eff, 0)
    # heard: a candidate that leaves less of the withheld gap than the baseline (better than the
    # sim), changes its prediction by at least the floor (big enough to hear) and accounts for
    # a part of the gap the record resolves (explained)
    heard = [s for s in [*singles, *[p for p in pairs if not _collapsed(p, singles)],
                         *families]
             if s.force is not None and "sensor_noise" not in s.effects
             and s.after["total_pct"] is not None and s.after["total_pct"] < gap
             and (not s.effects or (s.size >= floor and explained(s) >= resolved))]
    bic = {id(s): information(s.after, n_eff, s.n_free) for s in heard}
    ranked = sorted(heard, key=lambda s: bic[id(s)])
    best = ranked[0] if ranked else None
    if best is None or bic[id(best)] >= base_bic:
        return _no_candidate(best, gap, base_bic, bic, systematic_cal, floor, law, n_eff)
    low = min(base_bic, bic[id(best)])
    total = math.exp(-(base_bic - low) / 2.0) + sum(math.exp(-(bic[id(s)] - low) / 2.0)
                                                  for s in ranked)

    def weight(s: Scored) -> float:
        return math.exp(-(bic[id(s)] - low) / 2.0) / total

    if best.role != "candidate":
        after = best.after["total_pct"] or 0.0
        effect_best = next((s for s in ranked if s.role == "candidate"), None)
        return {"effect": "baseline_misfit", "confidence": weight(best),
                "shrink_pct": _finite(best.shrink), "gap_before_pct": gap,
                "gap_after_pct": after,
                "runner_up": None if effect_best is None else effect_best.name,
                "not_separated_from": None, "flags": {}, "better_family": best.name,
                "stories": [], "separated_by": None,
                "explanation": f"only a change of law family closes the gap: a {best.name} "
                               f"baseline shrinks the withheld gap from {gap:.2f} % to "
                               f"{after:.2f} % (BIC {bic[id(best)] - base_bic:+.1f} against "
                               f"the {law} baseline), more than any effect on the {law} law"}
    limit = _limit_form(best, ranked)
    if limit is not None:
        # the winner sits where its form is another candidate's (a rate law at its smallest
        # exponent is Coulomb friction): one story, told by the candidate that states the form
        # and weighed with the evidence of both
        limit_text = (f"{best.name} fitted at the bound where it is {limit.name} "
                      f"({', '.join(sorted(set(best.values) - best.free))}), leaving "
                      f"{pct_text(best.after['total_pct'])}: named {limit.name}; ")
        merged = weight(best) + weight(limit)
        told = [set(best.effects), set(limit.effects)]
        ranked = [limit, *[s for s in ranked if s is not limit and s is not best]]
        best = limit
    else:
        limit_text, merged, told = "", 0.0, [set(best.effects)]
    rivals = [s for s in ranked[1:] if s.role == "candidate"
              and not any(set(s.effects) >= t or set(s.effects) <= t for t in told)]
    runner = rivals[0] if rivals else None
    after = best.after["total_pct"] or 0.0
    flags = best.flags
    confidence = (merged or weight(best)) * policy.flag_factor ** len(flags)
    text = limit_text + (f"{best.name} shrinks the withheld gap from {gap:.2f} % to {after:.2f} % "
            f"(BIC {bic[id(best)] - base_bic:+.1f} against the baseline, {best.n_free} "
            f"parameter{'s' if best.n_free != 1 else ''} estimated, "
            f"{sum(x for x in n_eff if x):.0f} effective withheld samples)"
            + ("" if best.compared_with is None else
               f" (on the {best.fit.spec.law_kind if best.fit else law} law; measured from the "
               f"{best.compared_with}, which leaves {pct_text(best.before['total_pct'])})"))
    stories: list[dict[str, Any]] = []
    separated_by = None
    if runner is not None:
        delta = bic[id(runner)] - bic[id(best)]
        text += (f"; the runner-up {runner.name} leaves {pct_text(runner.after['total_pct'])} "
                 f"(ΔBIC {delta:.1f})")
        if delta <= policy.two_story_delta:
            pair_total = weight(best) + weight(runner)
            stories = [{"effect": s.name, "weight": weight(s) / pair_total,
                        "delta_bic": bic[id(s)] - bic[id(best)]} for s in (best, runner)]
            separated_by = SEPARATED_BY.get(frozenset((best.name, runner.name)),
                                            GENERIC_SEPARATION)
            text += (f"; two stories fit: {best.name} or {runner.name}, "
                     f"{stories[0]['weight']:.2f} / {stories[1]['weight']:.2f}: "
                     + separated_by)
    if flags:
        text += "; not measured by the record: " + ", ".join(
            f"{k} {v}" for k, v in flags.items())
    return {
        "effect": best.name, "confidence": confidence,
        "shrink_pct": _finite(best.shrink), "gap_before_pct": gap, "gap_after_pct": after,
        "runner_up": None if runner is None else runner.name,
        "not_separated_from": runner.name if stories and runner is not None else None,
        "flags": flags, "better_family": None, "stories": stories,
        "separated_by": separated_by, "explanation": text,
    }


def explained(s: Scored) -> float:
    """The part of the withheld gap a candidate accounts for, √(before² − after²) (NRMS %):
    the white noise is the same samples in both and cancels from the difference, so this is
    the systematic part the effect closes. An effect is heard only when it is at least what the
    record resolves (the systematic floor): a law absorbing 1.6 % of a misfit it does not
    model closes less than the noise lets the record tell from nothing."""
    b, a = s.before["total_pct"], s.after["total_pct"]
    if b is None or a is None or not math.isfinite(a) or not math.isfinite(b):
        return 0.0
    return math.sqrt(max(b * b - a * a, 0.0))


def _limit_form(best: Scored, ranked: Sequence[Scored]) -> Scored | None:
    """The candidate whose form ``best`` takes at a bound it sits at (``model.LIMIT_FORMS``),
    when that candidate was heard too."""
    if len(best.effects) != 1:
        return None
    params = {p.name: p for p in best.params}
    for (effect, name, side), form in LIMIT_FORMS.items():
        p = params.get(name)
        if effect == best.name and p is not None and name in best.values and at_bound(
                best.values[name], p.lo, p.hi, side):
            return next((s for s in ranked if s.name == form), None)
    return None


def _collapsed(pair: Scored, singles: Sequence[Scored]) -> bool:
    """A pair one of whose members has no parameter the record estimates (all at a bound: the
    gap is zero, the delay is zero) is the other member's model, not a second story."""
    for member in pair.effects:
        single = next((s for s in singles if s.effects == (member,)), None)
        names = set() if single is None else {p.name for p in single.params
                                              if p.role != "noise"}
        if names and not names & pair.free:
            return True
    return False


def _no_candidate(best: Scored | None, gap: float, base_bic: float, bic: dict[int, float],
                  systematic_cal: float, floor: float, law: str,
                  n_eff: tuple[float, float | None]) -> dict[str, Any]:
    """No candidate's evidence beats the baseline's: the law family is the first suspect when
    the baseline misses its own calibration part beyond the noise, else the gap is
    unexplained."""
    none_of_mine = ("no candidate changes the prediction by the floor" if best is None else
                    f"no candidate's withheld evidence beats the baseline's (best: {best.name}, "
                    f"BIC {bic[id(best)] - base_bic:+.1f}, leaving "
                    f"{pct_text(best.after['total_pct'])})")
    common: dict[str, Any] = {
        "confidence": 0.0, "shrink_pct": None if best is None else _finite(best.shrink),
        "gap_before_pct": gap, "gap_after_pct": None if best is None else
        best.after["total_pct"], "runner_up": None if best is None else best.name,
        "not_separated_from": None, "flags": {}, "better_family": None, "stories": [],
        "separated_by": None}
    if systematic_cal > floor:
        return {"effect": "baseline_misfit", **common,
                "explanation": f"the {law} baseline misses the calibration part it was fitted "
                               f"to by {systematic_cal:.2f} % beyond the white noise (withheld "
                               f"gap {gap:.2f} %) and {none_of_mine}: the law family does not "
                               "represent this specimen"}
    return {"effect": "unexplained", **common,
            "explanation": f"the baseline fits its calibration part to the noise, but the "
                           f"withheld gap {gap:.2f} % is above the floor and " + none_of_mine}


def pct_text(x: float | None) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.2f} %"


def confidence_words(verdict: dict[str, Any], policy: Policy | None = None) -> str:
    """The confidence in words, for a person: its level on the policy's scale and, unless high,
    why — the two stories the record does not separate and the measurement that would, or
    what it does not measure. Written once into the verdict, so the summary, the report and
    the demo say the same thing beside the same number."""
    p = policy or Policy()
    c = float(verdict["confidence"])
    level = "high" if c >= p.high_confidence else "moderate" if c >= p.low_confidence else "low"
    effect = verdict["effect"]
    if effect == "none":
        return "high" if level == "high" else (
            f"{level}: the withheld gap or the noise is close to its floor")
    if effect in ("unexplained", "baseline_misfit"):
        return f"{level}: no candidate effect explains the gap"
    reasons = []
    stories = verdict.get("stories") or []
    if len(stories) > 1:
        reasons.append(" or ".join(str(s["effect"]) for s in stories) + ", "
                       + " / ".join(f"{s['weight']:.2f}" for s in stories) + ": "
                       + str(verdict.get("separated_by") or GENERIC_SEPARATION))
    elif verdict.get("runner_up") and level != "high":
        reasons.append(f"the runner-up {verdict['runner_up']} explains much of the gap too")
    if verdict.get("flags"):
        reasons.append("the record does not measure " + ", ".join(verdict["flags"]))
    return level if level == "high" and not reasons else f"{level}: " + "; ".join(reasons)
