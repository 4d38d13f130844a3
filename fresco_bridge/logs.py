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
"""

from __future__ import annotations

import logging
import sys
import time
from collections import OrderedDict
from collections.abc import Callable

__all__ = ["LOG_INTERVAL", "RateLimitFilter", "RateLimitedLog", "configure"]

LOG_INTERVAL = 10.0
"""Seconds between two warning or error lines of one cause."""
MAX_CAUSES = 1024
"""Causes remembered at once (the oldest is forgotten first): the filter's memory is bounded."""


class RateLimitFilter(logging.Filter):
    """At most one line per cause per ``interval`` for warnings and errors.

    A cause is the logger, the level, the message's format string and its first argument (the
    site's name, by this project's convention): two sites' HOLDs are two causes, one site's
    thousand failed writes are one. A line with a traceback is caused by its exception's type
    and the line that raised it, whatever its message says.
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
        return (record.name, record.levelno, str(record.msg),
                first if isinstance(first, str | int) else None)

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


def configure(verbose: bool, interval: float = LOG_INTERVAL) -> None:
    """The daemon's logging: stderr, rate-limited, silent about its own write failures."""
    logging.raiseExceptions = False
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)-7s %(name)s: %(message)s"))
    handler.addFilter(RateLimitFilter(interval))
    logging.basicConfig(level=logging.DEBUG if verbose else logging.INFO, handlers=[handler])


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
