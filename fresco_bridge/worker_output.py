"""A worker process's output in the bridge's log, under its site's name.

A spawned worker (the twins' learner) inherits the bridge's stderr, so what it prints (numpy's
``RuntimeWarning: overflow encountered in multiply`` with its source line, a warning of its own
logging with no handler configured, a library's C-level message) landed raw in the operator's
log: no time, no site, several lines, no rate limit. ``forward_output`` (in the worker) sends
its log records, its Python warnings and everything written to its file descriptor 2 to the
bridge as ``("output", level, origin, text)`` replies on the channel it already has;
``relay_output`` (in the bridge) logs each as one line ``worker of <site> (pid N): …``,
limited per cause like every line of the bridge (``logs.RateLimitFilter``).

``quiet_tracker`` is the other stray line: the spawn context's queues hold named POSIX
semaphores (three per queue, six for the worker's two), and multiprocessing's resource tracker,
a helper process of the bridge, unlinks those a killed bridge (``kill -9``) could not release
and then warns "There appear to be 6 leaked semaphore objects to clean up at shutdown". Nothing
leaks: the warning reports the tracker's own clean-up of the killed parent's semaphores. The
filter is set in the environment the tracker starts with, for that message only.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import threading
from collections.abc import Callable
from typing import Any

from .logs import cause_of

__all__ = ["OUTPUT", "forward_output", "quiet_tracker", "relay_output"]

OUTPUT = "output"
"""The reply kind of a worker's line: ``("output", level, origin, text)``."""
MAX_TEXT = 2000
"""Characters of one forwarded line (a runaway print is cut, not carried whole)."""
_TRACKER_FILTER = "ignore:resource_tracker:UserWarning:multiprocessing.resource_tracker"

log = logging.getLogger("fresco_bridge.worker")

END_SECONDS = 2.0
"""How long a worker's ``end`` waits for the last lines of its fd 2."""

Send = Callable[[tuple[Any, ...]], None]


# -- the bridge's side --------------------------------------------------------------------------
def quiet_tracker() -> None:
    """Before the first queue of a spawned worker: the resource tracker started with it will
    not warn about the semaphores it releases for a killed bridge (module docstring)."""
    current = os.environ.get("PYTHONWARNINGS", "")
    if _TRACKER_FILTER not in current.split(","):
        os.environ["PYTHONWARNINGS"] = ",".join(filter(None, (current, _TRACKER_FILTER)))


def relay_output(site: str, pid: int | None, reply: tuple[Any, ...]) -> None:
    """Log one ``("output", level, origin, text)`` reply of the worker of ``site``."""
    _, level, origin, text = reply
    line = str(text)[:MAX_TEXT]
    log.log(int(level), "worker of %s (pid %s) %s: %s", site, pid, origin, line,
            extra=cause_of(f"{origin}: {line}"))


# -- the worker's side --------------------------------------------------------------------------
def forward_output(send: Send) -> Callable[[], None]:
    """In the worker, first thing: its log records (WARNING and up), its warnings and its
    file descriptor 2 go to the bridge through ``send`` (the reply channel's ``put``).

    Returns ``end``, which the worker calls last, while ``send`` still works: what was written
    to fd 2 just before the worker returns is read and sent, not lost with the process."""
    logging.raiseExceptions = False  # a closed channel: silence, not a traceback per line
    root = logging.getLogger()
    root.handlers[:] = [_Forward(send)]
    root.setLevel(logging.WARNING)
    logging.captureWarnings(True)
    pump: threading.Thread | None = None
    with contextlib.suppress(OSError):
        read, write = os.pipe()
        os.dup2(write, 2)
        os.close(write)
        pump = threading.Thread(target=_pump, args=(read, send), name="worker-stderr",
                                daemon=True)
        pump.start()

    def end() -> None:
        if pump is None:
            return
        with contextlib.suppress(Exception):
            sys.stderr.flush()
        with contextlib.suppress(OSError):  # fd 2 onto /dev/null: the pipe's last writer closes
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, 2)
            os.close(null)
        pump.join(END_SECONDS)

    return end


class _Forward(logging.Handler):
    """A record as one line: its message's first line, an exception as type and message."""

    def __init__(self, send: Send) -> None:
        super().__init__(logging.WARNING)
        self._send = send

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = record.getMessage().split("\n", 1)[0]
            if record.exc_info and record.exc_info[1] is not None:
                exc = record.exc_info[1]
                text = f"{text}: {type(exc).__name__}: {exc}"
            self._send((OUTPUT, record.levelno, record.name, text[:MAX_TEXT]))
        except Exception:  # the channel is closed: the bridge is gone, nothing to tell
            self.handleError(record)


def _pump(read: int, send: Send) -> None:
    """What reaches file descriptor 2, line by line, until the worker ends."""
    with open(read, "rb", buffering=0) as stream:
        pending = b""
        while chunk := stream.read(4096):
            pending += chunk
            *lines, pending = pending.split(b"\n")
            for raw in lines:
                if raw.strip():
                    send((OUTPUT, logging.WARNING, "stderr",
                          raw[:MAX_TEXT].decode("utf-8", "replace")))
            pending = pending[-MAX_TEXT:]
