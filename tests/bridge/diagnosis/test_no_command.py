"""Records without a command channel: accepted, the interface layer reported as not identifiable
(never fitted, never guessed), what stays identifiable still found."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.diagnosis.synth import synthetic_record
from fresco_bridge.cli import main
from fresco_bridge.diagnosis.load import load_record, record_from_arrays
from fresco_bridge.diagnosis.nocommand import NOT_IDENTIFIABLE
from fresco_bridge.diagnosis.verdict import Options, diagnose


def _csv(path: Path, header: str, *columns: np.ndarray) -> Path:
    rows = [",".join(repr(float(x)) for x in row) for row in zip(*columns, strict=True)]
    path.write_text("\n".join([header, *rows]) + "\n", encoding="utf-8")
    return path


def test_a_record_with_only_the_measured_displacement(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    rec = synthetic_record("friction", 4, steps=600).record
    assert rec.meas_disp is not None
    path = _csv(tmp_path / "no_cmd.csv", "time,meas_disp,meas_force", rec.time, rec.meas_disp,
                rec.force)
    out = tmp_path / "d.json"
    rc = main(["diagnose", str(path), "--json", str(out), "--report", str(tmp_path / "r"),
               "--no-progress"])
    text = capsys.readouterr().out
    assert rc == 0
    doc = json.loads(out.read_text())
    assert doc["record"]["command"] is False
    assert any("no command channel (the record has no cmd_disp column)" in n
               for n in doc["record"]["notes"])
    assert set(doc["not_identifiable"]) == {"actuator_delay", "actuator_amplitude",
                                            "actuator_undershoot"}
    tried = {e["name"] for e in doc["effects"]}
    assert not tried & set(NOT_IDENTIFIABLE)
    assert doc["verdict"]["effect"] == "friction"  # acts between the LVDT and the load cell
    assert "hidden    no command channel" in text
    assert "actuator_delay: not identifiable" in text
    assert "sensor_bias: only the load-cell offset" in text


def test_an_interface_effect_is_never_guessed_without_a_command() -> None:
    """An actuator delay of tens of ms: with the command, ``actuator_delay``; with the measured
    displacement alone the law follows the piston, so nothing is left to explain and the
    delay is listed as not identifiable instead of being fitted."""
    synthetic = synthetic_record("actuator_delay", 2, steps=800)
    rec = synthetic.record
    assert rec.meas_disp is not None
    blind = record_from_arrays(rec.time, rec.meas_disp, rec.force, source="delay, no command",
                               no_command=True)
    result = diagnose(blind, Options(pairs=False)).to_json()
    assert result["verdict"]["effect"] not in NOT_IDENTIFIABLE
    assert result["verdict"]["effect"] == "none", result["verdict"]["explanation"]
    assert "actuator_delay" in result["not_identifiable"]


def test_a_command_equal_to_the_measurement_is_noted_and_the_flag_forces_it(
        tmp_path: Path) -> None:
    """Identical columns are an ideal rig or a copied channel: kept, with a note."""
    rec = synthetic_record("none", 1, steps=300).record
    assert rec.meas_disp is not None
    same = _csv(tmp_path / "same.csv", "time,cmd_disp,meas_disp,meas_force", rec.time,
                rec.meas_disp, rec.meas_disp, rec.force)
    noted = load_record(same)
    assert not noted.no_command and "give --no-command" in noted.notes[-1]
    assert load_record(same, no_command=True).no_command
    both = _csv(tmp_path / "both.csv", "time,cmd_disp,meas_disp,meas_force", rec.time, rec.cmd,
                rec.meas_disp, rec.force)
    assert not load_record(both).no_command
    forced = load_record(both, no_command=True)
    assert forced.no_command and np.array_equal(forced.cmd, rec.meas_disp)
    only = _csv(tmp_path / "only.csv", "time,cmd_disp,meas_force", rec.time, rec.meas_disp,
                rec.force)
    assert load_record(only, no_command=True).no_command
    assert not load_record(only).no_command
