"""The run record's group-commit thread (``RunRecord``'s fdatasync, beside the step loop).

Its own module, not compiled: ``record/writer.py`` is compiled with mypyc (setup.py), and a
compiled subclass of ``threading.Thread`` crashed the garbage collector (mypyc 2.4.1;
BENCHMARKS.md, "Step cost and scaling"). It runs once per sync, not per step.
"""

from __future__ import annotations

import math
import os
import threading
import time

__all__ = ["Syncer"]


class Syncer(threading.Thread):
    """Group commit: one fdatasync covers every line written before it starts.

    Syncs at most once per ``interval``; a request while the last sync is younger than that
    waits out the rest of the interval, unless it is urgent (an event). Requests that arrive
    during a sync or a wait are coalesced into the next sync.

    Why a bare lock and flags rather than ``threading.Event``: a commit's request is then two
    attribute stores on the step loop (the thread is woken only when it is idle or for an
    event), and the thread itself wakes once per sync, not once per request; both sides run
    next to no Python code (an ``Event`` runs a ``Condition`` in Python on every call).
    """

    def __init__(self, fd: int, interval: float) -> None:
        super().__init__(name="fresco-record-sync", daemon=True)
        self._fd = fd
        self._interval = interval
        self._kick = threading.Lock()
        self._kick.acquire()  # released to wake the thread (a binary semaphore)
        self._kicked = False  # a release is pending: do not release twice
        self._idle = True  # the thread waits for a request, not for the interval to pass
        self._urgent = False
        self._stopping = False
        self._requested = 0  # lines written to the kernel when the last request came
        self.durable = 0  # lines covered by the last completed fdatasync
        self.syncs = 0
        self.error: OSError | None = None

    def _wake(self) -> None:
        if not self._kicked:
            self._kicked = True
            self._kick.release()

    def request(self, lines: int, urgent: bool) -> None:
        self._requested = lines
        if urgent:
            self._urgent = True
            self._wake()
        elif self._idle:  # else the thread's own timer covers these lines
            self._wake()

    def _wait(self, timeout: float = -1) -> None:
        if self._kick.acquire(timeout=timeout):
            self._kicked = False

    def run(self) -> None:
        last = -math.inf
        attempted = 0  # lines the last fdatasync was for (a failed one is retried on request)
        while True:
            # idle until a line is waiting for a sync (the flag is set before the check, the
            # request is stored before the flag is read: no request can be missed)
            self._idle = True
            if self._requested == attempted and not (self._urgent or self._stopping):
                self._wait()
            self._idle = False
            while not (self._urgent or self._stopping):  # at most one sync per interval
                wait = last + self._interval - time.monotonic()
                if wait <= 0.0:
                    break
                self._wait(wait)
            if self._stopping:
                return
            self._urgent = False
            attempted = self._requested
            last = time.monotonic()
            try:
                os.fdatasync(self._fd)
                self.durable = attempted
                self.syncs += 1
            except OSError as exc:  # reported on the next flush; retried on the next request
                self.error = exc

    def stop(self) -> None:
        self._stopping = True
        self._wake()
        self.join(timeout=5.0)
