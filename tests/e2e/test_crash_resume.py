"""kill -9 of a real ``fresco-bridge serve``, then restart and resume.

The restart reports the interrupted run (log, ``runs list`` state, ``run.json``), removes its
stale control socket; ``export`` reports the torn last line; ``runs resume`` continues the
same record from the last committed step, and nothing is sent to the controller before the
first client asks; killed again, ``serve --resume`` continues it once more.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import read_record
from fresco_bridge.record.export import committed_steps
from tests.support.spied_bridge import wait_for

K = 10.0
READY = re.compile(r"fresco-bridge ready: site=(\d+)")


def _config(tmp: Path) -> Path:
    path = tmp / "lab.toml"
    path.write_text(textwrap.dedent(f"""
        [bridge]
        run_dir = "{tmp / 'runs'}"
        run_name = "crash"
        [telemetry]
        username = "lab"
        password = "s3cret-broker-password"
        [[sites]]
        name = "site"
        port = 0
        [sites.controller]
        model = "elastic"
        params = {{ k = {K} }}
        """), encoding="utf-8")
    return path


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "fresco_bridge.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=60)


_STARTED: list[subprocess.Popen[str]] = []


class Serve:
    """A real bridge process; ``port`` once it printed its ready line.

    Every process started is kept in ``_STARTED`` so the test's teardown kills what a failed
    assertion left running (a leaked bridge would outlive the test run).
    """

    def __init__(self, cwd: Path, *args: str) -> None:
        self.log = cwd / f"serve-{time.monotonic_ns()}.log"
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "fresco_bridge.cli", *args], cwd=cwd,
            stdout=subprocess.PIPE, stderr=self.log.open("w"), text=True)
        _STARTED.append(self.proc)
        assert self.proc.stdout is not None
        deadline = time.monotonic() + 30
        line = ""
        while time.monotonic() < deadline:
            line = self.proc.stdout.readline()
            if READY.search(line) or self.proc.poll() is not None:
                break
        m = READY.search(line)
        assert m, f"no ready line: {line!r}\n{self.log.read_text()[-2000:]}"
        self.port = int(m.group(1))

    def stop(self, sig: int = signal.SIGTERM) -> str:
        self.proc.send_signal(sig)
        self.proc.wait(30)
        return self.log.read_text()


@pytest.fixture(autouse=True)
def _kill_leftover_bridges() -> Iterator[None]:
    yield
    while _STARTED:
        proc = _STARTED.pop()
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)


def _steps(port: int, start: int, n: int, *, commit_last: bool = True) -> None:
    link = GenericClientLink("127.0.0.1", port, 1, data_size=1, timeout=10.0).connect()
    for i in range(start, start + n):
        link.set_trial((0.1 * i,), time=0.01 * i)
        assert link.force()[0] == pytest.approx(K * 0.1 * i)
        if i < start + n - 1 or commit_last:
            link.commit()
    if commit_last:
        link.close()


def test_kill_9_is_reported_and_the_run_resumes_from_the_last_committed_step(
    tmp_path: Path
) -> None:
    cfg = _config(tmp_path)
    first = Serve(tmp_path, "serve", "--config", str(cfg))
    _steps(first.port, 1, 6, commit_last=False)  # 5 committed, the 6th only forwarded
    first.stop(signal.SIGKILL)
    (run,) = [p for p in (tmp_path / "runs").iterdir() if p.is_dir()]
    assert (run / "control.sock").exists()  # stale
    with (run / "record.jsonl").open("ab") as fh:
        fh.write(b'{"seq":99999,"t":1.0,"kind":"tri')  # killed mid-write

    # the snapshot never held the password; the run directory is private
    assert "s3cret-broker-password" not in (run / "config.toml").read_text()
    assert (run.stat().st_mode & 0o777) == 0o700
    assert {(p.stat().st_mode & 0o777) for p in run.iterdir() if p.is_file()} == {0o600}

    listed = _cli("runs", "list", "--runs", str(tmp_path / "runs"), cwd=tmp_path)
    assert "interrupted" in listed.stdout, listed.stdout
    exported = _cli("export", str(run), "-o", str(tmp_path / "steps.csv"), cwd=tmp_path)
    assert exported.returncode == 0 and "torn" in exported.stderr, exported.stderr
    assert "5 committed step(s)" in exported.stdout

    # a plain restart reports it and removes the stale socket
    second = Serve(tmp_path, "serve", "--config", str(cfg))
    log = second.stop()
    assert f"run {run.name} ended without a clean close" in log, log[-2000:]
    assert "site session 1 step 5" in log
    assert not (run / "control.sock").exists()
    assert json.loads((run / "run.json").read_text())["state"] == "interrupted"

    # resume: the same record goes on from step 5, nothing moved before the client asked
    resumed = Serve(tmp_path, "runs", "resume", run.name, "--config", str(cfg),
                    "--runs", str(tmp_path / "runs"))
    time.sleep(0.3)
    _steps(resumed.port, 6, 3)
    # commit (5) and DIE have no reply: kill only once the bridge closed the session
    wait_for(lambda: any(r.get("event") == "session-close" and r.get("session") == 2
                         for r in read_record(run)), "session 2 to be closed", timeout=30)
    resumed.stop(signal.SIGKILL)  # killed again, between sessions

    # the other documented way: serve --resume, from the last committed step again
    again = Serve(tmp_path, "serve", "--config", str(cfg), "--resume", run.name)
    _steps(again.port, 9, 2)
    again.stop()
    meta = json.loads((run / "run.json").read_text())
    assert meta["state"] == "closed" and len(meta["resumed"]) == 2
    records = list(read_record(run))
    kinds = [(r["kind"], r.get("event")) for r in records]
    i_resumed = kinds.index(("event", "resumed"))
    assert kinds[i_resumed + 1] == ("event", "session-open")  # nothing sent before it
    assert "step 5" in records[i_resumed]["reason"]
    steps = committed_steps(run)
    assert [(s.session, s.step) for s in steps] == [(1, 1), (1, 2), (1, 3), (1, 4), (1, 5),
                                                    (2, 6), (2, 7), (2, 8), (3, 9), (3, 10)]
    seqs = [r["seq"] for r in records]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    assert (run / "record.jsonl.torn").read_bytes().startswith(b'{"seq":99999')
    assert oct(os.stat(run / "record.jsonl").st_mode & 0o777) == oct(0o600)
    # the sessions cut by the kills were continued: no stale "never closed" note
    final = _cli("export", str(run), "-o", str(tmp_path / "final.csv"), cwd=tmp_path)
    assert final.returncode == 0 and "never closed" not in final.stdout + final.stderr
