"""``Diagnosis`` and its JSON document (``docs/diagnosis.md``'s schema) are one thing.

A real diagnosis serialised, written as text, read back and serialised again gives the same
document; reading it back gives the same typed diagnosis (without the plotted series); every
key the schema section of the docs names at the top level and in the verdict is there, and a
document of another schema, or with a key missing, is refused with a clear error.
"""

from __future__ import annotations

import json
import re
from dataclasses import fields, replace
from pathlib import Path

import pytest

from benchmarks.diagnosis.synth import synthetic_record
from fresco_bridge.diagnosis.outputs import to_json
from fresco_bridge.diagnosis.result import SCHEMA, Diagnosis, Verdict
from fresco_bridge.diagnosis.verdict import Options, diagnose

DOCS = Path(__file__).resolve().parents[3] / "docs" / "diagnosis.md"


@pytest.fixture(scope="module")
def diagnosis() -> Diagnosis:
    record = synthetic_record("friction", 4, steps=900).record
    return diagnose(record, Options(effects=("friction", "rate_dependence", "sensor_noise")))


def test_the_document_round_trips(diagnosis: Diagnosis) -> None:
    doc = json.loads(to_json(diagnosis))
    assert doc["schema"] == SCHEMA
    again = Diagnosis.from_json(doc)
    assert again == diagnosis  # the series is not compared: it is not in the document
    assert again.series is None and diagnosis.series is not None
    assert json.loads(to_json(again)) == doc
    assert isinstance(again.verdict, Verdict) and again.verdict.effect == "friction"
    assert again.winner() == diagnosis.winner() is not None


def test_the_docs_name_every_key(diagnosis: Diagnosis) -> None:
    text = DOCS.read_text(encoding="utf-8")
    section = text[text.index("## What it prints and writes"):]
    top = [f.name for f in fields(Diagnosis) if f.name != "series"]
    verdict = [f.name for f in fields(Verdict)]
    for key in [*top, *verdict]:
        assert re.search(rf"\b{key}\b", section), key
    assert set(diagnosis.to_json()) == {"schema", *top}


def test_another_schema_or_a_missing_key_is_refused(diagnosis: Diagnosis) -> None:
    doc = diagnosis.to_json()
    with pytest.raises(ValueError, match="schema 'other/1'"):
        Diagnosis.from_json({**doc, "schema": "other/1"})
    with pytest.raises(ValueError, match="lacks verdict"):
        Diagnosis.from_json({k: v for k, v in doc.items() if k != "verdict"})
    with pytest.raises(ValueError, match="unknown key"):
        Diagnosis.from_json({**doc, "verdict": {**doc["verdict"], "guess": 1}})


def test_the_interface_gap_round_trips_and_schema_1_is_still_read(diagnosis: Diagnosis) -> None:
    run = {"source": "runs/a (site s, session 1, actuator 1)", "steps": 900,
           "channel": "external", "nrms_pct": 0.07, "peak_error_mm": 0.01,
           "correction_lines": True, "corrections_median": 1.0, "corrections_max": 3,
           "not_converged": 0, "tolerance_mm": 0.01}
    gap = {"run": run, "against": {**run, "nrms_pct": 4.5, "corrections_median": 0.0},
           "closed_pct": 98.4, "notes": []}
    with_gap = replace(diagnosis, interface_gap=gap)
    doc = json.loads(to_json(with_gap))
    assert doc["interface_gap"] == gap
    assert Diagnosis.from_json(doc) == with_gap
    older = {**diagnosis.to_json(), "schema": "fresco-bridge/diagnosis/1"}
    del older["interface_gap"]
    assert Diagnosis.from_json(older) == diagnosis and diagnosis.interface_gap is None
    text = DOCS.read_text(encoding="utf-8")
    for key in [*run, *gap]:
        assert re.search(rf"\b{key}\b", text), key
