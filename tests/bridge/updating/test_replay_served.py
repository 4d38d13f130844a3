"""``updater replay`` never scores against, nor learns from, an updatable site's served forces:
they are its updater's predictions (a real bridge run with a source and its twin)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from fresco_bridge.cli import main
from fresco_bridge.integrator.link import GenericClientLink
from tests.bridge.twins.test_twin_bridge import TOML
from tests.support.bridge import RunningBridge


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    pytest.importorskip("filterpy")
    root = tmp_path_factory.mktemp("served")
    with RunningBridge(TOML, root) as bridge, \
            GenericClientLink("127.0.0.1", bridge.ports["damper"], 1) as source, \
            GenericClientLink("127.0.0.1", bridge.ports["twin1"], 1) as twin:
        for i in range(1, 41):
            d = 1.5 * math.sin(i / 4.0)
            source.set_trial((d,), time=0.01 * i)
            source.force()
            twin.set_trial((0.8 * d,), time=0.01 * i)
            twin.force()
            source.commit()
            twin.commit()
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
