"""``fresco-bridge diagnose`` on each measured CSV the repository ships, as shipped.

``examples/data/brfd_*.csv`` are ``time,disp,force``: the measured displacement and force of a
friction damper, no command channel. The one CSV vocabulary (``element_history.ALIASES``)
reads them as they are; the diagnosis runs as a user runs it (a real process, the installed
entry point's code), says the record has no command channel and writes its JSON.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from fresco_bridge.diagnosis.names import EFFECT_NAMES

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = sorted((ROOT / "examples" / "data").glob("*.csv"))
VERDICTS = {*EFFECT_NAMES, "none", "unexplained", "baseline_misfit"}


def test_the_repository_ships_measured_csvs() -> None:
    assert len(SHIPPED) >= 3


@pytest.mark.parametrize("csv", SHIPPED, ids=[p.name for p in SHIPPED])
def test_diagnose_reads_each_shipped_csv_as_shipped(csv: Path, tmp_path: Path) -> None:
    out = tmp_path / "d.json"
    run = subprocess.run(
        [sys.executable, "-m", "fresco_bridge.cli", "diagnose", str(csv.relative_to(ROOT)),
         "--json", str(out), "--no-progress"],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
        env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert run.returncode == 0, run.stderr
    assert "Traceback" not in run.stderr
    assert "VERDICT" in run.stdout and "no command channel" in run.stdout
    doc = json.loads(out.read_text())
    assert doc["record"]["command"] is False
    assert doc["record"]["samples"] == len(csv.read_text().splitlines()) - 1
    for part in doc["verdict"]["effect"].split("+"):
        assert part in VERDICTS
    assert doc["not_identifiable"]  # the interface effects, with their reasons
