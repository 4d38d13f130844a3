"""A run record that cannot be written is a fault of the site, never of the bridge.

A real bridge in a thread whose run directory is on a small filesystem the test fills mid-run
(a tmpfs mounted by the test when it may; else an ENOSPC injected at the writer's ``write``):
the site HOLDs with the path and errno as its reason, the controller is held, the integrator is
answered NaN, new clients are refused while the disk is full, the next client is served once
space returns, and the record is readable with no torn line.
"""

from __future__ import annotations

import contextlib
import errno
import itertools
import json
import math
import os
import subprocess
import textwrap
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink, LinkError
from fresco_bridge.record import export_csv, read_record
from fresco_bridge.record.rundir import RECORD_FILE
from fresco_bridge.runs import load_run
from tests.support.bridge import RunningBridge
from tests.support.spied_bridge import wait_for

K = 10.0
SITE = "s"


def config(min_free_mb: float) -> str:
    return textwrap.dedent(f"""
        [bridge]
        run_name = "disk"
        allowed_clients = ["127.0.0.1"]
        [record]
        min_free_mb = {min_free_mb}
        [[sites]]
        name = "{SITE}"
        port = 0
        [sites.controller]
        model = "elastic"
        params = {{ k = {K} }}
        """)


@contextlib.contextmanager
def small_filesystem(where: Path, size_kib: int) -> Iterator[Path]:
    """A tmpfs of ``size_kib`` at ``where`` (root only), unmounted however the test ends."""
    if os.geteuid() != 0:
        pytest.skip("mounting a small filesystem needs root")
    where.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kib}k", "tmpfs",
                           str(where)], capture_output=True, text=True, timeout=30)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], capture_output=True, timeout=30)


def fill(path: Path, leave_kib: int = 0) -> None:
    """Write ``path`` until its filesystem is full (or has ``leave_kib`` KiB free)."""
    chunk = b"\0" * 4096
    with open(path, "wb", buffering=0) as f:
        while True:
            st = os.statvfs(path)
            if st.f_bavail * st.f_frsize <= leave_kib * 1024:
                return
            try:
                f.write(chunk)
            except OSError as exc:
                assert exc.errno == errno.ENOSPC
                return


def spy_holds(bridge: BridgeThread) -> list[int]:
    """Every ``hold()`` the site's controller gets is counted in the returned list."""
    calls: list[int] = []

    def install() -> None:
        controller = bridge.bridge.sites[SITE].controller
        original = controller.hold

        async def hold() -> None:
            calls.append(1)
            await original()

        controller.hold = hold  # type: ignore[method-assign]

    bridge.call(install)
    return calls


def status(bridge: BridgeThread) -> dict[str, Any]:
    result = bridge.call(lambda: bridge.bridge.sites[SITE].status())
    assert isinstance(result, dict)
    return result


def step(link: GenericClientLink, i: int) -> float:
    link.set_trial((0.01 * i,), time=0.01 * i)
    force = link.force()[0]
    link.commit()
    return force


def step_until_nan(link: GenericClientLink, start: int, limit: int = 100_000) -> int:
    """Steps until the bridge answers NaN (the site HOLDs): the step that got it."""
    for i in range(start, start + limit):
        force = step(link, i)
        if math.isnan(force):
            return i
        assert force == pytest.approx(K * 0.01 * i)
    raise AssertionError(f"no NaN answer within {limit} steps")


def refused_now(port: int) -> bool:
    """A new client is refused at once: told to stop (its first request answered with NaN,
    ``server/refusal.py``) or closed before any reply."""
    link = GenericClientLink("127.0.0.1", port, 1, data_size=1, timeout=5.0)
    try:
        link.connect()
        link.set_trial((0.0,), time=0.0)
        return math.isnan(link.force()[0])
    except (LinkError, ConnectionError):
        return True
    finally:
        if link.sock is not None:
            link.sock.close()
    return False


def served(port: int, steps: int = 3) -> None:
    with GenericClientLink("127.0.0.1", port, 1, data_size=1, timeout=5.0) as link:
        for i in range(1, steps + 1):
            assert step(link, i) == pytest.approx(K * 0.01 * i)


def assert_readable(run_dir: Path) -> list[dict[str, Any]]:
    """Every line of the record is complete JSON; the readers and the CSV export take it."""
    raw = (run_dir / RECORD_FILE).read_bytes()
    assert raw.endswith(b"\n"), "a torn last line was left behind"
    for line in raw.splitlines():
        json.loads(line)
    lines = list(read_record(run_dir))
    assert export_csv(run_dir, run_dir.parent / "steps.csv") >= 1
    load_run(run_dir)
    return lines


def test_a_disk_that_fills_mid_run_holds_the_site_and_frees_it(tmp_path: Path) -> None:
    with small_filesystem(tmp_path / "fs", 4096) as fs, \
            RunningBridge(config(min_free_mb=0), fs) as bridge:
        holds = spy_holds(bridge)
        port = bridge.ports[SITE]
        ballast = fs / "ballast"
        with GenericClientLink("127.0.0.1", port, 1, data_size=1, timeout=5.0) as link:
            for i in range(1, 4):
                assert step(link, i) == pytest.approx(K * 0.01 * i)
            fill(ballast)
            nan_at = step_until_nan(link, 4)
            st = status(bridge)
            assert st["state"] == "HOLD"
            assert "Errno 28" in st["reason"] and str(fs) in st["reason"]
            assert st["record"] is not None and "Errno 28" in st["record"]
            assert st["holds"] == 1
            wait_for(lambda: holds == [1], "the controller to be held")
            assert math.isnan(link.force()[0])  # told to stop until it leaves
        wait_for(lambda: status(bridge)["peer"] is None, "the session to end")
        assert status(bridge)["state"] == "IDLE"
        assert refused_now(port), "a new client was served while the record cannot be written"
        ballast.unlink()
        served(port)
        lines = assert_readable(bridge.run_dir)
        committed = [ln for ln in lines if ln["kind"] == "commit" and ln["session"] == 1]
        assert committed and max(ln["step"] for ln in committed) < nan_at
        assert any(ln.get("event") == "session-open" and ln["session"] == 2 for ln in lines)


def test_the_headroom_holds_before_the_disk_is_full(tmp_path: Path) -> None:
    with small_filesystem(tmp_path / "fs", 4096) as fs, \
            RunningBridge(config(min_free_mb=2), fs) as bridge:
        holds = spy_holds(bridge)
        port = bridge.ports[SITE]
        ballast = fs / "ballast"
        with GenericClientLink("127.0.0.1", port, 1, data_size=1, timeout=5.0) as link:
            assert step(link, 1) == pytest.approx(K * 0.01)
            fill(ballast, leave_kib=1024)
            step_until_nan(link, 2)  # the check runs about once a second
            st = status(bridge)
            assert st["state"] == "HOLD" and "record.min_free_mb = 2" in st["reason"]
            wait_for(lambda: holds == [1], "the controller to be held")
        wait_for(lambda: status(bridge)["peer"] is None, "the session to end")
        assert refused_now(port)
        ballast.unlink()
        served(port)
        lines = assert_readable(bridge.run_dir)
        holds_recorded = [ln for ln in lines if ln.get("event") == "hold"]
        assert holds_recorded and "min_free_mb" in holds_recorded[0]["reason"]


def test_an_enospc_at_the_writer_holds_the_site_and_leaves_no_torn_line(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without root: the kernel's ENOSPC is injected at the record's ``write`` after half of
    the data went in (a short write, then a full disk)."""
    import fresco_bridge.record.writer as writer

    full = False
    real_write = os.write

    def write(fd: int, data: bytes | memoryview) -> int:
        if full:
            if len(data) > 1:
                return real_write(fd, bytes(data)[: len(data) // 2])
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_write(fd, data)

    def write_then_fail(fd: int, data: bytes | memoryview) -> int:
        n = write(fd, data)
        monkeypatch.setattr(writer, "_os_write", fail)
        return n

    def fail(fd: int, data: bytes | memoryview) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr("fresco_bridge.sites.core.ABORT_GRACE", 0.5)
    with RunningBridge(config(min_free_mb=0), tmp_path) as bridge:
        holds = spy_holds(bridge)
        port = bridge.ports[SITE]
        with GenericClientLink("127.0.0.1", port, 1, data_size=1, timeout=5.0) as link:
            for i in range(1, 4):
                assert step(link, i) == pytest.approx(K * 0.01 * i)
            wait_for(lambda: status(bridge)["step"] == 3, "the third commit to be handled")
            full = True
            monkeypatch.setattr(writer, "_os_write", write_then_fail)
            assert step(link, 4) == pytest.approx(K * 0.04)  # its commit fails
            assert math.isnan(step(link, 5))
            st = status(bridge)
            assert st["state"] == "HOLD" and "Errno 28" in st["reason"]
            assert st["step"] == 3, "the step whose commit failed was counted"
            wait_for(lambda: holds == [1], "the controller to be held")
            # the integrator stays, silent: the bridge ends its session
            wait_for(lambda: status(bridge)["peer"] is None, "the session to end", timeout=10)
        monkeypatch.setattr(writer, "_os_write", real_write)
        served(port)
        lines = assert_readable(bridge.run_dir)
        steps = [ln["step"] for ln in lines if ln["kind"] == "commit" and ln["session"] == 1]
        assert steps == [1, 2, 3]


def test_a_torn_write_that_cannot_be_cut_at_once_blocks_every_line_until_it_is(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import fresco_bridge.record.writer as writer

    real_write, real_truncate = os.write, os.ftruncate

    def half_then_full(fd: int, data: bytes | memoryview) -> int:
        monkeypatch.setattr(writer, "_os_write", full)
        return real_write(fd, bytes(data)[: len(data) // 2])

    def full(fd: int, data: bytes | memoryview) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def truncate_fails(fd: int, size: int) -> None:
        raise OSError(errno.EIO, os.strerror(errno.EIO))

    def commit(record: writer.RunRecord, n: int) -> None:
        record.trial("s", 1, n, 0.01 * n, (0.1 * n,), (0.1 * n,))
        record.measurement("s", 1, n, (0.1 * n,), (K * 0.1 * n,))
        record.commit("s", 1, n, 0.01 * n)

    record = writer.RunRecord.create(tmp_path, "t", "", {}, fsync="off", min_free_mb=0)
    path = record.directory / RECORD_FILE
    try:
        commit(record, 1)
        intact = path.read_bytes()
        monkeypatch.setattr(writer, "_os_write", half_then_full)
        monkeypatch.setattr(os, "ftruncate", truncate_fails)
        with pytest.raises(writer.RecordError, match=r"Errno 28.*No space left"):
            commit(record, 2)
        torn = path.read_bytes()
        assert torn.startswith(intact) and len(torn) > len(intact)
        monkeypatch.setattr(writer, "_os_write", real_write)
        with pytest.raises(writer.RecordError):
            record.event("s", 1, "hold", "the record failed")  # nothing after a torn line
        assert record.check_writable() is not None and path.read_bytes() == torn
        monkeypatch.setattr(os, "ftruncate", real_truncate)
        assert record.check_writable() is None
        assert path.read_bytes() == intact
        record.event("s", 1, "hold", "the record failed")
        commit(record, 3)
    finally:
        monkeypatch.undo()
        record.close()
    assert_readable(record.directory)
    lines = list(read_record(record.directory))
    assert [ln["step"] for ln in lines if ln["kind"] == "commit"] == [1, 3]


def test_free_space_is_checked_per_quarter_headroom_written_within_a_second(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A step loop fast enough to write the whole headroom within the 1 s check interval
    (the compiled path: ~10,000 steps a second) still meets a check before the disk is full:
    one every quarter of ``min_free_mb`` written."""
    import fresco_bridge.record.writer as writer

    checks: list[int] = []
    real_statvfs = os.statvfs

    def counting(path: Any) -> Any:
        checks.append(record.path.stat().st_size)  # bytes written at this check
        return real_statvfs(path)

    monkeypatch.setattr(writer, "_monotonic", lambda: 100.0)  # the clock stands still
    record = writer.RunRecord.create(tmp_path, "t", "", {}, fsync="off", min_free_mb=1)
    monkeypatch.setattr(writer, "_statvfs", counting)
    try:
        n = 0
        while record.path.stat().st_size < 1 << 20:  # 1 MiB: four quarters of the headroom
            n += 1
            record.trial("s", 1, n, 0.01 * n, (0.1 * n,), (0.1 * n,))
            record.measurement("s", 1, n, (0.1 * n,), (K * 0.1 * n,))
            record.commit("s", 1, n, 0.01 * n)
    finally:
        record.close()
    quarter = (1 << 20) // 4
    gaps = [b - a for a, b in itertools.pairwise(checks)]
    assert len(gaps) >= 2 and all(quarter <= g < quarter + 4096 for g in gaps), checks
