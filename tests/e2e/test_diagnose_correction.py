"""``diagnose RUN --against UNCORRECTED`` on two real bridge runs of one record: a compliant
frame (48 kN/mm behind an 8 kN/mm specimen) served by the ``rig`` controller with its external
specimen channel, driven by the project's genericClient; one run corrects
(``[sites.correction]``, tolerance 0.01 mm), the other records the same channel without
correcting (a tolerance no error reaches). The interface gap — the specimen displacement
against the integrator's target — is reported for both, and is smaller with the correction."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from fresco_bridge.cli import main
from fresco_bridge.element_history import read_interface
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record.export import committed_steps
from tests.bridge.sites.test_site_correction import lab
from tests.support.bridge import RunningBridge

CORRECTING = "tolerance = 0.01\nmax_correction = 3.0\nmeasured = \"external\""
RECORDING = "tolerance = 1e9\nmax_correction = 3.0\nmeasured = \"external\""
TARGETS = [8.0 * math.sin(2 * math.pi * i / 40) * (1 + i / 160) for i in range(1, 161)]


def run(tmp_path: Path, correction: str | None) -> Path:
    with RunningBridge(lab(tmp_path, correction), tmp_path / "runs") as b, \
            GenericClientLink("127.0.0.1", b.ports["frame"], 1, timeout=30.0) as link:
        for i, t in enumerate(TARGETS, 1):
            link.set_trial((t,), time=0.01 * i)
            link.force()
            link.commit()
        return b.run_dir


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return {name: run(tmp_path_factory.mktemp(name), c)
            for name, c in [("corrected", CORRECTING), ("recorded", RECORDING),
                            ("plain", None)]}


def test_the_reader_takes_the_integrators_target_not_the_corrected_command(
        runs: dict[str, Path]) -> None:
    h = read_interface(runs["corrected"], site="frame")
    assert h.channel == "external" and h.tolerance == 0.01
    assert h.corrections is not None and int(np.median(h.corrections)) >= 1
    steps = committed_steps(runs["corrected"])
    assert h.target.tolist() == pytest.approx(TARGETS)
    cmd = np.array([s.cmd_disp[0] for s in steps])
    # the committed command is the last corrected one: beyond the target on a compliant frame
    assert np.max(np.abs(cmd) - np.abs(h.target)) > 0.5
    assert np.max(np.abs(h.measured - h.target)) <= 0.01 + 1e-12


def test_diagnose_reports_the_gap_closed_against_the_uncorrected_run(
        runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out, corrections = tmp_path / "d.json", tmp_path / "corrections.csv"
    folder = runs["corrected"] / "diagnosis-frame"  # where the run's report finds it
    rc = main(["diagnose", str(runs["corrected"]), "--site", "frame", "--against",
               str(runs["recorded"]), "--json", str(out), "--report", str(folder),
               "--no-progress"])
    printed = capsys.readouterr()
    assert rc == 0, printed.err
    gap = json.loads(out.read_text())["interface_gap"]
    mine, theirs = gap["run"], gap["against"]
    assert mine["channel"] == theirs["channel"] == "external" and not gap["notes"]
    assert mine["steps"] == theirs["steps"] == len(TARGETS)
    assert theirs["nrms_pct"] > 5.0  # the frame takes 1/7 of every command
    assert mine["nrms_pct"] < 0.1 * theirs["nrms_pct"]
    assert gap["closed_pct"] == pytest.approx(100 * (1 - mine["nrms_pct"] / theirs["nrms_pct"]))
    assert mine["not_converged"] == 0 and theirs["corrections_max"] == 0
    assert "gap closed" in printed.out
    assert json.loads((folder / "diagnosis.json").read_text())["interface_gap"] == gap
    assert main(["report", str(runs["corrected"]), "-o", str(tmp_path / "r.html")]) == 0
    section = (tmp_path / "r.html").read_text().split('id="diagnosis-frame"')[1]
    assert (f"{mine['nrms_pct']:.2f} % (uncorrected run {theirs['nrms_pct']:.2f} %: "
            f"{gap['closed_pct']:.2f} % closed)") in section
    # the figures are those of the record's correction lines, as export --corrections writes them
    assert main(["export", str(runs["corrected"]), "--corrections", "-o",
                 str(corrections)]) == 0
    with corrections.open() as fh:
        rows = list(csv.DictReader(fh))
    last = {int(r["step"]): r for r in rows}
    target = np.array([float(r["target"]) for r in last.values()])
    measured = np.array([float(r["measured"]) for r in last.values()])
    expected = 100 * np.sqrt(np.sum((measured - target) ** 2) / np.sum(target**2))
    assert mine["nrms_pct"] == pytest.approx(expected)
    assert mine["peak_error_mm"] == pytest.approx(np.max(np.abs(measured - target)))


def test_an_uncorrected_run_on_another_channel_is_said(runs: dict[str, Path]) -> None:
    from fresco_bridge.diagnosis.interface_gap import interface_gap

    gap = interface_gap(runs["corrected"], "frame", runs["plain"])
    assert gap is not None and gap["against"]["channel"] == "daq"
    assert any("different channels" in n for n in gap["notes"])
    assert interface_gap(runs["plain"], "frame") is None  # nothing beyond the diagnosis' own
    reversed_ = interface_gap(runs["recorded"], "frame", runs["corrected"])
    assert reversed_ is not None and reversed_["closed_pct"] < 0
    assert any("give the corrected run first" in n for n in reversed_["notes"])


def test_against_a_csv_is_refused(runs: dict[str, Path], tmp_path: Path,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    csv_path = tmp_path / "steps.csv"
    assert main(["export", str(runs["plain"]), "-o", str(csv_path)]) == 0
    rc = main(["diagnose", str(csv_path), "--against", str(runs["plain"]), "--no-progress"])
    assert rc == 2 and "--against compares two run directories" in capsys.readouterr().err
    rc = main(["diagnose", str(runs["corrected"]), "--site", "frame", "--against",
               str(csv_path), "--no-progress"])
    assert rc == 2 and "needs a run directory" in capsys.readouterr().err
