"""The report's diagnosis section reads as numbers for people (issue 27): a withheld gap below
the noise floor is said to be below it, not printed as ``3.26e-12 % → 3.26e-12 %``, and a
shrink is undefined (``–``) when there was no gap to shrink."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from fresco_bridge.report.diagnosis import diagnosis_sections
from tests.bridge.record.test_report import parse


def _result(effect: str, before: float, after: float, shrink: float | None) -> dict[str, Any]:
    candidate = {"name": "backlash", "gap_after": {"total_pct": after}, "shrink_pct": shrink,
                 "score": None if shrink is None else shrink - 2.0,
                 "params": {"gap": {"value": 0.2512345, "std": 0.0123, "unit": "mm",
                                    "meaning": "total free play"}}}
    return {
        "record": {"source": "runs/x (site damper)"},
        "baseline": {"kind": "bilinear"},
        "verdict": {"effect": effect, "confidence": 1.0, "gap_before_pct": before,
                    "gap_after_pct": after, "shrink_pct": shrink,
                    "explanation": "why"},
        "effects": [candidate], "pairs": [],
        "noise_floor": {"floor_pct": 1.0},
    }


def _cells(tmp_path: Path, result: dict[str, Any]) -> tuple[dict[str, str], str]:
    folder = tmp_path / "diagnosis-damper"
    folder.mkdir()
    (folder / "diagnosis.json").write_text(json.dumps(result), encoding="utf-8")
    (section,) = diagnosis_sections(tmp_path, lambda data, alt, caption: "")
    page_file = tmp_path / "page.html"
    page_file.write_text(f"<html><body>{section}</body></html>", encoding="utf-8")
    page = parse(page_file)
    return {key: text for _, key, text in page.cells}, section


def test_a_gap_below_the_noise_floor_reads_as_below_it(tmp_path: Path) -> None:
    cells, section = _cells(tmp_path, _result("none", 3.26e-12, 3.26e-12, 0.0))
    assert cells["withheld"] == "0.00 %: below the noise floor (1 %), nothing to explain"
    assert cells["shrink"].startswith("– (none")
    assert "e-12" not in section
    # the candidates' shrink and score are undefined without a gap to shrink
    assert '<td class="n">–</td><td class="n">–</td>' in section


def test_an_effect_reads_with_significant_digits(tmp_path: Path) -> None:
    cells, section = _cells(tmp_path, _result("backlash", 12.3456, 4.5678, 63.0001))
    assert cells["withheld"] == "12.35 % → 4.57 %"
    assert cells["shrink"] == "63.0 %"
    assert cells["magnitude"] == "gap = 0.251 ± 0.012 mm (total free play)"
    assert '<td class="n">63.0 %</td><td class="n">61</td>' in section
