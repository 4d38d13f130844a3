"""The pipe to one learner worker process: ordered batches out, replies in, never blocking the
event loop (``learner.py`` decides what goes through it and what the replies mean).

Batches go through a bounded queue with ``put_nowait``; when it is full they wait in a local
backlog that a flush task drains, in order (training data is never dropped). Replies come back
through a reader thread and ``call_soon_threadsafe``; the worker's end (however it ends) too.
A stopped channel delivers nothing more: a replacement worker gets a new channel, so the old
one's late replies cannot reach the new one's requests.
"""

from __future__ import annotations

import asyncio
import contextlib
import multiprocessing
import multiprocessing.queues
import queue
import threading
from collections import deque
from collections.abc import Callable
from multiprocessing.process import BaseProcess
from typing import Any

from .. import WORKER_PROCESS_PREFIX
from ..worker_output import quiet_tracker
from .worker import LearnerSpec, Message, Reply, worker_main

__all__ = ["FLUSH_PAUSE", "QUEUE_SIZE", "STOP_DEADLINE", "WorkerChannel"]

QUEUE_SIZE = 4096
"""Batches in flight to the worker before the local backlog takes them."""
FLUSH_PAUSE = 0.002
"""Seconds the flush task waits for room in the queue between two attempts."""
STOP_DEADLINE = 5.0
"""Seconds a worker is given to end after the stop message, then it is killed."""


class WorkerChannel:
    """One worker process of ``spec`` (started from the pickled state ``start``, or built)
    and its queues; ``on_reply(reply)`` and ``on_exit(exit code)`` run on the loop."""

    def __init__(self, spec: LearnerSpec, start: bytes | None, *,
                 on_reply: Callable[[Reply], None],
                 on_exit: Callable[[int | None], None]) -> None:
        self.spec = spec
        self._start = start
        self._on_reply, self._on_exit = on_reply, on_exit
        self._loop: asyncio.AbstractEventLoop | None = None
        self._proc: BaseProcess | None = None
        self._inbox: multiprocessing.queues.Queue[list[Message] | None] | None = None
        self._reader: threading.Thread | None = None
        self._backlog: deque[list[Message]] = deque()
        self._flush: asyncio.Task[None] | None = None
        self._stopped = False

    @property
    def pid(self) -> int | None:
        return None if self._proc is None else self._proc.pid

    async def start(self) -> None:
        """Start the process and its reader (its ``ready`` reply says it is built)."""
        self._loop = loop = asyncio.get_running_loop()
        ctx = multiprocessing.get_context("spawn")
        quiet_tracker()  # its report of a killed bridge's semaphores (worker_output)
        inbox: multiprocessing.queues.Queue[list[Message] | None] = ctx.Queue(QUEUE_SIZE)
        outbox: multiprocessing.queues.Queue[Reply] = ctx.Queue()
        source = self.spec.source
        proc = ctx.Process(target=worker_main, args=(self.spec, inbox, outbox, self._start),
                           name=f"{WORKER_PROCESS_PREFIX}learner-{source}", daemon=True)
        await loop.run_in_executor(None, proc.start)
        self._proc, self._inbox = proc, inbox
        self._reader = threading.Thread(target=self._read, args=(proc, outbox),
                                        name=f"learner-reader-{source}", daemon=True)
        self._reader.start()

    def _read(self, proc: BaseProcess, outbox: multiprocessing.queues.Queue[Reply]) -> None:
        """The reader thread: the worker's replies to the loop, then its end."""
        while not self._stopped:
            try:
                reply = outbox.get(timeout=0.2)
            except queue.Empty:
                if not proc.is_alive():
                    self._call(self._exited, proc.exitcode)
                    return
                continue
            except (EOFError, OSError):
                self._call(self._exited, proc.exitcode)
                return
            self._call(self._deliver, reply)

    def _call(self, fn: Callable[..., None], *args: Any) -> None:
        loop = self._loop
        if loop is not None:
            with contextlib.suppress(RuntimeError):  # the loop closed: the bridge has stopped
                loop.call_soon_threadsafe(fn, *args)

    def _deliver(self, reply: Reply) -> None:
        if not self._stopped:
            self._on_reply(reply)

    def _exited(self, code: int | None) -> None:
        if not self._stopped:
            self._on_exit(code)

    def post(self, batch: list[Message]) -> None:
        """``batch`` to the worker after every batch posted before it; never blocks."""
        inbox = self._inbox
        if inbox is None or self._stopped:
            return
        if not self._backlog:
            try:
                inbox.put_nowait(batch)
                return
            except queue.Full:
                pass
        self._backlog.append(batch)
        if self._flush is None or self._flush.done():
            assert self._loop is not None
            self._flush = self._loop.create_task(self._drain(),
                                                 name=f"learner.{self.spec.source}")

    async def _drain(self) -> None:
        while self._backlog:
            inbox = self._inbox
            if inbox is None:
                return
            try:
                inbox.put_nowait(self._backlog[0])
            except queue.Full:
                await asyncio.sleep(FLUSH_PAUSE)
                continue
            self._backlog.popleft()

    async def stop(self, *, kill: bool) -> None:
        """End the worker (the stop message, then a kill past ``STOP_DEADLINE``; ``kill``: at
        once); nothing it says from now on is delivered."""
        self._stopped = True
        if self._flush is not None and not self._flush.done():
            self._flush.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._flush
        self._backlog.clear()
        proc, inbox, reader = self._proc, self._inbox, self._reader
        self._proc = self._inbox = self._reader = None
        if proc is None:
            return
        loop = asyncio.get_running_loop()
        if not kill and inbox is not None:
            with contextlib.suppress(queue.Full, ValueError, OSError):
                inbox.put_nowait(None)
            await loop.run_in_executor(None, proc.join, STOP_DEADLINE)
        if proc.is_alive():
            proc.kill()
            await loop.run_in_executor(None, proc.join, STOP_DEADLINE)
        if inbox is not None:
            inbox.cancel_join_thread()
            inbox.close()
        if reader is not None:
            await loop.run_in_executor(None, reader.join, 1.0)
