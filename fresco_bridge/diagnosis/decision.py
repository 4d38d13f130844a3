"""The decision: which candidate the record names, how sure it is, and what it says.

Items 3-7 of the procedure in ``verdict`` (the floor, the shrink a winner needs, pairs, the
confidence and its flags, white noise as no rival), applied to candidates already fitted and
scored there; pure, no fitting.
"""

from __future__ import annotations

import math
from typing import Any

from .load import Record
from .scored import (
    MIN_SHRINK_PCT,
    both_matter,
    limit_form,
    raw_before,
    without_noise,
)
from .scored import Scored as _Scored
from .scored import finite as _finite
from .scored import gap as _gap

__all__ = ["FLAG_CONFIDENCE_FACTOR", "HIGH_CONFIDENCE", "LOW_CONFIDENCE", "PAIR_MARGIN_PCT",
           "confidence_words", "decide", "pct_text", "systematic_verdict"]

FLAG_CONFIDENCE_FACTOR = 0.5
"""The confidence is multiplied by this for each flagged parameter of the winning effect."""
LOW_CONFIDENCE = 0.5
"""Below this confidence the verdict names the runner-up it could not separate."""
HIGH_CONFIDENCE = 0.8
"""From this confidence on the words say "high" (between the two: "moderate")."""
PAIR_MARGIN_PCT = 5.0


def systematic_verdict(record: Record, withheld: slice, noise: tuple[float, float],
                        sys_before: dict[str, float | None], sys_floor: float,
                        raw: dict[str, Any], singles: list[_Scored], pairs: list[_Scored],
                        families: list[_Scored], floor: float, systematic_cal: float,
                        law: str) -> dict[str, Any]:
    """The verdict on the systematic gap: every candidate scored with the white noise (std
    from the calibration residual) removed from its withheld gap.

    White measurement noise is in every record and no systematic candidate predicts it; on the
    raw gap it dilutes a real effect's shrink (a friction that removes 47 % of the systematic
    gap removes 6 % of a noisy raw one) while ``sensor_noise`` claims all of it, so on a noisy
    record the noise won over the effect. Here ``sensor_noise`` is the verdict only when the
    systematic gap is below what the record resolves (:func:`systematic_floor`), i.e. the noise
    is all there is above the floor; otherwise the systematic candidates compete alone (pairs
    with noise are not named: the white noise's level is reported in ``noise_floor``). When no
    systematic candidate explains the systematic gap and the raw verdict named the noise (noise
    that is not white, which the white estimate only partly removes), the raw verdict stands."""
    noise_single = [s for s in singles if s.name == "sensor_noise"]
    if (sys_before["total_pct"] or 0.0) < sys_floor:
        verdict = decide(raw_before(noise_single, raw), noise_single, [], [], floor,
                           systematic_cal, law) if noise_single else raw
        verdict["explanation"] += (f"; without the white noise the withheld gap is "
                                   f"{sys_before['total_pct'] or 0.0:.2f} %, below the "
                                   f"{sys_floor:.2f} % the record resolves: nothing systematic")
        return verdict
    refs = {f.name: _gap(record, f.force, f.disp, withheld, noise)
            for f in families if f.force is not None}
    sys_families = [without_noise(f, record, withheld, noise, sys_before, {}) for f in families]
    sys_singles = sorted((without_noise(s, record, withheld, noise, sys_before, refs)
                          for s in singles if "sensor_noise" not in s.effects),
                         key=lambda s: s.score, reverse=True)
    sys_pairs = [without_noise(p, record, withheld, noise, sys_before, refs)
                 for p in pairs if "sensor_noise" not in p.effects]
    if not sys_singles:
        return raw
    verdict = decide(sys_before, sys_singles, sys_pairs, sys_families, sys_floor,
                       systematic_cal, law)
    if verdict["effect"] in ("none", "baseline_misfit", "unexplained") and (
            "sensor_noise" in raw["effect"].split("+")):
        return raw
    verdict["explanation"] = ("scored without the white noise (std from the calibration "
                              "residual): " + verdict["explanation"])
    verdict["gap_basis"] = "systematic"
    return verdict


def decide(before: dict[str, float | None], singles: list[_Scored], pairs: list[_Scored],
             families: list[_Scored], floor: float, systematic_cal: float,
             law: str) -> dict[str, Any]:
    gap = before["total_pct"] or 0.0
    if gap < floor:
        return {"effect": "none", "confidence": max(0.0, 1.0 - gap / floor),
                "shrink_pct": 0.0, "gap_before_pct": gap, "gap_after_pct": gap,
                "runner_up": None, "not_separated_from": None, "flags": {},
                "better_family": None,
                "explanation": f"withheld gap {gap:.2f} % is below the noise floor {floor:g} %"}
    ranked = sorted([*singles, *pairs, *families], key=lambda s: s.score, reverse=True)
    best_single = next((s for s in singles if _nameable(s, gap, floor)), singles[0])
    best = best_single
    if pairs:
        eligible = [p for p in pairs if both_matter(p, singles) and _nameable(p, gap, floor)]
        best_pair = max(eligible, key=lambda s: s.score) if eligible else None
        if best_pair is not None and best_pair.score > best_single.score + PAIR_MARGIN_PCT:
            best = best_pair
    family = max(families, key=lambda s: s.score) if families else None
    if family is not None and family.shrink >= MIN_SHRINK_PCT and family.score > best.score:
        after = family.after["total_pct"] or 0.0
        left = best.after["total_pct"]
        return {"effect": "baseline_misfit",
                "confidence": 0.0 if left is None else float(min(max(
                    (left - after) / max(gap - after, 1e-12), 0.0), 1.0)),
                "shrink_pct": _finite(family.shrink), "gap_before_pct": gap,
                "gap_after_pct": after, "runner_up": best.name, "not_separated_from": None,
                "flags": {}, "better_family": family.name,
                "explanation": f"only a change of law family closes the gap: a {family.name} "
                               f"baseline shrinks the withheld gap from {gap:.2f} % to "
                               f"{after:.2f} %; the best effect on the {law} baseline, "
                               f"{best.name}, leaves {pct_text(left)}"}
    if best.shrink < MIN_SHRINK_PCT or not _nameable(best, gap, floor):
        better = family.name if family is not None and family.score > best.score else None
        none_of_mine = (f"no candidate shrinks it by {MIN_SHRINK_PCT:g} % (best: {best.name}, "
                        f"{best.shrink:.1f} %)" if best.shrink < MIN_SHRINK_PCT else
                        f"the best candidate, {best.name}, moves the prediction by "
                        f"{best.size:.2f} % and leaves {pct_text(best.after['total_pct'])} "
                        f"(named: at least the floor {floor:.2f} %, less than {gap:.2f} %)")
        common: dict[str, Any] = {
            "confidence": 0.0, "shrink_pct": _finite(best.shrink), "gap_before_pct": gap,
            "gap_after_pct": best.after["total_pct"], "runner_up": best.name,
            "not_separated_from": None, "flags": {}, "better_family": better}
        if systematic_cal > floor:
            return {"effect": "baseline_misfit", **common,
                    "explanation": f"the {law} baseline misses the calibration part it was "
                                   f"fitted to by {systematic_cal:.2f} % beyond the white noise "
                                   f"(withheld gap {gap:.2f} %) and {none_of_mine}: the law "
                                   "family does not represent this specimen"
                                   + ("" if better is None else
                                      f" (a {better} baseline does better)")}
        return {"effect": "unexplained", **common,
                "explanation": f"the baseline fits its calibration part to the noise, but the "
                               f"withheld gap {gap:.2f} % is above the floor and "
                               + none_of_mine}
    others = [s for s in ranked if s is not best and not set(s.effects) >= set(best.effects)]
    runner = others[0] if others else None
    confidence = _separation(best, runner, gap)
    if runner is not None and confidence < LOW_CONFIDENCE and limit_form(best, runner):
        best, runner = runner, best  # the form the winner tends to at its bound: named as such
        confidence = _separation(best, runner, gap)
    after = best.after["total_pct"] or 0.0
    flags = best.flags
    confidence *= FLAG_CONFIDENCE_FACTOR ** len(flags)
    unsure = runner.name if runner is not None and confidence < LOW_CONFIDENCE else None
    text = (f"{best.name} shrinks the withheld gap from {gap:.2f} % to {after:.2f} %"
            + ("" if best.compared_with is None else
               f" (on the {best.fit.spec.law_kind if best.fit else law} law; measured from the "
               f"{best.compared_with}, which leaves {pct_text(best.before['total_pct'])})")
            + ("" if runner is None else
               f"; the runner-up {runner.name} leaves {runner.after['total_pct']:.2f} %"))
    if flags:
        text += "; not measured by the record: " + ", ".join(
            f"{k} {v}" for k, v in flags.items())
    if unsure is not None:
        text += f"; low confidence: not separated from {unsure}"
    return {
        "effect": best.name, "confidence": confidence,
        "shrink_pct": _finite(best.shrink), "gap_before_pct": gap, "gap_after_pct": after,
        "runner_up": None if runner is None else runner.name,
        "not_separated_from": unsure, "flags": flags, "better_family": None,
        "explanation": text,
    }


def _nameable(s: _Scored, gap: float, floor: float) -> bool:
    """Big enough to hear (it moves the prediction by the floor) and better than the sim."""
    after = s.after["total_pct"]
    return s.size >= floor and after is not None and after < gap


def _separation(best: _Scored, runner: _Scored | None, gap: float) -> float:
    """The share of ``best``'s gap reduction that ``runner`` does not achieve, in [0, 1]."""
    if runner is None or runner.after["total_pct"] is None:
        return 1.0
    after = best.after["total_pct"] or 0.0
    return float(min(max((runner.after["total_pct"] - after) / max(gap - after, 1e-12), 0.0),
                     1.0))


def pct_text(x: float | None) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.2f} %"


def confidence_words(verdict: dict[str, Any]) -> str:
    """The confidence in words, for a person: its level on the scale (:data:`LOW_CONFIDENCE`,
    :data:`HIGH_CONFIDENCE`) and, unless high, why — what the record does not separate or
    measure. Written once into the verdict, so the summary, the report and the demo say the
    same thing beside the same number."""
    c = float(verdict["confidence"])
    level = "high" if c >= HIGH_CONFIDENCE else "moderate" if c >= LOW_CONFIDENCE else "low"
    effect = verdict["effect"]
    if effect == "none":
        return "high" if level == "high" else f"{level}: the withheld gap is close to the floor"
    if effect in ("unexplained", "baseline_misfit"):
        return f"{level}: no candidate effect explains the gap"
    reasons = []
    if verdict.get("not_separated_from"):
        reasons.append(f"the record does not separate it from {verdict['not_separated_from']}")
    elif verdict.get("runner_up") and level != "high":
        reasons.append(f"the runner-up {verdict['runner_up']} explains much of the gap too")
    if verdict.get("flags"):
        reasons.append("the record does not measure " + ", ".join(verdict["flags"]))
    return level if level == "high" and not reasons else f"{level}: " + "; ".join(reasons)
