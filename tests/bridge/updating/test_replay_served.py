"""``updater replay`` never scores against, nor learns from, an updatable site's served forces:
they are its updater's predictions (a real bridge run with a source and its twin)."""

from __future__ import annotations

from pathlib import Path

import pytest

from fresco_bridge.cli import main
from fresco_bridge.integrator.link import GenericClientLink
from tests.bridge.twins.test_twin_bridge import TOML
from tests.support.bridge import RunningBridge
from tests.support.serve import lockstep


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    pytest.importorskip("filterpy")
    root = tmp_path_factory.mktemp("served")
    with RunningBridge(TOML, root) as bridge, \
            GenericClientLink("127.0.0.1", bridge.ports["damper"], 1) as source, \
            GenericClientLink("127.0.0.1", bridge.ports["twin1"], 1) as twin:
        lockstep(source, twin, 1, 40)
        path: Path = bridge.run_dir
    return path


def test_served_forces_are_not_scored_against(run_dir: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "pred.csv"
    assert main(["updater", "replay", "--source", str(run_dir), "--site", "damper",
                 "--twin", str(run_dir), "--twin-site", "twin1", "--updater", "online_ukf",
                 "-o", str(out), "--quiet"]) == 0
    captured = capsys.readouterr()
    assert "site 'twin1' is an updatable site" in captured.err
    assert "not scored against" in captured.err
    assert "MAETH" not in captured.out and "lower in" not in captured.out
    assert out.read_text().splitlines()[0] == "step,disp,force_pred"


def test_an_updatable_site_is_no_source_to_learn_from(run_dir: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["updater", "replay", "--source", str(run_dir), "--site", "twin1",
                 "--twin", str(run_dir), "--updater", "online_ukf",
                 "-o", str(tmp_path / "pred.csv"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "site 'twin1' is an updatable site" in err and "learns_from" in err
    assert not (tmp_path / "pred.csv").exists()


def test_the_source_site_itself_is_still_scored(run_dir: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """The tested element's measured forces are a truth: replaying the source onto itself
    scores as before."""
    assert main(["updater", "replay", "--source", str(run_dir), "--site", "damper",
                 "--twin", str(run_dir), "--updater", "online_ukf",
                 "-o", str(tmp_path / "pred.csv"), "--quiet"]) == 0
    assert "MAETH" in capsys.readouterr().out


def test_an_export_says_which_forces_are_predicted_and_replay_heeds_it(
        run_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``fresco-bridge export`` writes each row's site kind and whether its force is a
    prediction; replaying the CSV refuses the twin as a source and does not score against
    its forces, as with the run directory."""
    csv = tmp_path / "steps.csv"
    assert main(["export", str(run_dir), "-o", str(csv)]) == 0
    rows = [r.split(",") for r in csv.read_text().splitlines()]
    assert rows[0][-3:] == ["session", "site_kind", "predicted"]
    assert {(r[2], r[-2], r[-1]) for r in rows[1:]} == {("damper", "experimental", "0"),
                                                         ("twin1", "updatable", "1")}
    capsys.readouterr()
    out = tmp_path / "pred.csv"
    assert main(["updater", "replay", "--source", str(csv), "--site", "damper",
                 "--twin", str(csv), "--twin-site", "twin1", "--updater", "online_ukf",
                 "-o", str(out), "--quiet"]) == 0
    captured = capsys.readouterr()
    assert f"twin: {csv} (site twin1): an updatable site's, as the export says (predicted = 1)" \
        in captured.err
    assert "not scored against" in captured.err and "MAETH" not in captured.out
    assert main(["updater", "replay", "--source", str(csv), "--site", "twin1",
                 "--twin", str(csv), "--twin-site", "damper", "--updater", "online_ukf",
                 "-o", str(tmp_path / "none.csv"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "predicted" in err and "learns_from" in err
    assert not (tmp_path / "none.csv").exists()
    assert main(["updater", "replay", "--source", str(csv), "--site", "damper",
                 "--twin", str(csv), "--twin-site", "damper", "--updater", "online_ukf",
                 "-o", str(out), "--quiet"]) == 0
    assert "MAETH" in capsys.readouterr().out  # the measured site is scored as before
