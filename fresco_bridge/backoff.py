"""The one reconnect backoff: jittered exponential delays between ``low`` and ``high`` seconds.

Used by the networked controller adapters (reconnect), the site's controller recovery (probes)
and the MQTT telemetry (reconnect). Pure bookkeeping on an injected clock and random source.
"""

from __future__ import annotations

import math
import random
import time
from collections.abc import Callable

__all__ = ["Backoff"]


class Backoff:
    """After the n-th consecutive failure wait ``min(high, low·2^(n-1))·U(0.5, 1)`` s."""

    def __init__(self, low: float, high: float, clock: Callable[[], float] = time.monotonic,
                 rng: random.Random | None = None) -> None:
        if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low <= high):
            raise ValueError(f"backoff delays need 0 <= min <= max, got {low!r}, {high!r}")
        self.low, self.high = low, high
        self._clock = clock
        self._rng = rng or random.Random()
        self._delay = 0.0
        self._not_before = 0.0

    def failed(self) -> float:
        """A link was lost or an attempt failed: the next attempt waits; returns the wait."""
        self._delay = self.low if self._delay == 0.0 else min(self.high, 2.0 * self._delay)
        jittered = self._delay * self._rng.uniform(0.5, 1.0)
        self._not_before = self._clock() + jittered
        return jittered

    def succeeded(self) -> None:
        """Connected: the next loss starts again from the minimum delay."""
        self._delay = 0.0
        self._not_before = 0.0

    def wait_time(self) -> float:
        """Seconds to wait before the next attempt (0 when it may go now)."""
        return max(0.0, self._not_before - self._clock())
