"""Every figure the diagnosis prints comes from one source (issue 36, item 4).

The verdict, the candidate table of the summary, the overlay figure, the report's section and
the demo's line quote the same withheld gaps on the same basis (``verdict.gap_basis``: as
measured — the likelihood the selection rule weighs — or with the white noise removed), and
the confidence comes with its words.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from benchmarks.diagnosis.synth import synthetic_record
from fresco_bridge.diagnosis.figures import overlay_figure
from fresco_bridge.diagnosis.outputs import summary, write_report
from fresco_bridge.diagnosis.result import Diagnosis
from fresco_bridge.diagnosis.verdict import Options, diagnose
from fresco_bridge.numbers import pct
from fresco_bridge.report.diagnosis import diagnosis_sections, headline, on_basis


@pytest.fixture(scope="module")
def result() -> Diagnosis:
    record = synthetic_record("degradation", 5, steps=1500).record
    return diagnose(record, Options(effects=("degradation", "pinching", "sensor_noise")))


def test_the_verdict_quotes_its_winners_row(result: Diagnosis) -> None:
    verdict = result.verdict
    assert verdict.effect == "degradation"
    assert verdict.gap_basis == "raw"
    winner = result.winner()
    assert winner is not None
    after, shrink, _score = on_basis(winner, verdict.gap_basis)
    assert after == pytest.approx(verdict.gap_after_pct, rel=1e-12)
    assert shrink == pytest.approx(verdict.shrink_pct, rel=1e-12)
    # the systematic figure differs: quoting it would be the second source
    assert winner["systematic"]["gap_after_pct"] != pytest.approx(after, rel=1e-6)


def test_summary_table_figure_and_report_agree(result: Diagnosis, tmp_path: Path) -> None:
    verdict = result.verdict
    after, before = pct(verdict.gap_after_pct), pct(verdict.gap_before_pct)
    text = summary(result)
    verdict_line = next(line for line in text.splitlines() if line.startswith("VERDICT"))
    assert f"from {before} to {after}" in verdict_line
    row = next(line for line in text.splitlines() if line.strip().startswith("degradation "))
    assert after in row
    assert "as measured" in text
    fig = overlay_figure(result)
    labels = [t.get_text() for t in fig.axes[2].get_legend().get_texts()]
    assert any(f"gap {after}" in label for label in labels)
    assert any(f"gap {before}" in label for label in labels)
    write_report(result, tmp_path / "diagnosis-damper")
    (section,) = diagnosis_sections(tmp_path, lambda data, alt, caption: "")
    assert f"{before} → {after}" in section
    assert f'<td class="n">{after}</td>' in section


def test_the_confidence_comes_with_its_words(result: Diagnosis) -> None:
    verdict = result.verdict
    words = verdict.confidence_words
    assert words.split(":")[0] in ("high", "moderate", "low")
    h = headline(result.to_json())
    assert h["confidence_text"] == f"{verdict.confidence:.2f} ({words})"
    assert h["confidence_text"] in summary(result)
    if verdict.confidence < 0.5:
        assert words.startswith("low: ")


@pytest.mark.parametrize(("verdict", "words"), [
    ({"effect": "rate_dependence", "confidence": 0.3, "not_separated_from": "friction",
      "runner_up": "friction", "flags": {}, "separated_by": "cycles at two rates",
      "stories": [{"effect": "rate_dependence", "weight": 0.55},
                  {"effect": "friction", "weight": 0.45}]},
     "low: rate_dependence or friction, 0.55 / 0.45: cycles at two rates"),
    ({"effect": "degradation", "confidence": 0.6, "not_separated_from": None,
      "runner_up": "pinching", "flags": {"delta_nu": "at its upper bound 0.5"}},
     "moderate: the runner-up pinching explains much of the gap too; the record does not "
     "measure delta_nu"),
    ({"effect": "backlash", "confidence": 0.95, "not_separated_from": None,
      "runner_up": "friction", "flags": {}}, "high"),
    ({"effect": "none", "confidence": 0.3},
     "low: the withheld gap or the noise is close to its floor"),
    ({"effect": "baseline_misfit", "confidence": 0.0},
     "low: no candidate effect explains the gap"),
])
def test_confidence_words(verdict: dict[str, Any], words: str) -> None:
    from fresco_bridge.diagnosis.decision import confidence_words

    assert confidence_words(verdict) == words
