"""``fresco-bridge diagnose`` as a user runs it: the installed console script in a new process.

Bad input ends the process with exit code 2 and one line on stderr (no traceback); a good CSV
is diagnosed end to end. The console entry parses the diagnosis commands without importing the
daemon (``fresco_bridge.entry``); every other command line still reaches ``cli.main``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from benchmarks.diagnosis.synth import synthetic_record

SCRIPT = Path(sys.executable).parent / "fresco-bridge"
DEADLINE = 120.0


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(SCRIPT), *args], capture_output=True, text=True,
                          timeout=DEADLINE, check=False)


def _csv(path: Path, steps: int, nan_at: int | None = None) -> Path:
    rec = synthetic_record("friction", 12, steps=steps).record
    assert rec.meas_disp is not None
    rows = np.c_[rec.time, rec.cmd, rec.meas_disp, rec.force]
    if nan_at is not None:
        rows[nan_at, 3] = np.nan
    np.savetxt(path, rows, delimiter=",", header="time,cmd_disp,meas_disp,meas_force",
               comments="")
    return path


def test_bad_input_ends_the_process_with_code_2_and_one_line(tmp_path: Path) -> None:
    done = _run("diagnose", str(_csv(tmp_path / "a.csv", 300, nan_at=40)), "--no-progress")
    assert done.returncode == 2, done.stderr
    assert "a.csv:42: column meas_force is 'nan'" in done.stderr
    assert "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1
    done = _run("diagnose", str(tmp_path / "absent.csv"))
    assert done.returncode == 2 and "absent.csv" in done.stderr
    assert "Traceback" not in done.stderr


def test_a_csv_is_diagnosed_in_a_new_process(tmp_path: Path) -> None:
    out = tmp_path / "d.json"
    done = _run("diagnose", str(_csv(tmp_path / "a.csv", 500)), "--json", str(out),
                "--no-progress")
    assert done.returncode == 0, done.stderr
    assert "VERDICT   friction" in done.stdout and out.stat().st_size > 0


def test_other_commands_still_reach_the_full_cli() -> None:
    done = _run("--help")
    assert done.returncode == 0 and "serve" in done.stdout and "diagnose-bench" in done.stdout
