"""Ctrl-C as a terminal sends it: SIGINT to the whole process group (the bridge and its learner
worker alike). ``serve`` with an updatable site stopped mid-test and ``demo`` stopped mid-run
each end with one ``interrupted:`` line, exit 130, no traceback from any process, and the run
recorded as ``interrupted`` (resumable); ``serve`` stopped between tests stops cleanly (0)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from fresco_bridge.runs import load_run
from tests.support.serve import lockstep, pair, source_and_twin, start_cli, started

pytest.importorskip("filterpy")

DEADLINE = 60.0  # s for a start or a stop on a busy machine


def _config(tmp_path: Path) -> Path:
    return source_and_twin(tmp_path / "lab.toml", tmp_path / "runs", "ctrl-c")


def _start(args: list[str], cwd: Path, err: Path) -> subprocess.Popen[str]:
    """A new session, as a shell's job: ``os.killpg`` is then the terminal's Ctrl-C."""
    return start_cli(cwd, *args, stderr=err, new_session=True)


def _ready(proc: subprocess.Popen[str], err: Path) -> tuple[int, ...]:
    return started(proc, deadline=DEADLINE, log=err)[0]


def _ctrl_c(proc: subprocess.Popen[str]) -> int:
    try:
        os.killpg(proc.pid, signal.SIGINT)
        return proc.wait(DEADLINE)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)


def _settled(err: Path) -> str:
    """stderr once every process of the group wrote its last line (a worker may outlive its
    parent by a moment)."""
    time.sleep(1.5)
    return err.read_text()


def _run_state(tmp_path: Path, runs: str = "runs") -> str:
    (run,) = [p for p in (tmp_path / runs).iterdir() if p.is_dir()]
    return str(json.loads((run / "run.json").read_text())["state"])


def test_serve_with_a_twin_interrupted_mid_test(tmp_path: Path) -> None:
    err = tmp_path / "serve.err"
    proc = _start(["serve", "--config", str(_config(tmp_path))], tmp_path, err)
    ports = _ready(proc, err)
    with pair(ports) as (source, twin):
        lockstep(source, twin, 1, 20)  # the test is under way when Ctrl-C comes
        code = _ctrl_c(proc)
    text = _settled(err)
    assert code == 130, text
    assert "Traceback" not in text, text
    lines = [ln for ln in text.splitlines() if ln.startswith("interrupted:")]
    assert len(lines) == 1, text
    assert "the run is recorded as interrupted" in lines[0], text
    assert "--resume" in lines[0] and "damper" in lines[0], text
    assert _run_state(tmp_path) == "interrupted"
    (run,) = (tmp_path / "runs").iterdir()
    assert "stopped (Ctrl-C or SIGTERM) while a client was served" in " ".join(load_run(run).notes)


def test_serve_with_a_twin_stopped_between_tests(tmp_path: Path) -> None:
    err = tmp_path / "serve.err"
    proc = _start(["serve", "--config", str(_config(tmp_path))], tmp_path, err)
    _ready(proc, err)
    code = _ctrl_c(proc)
    text = _settled(err)
    assert code == 0, text
    assert "Traceback" not in text and "interrupted" not in text, text
    assert "stopped; run record" in text, text
    assert _run_state(tmp_path) == "closed"


@pytest.mark.timeout(300)
def test_demo_interrupted_in_the_hybrid_test(tmp_path: Path) -> None:
    err = tmp_path / "demo.err"
    proc = _start(["demo", "--runs", str(tmp_path / "runs")], tmp_path, err)
    end = time.monotonic() + 180
    log = None
    while time.monotonic() < end and proc.poll() is None:  # the hybrid test under way
        logs = list((tmp_path / "runs").glob("*-demo/bridge.log"))
        if logs and "site twin: session 1 opened" in logs[0].read_text():
            log = logs[0]
            break
        time.sleep(0.05)
    assert log is not None, err.read_text()
    time.sleep(1.0)
    assert proc.poll() is None, err.read_text()
    code = _ctrl_c(proc)
    text = _settled(err)
    assert code == 130, text
    assert "Traceback" not in text and "ERROR" not in text, text
    lines = [ln for ln in text.splitlines() if ln.startswith("interrupted:")]
    assert len(lines) == 1, text
    assert "the run is recorded as interrupted" in lines[0], text
    (run,) = [p for p in (tmp_path / "runs").iterdir() if p.name.endswith("-demo")]
    assert json.loads((run / "run.json").read_text())["state"] == "interrupted", text
    assert "session 1 closed" in log.read_text()  # the bridge's log: its last lines too
