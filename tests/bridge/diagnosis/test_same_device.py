"""``diagnose A B C --same-device``: one law fitted on all the records, effects consistent
across them reported with each record's departures."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.diagnosis.synth import command_history
from fresco_bridge.cli import main
from fresco_bridge.diagnosis.load import Record, record_from_arrays
from fresco_bridge.diagnosis.model import law_vector
from fresco_bridge.diagnosis.multi import diagnose_device
from fresco_bridge.diagnosis.verdict import Options
from sim_actuator.models.paths import drive

SPECIMEN = {"k0": 10.0, "fy": 20.0, "alpha": 0.03, "n": 2.0, "bg_sum": 1.0, "beta_share": 0.6}
COULOMB = 1.6
"""kN: 8 % of fy, the same fixture friction in every test of the specimen."""


def _record(seed: int, coulomb: float, steps: int = 900) -> Record:
    """One test of the specimen: its own command history (seed), the fixture's friction on
    the piston velocity, 0.3 % load-cell noise."""
    rng = np.random.default_rng(seed)
    cmd = command_history(rng, steps, 0.01, float(rng.uniform(3.0, 6.0)) * 2.0)
    force = drive(*law_vector("bouc-wen", SPECIMEN), cmd, 0.0, 0.2)
    v = np.diff(cmd, prepend=cmd[0])
    force = force + coulomb * np.sign(v) + rng.normal(0.0, 0.003 * 20.0, cmd.size)
    time = np.arange(cmd.size, dtype=np.float64) * 0.01
    return record_from_arrays(time, cmd, force, cmd.copy(), source=f"test {seed}")


EFFECTS = ("friction", "backlash", "sensor_bias", "rate_dependence")


def test_the_same_effect_in_three_records_is_reported_as_consistent() -> None:
    doc = diagnose_device([_record(s, COULOMB) for s in (11, 12, 13)],
                          Options(baseline="bouc-wen", pairs=False, effects=EFFECTS))
    assert doc["baseline"]["kind"] == "bouc-wen"
    assert doc["baseline"]["params"]["k0"] == pytest.approx(10.0, rel=0.05)
    assert doc["story"]["effect"] == "friction", doc["story"]["explanation"]
    top = doc["consistent"][0]
    assert top["effect"] == "friction" and top["magnitudes_agree"]
    assert top["params"]["coulomb"]["values"] == pytest.approx([COULOMB] * 3, rel=0.1)
    # with the story held (the shared law, each test's friction) nothing departs
    assert [p["verdict"] for p in doc["per_record"]] == ["none"] * 3
    assert all(p["departures"] == [] for p in doc["per_record"])
    assert all(r.baseline["fitted"] is False for r in doc["results"])


def test_one_record_that_departs_is_named(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """Two tests with the fixture's friction and one without: friction explains the device
    (fitted per test) but is absent from one test, so it is not consistent: the two records
    with friction name it as their departure. Through the CLI: CSVs in, summary and JSON out."""
    paths = []
    for seed, coulomb in ((21, COULOMB), (22, COULOMB), (23, 0.0)):
        rec = _record(seed, coulomb)
        assert rec.meas_disp is not None
        path = tmp_path / f"t{seed}.csv"
        rows = [",".join(repr(float(x)) for x in row)
                for row in zip(rec.time, rec.cmd, rec.meas_disp, rec.force, strict=True)]
        path.write_text("\n".join(["time,cmd_disp,meas_disp,meas_force", *rows]) + "\n",
                        encoding="utf-8")
        paths.append(str(path))
    out = tmp_path / "device.json"
    rc = main(["diagnose", *paths, "--same-device", "--baseline", "bouc-wen", "--json",
               str(out), "--no-progress"])
    text = capsys.readouterr().out
    assert rc == 0
    doc = json.loads(out.read_text())
    assert doc["schema"] == "fresco-bridge/diagnosis-device/1"
    assert doc["consistent"] == []
    assert doc["story"]["effect"] == "friction" and doc["story"]["consistent"] is False
    assert doc["partial"][0]["absent_from"] == [paths[2]]
    assert [p["departures"] for p in doc["per_record"]] == [["friction"], ["friction"], []]
    assert "STORY     friction" in text and "departures: friction" in text


def test_several_records_need_the_flag(tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    csv = tmp_path / "a.csv"
    csv.write_text("time,cmd_disp,meas_force\n0,0,0\n", encoding="utf-8")
    assert main(["diagnose", str(csv), str(csv), "--no-progress"]) == 2
    assert "--same-device" in capsys.readouterr().err


def test_a_family_change_is_not_the_device_story() -> None:
    """Three tests of a Menegotto-Pinto specimen with no effect, diagnosed on a bilinear law:
    pinching (which drives Bouc-Wen) is measured from the joint Bouc-Wen law, and the story is
    the family change (``baseline_misfit`` naming it), not an effect credited with it."""
    mp = {"k0": 10.0, "fy": 20.0, "alpha": 0.02, "R0": 12.0, "cR1": 0.85, "cR2": 0.1}
    records = []
    for seed in (41, 42, 43):
        rng = np.random.default_rng(seed)
        cmd = command_history(rng, 900, 0.01, float(rng.uniform(3.0, 6.0)) * 2.0)
        force = drive(*law_vector("menegotto-pinto", mp), cmd, 0.0, 0.2)
        force = force + rng.normal(0.0, 0.003 * 20.0, cmd.size)
        time = np.arange(cmd.size, dtype=np.float64) * 0.01
        records.append(record_from_arrays(time, cmd, force, cmd.copy(), source=f"mp {seed}"))
    doc = diagnose_device(records, Options(baseline="bilinear", pairs=False,
                                           effects=("pinching", "degradation", "friction")))
    assert doc["baseline"]["kind"] == "bilinear"
    assert doc["story"]["effect"] == "baseline_misfit", doc["story"]
    assert doc["story"]["better_family"] in ("menegotto-pinto", "steel02")
