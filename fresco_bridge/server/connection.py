"""The per-connection pump shared by TCP and UDP: feed bytes, step handlers, close on errors.

Events are processed inside ``data_received``. A handler that completes without suspending
(in-process controller) costs no scheduler round trip; one that waits (a network controller, an
operator pause) is finished in a task, and what arrives meanwhile is only buffered, so messages
are still handled strictly in order. Reading goes on while a request waits, so a client that
vanishes is noticed: an operator wait is then cancelled (its command is never forwarded), while
a controller call finishes under its own deadline. Only a client that keeps sending more than
``HELD_BYTES_CAP`` during one wait is paused (backpressure).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from time import perf_counter
from typing import Protocol

from protocol import NEED_DATA, PAUSED, ActorSession, ElementServerSession, ProtocolError

from ..eager import Suspended, start_eager
from ..sites import ExperimentalSite, SiteError
from .handlers import ActorHandler, ElementHandler, SessionEnded

log = logging.getLogger("fresco_bridge.server")
HELD_BYTES_CAP = 1 << 20
"""Bytes buffered while a request waits before the transport stops reading."""


class _Handler(Protocol):
    async def handle(self, ev: object) -> None: ...


class SessionPump:
    """Owns one protocol session and its handler for the lifetime of one client session."""

    def __init__(
        self,
        site: ExperimentalSite,
        peer: str,
        send: Callable[[bytes], None],
        close: Callable[[], None],
        pause: Callable[[bool], None],
        *,
        max_data_size: int,
        transport: str,
    ) -> None:
        self.site = site
        self.peer = peer
        self._close = close
        self._pause = pause
        self._pending: asyncio.Task[None] | None = None
        self._held = 0  # bytes received while a request waits
        self._reading_paused = False
        self._timing: tuple[object, float] | None = None  # (event, start) of a pending request
        self.closed = False
        self.session: ElementServerSession | ActorSession
        self.handler: _Handler
        if site.cfg.protocol == "element":
            self.session = ElementServerSession(max_data_size=max_data_size)
            self.handler = ElementHandler(site, self.session, send, peer)
        else:
            self.session = ActorSession(transport=transport)  # type: ignore[arg-type]
            self.handler = ActorHandler(site, self.session, send, peer)

    def feed(self, data: bytes) -> None:
        if self.closed:
            return
        self.session.receive_data(data)
        if self._pending is None:
            self._run()
        elif not self._reading_paused:
            self._held += len(data)
            if self._held > HELD_BYTES_CAP:
                self._reading_paused = True
                self._pause(True)

    def _run(self) -> None:
        session, handle, metrics = self.session, self.handler.handle, self.site.metrics
        while not self.closed:
            try:
                ev = session.next_event()
            except ProtocolError as exc:
                self._end(f"protocol error from {self.peer}: {exc}", error=True)
                return
            if ev is NEED_DATA or ev is PAUSED:
                return
            t0 = perf_counter() if metrics is not None else 0.0
            try:
                r = start_eager(handle(ev))
            except SessionEnded as exc:
                self._end(str(exc))
                return
            except (SiteError, ProtocolError) as exc:
                self._end(str(exc), error=True)
                return
            except Exception as exc:  # a bug must not take the daemon down: end this session
                log.exception("site %s: internal error handling %r", self.site.name, ev)
                self._end(f"internal error: {exc!r}", error=True)
                return
            if isinstance(r, Suspended):
                self._held = 0
                self._pending = r.task(name=f"{self.site.name}.request")
                self._pending.add_done_callback(self._resumed)
                if metrics is not None:
                    self._timing = (ev, t0)
                return
            if metrics is not None:
                metrics.message(ev, perf_counter() - t0)

    def _resumed(self, task: asyncio.Task[None]) -> None:
        self._pending = None
        if task.cancelled():
            self._end("request cancelled (bridge shutting down)", error=True)
            return
        exc = task.exception()
        if isinstance(exc, SessionEnded):
            self._end(str(exc))
            return
        if exc is not None:
            self._end(f"{type(exc).__name__}: {exc}", error=exc is not None)
            return
        if self._timing is not None and self.site.metrics is not None:
            self.site.metrics.message(self._timing[0], perf_counter() - self._timing[1])
        self._timing = None
        if self._reading_paused:
            self._reading_paused = False
            self._pause(False)
        self._run()

    def _end(self, reason: str, *, error: bool = False) -> None:
        if self.closed:
            return
        self.closed = True
        self.site.close_session(reason, error=error)
        self._close()

    @property
    def busy(self) -> bool:
        """A request is waiting on the controller; it finishes (with its deadline) first."""
        return self._pending is not None

    def peer_lost(self, reason: str) -> None:
        """The client is gone (EOF already fed). A wait for the operator is cancelled at once,
        so a later resume cannot forward a dead client's command; a controller call finishes
        under its deadline and the session then ends on the EOF."""
        if self._pending is None or self.site.pending is not None:
            self.abort(reason)

    def abort(self, reason: str) -> None:
        """The transport went away or the bridge stops."""
        if self._pending is not None:
            self._pending.cancel()
        self._end(reason, error=True)
