"""At most one log line per cause per interval, the rest counted and said in the next line.

A peer's misbehaviour repeated thousands of times (connect-reset floods, ICMP errors, a
misconfigured integrator retrying) must grow neither the log nor the disk it shares with the
run record; the first occurrence is said at once, so nothing is hidden from the operator.
Pure but for the logger: the clock is injected.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

RATE_LOG_INTERVAL = 10.0
"""Seconds between two lines of one cause."""


class RateLimitedLog:
    """One logger's lines, at most one per cause per ``interval``."""

    def __init__(self, logger: logging.Logger, interval: float = RATE_LOG_INTERVAL,
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
