"""Ctrl-C as a terminal sends it: SIGINT to the whole process group (the bridge and its learner
worker alike). ``serve`` with an updatable site stopped mid-test and ``demo`` stopped mid-run
each end with one ``interrupted:`` line, exit 130, no traceback from any process, and the run
recorded as ``interrupted`` (resumable); ``serve`` stopped between tests stops cleanly (0)."""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.runs import load_run

pytest.importorskip("filterpy")

REPO = Path(__file__).resolve().parents[2]
READY = re.compile(r"fresco-bridge ready: damper=(\d+), twin1=(\d+)")
DEADLINE = 60.0  # s for a start or a stop on a busy machine


def _config(tmp_path: Path) -> Path:
    cfg = tmp_path / "lab.toml"
    cfg.write_text(textwrap.dedent(f"""
        [bridge]
        run_dir = "{tmp_path / 'runs'}"
        run_name = "ctrl-c"
        [[sites]]
        name = "damper"
        port = 0
        [sites.controller]
        model = "bilinear"
        params = {{ k0 = 20.0, fy = 5.0, alpha = 0.05 }}
        [[sites]]
        name = "twin1"
        port = 0
        kind = "updatable"
        learns_from = "damper"
        updater = "online_ukf"
        """))
    return cfg


def _start(args: list[str], cwd: Path, err: Path) -> subprocess.Popen[str]:
    """A new session, as a shell's job: ``os.killpg`` is then the terminal's Ctrl-C."""
    return subprocess.Popen([sys.executable, "-m", "fresco_bridge.cli", *args], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=err.open("w"), text=True,
                            start_new_session=True,
                            env={**os.environ, "PYTHONPATH": str(REPO)})


def _ready(proc: subprocess.Popen[str], err: Path) -> tuple[int, int]:
    assert proc.stdout is not None
    end = time.monotonic() + DEADLINE
    while time.monotonic() < end:
        m = READY.search(proc.stdout.readline())
        if m or proc.poll() is not None:
            break
    assert m, err.read_text()
    return int(m.group(1)), int(m.group(2))


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
    source = GenericClientLink("127.0.0.1", ports[0], 1, data_size=1)
    twin = GenericClientLink("127.0.0.1", ports[1], 1, data_size=1)
    with source, twin:
        for i in range(1, 21):  # the test is under way when Ctrl-C comes
            d = 1.5 * math.sin(i / 4.0)
            source.set_trial((d,), time=0.01 * i)
            source.force()
            twin.set_trial((0.8 * d,), time=0.01 * i)
            twin.force()
            source.commit()
            twin.commit()
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
