"""``diagnose-bench --independent``: records from specimens and effect forms written anew.

Checked here: the generator's contract (deterministic per seed, every effect changes the record
in its physical form, the truth it reports is what it put in, labels the diagnosis can score),
the laws' physics (R decay, saturating isotropic hardening, pinching, degradation), the scoring
of pairs (any order right, half credit for one member, 'none' never a systematic effect), and
the bench end to end. Its accuracy is a benchmark (BENCHMARKS.md, "Diagnosis"), not a test.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.diagnosis.bench import bench_items, credit, summarise_bench
from benchmarks.diagnosis.independent import (
    CYCLE,
    EFFECTS,
    PAIR,
    UNDERSHOOT,
    case_label,
    independent_record,
)
from benchmarks.diagnosis.independent_laws import (
    BoucWenBaberNoori,
    GiuffreMenegottoPinto,
    IsotropicBilinear,
    SpecimenLaw,
)
from fresco_bridge import indicators as ind
from fresco_bridge.cli import main
from fresco_bridge.diagnosis.names import EFFECT_NAMES

STEPS = 600


def _bouc_wen_seed() -> int:
    """A seed whose specimen is Bouc-Wen, so that a pinching or degradation record (BWBN)
    and the record without an effect share the specimen."""
    seed = next(s for s in range(50) if independent_record("none", s, steps=200).law
                == "bouc-wen")
    return seed


def _rms(a: Any) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def test_a_record_is_a_function_of_its_seed() -> None:
    a = independent_record("friction+sensor_noise", 21, steps=STEPS)
    b = independent_record("friction+sensor_noise", 21, steps=STEPS)
    c = independent_record("friction+sensor_noise", 22, steps=STEPS)
    assert a.truth == b.truth and a.specimen == b.specimen and a.law == b.law
    for name in ("time", "cmd", "force", "meas_disp"):
        assert np.array_equal(getattr(a.record, name), getattr(b.record, name))
    assert not np.array_equal(a.record.force, c.record.force)
    assert a.truth != c.truth
    assert [case_label(9, i) for i in range(30)] == [case_label(9, i) for i in range(30)]


def test_lengths_and_intervals_are_drawn_in_the_stated_ranges() -> None:
    records = [independent_record("none", s) for s in range(6)]
    sizes = [r.record.size for r in records]
    dts = [float(r.record.time[1] - r.record.time[0]) for r in records]
    assert all(1500 <= n <= 6000 for n in sizes) and len(set(sizes)) > 1
    assert all(0.01 <= dt <= 0.02 for dt in dts)
    assert {r.law for r in records} <= {"menegotto-pinto", "bilinear-isotropic", "bouc-wen"}


def test_labels_are_names_the_diagnosis_scores_and_a_fifth_are_pairs() -> None:
    known = {*EFFECT_NAMES, UNDERSHOOT}  # the undershoot candidate: issue 29, item 0
    labels = [case_label(seed, i) for seed in (1, 2, 3) for i in range(3 * len(CYCLE))]
    pairs = [label for label in labels if "+" in label]
    assert len(pairs) == len(labels) * CYCLE.count(PAIR) // len(CYCLE)
    assert CYCLE.count(PAIR) / len(CYCLE) == pytest.approx(0.2)
    for label in labels:
        members = label.split("+")
        assert label == "none" or set(members) <= known, label
        assert members == sorted(members) and len(set(members)) == len(members)
    assert {m for p in pairs for m in p.split("+")} > {"friction", "pinching"}
    with pytest.raises(ValueError, match="invalid effect label"):
        independent_record("friction+friction", 1, steps=200)
    with pytest.raises(ValueError, match="unknown"):
        independent_record("gremlins", 1, steps=200)


@pytest.mark.parametrize("effect", EFFECTS)
def test_each_effect_changes_the_record(effect: str) -> None:
    seed = _bouc_wen_seed()
    base = independent_record("none", seed, steps=STEPS)
    with_effect = independent_record(effect, seed, steps=STEPS)
    assert with_effect.effect == effect and with_effect.truth
    assert np.array_equal(base.record.cmd, with_effect.record.cmd)  # the same test...
    assert with_effect.specimen["k0"] == base.specimen["k0"]  # ...on the same specimen
    assert base.record.meas_disp is not None and with_effect.record.meas_disp is not None
    force = _rms(with_effect.record.force - base.record.force) / _rms(base.record.force)
    disp = _rms(with_effect.record.meas_disp - base.record.meas_disp) / _rms(
        base.record.meas_disp)
    assert max(force, disp) > 0.01, (force, disp)


def test_delay_and_lag_shift_the_piston_by_their_sum() -> None:
    synthetic = independent_record("actuator_delay", 5, steps=3000)
    rec = synthetic.record
    dt = float(rec.time[1] - rec.time[0])
    assert rec.meas_disp is not None
    lag = ind.xcorr_delay(rec.cmd, rec.meas_disp, dt, 10)
    assert lag == pytest.approx(synthetic.truth["tau"], abs=dt)


def test_undershoot_stops_short_against_the_direction_of_motion() -> None:
    seed = 6
    base = independent_record("none", seed, steps=STEPS)
    short = independent_record(UNDERSHOOT, seed, steps=STEPS)
    assert base.record.meas_disp is not None and short.record.meas_disp is not None
    direction = np.sign(np.diff(base.record.cmd))
    moving = np.abs(np.diff(base.record.cmd)) > 1e-3 * np.max(np.abs(base.record.cmd))
    offset = (short.record.meas_disp - base.record.meas_disp)[1:][moving] * direction[moving]
    assert float(np.median(offset)) == pytest.approx(-short.truth["undershoot"], rel=0.1)


def test_friction_behind_a_spring_is_bounded_by_its_coulomb_force() -> None:
    seed = 7
    base = independent_record("none", seed, steps=STEPS)
    rubbing = independent_record("friction", seed, steps=STEPS)
    extra = np.abs(rubbing.record.force - base.record.force)
    coulomb = rubbing.truth["coulomb"]
    assert 0.5 * coulomb < float(np.percentile(extra, 90)) < 1.2 * coulomb


def test_load_cell_drift_reports_its_mean_offset() -> None:
    seed = 8
    base = independent_record("none", seed, steps=STEPS)
    drifting = independent_record("sensor_bias", seed, steps=STEPS)
    offset = drifting.record.force - base.record.force
    assert float(np.mean(offset)) == pytest.approx(drifting.truth["force_bias"], rel=0.05)
    assert float(np.std(offset)) > 0.0  # it drifts: not a constant


def test_the_pin_gap_leaves_the_force_flat_across_the_clearance() -> None:
    seed = _bouc_wen_seed()
    gappy = independent_record("backlash", seed, steps=STEPS)
    base = independent_record("none", seed, steps=STEPS)
    fy = gappy.specimen["fy"]
    near_zero = np.mean(np.abs(gappy.record.force) < 0.05 * fy)
    assert near_zero > 2.0 * np.mean(np.abs(base.record.force) < 0.05 * fy)


def _drive(law: SpecimenLaw, path: Any) -> Any:
    return np.array([law.step(float(u)) for u in path])


def _cycles(amplitude: float, count: int, per_cycle: int = 400) -> Any:
    s = np.linspace(0.0, count, count * per_cycle + 1)
    return amplitude * np.sin(2.0 * math.pi * s)


def test_menegotto_pinto_rounds_its_reloading_with_the_plastic_excursion() -> None:
    path = _cycles(5.0, 2)  # u_y = 1
    sharp = _drive(GiuffreMenegottoPinto(10.0, 10.0, 0.02, 20.0, 0.0, 0.15), path)
    decayed = _drive(GiuffreMenegottoPinto(10.0, 10.0, 0.02, 20.0, 18.5, 0.15), path)
    np.testing.assert_allclose(sharp[:50], decayed[:50])  # the virgin curve: R = R0 both
    second = slice(len(path) // 2, None)
    assert np.max(np.abs(sharp[second] - decayed[second])) > 0.1 * 10.0
    assert np.max(np.abs(np.diff(decayed))) < 10.0 * np.max(np.abs(np.diff(path))) + 1e-9


def test_isotropic_hardening_grows_the_yield_force_and_saturates() -> None:
    law = IsotropicBilinear(10.0, 10.0, q_inf=4.0, kappa_s=20.0, h_kin=0.05)
    force = _drive(law, _cycles(3.0, 12))
    per = 400
    peaks = [float(np.max(force[i * per:(i + 1) * per])) for i in range(12)]
    assert peaks[3] > peaks[0] + 1.0  # isotropic: the surface grows...
    assert abs(peaks[-1] - peaks[-2]) < 0.05  # ...and saturates
    assert peaks[-1] == pytest.approx(14.0, abs=0.6)  # fy + q_inf (+ a little kinematic)


def test_bwbn_pinching_and_degradation_change_the_loop() -> None:
    path = _cycles(4.0, 6)
    args = (10.0, 10.0, 0.05, 1.5, 0.5, 0.5)
    plain = _drive(BoucWenBaberNoori(*args), path)
    pinched = _drive(BoucWenBaberNoori(*args, zeta_s=0.7, psi0=0.2, q=0.1, p=2.0,
                                       lam=0.5), path)
    degraded = BoucWenBaberNoori(*args, d_nu=0.02, d_eta=0.02)
    softened = _drive(degraded, path)
    late = slice(5 * 400, None)

    def area(f: Any) -> float:
        return abs(float(np.trapezoid(f[late], path[late])))

    assert area(pinched) < 0.93 * area(plain)  # pinched loops enclose less
    assert np.max(softened[late]) < 0.95 * np.max(plain[late])
    assert degraded.energy > 0.0


def test_pairs_score_in_any_order_with_half_credit_for_one_member() -> None:
    assert credit("friction+pinching", "pinching+friction") == 1.0
    assert credit("friction+pinching", "friction") == 0.5
    assert credit("friction", "friction+sensor_noise") == 0.5
    assert credit("friction+pinching", "backlash") == 0.0
    assert credit("none", "sensor_noise") == 0.0
    rows: list[dict[str, Any]] = [
        {"effect": t, "predicted": p, "relative_errors": {}, "shrink_pct": None,
         "diagnose_seconds": 1.0, "law": "bouc-wen"}
            for t, p in [("friction", "friction"), ("backlash", "pinching"),
                         ("friction+pinching", "pinching+friction"),
                         ("degradation+sensor_bias", "sensor_bias"),
                         ("none", "none"), ("none", "sensor_noise"),
                         ("none", "baseline_misfit"), ("none", "friction")]]
    s = summarise_bench(rows)
    assert s["singles_top1_pct"] == pytest.approx(50.0)
    assert s["pairs_exact_pct"] == pytest.approx(50.0)
    assert s["overall_credit_pct"] == pytest.approx(100.0 * 3.5 / 8)
    assert s["none_false_alarm_pct"] == pytest.approx(75.0)
    assert s["none_systematic_pct"] == pytest.approx(25.0)  # only "friction" claims a cause
    assert s["confusion"]["friction+pinching"] == {"friction+pinching": 1}


def test_bench_items_carry_the_independent_labels() -> None:
    items = bench_items(16, 3, None, independent=True)
    assert [i[1] for i in items] == [case_label(3, k) for k in range(16)]
    assert {i[4] for i in items} == {"independent"} and items[0][3] is None
    assert bench_items(1, 3, None)[0][3] == 3000  # the plain bench keeps its default


@pytest.mark.timeout(900)
def test_the_bench_runs_in_independent_mode(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "bench.json"
    rc = main(["diagnose-bench", "--independent", "--n", "2", "--seed", "4", "--steps", "300",
               "--workers", "1", "--json", str(out), "--no-progress"])
    assert rc == 0
    assert "diagnose-bench --independent: 2 records" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert doc["independent"] is True
    rows = doc["records"]
    assert [r["effect"] for r in rows] == [case_label(4, 0), case_label(4, 1)]
    assert [r["law"] for r in rows] == [
        independent_record(r["effect"], 4 * 100_003 + i, steps=300).law
        for i, r in enumerate(rows)]
    assert all(r["samples"] == 300 for r in rows)
    assert np.isfinite(doc["summary"]["overall_credit_pct"])


def test_realism_and_independent_are_exclusive(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["diagnose-bench", "--independent", "--realism", "--n", "1"]) == 2
    assert "choose one generator" in capsys.readouterr().err
