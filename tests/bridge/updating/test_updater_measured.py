"""``updater pretrain`` on a measured friction damper (``../shared``): the paper's network fits
the rectangular friction loop one step ahead, but its own recurrence runs away, and the command
says so (every updater on these data: ``benchmarks/updater_measured.py``, BENCHMARKS.md,
"Online updating")."""

from __future__ import annotations

from pathlib import Path

import pytest

from fresco_bridge.cli import main
from tests.support.measured import BRFD, brfd_csv


def test_pretrain_warns_that_the_papers_recurrence_is_unstable_on_the_damper(
        shared_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    if not BRFD.is_dir():
        pytest.skip(f"no BRFD data at {BRFD}")
    offline = brfd_csv("0.25Hz30lbtension1amplitude", 64, tmp_path / "sine.csv")
    assert main(["updater", "pretrain", str(offline), "-o", str(tmp_path / "m.pt"),
                 "--units", "in,kip", "--no-plot"]) == 0
    err = capsys.readouterr().err
    assert "warning: the network's own recurrence" in err and "unstable" in err
