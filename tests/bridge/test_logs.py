"""The daemon's log: one line per cause per interval, and a handler that cannot write is no fault
of the bridge."""

from __future__ import annotations

import errno
import io
import logging

import pytest

from fresco_bridge.logs import MAX_CAUSES, RateLimitFilter, configure


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def logger_with(filt: RateLimitFilter) -> tuple[logging.Logger, io.StringIO]:
    out = io.StringIO()
    handler = logging.StreamHandler(out)
    handler.addFilter(filt)
    log = logging.getLogger(f"test.logs.{id(filt)}")
    log.propagate = False
    log.handlers[:] = [handler]
    log.setLevel(logging.DEBUG)
    return log, out


def test_one_line_per_cause_per_interval_then_the_count_of_those_dropped() -> None:
    clock = Clock()
    log, out = logger_with(RateLimitFilter(10.0, clock))
    for i in range(1000):
        log.error("site %s: write failed (%d)", "a", i)
        log.error("site %s: write failed (%d)", "b", i)
    assert out.getvalue().splitlines() == ["site a: write failed (0)", "site b: write failed (0)"]
    clock.now = 9.9
    log.error("site %s: write failed (%d)", "a", 1000)
    assert len(out.getvalue().splitlines()) == 2
    clock.now = 10.0
    log.error("site %s: write failed (%d)", "a", 1001)
    last = out.getvalue().splitlines()[-1]
    assert last == "site a: write failed (1001) [1000 more line(s) like this one dropped in 10 s]"
    clock.now = 30.0
    log.error("site %s: write failed (%d)", "a", 1002)
    assert out.getvalue().splitlines()[-1] == "site a: write failed (1002)"


def test_information_is_not_limited_and_tracebacks_are() -> None:
    log, out = logger_with(RateLimitFilter(10.0, Clock()))
    for _ in range(3):
        log.info("site %s: session opened", "a")
    for _ in range(3):
        try:
            raise ValueError("boom")
        except ValueError:
            log.exception("callback failed")
    text = out.getvalue()
    assert text.count("session opened") == 3
    assert text.count("Traceback") == 1


def test_tracebacks_of_one_fault_are_one_cause_whatever_their_messages() -> None:
    log, out = logger_with(RateLimitFilter(10.0, Clock()))
    peername: tuple[str, int] | None = None  # a vanished peer's
    for port in range(100):
        try:
            peername[:2]  # type: ignore[index]
        except TypeError:
            log.error("Exception in callback <Handle %d>", port, exc_info=True)
    assert out.getvalue().count("Traceback") == 1


def test_the_causes_remembered_are_bounded() -> None:
    filt = RateLimitFilter(10.0, Clock())
    log, _ = logger_with(filt)
    for i in range(MAX_CAUSES + 50):
        log.warning("peer %s misbehaved", f"10.0.0.{i}")
    assert len(filt._causes) == MAX_CAUSES


class FullDisk(io.TextIOBase):
    """A stream on a full disk: every write fails, and is counted."""

    def __init__(self) -> None:
        self.attempts = 0

    def write(self, s: str) -> int:
        self.attempts += 1
        raise OSError(errno.ENOSPC, "No space left on device")


def test_a_handler_on_a_full_disk_neither_raises_nor_writes_tracebacks(
        monkeypatch: pytest.MonkeyPatch) -> None:
    root = logging.getLogger()
    monkeypatch.setattr(root, "handlers", [])
    monkeypatch.setattr(root, "level", root.level)
    monkeypatch.setattr(logging, "raiseExceptions", True)
    disk = FullDisk()
    monkeypatch.setattr("sys.stderr", disk)
    configure(verbose=False)
    assert logging.raiseExceptions is False
    for i in range(100):
        logging.getLogger("fresco_bridge.site").error("site %s: HOLD %d", "a", i)
    assert disk.attempts == 1  # the one line let through; no traceback written after it
