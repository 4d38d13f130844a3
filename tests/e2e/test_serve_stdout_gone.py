"""A real ``fresco-bridge serve`` whose stdout reader is gone before the ready line (a
``serve … | head -0``, a supervisor that closed the pipe): the daemon serves on, says so on
stderr, and stops cleanly on SIGTERM. Before, the ready line's ``BrokenPipeError`` ended it."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

WARNING = "stdout's reader went away before the ready line"


def _config(tmp: Path) -> Path:
    path = tmp / "lab.toml"
    path.write_text(textwrap.dedent(f"""
        [bridge]
        run_dir = "{tmp / 'runs'}"
        run_name = "gone"
        [[sites]]
        name = "site"
        port = 0
        [sites.controller]
        model = "elastic"
        params = {{ k = 10.0 }}
        """), encoding="utf-8")
    return path


def test_serve_goes_on_when_stdout_has_no_reader(tmp_path: Path) -> None:
    log = tmp_path / "serve.log"
    read_end, write_end = os.pipe()
    os.close(read_end)
    with log.open("w") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "fresco_bridge.cli", "serve", "--config",
             str(_config(tmp_path))], cwd=tmp_path, stdout=write_end, stderr=err, text=True)
    os.close(write_end)
    try:
        deadline = time.monotonic() + 30
        while WARNING not in log.read_text() and proc.poll() is None:
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.05)
        m = re.search(r"listening on TCP 127\.0\.0\.1:(\d+)", log.read_text())
        assert m is not None and proc.poll() is None, log.read_text()
        with socket.create_connection(("127.0.0.1", int(m.group(1))), timeout=10):
            pass  # still serving: it accepts a client
        assert proc.poll() is None, log.read_text()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0, log.read_text()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    text = log.read_text()
    assert WARNING in text and "site=" in text and "Traceback" not in text
