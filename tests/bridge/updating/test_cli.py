"""``fresco-bridge updater pretrain|replay`` end to end on real files and a real run directory."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fresco_bridge.cli import main
from fresco_bridge.updating.modelfile import load_model
from tests.support.histories import disp_history, force_history
from tests.support.recorded_run import record_run

N = 160


def _write(path: Path, header: list[str], *cols: np.ndarray) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for row in zip(*cols, strict=True):
            w.writerow([repr(float(v)) for v in row])
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("replay")
    t = np.arange(N) * 0.01
    d_src = disp_history(N, seed=21, amp=4.0)
    d_twin = 0.7 * d_src + 0.3 * disp_history(N, seed=22, amp=3.0)
    d_off = disp_history(N, seed=23, amp=3.0)
    return {
        "source": _write(root / "src.csv", ["time", "disp", "force"], t, d_src,
                         force_history(d_src)),
        "twin": _write(root / "twin.csv", ["time", "disp", "force"], t, d_twin,
                       force_history(d_twin)),
        "offline": _write(root / "offline.csv", ["time", "disp", "force"], t, d_off,
                          force_history(d_off)),
        "root": root,
    }


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open() as fh:
        return list(csv.DictReader(fh))


def test_pretrain_csv_writes_model_and_plot(files: dict[str, Path],
                                            capsys: pytest.CaptureFixture[str]) -> None:
    out = files["root"] / "damper.pt"
    code = main(["updater", "pretrain", str(files["offline"]), "-o", str(out),
                 "--iterations", "15", "--seed", "2"])
    assert code == 0
    text = capsys.readouterr().out
    assert "wrote" in text and "free-run MAETH" in text
    model = load_model(out)
    assert model.net.n_params == 301 and model.training["iterations"] == 15
    assert len(model.offline_d) == N and model.training["source"] == str(files["offline"])
    assert out.with_suffix(".png").stat().st_size > 10_000


def test_recurrence_warning_only_when_the_free_run_errs_beyond_the_measured_peak() -> None:
    from fresco_bridge.updating.ann import recurrence_warning

    assert recurrence_warning(3.0, 17.7) is None
    assert recurrence_warning(17.7, 17.7) is None
    text = recurrence_warning(122.6, 17.7)
    assert text is not None and text.startswith("warning: ")
    assert "122.6 kN" in text and "17.7 kN" in text and "unstable" in text


def test_pretrain_run_directory(tmp_path: Path) -> None:
    run_dir, _ = record_run(tmp_path, steps=120, hold_at_end=False)
    out = tmp_path / "run.pt"
    assert main(["updater", "pretrain", str(run_dir), "-o", str(out), "--iterations", "5",
                 "--no-plot"]) == 0
    model = load_model(out)
    assert len(model.offline_force) == 120  # every committed step of the session
    assert "site spring" in model.training["source"]
    assert main(["updater", "pretrain", str(run_dir), "-o", str(out), "--site", "x"]) == 2


def test_replay_writes_predictions_and_scores(files: dict[str, Path],
                                              capsys: pytest.CaptureFixture[str]) -> None:
    out = files["root"] / "pred_none.csv"
    code = main(["updater", "replay", "--source", str(files["source"]), "--twin",
                 str(files["twin"]), "--updater", "none", "--option", "model=\"bwbn\"",
                 "--option", "params=" + json.dumps(_bwbn_params()), "-o", str(out), "--quiet"])
    assert code == 0
    text = capsys.readouterr().out
    assert "MAETH 0 kN" in text  # the twin's true law predicts the twin exactly
    rows = _rows(out)
    assert list(rows[0]) == ["step", "disp", "force_pred", "force_true"] and len(rows) == N
    summary = json.loads(out.with_suffix(".json").read_text())
    assert summary["metrics_kN"]["maeth"] == 0.0 and summary["lag"] is False


def _bwbn_params() -> dict[str, float]:
    from tests.support.histories import DAMPER_BWBN

    return DAMPER_BWBN


def test_replay_online_ann_with_model_file_and_lag(files: dict[str, Path]) -> None:
    model = files["root"] / "damper.pt"
    if not model.exists():
        main(["updater", "pretrain", str(files["offline"]), "-o", str(model), "--iterations",
              "15", "--no-plot"])
    scores, base = {}, {}
    for name, extra in (("offline_ann", []), ("online_ann", ["--option", "max_iterations=3",
                                                             "--option", "offline_samples=100"])):
        out = files["root"] / f"pred_{name}.csv"
        assert main(["updater", "replay", "--source", str(files["source"]), "--twin",
                     str(files["twin"]), "--updater", name, "--model", str(model), "--lag",
                     *extra, "-o", str(out), "--quiet"]) == 0
        summary = json.loads(out.with_suffix(".json").read_text())
        assert summary["lag"] is True and summary["options"]["model_file"] == str(model)
        scores[name] = summary["metrics_kN"]["maeth"]
        # the baseline: the Bilinear calibrated to the model file's own offline database
        assert summary["baseline"]["updater"].startswith("none --offline")
        base[name] = summary["baseline"]["metrics_kN"]["maeth"]
    assert all(np.isfinite(v) for v in scores.values())
    assert base["offline_ann"] == base["online_ann"] > 0.0


def test_replay_without_a_baseline_when_the_model_database_is_too_short(
    files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A model pre-trained on 5 samples: the replay still scores, and says why no baseline."""
    model = tmp_path / "tiny.pt"
    assert main(["updater", "pretrain", str(files["offline"]), "-o", str(model), "--samples",
                 "5", "--iterations", "3", "--no-plot"]) == 0
    out = tmp_path / "pred.csv"
    assert main(["updater", "replay", "--source", str(files["source"]), "--twin",
                 str(files["twin"]), "--updater", "offline_ann", "--model", str(model),
                 "--quiet", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "no calibrated-Bilinear baseline: updater 'none': offline: calibration needs" in text
    summary = json.loads(out.with_suffix(".json").read_text())
    assert "baseline" not in summary and np.isfinite(summary["metrics_kN"]["rms"])


def test_replay_units_round_trip(files: dict[str, Path], tmp_path: Path) -> None:
    """The same data in m and N give the same predictions, written back in m and N."""
    rows = _rows(files["source"])
    t = np.array([float(r["time"]) for r in rows])
    d = np.array([float(r["disp"]) for r in rows])
    f = np.array([float(r["force"]) for r in rows])
    src = _write(tmp_path / "src_si.csv", ["time", "disp", "force"], t, d / 1000, f * 1000)
    out_si, out_mm = tmp_path / "si.csv", tmp_path / "mm.csv"
    assert main(["updater", "replay", "--source", str(src), "--twin", str(src), "--updater",
                 "none", "--units", "m,N", "-o", str(out_si), "--quiet"]) == 0
    assert main(["updater", "replay", "--source", str(files["source"]), "--twin",
                 str(files["source"]), "--updater", "none", "-o", str(out_mm), "--quiet"]) == 0
    si, mm = _rows(out_si), _rows(out_mm)
    assert float(si[50]["force_pred"]) == pytest.approx(1000 * float(mm[50]["force_pred"]))


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("time,disp\n0,1\n", r"src\.csv:1: missing column\(s\) meas_force \(or force\)"),
        ("time,disp,force\n0,1,2\n0.01,2,nan\n",
         r"src\.csv:3: column force is 'nan', not a finite number"),
        ("time,disp,force\n0,1,2\n0.02,2,3\n0.01,3,4\n",
         r"src\.csv: time is not strictly increasing at line 4 \(0\.02 then 0\.01\)"),
        ("time,disp,force\n0,1,2\n0.01,x,3\n", r"src\.csv:3: column disp is 'x', not a number"),
        ("", r"src\.csv: empty file"),
    ],
)
def test_bad_csv_is_a_clear_error(files: dict[str, Path], tmp_path: Path, content: str,
                                  message: str, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "src.csv"
    bad.write_text(content)
    out = tmp_path / "pred.csv"
    code = main(["updater", "replay", "--source", str(bad), "--twin", str(files["twin"]),
                 "--updater", "none", "-o", str(out)])
    assert code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ")
    assert re.search(message, err), err
    assert not out.exists()


def test_replay_none_with_offline_is_the_calibrated_bilinear(
    files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--updater none --offline`` is the baseline a lab compares an updater with."""
    from fresco_bridge.lawfit import calibrate_bilinear
    from sim_actuator.models import make_model

    out = tmp_path / "cal.csv"
    assert main(["updater", "replay", "--source", str(files["source"]), "--twin",
                 str(files["twin"]), "--updater", "none", "--offline", str(files["offline"]),
                 "--quiet", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "MAETH" in text and "calibrated to the same offline" not in text  # it is the baseline
    assert "baseline" not in json.loads(out.with_suffix(".json").read_text())
    off = _rows(files["offline"])
    law = make_model("bilinear", **calibrate_bilinear([float(r["disp"]) for r in off],
                                                      [float(r["force"]) for r in off]))
    for r in _rows(out):
        assert float(r["force_pred"]) == law.set_trial(float(r["disp"]))[0]
        law.commit()


def test_bad_options_are_clear_errors(files: dict[str, Path], tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    base = ["updater", "replay", "--source", str(files["source"]), "--twin", str(files["twin"]),
            "-o", str(tmp_path / "p.csv")]
    assert main([*base, "--updater", "none", "--option", "bogus=1"]) == 2
    assert "unknown option(s) bogus" in capsys.readouterr().err
    assert main([*base, "--updater", "online_ukf", "--model", "m.pt"]) == 2
    assert "takes no model file" in capsys.readouterr().err
    assert main([*base, "--updater", "offline_ann", "--model", str(tmp_path / "no.pt")]) == 2
    assert "no such model file" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([*base, "--updater", "none", "--units", "furlong,N"])


def test_replay_online_improved_with_an_offline_database_and_its_options(
    files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Our updater from an offline CSV, a subset of its experts, and a bad expert name."""
    base = ["updater", "replay", "--source", str(files["source"]), "--twin", str(files["twin"]),
            "--updater", "online_improved", "--offline", str(files["offline"]), "--quiet"]
    out = tmp_path / "pred.csv"
    assert main([*base, "--option", 'experts="reversal,reversal+memory"', "-o", str(out)]) == 0
    text = capsys.readouterr().out
    calibrated = json.loads(out.with_suffix(".json").read_text())["baseline"]["metrics_kN"]
    assert re.search(r"the Bilinear calibrated to the same offline database: MAETH [0-9.]+ kN, "
                     r"RMS error [0-9.]+ kN; online_improved is [0-9.]+ % (lower|higher) in "
                     r"MAETH", text), text
    assert main(["updater", "replay", "--source", str(files["source"]), "--twin",
                 str(files["twin"]), "--updater", "none", "--offline", str(files["offline"]),
                 "--quiet", "-o", str(tmp_path / "cal.csv")]) == 0
    capsys.readouterr()
    alone = json.loads((tmp_path / "cal.json").read_text())["metrics_kN"]
    assert calibrated["maeth"] == alone["maeth"] and calibrated["rms"] == alone["rms"]
    rows = _rows(out)
    assert len(rows) == N and all(np.isfinite(float(r["force_pred"])) for r in rows)
    assert main([*base, "--option", 'experts="reversal,plays"', "-o", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "experts must be distinct names" in err
    assert not (tmp_path / "x.csv").exists()


def test_a_reader_that_goes_away_is_not_an_error(files: dict[str, Path], tmp_path: Path) -> None:
    """``fresco-bridge updater replay … | head -0``: the predictions are written, no error line,
    exit 141 (128 + SIGPIPE, as coreutils)."""
    out = tmp_path / "pred.csv"
    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader is gone before the first line
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "fresco_bridge.cli", "updater", "replay", "--source",
             str(files["source"]), "--twin", str(files["twin"]), "--updater", "none",
             "--quiet", "-o", str(out)],
            stdout=write_end, stderr=subprocess.PIPE, text=True, timeout=120, check=False)
    finally:
        os.close(write_end)
    assert proc.returncode == 141, proc.stderr
    assert proc.stderr == ""
    assert len(_rows(out)) == N and out.with_suffix(".json").is_file()


def test_the_light_entry_treats_a_gone_reader_alike(monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """``fresco-bridge diagnose … | head`` goes through ``entry.main``, not ``cli.main``."""
    from fresco_bridge import entry

    def gone(_args: object) -> int:
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(entry, "diagnosis_command", gone)
    assert entry.main(["diagnose", "x.csv"]) == entry.BROKEN_PIPE_EXIT
    assert capsys.readouterr().err == ""
