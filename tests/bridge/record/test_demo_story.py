"""``fresco-bridge demo``: the paper's story on embedded defaults, and what its report shows.

One shortened demo (6 s of record) through the CLI, as a user runs it: the characterisation run,
the hybrid test with the rig damper and its served twin, the scores, the diagnosis, the report.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fresco_bridge.cli import main as cli_main
from fresco_bridge.demo_story import characterisation_path, story_config_text
from fresco_bridge.numbers import pct
from fresco_bridge.record.export import committed_steps
from fresco_bridge.report.html import write_report
from tests.bridge.record.test_report import PNG_SIGNATURE, parse


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any], str]:
    runs = tmp_path_factory.mktemp("runs")
    assert cli_main(["demo", "--duration", "6", "--runs", str(runs), "--no-progress"]) == 0
    (run_dir,) = runs.glob("*-demo")
    summary = json.loads((run_dir / "summary.json").read_text(encoding="utf-8"))
    return run_dir, summary, str(runs)


def test_the_demo_needs_nothing_outside_the_package() -> None:
    text = story_config_text(Path("/runs/char"))
    assert 'preset = "damper-lab"' in text and 'kind = "updatable"' in text
    assert "shared" not in text and "[telemetry]" not in text
    path = characterisation_path()
    assert path[0] == 0.0 and path[-1] == 0.0 and np.max(np.abs(path)) == pytest.approx(16.0)


def test_the_demo_runs_both_sites_and_the_characterisation_feeds_the_twin(
        demo: tuple[Path, dict[str, Any], str]) -> None:
    run_dir, summary, runs = demo
    char_dir = Path(summary["characterisation_dir"])
    assert char_dir.parent == Path(runs) and char_dir.name.endswith("-demo-characterisation")
    assert f'offline = "{char_dir.resolve()}"' in (run_dir / "config.toml").read_text()
    steps = committed_steps(run_dir)
    damper = [s for s in steps if s.site == "damper"]
    twin = [s for s in steps if s.site == "twin"]
    assert len(damper) == len(twin) == summary["steps"] + 1 == 601
    assert len(committed_steps(char_dir)) == characterisation_path().size  # from d = 0
    # the rig's effects are in the record: the measurement is not the command
    err = np.array([s.meas_disp[0] - s.cmd_disp[0] for s in damper])
    assert 0.01 < np.max(np.abs(err)) < 1.0
    assert summary["max_tracking_error_mm"] == pytest.approx(np.max(np.abs(err)), rel=1e-9)


def test_the_updated_twin_beats_the_calibrated_bilinear(
        demo: tuple[Path, dict[str, Any], str]) -> None:
    tw = demo[1]["twin"]
    assert tw["updater"] == "online_improved"
    assert tw["updated"]["rmseth_kN"] < 0.5 * tw["calibrated_bilinear"]["rmseth_kN"]
    assert tw["rmseth_reduction_pct"] > 50.0
    assert tw["calibrated_bilinear"]["params"]["k0"] > 0.0


def test_the_report_shows_tracking_error_the_served_twin_and_the_diagnosis(
        demo: tuple[Path, dict[str, Any], str]) -> None:
    run_dir, summary, _ = demo
    rep = parse(run_dir / "report.html")
    assert rep.sections[:5] == ["overview", "summary", "site-damper", "site-twin",
                                "updating-twin"]
    assert "diagnosis-damper" in rep.sections
    (detail,) = rep.summary["sites"]["damper"]["detail"]
    assert detail["max_tracking_error"] > 0.01 and detail["nrms"] > 1e-4  # not flat zeros
    # the twin has no actuator: no tracking numbers shown for it (no zeros that look measured)
    assert [t for site, key, t in rep.cells if site == "twin" and key == "nrms"] == ["–"]
    images = dict(rep.images)
    assert {"twin hysteresis", "twin updating", "damper diagnosis overlay"} <= set(images)
    assert (run_dir / "twin_vs_bilinear.png").read_bytes().startswith(PNG_SIGNATURE)
    assert all(png.startswith(PNG_SIGNATURE) for png in images.values())
    # the twin's served force is a hysteresis of the damper's size, not a constant
    forces = [s.meas_force[0] for s in committed_steps(run_dir) if s.site == "twin"]
    assert np.std(forces) > 1.0
    cells = {key: text for _, key, text in rep.cells}
    diagnosis = summary["diagnosis"]
    assert diagnosis["effect"] not in ("none", "unexplained", "baseline_misfit")
    assert cells["verdict"].startswith(diagnosis["effect"])
    assert diagnosis["shrink_pct"] > 20.0 and diagnosis["magnitude"]
    assert cells["shrink"] == pct(diagnosis["shrink_pct"], 1)
    assert next(iter(diagnosis["magnitude"])) in cells["magnitude"]


def test_the_report_opens_with_a_summary_whose_figures_are_the_runs_own(
        demo: tuple[Path, dict[str, Any], str]) -> None:
    """The first section a test engineer reads: each headline figure equals the run's JSON
    (summary.json, diagnosis-damper/diagnosis.json), shown rounded beside its exact value."""
    run_dir, summary, _ = demo
    rep = parse(run_dir / "report.html")
    assert rep.sections[0] == "overview"
    figures = {key: (float(value), text) for key, (value, text) in rep.figures.items()}
    diagnosis = json.loads((run_dir / "diagnosis-damper" / "diagnosis.json").read_text())
    verdict = diagnosis["verdict"]
    twin = summary["twin"]
    expected = {
        "tracking.damper.max_tracking_error_mm": summary["max_tracking_error_mm"],
        "tracking.damper.nrms": summary["tracking_nrms"],
        "holds.damper": summary["holds"],
        "holds.twin": 0,
        "twin.updated.rmseth_kN": twin["updated"]["rmseth_kN"],
        "twin.calibrated_bilinear.rmseth_kN": twin["calibrated_bilinear"]["rmseth_kN"],
        "twin.rmseth_reduction_pct": twin["rmseth_reduction_pct"],
        "diagnosis.damper.confidence": verdict["confidence"],
        "diagnosis.damper.gap_before_pct": verdict["gap_before_pct"],
        "diagnosis.damper.gap_after_pct": verdict["gap_after_pct"],
    }
    assert {k: v for k, (v, _) in figures.items()} == expected
    assert figures["twin.rmseth_reduction_pct"][1] == pct(twin["rmseth_reduction_pct"], 0)
    assert figures["diagnosis.damper.confidence"][1] == f"{verdict['confidence']:.2f}"
    text = "".join(rep.text)
    assert verdict["effect"] in text and "What to do next" in text
    assert rep.summary["overview"]["twin"]["rmseth_reduction_pct"] == twin["rmseth_reduction_pct"]
    assert rep.summary["overview"]["diagnosis"]["damper"]["effect"] == verdict["effect"]


def test_report_renders_the_diagnosis_again_and_can_compute_it(
        demo: tuple[Path, dict[str, Any], str], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    run_dir, _, _ = demo
    again = parse(write_report(run_dir, tmp_path / "again.html"))
    assert "diagnosis-damper" in again.sections
    assert cli_main(["report", str(run_dir), "--diagnose", "nosuch"]) != 0
    assert "no such site" in capsys.readouterr().err


def test_the_closing_note_names_real_next_commands(demo: tuple[Path, dict[str, Any], str],
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    from fresco_bridge.demo_story import format_story

    run_dir, summary, _ = demo
    note = format_story(summary)
    for needle in (f"diagnose {run_dir} --site damper", "demo --simple", "updater replay",
                   "study paper", "updating cuts the RMS error by"):
        assert needle in note
    # the replay command it prints runs as written
    line = next(ln for ln in note.splitlines() if "updater replay" in ln)
    args = line.split("fresco-bridge", 1)[1].split()
    args[args.index("-o") + 1] = str(run_dir.parent / "ukf.csv")
    assert cli_main([*args, "--quiet"]) == 0
    assert (run_dir.parent / "ukf.csv").read_text().startswith("step,")
