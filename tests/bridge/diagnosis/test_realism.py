"""``diagnose-bench --realism``: records whose effects come from the rig's physical forms.

What is checked is the generator's contract (the truth it reports is what the rig was given,
second effects the rig adds included; the forms differ from the candidates', the specimen law
varies), the scoring rule that counts those second effects (with the strict figure beside it),
and that the bench runs the mode end to end; its accuracy is a benchmark (BENCHMARKS.md,
"Diagnosis"), not a test.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.diagnosis.bench import (
    MAGNITUDE_OF,
    bench_items,
    credit,
    effect_magnitude,
    format_bench,
    generate,
    summarise_bench,
)
from benchmarks.diagnosis.realism import realistic_record
from benchmarks.diagnosis.synth import SyntheticRecord
from fresco_bridge import indicators as ind
from fresco_bridge.cli import main

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


def test_an_amplitude_record_lists_the_undershoot_its_rig_adds() -> None:
    # seed 0: a gain short of 1 (the rig then adds an undershoot); seed 2: a gain above 1
    short, over = (realistic_record("actuator_amplitude", seed, steps=STEPS) for seed in (0, 2))
    assert short.truth["amplitude_error"] < 0.0 < over.truth["amplitude_error"]
    assert set(short.truth) == {"amplitude_error"} and over.also_present == {}
    assert set(short.also_present) == {"actuator_undershoot"}
    listed = short.also_present["actuator_undershoot"]["undershoot"]
    rec = short.record
    assert rec.meas_disp is not None
    assert 0.0 < listed <= 0.01 * float(np.max(np.abs(rec.cmd)))
    # it is in the record: each move ends short by it, against the motion, before the gain
    # (the rig's servo is ideal here; the LVDT's noise averages out)
    moves = np.sign(np.diff(rec.cmd))
    short_by = -(rec.meas_disp[1:] / (1.0 + short.truth["amplitude_error"]) - rec.cmd[1:])
    assert float(np.mean((short_by * moves)[moves != 0])) == pytest.approx(listed, rel=0.05)


def test_an_undershoot_record_lists_its_servo_lag_as_a_delay() -> None:
    synthetic = realistic_record("actuator_undershoot", 3, steps=STEPS)
    assert set(synthetic.truth) == {"undershoot"}
    assert set(synthetic.also_present) == {"actuator_delay"}
    assert 0.001 <= synthetic.also_present["actuator_delay"]["tau"] <= 0.003


def test_other_realism_records_list_no_second_effect() -> None:
    for effect in ("actuator_delay", "sensor_bias", "pinching", "none"):
        assert realistic_record(effect, 7, steps=200).also_present == {}


def test_a_record_cached_before_the_second_effects_were_listed_is_made_anew(
        tmp_path: Path) -> None:
    item = bench_items(2, 14, 200, True, str(tmp_path))[1]  # an amplitude record, gain < 1
    fresh = generate(item)
    (cached,) = tmp_path.iterdir()
    old = pickle.loads(cached.read_bytes())
    object.__delattr__(old, "also_present")  # as a pickle written by the earlier code
    cached.write_bytes(pickle.dumps(old))
    again = generate(item)
    assert isinstance(again, SyntheticRecord) and isinstance(fresh, SyntheticRecord)
    assert again.also_present == fresh.also_present != {}
    assert "also_present" in vars(pickle.loads(cached.read_bytes()))


def test_credit_counts_a_second_effect_only_when_the_record_lists_it() -> None:
    amp, under = "actuator_amplitude", "actuator_undershoot"
    pair = "actuator_amplitude+actuator_undershoot"
    assert credit(amp, amp, [under]) == 1.0  # the primary alone
    assert credit(amp, pair, [under]) == 1.0  # the primary with what the rig added
    assert credit(amp, f"{under}+{amp}", {under: {"undershoot": 0.1}}) == 1.0  # any order
    assert credit(amp, pair) == 0.5  # strict: the truth is the primary alone
    assert credit(amp, pair, ["actuator_delay"]) == 0.5  # not what the rig added
    assert credit(amp, under, [under]) == 0.0  # the second effect without the primary
    assert credit(amp, "actuator_delay", [under]) == 0.0
    assert credit("none", "sensor_noise") == 0.0


def test_the_summary_gives_both_figures_and_names_the_records_between_them() -> None:
    also = {"actuator_undershoot": {"undershoot": 0.05}}
    rows: list[dict[str, Any]] = [
        {"index": i, "seed": 100 + i, "effect": t, "predicted": p, "also_present": a,
         "estimates": {"amplitude_error": -0.05, "undershoot": 0.049},
         "relative_errors": {"magnitude": 0.01}, "shrink_pct": 90.0, "diagnose_seconds": 1.0,
         "law": "bouc-wen", "confidence": 0.9, "gap_before_pct": 5.0, "truth": {},
         "baseline": "bouc-wen"}
        for i, (t, p, a) in enumerate([
            ("actuator_amplitude", "actuator_amplitude+actuator_undershoot", also),
            ("actuator_amplitude", "actuator_amplitude", also),
            ("actuator_amplitude", "actuator_delay+actuator_amplitude", also),
            ("none", "none", {})])]
    s = summarise_bench(rows)
    assert s["top1_pct"] == pytest.approx(75.0) and s["top1_strict_pct"] == pytest.approx(50.0)
    assert s["effects_top1_strict_pct"] == pytest.approx(100.0 / 3)
    assert [r["index"] for r in s["rig_added"]] == [0]
    assert [f["index"] for f in s["failures"]] == [2]
    assert s["per_effect"]["actuator_amplitude"] == {
        "records": 3, "correct": 2, "correct_strict": 1, "credit": 2.5}
    text = format_bench(s, 1, 1.0, realism=True)
    assert "top-1 50.0 % strict, 75.0 % counting effects the rig really adds" in text
    assert "record 0 (seed 100) actuator_amplitude -> actuator_amplitude+actuator_undershoot " \
           "(undershoot 0.05 put in, 0.049 found)" in text
    plain = format_bench(summarise_bench([{**r, "also_present": {}} for r in rows]), 1, 1.0)
    assert "strict" not in plain and "top-1 50.0 %" in plain


def test_the_specimen_law_varies_between_records() -> None:
    laws = {realistic_record("none", seed, steps=200).law for seed in range(8)}
    assert laws == {"bouc-wen", "menegotto-pinto"}


def test_the_bench_runs_in_realism_mode(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "bench.json"
    rc = main(["diagnose-bench", "--realism", "--n", "2", "--seed", "4", "--steps", "300",
               "--workers", "1", "--json", str(out), "--no-progress"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "diagnose-bench --realism: 2 records" in printed
    assert "strict" in printed and "counting effects the rig really adds" in printed
    doc = json.loads(out.read_text())
    assert doc["realism"] is True
    made = [realistic_record(e, 4 * 100_003 + i, steps=300)
            for i, e in enumerate(("actuator_delay", "actuator_amplitude"))]
    assert [r["law"] for r in doc["records"]] == [m.law for m in made]
    assert [r["also_present"] for r in doc["records"]] == [m.also_present for m in made]
    assert {"top1_pct", "top1_strict_pct", "rig_added"} <= set(doc["summary"])
    assert np.isfinite(doc["summary"]["top1_pct"])
