"""The daemon's log: one line per cause per interval, and a handler that cannot write is no fault
of the bridge."""

from __future__ import annotations

import errno
import io
import logging

import pytest

from fresco_bridge.logs import (
    MAX_CAUSES,
    OUTSIDE_LOGGERS,
    RateLimitFilter,
    cause_of,
    configure,
    printable,
)


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


# -- one line whatever a message quotes; libraries in the bridge's words ----------------------
FORGED_ID = "x\n2026-12-07 09:00:00,000 INFO fresco_bridge: stopped\u001b[2J"


def configured(monkeypatch: pytest.MonkeyPatch, verbose: bool = False) -> io.StringIO:
    """``configure`` writing into a buffer, restored after the test."""
    root = logging.getLogger()
    monkeypatch.setattr(root, "handlers", [])
    monkeypatch.setattr(root, "level", root.level)
    for name in OUTSIDE_LOGGERS:
        monkeypatch.setattr(logging.getLogger(name), "level", logging.getLogger(name).level)
    out = io.StringIO()
    monkeypatch.setattr("sys.stderr", out)
    monkeypatch.setattr(logging, "_warnings_showwarning", None)  # pytest restored warnings'
    configure(verbose=verbose)
    monkeypatch.setattr(logging, "raiseExceptions", True)
    return out


def test_printable_escapes_what_a_terminal_or_a_reader_would_act_on() -> None:
    assert printable("site a: ok") == "site a: ok"
    assert printable(FORGED_ID) == ("x\\n2026-12-07 09:00:00,000 INFO fresco_bridge: stopped"
                                    "\\x1b[2J")
    assert printable("a\rb\tc\x00d\x7fe\x85f") == "a\\rb\\tc\\x00d\\x7fe\\x85f"
    assert printable("l\u2028p\u2029b\u202egr\ud800") == "l\\u2028p\\u2029b\\u202egr\\ud800"
    assert printable("déjà vu, 1 kN → 2 kN") == "déjà vu, 1 kN → 2 kN"  # text stays text


def test_a_forged_line_through_an_argument_stays_inside_its_line(
        monkeypatch: pytest.MonkeyPatch) -> None:
    out = configured(monkeypatch)
    logging.getLogger("fresco_bridge.telemetry").warning(
        "telemetry: operator command %s accepted for site %s (id %s)", "pause", "s", FORGED_ID)
    lines = out.getvalue().splitlines()
    assert len(lines) == 1
    assert lines[0].endswith("(id x\\n2026-12-07 09:00:00,000 INFO fresco_bridge: stopped"
                             "\\x1b[2J)")


def test_a_library_hex_dump_and_traceback_become_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    out = configured(monkeypatch)
    pymodbus = logging.getLogger("pymodbus.logging")
    pymodbus.error("No response received after 3 retries, continue with next request\n"
                   ">>>>> send: 0x0 0x1 0x0 0x0 0x0 0x6 0x1 0x3 0x0 0x0 0x0 0x2\n"
                   ">>>>> recv: 0x17 0x5a extra data: ")
    pymodbus.debug(">>>>> recv: 0x17 0x5a")  # frames are debug content: below WARNING
    try:
        json_line = "[" * 4000
        raise RecursionError(f"maximum recursion depth exceeded ({len(json_line)})")
    except RecursionError:
        logging.getLogger("asyncio").error("Unhandled exception in client_connected_cb",
                                           exc_info=True)
    lines = out.getvalue().splitlines()
    assert len(lines) == 2, lines
    assert lines[0].endswith("ERROR   pymodbus.logging: No response received after 3 retries, "
                             "continue with next request")
    assert "Unhandled exception in client_connected_cb: RecursionError: maximum recursion depth "\
           "exceeded (4000) (test_logs.py:" in lines[1]
    assert "0x" not in out.getvalue() and "Traceback" not in out.getvalue()


def test_a_python_warning_is_a_line_of_the_log(monkeypatch: pytest.MonkeyPatch) -> None:
    import numpy as np

    out = configured(monkeypatch)
    with np.errstate(over="warn"):
        np.array([1e308]) * 10.0
    logging.captureWarnings(False)
    (line,) = out.getvalue().splitlines()
    assert "WARNING py.warnings: " in line and "RuntimeWarning: overflow encountered" in line


def test_one_line_per_cause_the_caller_names() -> None:
    clock = Clock()
    log, out = logger_with(RateLimitFilter(10.0, clock))
    reasons = ["controller failed on get_daq: no answer within 0.2 s",
               "limit exceeded, command [41.5] not forwarded: disp 41.5 > 40 mm",
               "controller failed on get_daq: no answer within 0.2 s",
               "limit exceeded, command [43.25] not forwarded: disp 43.25 > 40 mm"]
    for step, reason in enumerate(reasons):
        log.error("site %s: HOLD at step %d: %s", "a", step, reason, extra=cause_of(reason))
    assert [line.split(": ", 2)[2] for line in out.getvalue().splitlines()] == reasons[:2]


def test_a_verbose_log_keeps_a_librarys_traceback_but_not_its_hex(
        monkeypatch: pytest.MonkeyPatch) -> None:
    out = configured(monkeypatch, verbose=True)
    logging.getLogger("pymodbus.logging").error("No response received\n>>>>> recv: 0x17 0x5a")
    logging.getLogger("pymodbus.logging").debug(">>>>> recv: 0x17 0x5a")
    try:
        raise ValueError("boom")
    except ValueError:
        logging.getLogger("asyncio").error("Exception in callback", exc_info=True)
    text = out.getvalue()
    assert "0x" not in text and "No response received\n" in text
    assert "Traceback (most recent call last)" in text  # -v: the developer's detail
