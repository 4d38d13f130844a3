"""Group commit: each commit reaches the kernel at once, fdatasync at most every
``sync_interval`` for all commits since the last one, events synced at once.

``kill -9`` of a real bridge right after its last commit loses nothing even when no
fdatasync ran for seconds (the page cache survives a killed process; only a power loss needs
the sync, and then at most ``sync_interval`` of commits is at stake).
"""

from __future__ import annotations

import errno
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
from fresco_bridge.record import RecordError, RunRecord, read_record, writer
from fresco_bridge.record.export import committed_steps, monitor_lines
from fresco_bridge.telemetry.taps import MONITOR_BATCH_STEPS

DEADLINE = 10.0


def wait_for(cond: object, what: str) -> None:
    deadline = time.monotonic() + DEADLINE
    while not cond():  # type: ignore[operator]
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.002)


def step(record: RunRecord, n: int) -> None:
    record.trial("s", 1, n - 1, 0.01 * n, (0.1 * n,), (0.1 * n,))
    record.measurement("s", 1, n - 1, (0.1 * n,), (1.0 * n,))
    record.commit("s", 1, n, 0.01 * n)


def test_commits_are_written_at_once_and_synced_together(tmp_path: Path) -> None:
    record = RunRecord.create(tmp_path, "g", "", {}, sync_interval=3600.0)
    path = record.directory / "record.jsonl"
    try:
        step(record, 1)
        wait_for(lambda: record.syncs == 1, "the first commit's sync")  # idle: syncs at once
        assert record.durable_lines == 3
        for n in range(2, 51):
            step(record, n)
            # in the kernel before the next message is processed: another reader sees it
            assert path.read_bytes().count(b'"kind":"step"') == n - 1  # one line a step
            assert committed_steps(record.directory)[-1].meas_force == (1.0 * n,)
        assert record.syncs == 1 and record.durable_lines == 3  # the rest waits the interval
        record.event("s", 1, "hold", "limit exceeded")
        wait_for(lambda: record.syncs == 2, "the event's sync")  # events do not wait
        assert record.durable_lines == record.lines == 151
    finally:
        record.close()
    assert [s.step for s in committed_steps(record.directory)] == list(range(1, 51))


def test_a_short_interval_makes_every_commit_durable_soon(tmp_path: Path) -> None:
    record = RunRecord.create(tmp_path, "g", "", {}, sync_interval=0.02)
    try:
        for n in range(1, 201):
            step(record, n)
        wait_for(lambda: record.durable_lines == record.lines, "every line on disk")
        assert 1 <= record.syncs <= 200
    finally:
        record.close()


def test_inline_syncs_before_the_commit_returns(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                                ) -> None:
    calls: list[int] = []
    real = os.fdatasync
    monkeypatch.setattr(os, "fdatasync", lambda fd: (calls.append(fd), real(fd))[1])
    record = RunRecord.create(tmp_path, "g", "", {}, fsync="inline")
    try:
        for n in range(1, 4):
            step(record, n)
            assert len(calls) == n and record.durable_lines == record.lines
        record.event("s", 1, "hold", "x")
        assert len(calls) == 4
    finally:
        record.close()


def test_a_failed_fdatasync_is_reported_and_retried_once_the_record_is_checked(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    attempts: list[int] = []
    real = os.fdatasync

    def first_fails(fd: int) -> None:
        attempts.append(fd)
        if len(attempts) == 1:
            raise OSError(errno.EIO, "Input/output error")
        real(fd)

    monkeypatch.setattr(os, "fdatasync", first_fails)
    record = RunRecord.create(tmp_path, "g", "", {}, sync_interval=0.0)
    try:
        step(record, 1)
        wait_for(lambda: len(attempts) == 1, "the failing fdatasync")
        time.sleep(0.05)  # no retry loop: the thread waits for the next request
        assert len(attempts) == 1 and record.syncs == 0 and record.durable_lines == 0
        with pytest.raises(RecordError, match="fdatasync failed: Input/output error"):
            step(record, 2)  # written to the kernel first, then the error is reported
        assert record.failure is not None  # no commit until it is checked (a new session)
        assert record.check_writable() is None
        step(record, 3)
        wait_for(lambda: record.durable_lines == record.lines == 9, "the retry")
        assert record.syncs == 1
    finally:
        record.close()
    assert [s.step for s in committed_steps(record.directory)] == [1, 2, 3]


def test_a_short_write_is_finished_and_a_failed_one_reported(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A commit's ``write``: a short one is completed before the commit returns, a failed one
    raises RecordError at once."""
    real = writer._os_write
    mode, calls = [""], [0]

    def flaky(fd: int, data: bytes) -> int:
        calls[0] += 1
        if calls[0] == 2:  # step 2's line: a signal, a nearly full disk
            return real(fd, bytes(data[:7]))
        if mode[0] == "fail":
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd, data)

    monkeypatch.setattr(writer, "_os_write", flaky)
    record = RunRecord.create(tmp_path, "g", "", {}, fsync="off")
    try:
        for n in (1, 2, 3):
            step(record, n)  # step 2: a step line, written in two parts
        assert calls[0] == 4
        mode[0] = "fail"
        with pytest.raises(RecordError, match="cannot be written: No space left on device"):
            step(record, 4)
    finally:
        mode[0] = ""
        record.close()
    assert [s.step for s in committed_steps(record.directory)] == [1, 2, 3]


READY = re.compile(r"fresco-bridge ready: site=(\d+)")


def test_kill_9_after_the_last_commit_loses_no_step_with_a_long_sync_interval(
        tmp_path: Path) -> None:
    cfg = tmp_path / "lab.toml"
    cfg.write_text(textwrap.dedent(f"""
        [bridge]
        run_dir = "{tmp_path / 'runs'}"
        [record]
        sync_interval = 10.0
        [[sites]]
        name = "site"
        port = 0
        [sites.controller]
        model = "elastic"
        params = {{ k = 10.0 }}
        """))
    proc = subprocess.Popen([sys.executable, "-m", "fresco_bridge.cli", "serve", "--config",
                             str(cfg)], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        deadline = time.monotonic() + 30
        port = None
        while port is None and time.monotonic() < deadline and proc.poll() is None:
            m = READY.search(proc.stdout.readline())
            port = int(m.group(1)) if m else None
        assert port is not None, "the bridge never became ready"
        link = GenericClientLink("127.0.0.1", port, 1, data_size=1, timeout=10.0).connect()
        for i in range(1, 41):
            link.set_trial((0.01 * i,), time=0.01 * i)
            link.force()
            link.commit()
        link.set_trial((0.5,), time=0.41)
        link.force()  # answered: the bridge has processed the 40th commit
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        link.sock.close()  # type: ignore[union-attr]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    (run,) = (tmp_path / "runs").iterdir()
    steps = committed_steps(run)
    assert [s.step for s in steps] == list(range(1, 41))
    assert [s.cmd_disp for s in steps] == [(0.01 * i,) for i in range(1, 41)]
    assert [s.meas_force for s in steps] == [(10.0 * (0.01 * i),) for i in range(1, 41)]
    assert sum(r["kind"] == "trial" for r in read_record(run)) >= 40
    # format 3: one line a step after the session's first; the monitor samples (derived data)
    # are written in batches (format 4, ``MonitorBatch``): those of the last batch, at most
    # MONITOR_BATCH_STEPS − 1 steps, waited in memory
    assert (run / "record.jsonl").read_text().count('"kind":"step"') == 39
    monitored = [m.step for m in monitor_lines(read_record(run))]
    assert monitored == list(range(1, len(monitored) + 1))
    assert len(monitored) >= 40 - (MONITOR_BATCH_STEPS - 1)
