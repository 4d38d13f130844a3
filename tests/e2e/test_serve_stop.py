"""Ctrl-C on a real ``fresco-bridge serve``: it stops with status 0 and says where its run record
went and what to do with it (issue 27: a stopped bridge printed nothing, the README says "each
run's record is under runs/")."""

from __future__ import annotations

import select
import signal
import subprocess
import sys
import time
from pathlib import Path

from tests.e2e.test_serve_stdout_gone import _config


def test_ctrl_c_names_the_run_record_and_the_next_command(tmp_path: Path) -> None:
    log = tmp_path / "serve.log"
    with log.open("w") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "fresco_bridge.cli", "serve", "--config",
             str(_config(tmp_path))], cwd=tmp_path, stdout=subprocess.PIPE, stderr=err,
            text=True)
    try:
        assert proc.stdout is not None
        readable, _, _ = select.select([proc.stdout], [], [], 60.0)  # the deadline
        assert readable, log.read_text()
        ready = proc.stdout.readline()  # the line is written and flushed at once
        assert ready.startswith("fresco-bridge ready:"), log.read_text()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=30) == 0, log.read_text()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    (run,) = (tmp_path / "runs").iterdir()
    deadline = time.monotonic() + 10  # the log is flushed at exit; read it once it is there
    while "stopped;" not in log.read_text() and time.monotonic() < deadline:
        time.sleep(0.05)
    text = log.read_text()
    assert f"stopped; run record {run} (next: fresco-bridge runs show {run})" in text, text
