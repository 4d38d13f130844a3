"""The one selection rule (``decision``): BIC on the withheld part, the parameters the record
estimates counted, two stories named with their weights when the evidence cannot separate them.

Pure-logic tests of ``decide`` on candidates whose withheld gaps are given (no fitting: the
rule alone), then real records: friction at the Coulomb limit, a ``none`` record whose noise is
at a lab's ordinary level, and a two-story verdict that survives the JSON schema.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from benchmarks.diagnosis.bench import contains_truth, credit, verdict_label
from benchmarks.diagnosis.forms import form_record
from fresco_bridge.diagnosis.decision import SEPARATED_BY, confidence_words, decide
from fresco_bridge.diagnosis.model import Param
from fresco_bridge.diagnosis.options import Policy
from fresco_bridge.diagnosis.outputs import summary, to_json
from fresco_bridge.diagnosis.result import Diagnosis, Verdict
from fresco_bridge.diagnosis.scored import Scored, evidence_samples, information
from fresco_bridge.diagnosis.verdict import diagnose

BEFORE = {"force_pct": 10.0, "disp_pct": None, "total_pct": 10.0}
N_EFF = (200.0, None)
FORCE = np.zeros(10)

COULOMB = Param("coulomb", "out", "kN", 0.0, 10.0, 0.2, "Coulomb force")
SLIP = Param("slip", "out", "mm", 0.0, 2.0, 0.05, "slip")
VISCOUS = Param("viscous", "out", "kN*s/mm", 0.0, 10.0, 0.2, "force per velocity")
EXPONENT = Param("rate_exponent", "out", "1", 0.1, 2.0, 1.0, "velocity exponent")
GAP = Param("gap", "gap", "mm", 0.0, 3.0, 0.1, "clearance")
ZETA = Param("zeta_s", "out", "1", 0.0, 0.99, 0.5, "pinching severity")
PSI = Param("psi0", "out", "1", 0.0, 1.0, 0.2, "pinching spread")


def candidate(name: str, params: list[Param], values: dict[str, float], after: float
              ) -> Scored:
    return Scored(name, (name,), params, None, values, {k: 0.01 * abs(v) + 1e-6
                                                        for k, v in values.items()},
                  BEFORE, {"force_pct": after, "disp_pct": None, "total_pct": after},
                  FORCE, None, size=math.inf)


def test_a_rate_law_that_fits_no_better_than_coulomb_friction_is_friction() -> None:
    # the exponent is free (0.3), but the withheld fit is the rigid Coulomb force's: the
    # extra parameter is not paid for
    friction = candidate("friction", [COULOMB, SLIP], {"coulomb": 1.0, "slip": 0.0}, 4.0)
    rate = candidate("rate_dependence", [VISCOUS, EXPONENT],
                     {"viscous": 1.0, "rate_exponent": 0.3}, 3.99)
    assert friction.n_free == 1 and rate.n_free == 2  # a slip of zero: a rigid fixture
    verdict = decide(BEFORE, [friction, rate], [], [], Policy(), 0.0, "bouc-wen", N_EFF)
    assert verdict["effect"] == "friction", verdict
    # a rate law the withheld data demand wins
    rate_demanded = candidate("rate_dependence", [VISCOUS, EXPONENT],
                              {"viscous": 1.0, "rate_exponent": 0.3}, 3.0)
    verdict = decide(BEFORE, [friction, rate_demanded], [], [], Policy(), 0.0, "bouc-wen",
                     N_EFF)
    assert verdict["effect"] == "rate_dependence" and not verdict["stories"], verdict


def test_a_rate_law_at_its_smallest_exponent_is_coulomb_friction() -> None:
    rate = candidate("rate_dependence", [VISCOUS, EXPONENT],
                     {"viscous": 1.0, "rate_exponent": 0.1}, 3.8)
    assert rate.n_free == 1
    friction = candidate("friction", [COULOMB, SLIP], {"coulomb": 1.0, "slip": 0.1}, 4.0)
    gap = candidate("backlash", [GAP], {"gap": 0.5}, 9.0)
    verdict = decide(BEFORE, [rate, friction, gap], [], [], Policy(), 0.0, "bouc-wen", N_EFF)
    assert verdict["effect"] == "friction", verdict
    assert "at the bound where it is friction" in verdict["explanation"]
    assert not verdict["stories"]  # one story told twice is not two stories


def test_a_pinching_indistinguishable_from_a_gap_is_two_stories_with_weights() -> None:
    gap = candidate("backlash", [GAP], {"gap": 0.5}, 5.0)
    pinching = candidate("pinching", [ZETA, PSI], {"zeta_s": 0.5, "psi0": 0.3}, 4.955)
    verdict = decide(BEFORE, [gap, pinching], [], [], Policy(), 0.0, "bouc-wen", N_EFF)
    stories = verdict["stories"]
    assert [s["effect"] for s in stories] == [verdict["effect"], verdict["not_separated_from"]]
    assert {s["effect"] for s in stories} == {"backlash", "pinching"}
    assert sum(s["weight"] for s in stories) == pytest.approx(1.0)
    assert stories[0]["weight"] >= stories[1]["weight"] > 0.1
    assert verdict["separated_by"] == SEPARATED_BY[frozenset({"backlash", "pinching"})]
    words = confidence_words(verdict)
    assert words.startswith("low") or words.startswith("moderate")
    assert f"{stories[0]['weight']:.2f} / {stories[1]['weight']:.2f}" in words
    assert verdict["separated_by"] in words
    # the benches score it half right, whichever story is true; and it contains the truth
    label = Verdict.from_json(verdict | {"confidence_words": words}).label
    assert label == f"{stories[0]['effect']}|{stories[1]['effect']}"
    assert credit("pinching", label) == credit("backlash", label) == 0.5
    assert credit("friction", label) == 0.0
    assert contains_truth("pinching", label) and not contains_truth("friction", label)


def test_the_weights_follow_the_withheld_evidence() -> None:
    # BIC = n ln(gap²) + k ln(n): the formula docs/diagnosis.md states
    gaps = {"force_pct": 4.0, "disp_pct": None, "total_pct": 4.0}
    assert information(gaps, N_EFF, 2) == pytest.approx(
        200.0 * math.log(16.0) + 2 * math.log(200.0))
    # white noise is every sample's evidence; a slow misfit is a few samples' a cycle
    rng = np.random.default_rng(1)
    assert evidence_samples(rng.standard_normal(2000)) > 1500
    slow = np.sin(np.linspace(0.0, 20.0 * np.pi, 2000))
    assert evidence_samples(slow) < 100


def test_a_pair_whose_second_member_is_absent_is_the_single() -> None:
    degradation = candidate("degradation", [ZETA], {"zeta_s": 0.4}, 4.0)
    gap = candidate("backlash", [GAP], {"gap": 0.5}, 9.0)
    pair = Scored("backlash+degradation", ("backlash", "degradation"), [GAP, ZETA], None,
                  {"gap": 0.0, "zeta_s": 0.4}, {"gap": 0.01, "zeta_s": 0.01}, BEFORE,
                  {"force_pct": 3.99, "disp_pct": None, "total_pct": 3.99}, FORCE, None)
    verdict = decide(BEFORE, [degradation, gap], [pair], [], Policy(), 0.0, "bouc-wen", N_EFF)
    assert verdict["effect"] == "degradation", verdict


def test_no_candidate_paying_for_its_parameters_is_not_an_effect() -> None:
    weak = candidate("friction", [COULOMB, SLIP], {"coulomb": 1.0, "slip": 0.5}, 9.99)
    verdict = decide(BEFORE, [weak], [], [], Policy(), 0.0, "bouc-wen", N_EFF)
    assert verdict["effect"] == "unexplained" and verdict["confidence"] == 0.0


def test_friction_at_the_coulomb_limit_is_friction_on_a_short_record() -> None:
    rec = form_record("friction/sign", 4242, steps=1200)
    verdict = diagnose(rec.record).verdict
    assert verdict.effect == "friction", verdict.explanation


def test_a_none_record_at_a_labs_noise_floor_is_none() -> None:
    rec = form_record("none/floor", 4266, steps=1200)
    result = diagnose(rec.record)
    noise = result.noise_floor["noise_pct_of_peak"]
    assert 0.2 < noise <= Policy().ordinary_noise_pct, noise
    assert result.verdict.effect == "none", result.verdict.explanation
    assert "ordinarily carry" in result.verdict.explanation


def test_a_two_story_verdict_round_trips_through_the_schema_and_the_summary() -> None:
    rec = form_record("friction/tanh-2", 4244, steps=1200)
    diagnosis = diagnose(rec.record)
    verdict = diagnosis.verdict
    assert len(verdict.stories) == 2, verdict.explanation  # the record's measured state
    assert {s["effect"] for s in verdict.stories} == {"friction", "rate_dependence"}
    assert verdict.separated_by == SEPARATED_BY[frozenset({"friction", "rate_dependence"})]
    doc = json.loads(to_json(diagnosis))
    assert doc["verdict"]["stories"] == json.loads(json.dumps(verdict.stories))
    again = Diagnosis.from_json(doc)
    assert again.verdict == verdict and verdict_label(doc["verdict"]) == verdict.label
    text = summary(diagnosis)
    assert "TWO STORIES" in text and verdict.separated_by in text
    assert verdict.confidence_words in text
