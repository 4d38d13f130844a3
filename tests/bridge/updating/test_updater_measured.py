"""``benchmarks.updater_measured``: every updater on the measured friction damper, end to end
through ``fresco-bridge updater pretrain|replay`` (a short, coarse slice: the harness, not the
numbers, which live in BENCHMARKS.md "updating part 17")."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from benchmarks import updater_measured as um


@pytest.fixture()
def brfd(shared_dir: Path) -> Path:
    path = shared_dir / "data" / "measured" / "rotary_friction_damper_BRFD"
    if not path.is_dir():
        pytest.skip(f"no BRFD data at {path}")
    return path


def test_load_brfd_thins_the_record(brfd: Path) -> None:
    full = um.load_brfd(um.KO_DBE, 1)
    thin = um.load_brfd(um.KO_DBE, 8)
    assert full.shape == (27342, 3) and thin.shape == (3418, 3)
    assert (thin == full[::8]).all()


def test_a_pair_runs_every_case_through_the_cli(brfd: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    um.main(["-o", str(tmp_path), "--workers", "1", "--decimate", "64",
             "--only", f"{um.KO_DBE}->{um.KO_MCE}"])
    printed = capsys.readouterr().out
    assert f"| {um.KO_DBE}->{um.KO_MCE} |" in printed
    summary = json.loads((tmp_path / "summary.json").read_text())
    rows = {r["case"]: r for r in summary["rows"]}
    assert set(rows) == set(um.CASES)
    for case, row in rows.items():
        assert "error" not in row, (case, row)
        assert row["steps"] == 428 and row["bounded"] and math.isfinite(row["rms_kN"])
    # every case scored against the same measured twin force
    assert len({round(r["twin_peak_kN"], 9) for r in rows.values()}) == 1
    assert (tmp_path / "brfd.pt").is_file()


def test_pretrain_warns_that_the_papers_recurrence_is_unstable_on_the_damper(
        brfd: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The rectangular friction loop: a fine one-step fit whose own recurrence runs away."""
    from fresco_bridge.cli import main

    offline = um._write_csv(tmp_path / "sine.csv", um.load_brfd(um.OFFLINE_RECORD, 64))
    assert main(["updater", "pretrain", str(offline), "-o", str(tmp_path / "m.pt"),
                 "--units", um.UNITS, "--no-plot"]) == 0
    err = capsys.readouterr().err
    assert "warning: the network's own recurrence" in err and "unstable" in err
