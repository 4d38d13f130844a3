"""The restated updating targets: each rule met and missed, the bad runs named, the median rule,
"not run" and "no target", per causality (summary documents built here, no simulation)."""

from __future__ import annotations

import math
from typing import Any

from fresco_bridge.study.constants import BOUNDED_PEAK_RATIO, TARGETS
from fresco_bridge.study.report import score_targets, summary_table, targets_markdown

TRUE_PEAK = 20.0


def _case(maeth: float, rmseth: float | None = None, peak: float = TRUE_PEAK) -> dict[str, Any]:
    return {"maeth": maeth, "rmseth": maeth / 4 if rmseth is None else rmseth,
            "pv_es_pos": TRUE_PEAK, "pv_es_neg": TRUE_PEAK * 0.9,
            "pv_ums_pos": peak, "pv_ums_neg": peak * 0.9, "one_step_rmse": 0.1}  # fmt: skip


def _run(specimen: str, noise: float, improved: dict[str, Any], *, seed: int = 1,
         causality: str = "same-step", ukf: float | None = 10.0,
         ann: float | None = None) -> dict[str, Any]:  # fmt: skip
    """One run's summary document: calibrated MAETH 10 kN, RMSETH 2 kN."""
    cases = {"conventional_calibrated": _case(10.0, 2.0), "online_improved": improved}
    if ukf is not None:
        cases["online_ukf"] = _case(ukf)
    if ann is not None:
        cases["online_ann"] = _case(ann)
    return {"record": "rec.AT2", "specimen": specimen, "noise_pct": noise, "seed": seed,
            "causality": causality,
            "layouts": {"paper": {"cases": cases}, "generalisation": {"cases": cases}}}  # fmt: skip


def _targets(documents: list[dict[str, Any]], causality: str = "same-step") -> dict[str, Any]:
    body = score_targets(documents)["by_causality"][causality]
    return {entry["target"]: entry for entry in body["targets"]} | {"_body": body}


def test_every_target_met() -> None:
    runs = [_run("bwbn", 0.0, _case(1.0, 0.1)),  # 90 % MAETH, 95 % RMSETH
            _run("bwbn", 1.0, _case(1.5)),  # 85 %
            _run("menegotto-pinto", 0.0, _case(4.0), ann=8.0),  # 60 %
            _run("menegotto-pinto", 1.0, _case(5.0), seed=2, ann=8.0),  # 50 %
            _run("bilinear", 0.0, _case(11.0)),  # 1.1x the calibrated Bilinear: no harm
            _run("bouc-wen", 1.0, _case(2.0), ukf=1.0)]  # in family the UKF may win  # fmt: skip
    got = _targets(runs)
    for spec in TARGETS:
        assert got[spec.name]["verdict"] == "met", spec.name
        assert got[spec.name]["bad"] == []
    assert got["bwbn_noise0"]["runs"] == got["bwbn_noise0"]["meeting"] == 1
    assert got["below_online_ukf"]["meeting"] == 4  # out of family only
    assert got["in_family_no_harm"]["runs"] == 2
    assert got["below_online_ann"]["runs"] == 2  # scored where online_ann ran
    assert got["menegotto_pinto"]["median_pct"] == 55.0
    text = targets_markdown(score_targets(runs))
    assert "### causality same-step (6 run(s))" in text and "**missed**" not in text
    assert "- bwbn, 0 % noise: MAETH ≥ 85 % and RMSETH ≥ 90 % below: met, 1 of 1 run(s)" in text


def test_bwbn_0_needs_both_metrics_and_names_the_bad_run() -> None:
    runs = [_run("bwbn", 0.0, _case(1.0, 0.1)),
            _run("bwbn", 0.0, _case(1.0, 0.3), seed=7)]  # MAETH 90 %, RMSETH only 85 %
    entry = _targets(runs)["bwbn_noise0"]
    assert (entry["verdict"], entry["meeting"], entry["runs"]) == ("missed", 1, 2)
    assert entry["bad"] == [{"record": "rec.AT2", "specimen": "bwbn", "noise_pct": 0.0,
                             "seed": 7, "causality": "same-step",
                             "figure": "MAETH 90.0 % below, RMSETH 85.0 % below"}]  # fmt: skip
    text = targets_markdown(score_targets(runs))
    assert "RMSETH ≥ 90 % below: **missed**, 1 of 2 run(s)" in text
    assert ("  - bad: rec.AT2, bwbn, 0 % noise, seed 7, same-step: MAETH 90.0 % below, "
            "RMSETH 85.0 % below") in text  # fmt: skip


def test_bwbn_1_percent_threshold() -> None:
    assert _targets([_run("bwbn", 1.0, _case(2.0))])["bwbn_noise1"]["verdict"] == "met"  # 80 %
    entry = _targets([_run("bwbn", 1.0, _case(2.1))])["bwbn_noise1"]  # 79 %
    assert entry["verdict"] == "missed" and entry["bad"][0]["figure"] == "MAETH 79.0 % below"


def test_menegotto_pinto_every_run_and_the_median() -> None:
    every = [_run("menegotto-pinto", 0.0, _case(m), seed=s) for s, m in enumerate((2, 3, 4))]
    assert _targets(every)["menegotto_pinto"]["verdict"] == "met"  # 80, 70, 60 %
    one_low = [*every, _run("menegotto-pinto", 1.0, _case(8.0), seed=9)]  # 20 %
    entry = _targets(one_low)["menegotto_pinto"]
    assert (entry["verdict"], entry["meeting"], entry["runs"]) == ("missed", 3, 4)
    assert [b["seed"] for b in entry["bad"]] == [9] and entry["median_pct"] == 65.0
    low_median = [_run("menegotto-pinto", 0.0, _case(m), seed=s)
                  for s, m in enumerate((7.0, 6.0, 4.0))]  # 30, 40, 60 %: each >= 25 %
    entry = _targets(low_median)["menegotto_pinto"]
    assert (entry["verdict"], entry["meeting"], entry["bad"]) == ("missed", 3, [])
    assert math.isclose(entry["median_pct"], 40.0)
    assert "median over the runs ≥ 50 %: **missed**, 3 of 3 run(s), median 40.0 %" in (
        targets_markdown(score_targets(low_median)))


def test_below_rivals_missed_and_not_run() -> None:
    runs = [_run("bwbn", 0.0, _case(1.0, 0.1), ukf=0.5),
            _run("bwbn", 0.0, _case(1.0, 0.1), seed=2, ukf=None)]
    got = _targets(runs)
    assert (got["below_online_ukf"]["verdict"], got["below_online_ukf"]["runs"]) == ("missed", 1)
    assert got["below_online_ukf"]["bad"][0]["figure"] == "MAETH 1.000 kN, online_ukf 0.500 kN"
    assert got["below_online_ann"]["verdict"] == "not run"
    assert got["below_online_ann"]["runs"] == 0
    assert "- bwbn, menegotto-pinto: MAETH below online_ann on every run: not run\n" in (
        targets_markdown(score_targets(runs)))


def test_in_family_no_harm_names_the_run_that_did_harm() -> None:
    runs = [_run("bilinear", 0.0, _case(10.9)),
            _run("bouc-wen", 0.0, _case(11.2), seed=4)]  # 1.12x the calibrated Bilinear
    entry = _targets(runs)["in_family_no_harm"]
    assert (entry["verdict"], entry["meeting"], entry["runs"]) == ("missed", 1, 2)
    assert entry["bad"][0]["seed"] == 4
    assert entry["bad"][0]["figure"] == ("MAETH 11.2000 kN, conventional_calibrated 10.0000 kN "
                                         "(×1.120)")
    text = targets_markdown(score_targets(runs))
    assert ("- bilinear, bouc-wen (in family): MAETH ≤ 1.1× conventional_calibrated's on every "
            "run: **missed**, 1 of 2 run(s)") in text
    assert "no target" not in text and "| no target |" not in summary_table(runs)


def test_bounded_missed_when_the_twin_overshoots_or_is_not_finite() -> None:
    over = BOUNDED_PEAK_RATIO * TRUE_PEAK * 1.01
    runs = [_run("bwbn", 1.0, _case(1.0, peak=BOUNDED_PEAK_RATIO * TRUE_PEAK)),  # at the limit
            _run("bwbn", 1.0, _case(1.0, peak=over), seed=2),
            _run("bwbn", 1.0, _case(math.nan), seed=3)]  # fmt: skip
    entry = _targets(runs)["bounded"]
    assert (entry["verdict"], entry["meeting"]) == ("missed", 1)
    assert [b["seed"] for b in entry["bad"]] == [2, 3]
    assert entry["bad"][0]["figure"] == f"peak |twin force| {over:.3f} kN, true 20.000 kN"


def test_not_run_without_the_specimen_or_the_cases_and_no_target_for_other_noise() -> None:
    runs = [_run("bwbn", 2.0, _case(1.0)), _run("bwbn", 2.0, _case(1.0), seed=2)]
    got = _targets(runs)
    for name in ("bwbn_noise0", "bwbn_noise1", "menegotto_pinto"):
        assert got[name]["verdict"] == "not run"
    assert got["_body"]["no_target"] == [{"specimen": "bwbn", "noise_pct": 2.0, "runs": 2}]
    assert "- bwbn, 2 % noise: no target (2 run(s))" in targets_markdown(score_targets(runs))
    assert "| rec.AT2 | bwbn | 2 | 1 | same-step |" in summary_table(runs)
    assert "| no target |" in summary_table(runs)
    without = _run("bwbn", 0.0, _case(1.0))
    del without["layouts"]["generalisation"]["cases"]["online_improved"]
    assert all(e["verdict"] == "not run" for e in score_targets([without])["by_causality"]
               ["same-step"]["targets"])  # fmt: skip


def test_verdicts_are_per_causality() -> None:
    runs = [_run("bwbn", 1.0, _case(1.0)),
            _run("bwbn", 1.0, _case(3.0), causality="previous-step")]  # 70 %
    scored = score_targets(runs)
    assert list(scored["by_causality"]) == ["same-step", "previous-step"]
    assert _targets(runs)["bwbn_noise1"]["verdict"] == "met"
    late = _targets(runs, "previous-step")["bwbn_noise1"]
    assert late["verdict"] == "missed" and late["bad"][0]["causality"] == "previous-step"
    assert "### causality previous-step (1 run(s))" in targets_markdown(scored)
