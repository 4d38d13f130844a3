"""``diagnose-bench --realism``: records whose effects come from the rig's physical forms.

What is checked is the generator's contract (the truth it reports is what the rig was given,
the forms differ from the candidates', the specimen law varies) and that the bench runs the
mode end to end; its accuracy is a benchmark (BENCHMARKS.md, "Diagnosis"), not a test.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fresco_bridge import indicators as ind
from fresco_bridge.cli import main
from fresco_bridge.diagnosis.bench import MAGNITUDE_OF, effect_magnitude
from fresco_bridge.diagnosis.realism import realistic_record

STEPS = 300


@pytest.mark.parametrize("effect", [e for e in MAGNITUDE_OF if e != "backlash"])
def test_each_record_reports_the_magnitude_it_was_given(effect: str) -> None:
    synthetic = realistic_record(effect, 40 + len(effect), steps=STEPS)
    assert synthetic.effect == effect and synthetic.record.size == STEPS
    assert effect_magnitude(effect, synthetic.truth) not in (None, 0.0)
    if effect in ("pinching", "degradation"):
        assert synthetic.law == "bwbn"


def test_servo_dynamics_lag_the_piston_by_the_reported_equivalent_delay() -> None:
    synthetic = realistic_record("actuator_delay", 5, steps=1000)
    rec = synthetic.record
    assert rec.meas_disp is not None
    lag = ind.xcorr_delay(rec.cmd, rec.meas_disp, 0.01, 20)
    assert lag == pytest.approx(synthetic.truth["tau"], abs=0.011)  # one sample


def test_the_specimen_law_varies_between_records() -> None:
    laws = {realistic_record("none", seed, steps=200).law for seed in range(8)}
    assert laws == {"bouc-wen", "menegotto-pinto"}


def test_the_bench_runs_in_realism_mode(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "bench.json"
    rc = main(["diagnose-bench", "--realism", "--n", "2", "--seed", "4", "--steps", "300",
               "--workers", "1", "--json", str(out), "--no-progress"])
    assert rc == 0
    assert "diagnose-bench --realism: 2 records" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert doc["realism"] is True
    assert [r["law"] for r in doc["records"]] == [
        realistic_record(e, 4 * 100_003 + i, steps=300).law
        for i, e in enumerate(("actuator_delay", "actuator_amplitude"))]
    assert np.isfinite(doc["summary"]["top1_pct"])
