"""The daemon's log: at most one line per cause per interval, and never a fault of its own.

A cause that repeats (a peer that misbehaves on every connection, a record that fails on every
line, a traceback per callback) would otherwise grow the log without bound, and the log may
share the run directory's disk. ``RateLimitFilter`` lets the first warning or error of a cause
through, drops the repeats for ``interval`` seconds and says how many it dropped on the next
line of that cause. Informational lines are not limited: they are per session, and a site
holds one session at a time.

A handler that cannot write (a full disk, a closed stream) must not take the bridge down or
print a traceback per line to stderr: ``configure`` sets ``logging.raiseExceptions = False``,
so ``Handler.handleError`` drops the line silently and the caller (the step path) goes on.

``RateLimitedLog`` is the same rule where the caller names the cause itself (a transport's
refusals, ICMP errors, ignored action codes): it holds wherever the bridge runs, with or
without ``configure`` (an embedded ``BridgeThread`` in a test or a notebook).

The log is evidence, so a line is one line whatever it quotes: ``printable`` escapes control
characters, line and paragraph separators, bidirectional overrides and lone surrogates, and
``OneLineFormatter`` applies it to every message, ours and the libraries', after its arguments
are in (an MQTT request id, a peer's name, a config string cannot forge a line or clear the
operator's screen). Libraries log in their own words: ``OutsideLineFilter`` keeps the first line
of a library's message (pymodbus appends its last 20 frames as hex to an error) and turns its
traceback into one line (type, message, where) unless the log is verbose; ``configure`` sets
the libraries' loggers to WARNING, verbose or not, and routes Python warnings (numpy's) into
the log.
"""

from __future__ import annotations

import logging
import re
import sys
import time
from collections import OrderedDict
from collections.abc import Callable, Mapping

__all__ = ["LOG_INTERVAL", "OUTSIDE_LOGGERS", "OneLineFormatter", "OutsideLineFilter",
           "RateLimitFilter", "RateLimitedLog", "cause_of", "configure", "printable"]

LOG_INTERVAL = 10.0
"""Seconds between two warning or error lines of one cause."""
MAX_CAUSES = 1024
"""Causes remembered at once (the oldest is forgotten first): the filter's memory is bounded."""
OUTSIDE_LOGGERS = ("asyncio", "pymodbus", "paho", "aiomqtt", "py.warnings", "concurrent",
                   "distributed", "torch", "numba", "matplotlib", "PIL")
"""Libraries whose loggers ``configure`` sets to WARNING (their per-frame chatter and hex dumps
are debug content even when the bridge's own log is verbose)."""
MAX_CAUSE_TEXT = 200

_UNPRINTABLE = re.compile("[\x00-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028\u2029"
                          "\u202a-\u202e\u2066-\u2069\ud800-\udfff]")
_NAMED = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def printable(text: str) -> str:
    """``text`` on one line, with nothing a terminal would act on: newlines as ``\\n``, other
    control characters, separators, bidirectional overrides and lone surrogates as ``\\xNN`` or
    ``\\uNNNN``. The one escape for whatever reaches the log or the operator's terminal."""
    if _UNPRINTABLE.search(text) is None:
        return text
    return _UNPRINTABLE.sub(_escape, text)


def _escape(match: re.Match[str]) -> str:
    ch = match.group()
    named = _NAMED.get(ch)
    if named is not None:
        return named
    code = ord(ch)
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def cause_of(text: str) -> Mapping[str, str]:
    """``extra=`` for a line whose cause is its text's words, not its numbers (a HOLD's reason:
    a limit, a lost controller, a non-finite trial are three causes; the step and the values
    in it are not): ``log.error("site %s: HOLD at step %d: %s", site, step, reason,
    extra=cause_of(reason))``."""
    return {"log_cause": _NUMBER.sub("#", text)[:MAX_CAUSE_TEXT]}


class RateLimitFilter(logging.Filter):
    """At most one line per cause per ``interval`` for warnings and errors.

    A cause is the logger, the level, the message's format string with its numbers masked (a
    library's preformatted text), its first argument (the site's name, by this project's
    convention) and the caller's ``cause_of``, if given: two sites' HOLDs are two causes, one
    site's thousand failed writes are one, and a limit's HOLD does not hide a lost controller's.
    A line with a traceback is caused by its exception's type and the line that raised it,
    whatever its message says.
    """

    def __init__(self, interval: float = LOG_INTERVAL,
                 clock: Callable[[], float] = time.monotonic,
                 level: int = logging.WARNING) -> None:
        super().__init__()
        self.interval = interval
        self.level = level
        self._clock = clock
        self._causes: OrderedDict[tuple[object, ...], tuple[float, int]] = OrderedDict()
        """Per cause: when its last line went out, and how many were dropped since."""

    @staticmethod
    def cause(record: logging.LogRecord) -> tuple[object, ...]:
        exc = record.exc_info
        if exc and exc[0] is not None and exc[2] is not None:
            # a traceback: its exception and where it was raised (asyncio's "Exception in
            # callback <handle>" message differs per connection, the fault does not)
            tb = exc[2]
            while tb.tb_next is not None:
                tb = tb.tb_next
            return (record.name, record.levelno, exc[0].__qualname__,
                    tb.tb_frame.f_code.co_filename, tb.tb_lineno)
        args = record.args
        first = args[0] if isinstance(args, tuple) and args else None
        named = getattr(record, "log_cause", None)
        text = None if named is not None else _NUMBER.sub("#", str(record.msg))[:MAX_CAUSE_TEXT]
        return (record.name, record.levelno, text,
                first if isinstance(first, str | int) else None, named)

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno < self.level:
            return True
        key = self.cause(record)
        now = self._clock()
        seen = self._causes.get(key)
        if seen is not None and now - seen[0] < self.interval:
            self._causes[key] = (seen[0], seen[1] + 1)
            return False
        self._causes[key] = (now, 0)
        self._causes.move_to_end(key)
        if len(self._causes) > MAX_CAUSES:
            self._causes.popitem(last=False)
        if seen is not None and seen[1]:
            # no "%" in the note: the message is still formatted with its own arguments
            record.msg = (f"{record.msg} [{seen[1]} more line(s) like this one dropped in "
                          f"{now - seen[0]:.0f} s]")
        return True


class OneLineFormatter(logging.Formatter):
    """Every message on one line (``printable``), its arguments in; a traceback of the bridge's
    own (a bug) keeps its lines below it."""

    def formatMessage(self, record: logging.LogRecord) -> str:
        record.message = printable(record.message)
        return super().formatMessage(record)


class OutsideLineFilter(logging.Filter):
    """A library's line in the bridge's words: its message's first line (pymodbus appends hex
    frames to an error), its traceback as one line (``ValueError: boom (streams.py:42)``) unless
    ``tracebacks`` (a verbose log). Lines of ``fresco_bridge`` pass untouched."""

    def __init__(self, own: str = "fresco_bridge", *, tracebacks: bool = False) -> None:
        super().__init__()
        self.own = own
        self.tracebacks = tracebacks

    def filter(self, record: logging.LogRecord) -> bool:
        if record.name == self.own or record.name.startswith(self.own + "."):
            return True
        text = record.getMessage()
        first, newline, _ = text.partition("\n")
        exc = record.exc_info
        if exc and exc[1] is not None and not self.tracebacks:
            tb = exc[2]
            while tb is not None and tb.tb_next is not None:
                tb = tb.tb_next
            where = "" if tb is None else \
                f"{tb.tb_frame.f_code.co_filename.rsplit('/', 1)[-1]}:{tb.tb_lineno}"
            first = f"{first.rstrip()}: {type(exc[1]).__name__}: {exc[1]} ({where})"
            record.exc_info, record.exc_text = None, None
            record.log_cause = f"{type(exc[1]).__qualname__} at {where}"  # as a traceback's
        elif not newline:
            return True
        record.msg, record.args = first.rstrip(), None
        return True


def configure(verbose: bool, interval: float = LOG_INTERVAL) -> None:
    """The daemon's logging: stderr, one line per message, rate-limited, silent about its own
    write failures; libraries at WARNING in one line each, Python warnings through it too."""
    logging.raiseExceptions = False
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(OneLineFormatter("%(asctime)s %(levelname)-7s %(name)s: %(message)s"))
    handler.addFilter(OutsideLineFilter(tracebacks=verbose))
    handler.addFilter(RateLimitFilter(interval))
    logging.basicConfig(level=logging.DEBUG if verbose else logging.INFO, handlers=[handler])
    for name in OUTSIDE_LOGGERS:
        logging.getLogger(name).setLevel(logging.WARNING)
    logging.captureWarnings(True)


class RateLimitedLog:
    """One logger's lines, at most one per cause per ``interval``."""

    def __init__(self, logger: logging.Logger, interval: float = LOG_INTERVAL,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.logger = logger
        self.interval = interval
        self._clock = clock
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def log(self, level: int, cause: str, msg: str, *args: object) -> bool:
        """Log ``msg % args`` unless ``cause`` was logged less than ``interval`` ago (then
        only count it); True if logged. ``cause`` is a fixed string, never peer data, so the
        bookkeeping stays bounded."""
        now = self._clock()
        last = self._last.get(cause)
        if last is not None and now - last < self.interval:
            self._suppressed[cause] = self._suppressed.get(cause, 0) + 1
            return False
        self._last[cause] = now
        suppressed = self._suppressed.pop(cause, 0)
        if suppressed:
            msg += " (%d more not logged in the last %g s)"
            args = (*args, suppressed, self.interval)
        self.logger.log(level, msg, *args)
        return True

    def warning(self, cause: str, msg: str, *args: object) -> bool:
        return self.log(logging.WARNING, cause, msg, *args)
