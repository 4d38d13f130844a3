"""``fresco-bridge diagnose``: a CSV end to end (summary, JSON, report), and bad input -> exit 2.

Every bad input gets one line on stderr naming the problem, exit code 2, no traceback.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.diagnosis.synth import synthetic_record
from fresco_bridge.cli import main
from fresco_bridge.record.rundir import META_FILE, RECORD_FILE


def _write_csv(path: Path, rows: list[list[float]],
               header: str = "time,cmd_disp,meas_disp,meas_force") -> Path:
    lines = [header] + [",".join(repr(float(x)) for x in row) for row in rows]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _rows(n: int = 600, seed: int = 4) -> list[list[float]]:
    rec = synthetic_record("friction", seed, steps=n).record
    assert rec.meas_disp is not None
    return [list(r) for r in zip(rec.time, rec.cmd, rec.meas_disp, rec.force, strict=True)]


def test_a_csv_is_diagnosed_with_summary_json_and_report(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    csv_path = _write_csv(tmp_path / "test.csv", _rows(450))
    out, report = tmp_path / "d.json", tmp_path / "report"
    rc = main(["diagnose", str(csv_path), "--json", str(out), "--report", str(report),
               "--no-progress"])
    text = capsys.readouterr().out
    assert rc == 0
    assert "VERDICT   friction" in text and "candidates" in text
    doc = json.loads(out.read_text())
    assert doc["schema"] == "fresco-bridge/diagnosis/2"
    assert doc["verdict"]["effect"] == "friction" and 0.0 <= doc["verdict"]["confidence"] <= 1.0
    names = [e["name"] for e in doc["effects"]]
    assert sorted(names) == sorted(["actuator_delay", "actuator_amplitude",
                                    "actuator_undershoot", "backlash", "friction", "pinching",
                                    "degradation", "rate_dependence", "sensor_bias",
                                    "sensor_noise"])
    for e in doc["effects"]:
        assert {"name", "params", "gap_before", "gap_after", "shrink_pct"} <= set(e)
    assert {"layers", "time", "amplitude", "phase"} <= set(doc["localization"])
    for png in ("hysteresis_overlay", "residual_vs_phase", "measured_vs_command",
                "residual_spectrum"):
        assert (report / f"{png}.png").read_bytes()[:4] == b"\x89PNG"
    assert json.loads((report / "diagnosis.json").read_text())["verdict"] == doc["verdict"]


def _no_steps_run(tmp_path: Path) -> Path:
    run = tmp_path / "20260101T000000-empty"
    run.mkdir()
    (run / META_FILE).write_text(json.dumps({"sites": ["s"]}))
    (run / RECORD_FILE).write_text(json.dumps({"seq": 1, "kind": "event", "site": "s",
                                               "event": "session-open"}) + "\n")
    return run


def _bad(tmp_path: Path, case: str) -> list[str]:
    rows = _rows(200, 5)
    if case == "missing columns":
        path = _write_csv(tmp_path / "a.csv", [r[:2] for r in rows], "time,cmd_disp")
    elif case == "nan row":
        rows[57][3] = float("nan")
        path = _write_csv(tmp_path / "a.csv", rows)
    elif case == "time goes back":
        rows[120][0] = rows[100][0]
        path = _write_csv(tmp_path / "a.csv", rows)
    elif case == "too short":
        path = _write_csv(tmp_path / "a.csv", rows[:40])
    elif case == "unknown baseline":
        return ["diagnose", str(_write_csv(tmp_path / "a.csv", rows)), "--baseline", "spline"]
    elif case == "no committed steps":
        return ["diagnose", str(_no_steps_run(tmp_path))]
    elif case == "bad units":
        return ["diagnose", str(_write_csv(tmp_path / "a.csv", rows)), "--units", "disp=ft"]
    else:  # a baseline file with an unknown parameter
        toml = tmp_path / "base.toml"
        toml.write_text('kind = "bouc-wen"\n[params]\nk0 = 5.0\nwidth = 3.0\n')
        return ["diagnose", str(_write_csv(tmp_path / "a.csv", rows)), "--baseline", str(toml)]
    return ["diagnose", str(path)]


@pytest.mark.parametrize(("case", "fragment"), [
    ("missing columns", "missing column(s) meas_force (or force)"),
    ("nan row", "a.csv:59: column meas_force is 'nan'"),
    ("time goes back", "time is not strictly increasing at line 122 (1.19 then 1.0)"),
    ("too short", "too short to split: 40 sample(s)"),
    ("unknown baseline", "unknown baseline 'spline'"),
    ("no committed steps", "the run has no committed steps"),
    ("bad units", "unknown disp unit 'ft'"),
    ("bad baseline file", "params.width: unknown for bouc-wen"),
])
def test_bad_input_is_one_clear_line_and_exit_2(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str],
                                                case: str, fragment: str) -> None:
    rc = main([*_bad(tmp_path, case), "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert fragment in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_a_given_baseline_held_fixed_is_the_sim(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    synthetic = synthetic_record("none", 8, steps=400)
    s = synthetic.specimen
    toml = tmp_path / "base.toml"
    toml.write_text('kind = "bouc-wen"\nfit = false\n[params]\n'
                    + "".join(f"{k} = {s[k]!r}\n" for k in ("k0", "fy", "alpha", "n", "beta",
                                                             "gamma")))
    rec = synthetic.record
    assert rec.meas_disp is not None
    rows = [list(r) for r in zip(rec.time, rec.cmd, rec.meas_disp, rec.force, strict=True)]
    out = tmp_path / "d.json"
    rc = main(["diagnose", str(_write_csv(tmp_path / "a.csv", rows)), "--baseline", str(toml),
               "--json", str(out), "--no-progress"])
    assert rc == 0, capsys.readouterr().err
    doc = json.loads(out.read_text())
    assert doc["baseline"]["fitted"] is False
    assert np.isclose(doc["baseline"]["params"]["k0"], s["k0"])
    assert doc["verdict"]["effect"] == "none"


def test_a_record_its_sim_explains_exactly_shows_no_shrink_and_no_float_dust(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An ideal rig and a bilinear specimen (the simple demo's record): the gap is rounding
    noise, so no shrink is defined against it (``–``, JSON null), and no ``e-19`` is printed."""
    from fresco_bridge.lawfit import law_forces
    from sim_actuator.models.bilinear import Bilinear

    time = np.arange(600) * 0.01
    cmd = 0.5 * time * np.sin(2.0 * np.pi * time / 1.5)
    force = law_forces(Bilinear(k0=8.0, fy=12.0, alpha=0.05), cmd)
    csv_path = _write_csv(tmp_path / "ideal.csv", [list(r) for r in zip(time, cmd, cmd, force,
                                                                        strict=True)])
    out = tmp_path / "d.json"
    assert main(["diagnose", str(csv_path), "--json", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert doc["verdict"]["effect"] == "none", text
    assert doc["baseline"]["gap_withheld"]["total_pct"] < 1e-6
    # against the chosen baseline's zero gap nothing shrinks; a candidate measured from another
    # law family's baseline (pinching, degradation: the Bouc-Wen one) has that baseline's gap
    own = [e for e in doc["effects"] if e.get("compared_with") is None]
    assert len(own) >= 8 and all(e["shrink_pct"] is None and e["score"] is None
                                 for e in own), text
    table = [line for line in text.split("candidates")[1].split("\ntime")[0].splitlines()[1:]
             if not line.startswith("note") and "(vs the" not in line
             and "law family" not in line]
    assert len(table) == len(own) and all(line.split()[-2:] == ["–", "–"] for line in table), text
    assert "e-1" not in text and "e+" not in text and "-0.00" not in text, text
    assert f"wrote     {out}" in text
