"""One progress bar for long commands (pretraining, studies, diagnosis), on stderr.

On a terminal it redraws one line at most every ``min_interval`` s; elsewhere (CI logs, pipes) it
prints a line at every 10 % so logs stay short. Silent when ``enabled`` is false.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["ProgressBar"]


class ProgressBar:
    """``bar = ProgressBar("fit", total); bar(done, total)`` (usable as a sweep's progress)."""

    def __init__(
        self,
        label: str,
        total: int,
        *,
        stream: TextIO | None = None,
        enabled: bool = True,
        min_interval: float = 0.1,
        rate_unit: str | None = None,
    ) -> None:
        self.label = label
        self.rate_unit = rate_unit
        """Also show the rate, e.g. ``rate_unit="steps"`` -> ``(1,650 steps/s)``."""
        self.total = max(int(total), 0)
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.min_interval = min_interval
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._start = time.monotonic()
        self._last_draw = -1.0
        self._last_decile = -1
        self._done = 0

    def __call__(self, done: int, total: int | None = None) -> None:
        if total is not None:
            self.total = max(int(total), 0)
        self._done = done
        if not self.enabled or self.total == 0:
            return
        finished = done >= self.total
        if self._tty:
            now = time.monotonic()
            if finished or now - self._last_draw >= self.min_interval:
                self._last_draw = now
                self.stream.write("\r" + self._line())
                if finished:
                    self.stream.write("\n")
                self.stream.flush()
            return
        decile = 10 * done // self.total
        if decile > self._last_decile:
            self._last_decile = decile
            self.stream.write(self._line() + "\n")
            self.stream.flush()

    def _line(self) -> str:
        fraction = min(self._done / self.total, 1.0)
        filled = round(24 * fraction)
        elapsed = time.monotonic() - self._start
        eta = elapsed / fraction - elapsed if fraction > 0 else 0.0
        bar = "#" * filled + "." * (24 - filled)
        rate = ""
        if self.rate_unit is not None:
            rate = f" ({self._done / max(elapsed, 1e-9):,.0f} {self.rate_unit}/s)"
        return (
            f"{self.label} [{bar}] {self._done}/{self.total} "
            f"{elapsed:5.1f} s elapsed, ~{eta:.1f} s left{rate}"
        )
