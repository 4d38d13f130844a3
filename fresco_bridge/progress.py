"""One progress display for long commands (pretraining, studies, diagnosis, the demo), on stderr.

On a terminal it is a ``rich`` progress bar (label, bar, done/total, elapsed, time left, and the
rate when asked), redrawn every ``min_interval`` s by rich's thread (the clock runs while a long
first step is computed) and left on screen when finished.
Elsewhere (CI logs, pipes, tests) it stays quiet: no bar, only a plain line at most every
``log_every`` s (default 30) and one when finished, so a log shows a long command is alive
without growing. Silent when ``enabled`` is false. ``rich`` is imported on the first draw on a
terminal only: the commands that start light stay light.
"""

from __future__ import annotations

import atexit
import os
import sys
import time
from types import TracebackType
from typing import Any, TextIO

__all__ = ["ProgressBar", "close_all", "command_name", "status"]

_LIVE: set[ProgressBar] = set()
"""Bars drawing on a terminal now (``close_all`` ends them before an error line)."""


def command_name() -> str:
    """How this process was started, for the next commands a person is told to type:
    ``.venv/bin/fresco-bridge`` after ``make demo`` (no activated environment), else
    ``fresco-bridge``."""
    argv0 = sys.argv[0] if sys.argv else ""
    if os.path.basename(argv0) == "fresco-bridge":
        rel = os.path.relpath(argv0)
        return rel if not rel.startswith("..") else argv0
    return "fresco-bridge"


def status(text: str, stream: TextIO | None = None) -> None:
    """A status line before a long silent phase (imports, fits), at once, on a terminal only:
    a person sees what the command is doing; logs and pipes keep the command's own output."""
    out = stream if stream is not None else sys.stderr
    if getattr(out, "isatty", lambda: False)():
        out.write(text + "\n")
        out.flush()


def close_all() -> None:
    """End every bar still drawing (the command failed): the cursor back, the line finished."""
    for bar in list(_LIVE):
        bar.close()


def _log_handlers_to(console: Any, stream: TextIO) -> list[tuple[Any, Any]]:
    """Log handlers writing to the bar's stream write through the bar's console while it is
    drawn (a log line above the bar, not glued to its end); their old streams, to restore."""
    import logging  # here: the light entry does not load logging

    from rich.file_proxy import FileProxy

    loggers = [logging.getLogger(), *(logger for logger in logging.Logger.manager.loggerDict
                                      .values() if isinstance(logger, logging.Logger))]
    return [(h, h.setStream(FileProxy(console, stream))) for logger in loggers
            for h in logger.handlers
            if type(h) is logging.StreamHandler and h.stream is stream]


class ProgressBar:
    """``bar = ProgressBar("fit", total); bar(done, total)`` (usable as a sweep's progress).

    ``with ProgressBar(...) as bar:`` shows the bar at once (on a terminal) and ends it even when
    the work raises; a bar that reaches its total ends itself. ``total`` 0: not known yet, the
    first ``bar(done, total)`` gives it (nothing is drawn before).
    """

    def __init__(
        self,
        label: str,
        total: int,
        *,
        stream: TextIO | None = None,
        enabled: bool = True,
        min_interval: float = 0.1,
        rate_unit: str | None = None,
        log_every: float = 30.0,
    ) -> None:
        self.label = label
        self.rate_unit = rate_unit
        """Also show the rate, e.g. ``rate_unit="steps"`` -> ``1,650 steps/s``."""
        self.total = max(int(total), 0)
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.min_interval = min_interval
        self.log_every = log_every
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._start = time.monotonic()
        self._last_log = self._start
        self._done = 0
        self._finished = False
        self._progress: Any = None  # rich.progress.Progress, on a terminal once drawn
        self._logs: list[tuple[Any, Any]] = []  # (log handler, its own stream) while drawn
        self._task: Any = None

    def __call__(self, done: int, total: int | None = None) -> None:
        if total is not None:
            self.total = max(int(total), 0)
        self._done = done
        if not self.enabled or self.total == 0 or self._finished:
            return
        finished = done >= self.total
        now = time.monotonic()
        if self._tty:
            self._draw(now, finished)
        elif finished or now - self._last_log >= self.log_every:
            self._last_log = now
            self.stream.write(self.line(finished) + "\n")
            self.stream.flush()
        if finished:
            self._finished = True
            self.close()

    def line(self, finished: bool = False) -> str:
        """The plain status line (off a terminal): ``demo: 250/500, 1.2 s elapsed, ~1.2 s
        left`` or, at the end, ``demo: 500/500 done in 2.4 s (208 steps/s)``."""
        elapsed = time.monotonic() - self._start
        rate = ""
        if self.rate_unit is not None:
            rate = f" ({self._done / max(elapsed, 1e-9):,.0f} {self.rate_unit}/s)"
        if finished:
            return f"{self.label}: {self._done}/{self.total} done in {elapsed:.1f} s{rate}"
        fraction = min(self._done / self.total, 1.0)
        left = f", ~{elapsed / fraction - elapsed:.0f} s left" if fraction > 0 else ""
        return f"{self.label}: {self._done}/{self.total}, {elapsed:.0f} s elapsed{left}{rate}"

    def _draw(self, now: float, finished: bool) -> None:
        if self._progress is None:
            self._progress, self._task = self._start_rich()
        fields = {}
        if self.rate_unit is not None:
            rate = self._done / max(now - self._start, 1e-9)
            fields["rate"] = f"{rate:,.0f} {self.rate_unit}/s"
        self._progress.update(self._task, completed=min(self._done, self.total),
                              total=self.total, **fields)
        if finished:
            self._progress.refresh()

    def _start_rich(self) -> tuple[Any, Any]:
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            ProgressColumn,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        columns: list[str | ProgressColumn] = [
            TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
            TimeElapsedColumn(), TextColumn("elapsed"), TimeRemainingColumn(), TextColumn("left")]
        if self.rate_unit is not None:
            columns.append(TextColumn("{task.fields[rate]}"))
        progress = Progress(*columns, console=Console(file=self.stream),
                            refresh_per_second=1.0 / max(self.min_interval, 0.05),
                            redirect_stdout=False, redirect_stderr=False)
        self._logs = _log_handlers_to(progress.console, self.stream)
        task = progress.add_task(self.label, total=self.total, rate="")
        # elapsed time counts from the bar's creation, not from its first draw
        progress.tasks[0].start_time = progress.get_time() - (time.monotonic() - self._start)
        progress.start()
        _LIVE.add(self)
        atexit.register(self.close)
        return progress, task

    def close(self) -> None:
        """End the display (idempotent): a terminal's bar is drawn a last time and the line
        ended; nothing is printed off a terminal."""
        progress, self._progress = self._progress, None
        if progress is None:
            return
        _LIVE.discard(self)
        atexit.unregister(self.close)
        progress.stop()
        for handler, stream in self._logs:
            handler.setStream(stream)  # flushes what the proxy holds
        self._logs = []

    def __enter__(self) -> ProgressBar:
        if self.enabled and self._tty and self.total > 0 and not self._finished:
            self._draw(time.monotonic(), finished=False)
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
