"""The per-connection pump shared by TCP and UDP: feed bytes, step handlers, close on errors.

Events are processed inside ``data_received``. A handler that completes without suspending
(in-process controller) costs no scheduler round trip; one that waits (a network controller, an
operator pause) is finished in a task, and what arrives meanwhile is only buffered, so messages
are still handled strictly in order. Reading goes on while a request waits, so a client that
vanishes is noticed: an operator wait is then cancelled (its command is never forwarded), while
a controller call finishes under its own deadline. Only a client that keeps sending more than
``HELD_BYTES_CAP`` during one wait is paused (backpressure).

Replies are bounded too: past ``WRITE_HIGH_WATER`` bytes queued for a client that does not read
them, the pump stops reading and answering that client (its requests wait in its own socket),
so what is queued never exceeds the high-water mark plus one reply; a client that leaves them
unread for ``session_idle_timeout`` is ended with the reason. The same deadline ends a session
that sends nothing while the bridge owes it nothing (no request being answered, no operator
wait, no controller call): a vanished UDP peer or a half-open TCP connection frees its site.

A message once begun must be complete within ``message_deadline`` (``bridge.message_deadline``),
whatever the idle clock says: a client trickling a byte now and then is ended. A connection
holds its site only from its size ID (or site setup) on, so one that never completes it keeps
nobody out. The deadline is a check every half deadline, not a timer per message: the step
path pays nothing for it.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from time import perf_counter
from typing import Any, Literal, Protocol

from protocol import ActorSession, ElementServerSession, ProtocolError, Sentinel

from ..eager import Suspended, start_eager
from ..logs import RateLimitedLog
from ..sites import Site, SiteError
from ..sites.access import Allowlist, RejectionLog
from .handlers import ActorHandler, ElementHandler, SessionEnded

log = logging.getLogger("fresco_bridge.server")
HELD_BYTES_CAP = 1 << 20
"""Bytes buffered while a request waits before the transport stops reading."""
WRITE_HIGH_WATER = 256 * 1024
"""Bytes queued for a client past which its requests are no longer read nor answered."""
WRITE_LOW_WATER = 64 * 1024
"""Queued bytes below which a paused client is read and answered again."""


@dataclass(slots=True)
class SiteListener:
    """What every connection of one site's listener shares."""

    site: Site
    allowlist: Allowlist
    max_data_size: int
    idle_timeout: float
    message_deadline: float = 5.0
    """Seconds a client has to complete a message it has begun (``bridge.message_deadline``)."""
    rejections: RejectionLog = field(default_factory=RejectionLog)
    ratelog: RateLimitedLog = field(default_factory=lambda: RateLimitedLog(log))
    """The listener's log lines about peers (errors, resets): one per cause per interval."""
    tls_handshakes: int = 0
    """TLS handshakes in flight (bounded by ``tls.MAX_HANDSHAKES``)."""
    told_to_stop: int = 0
    """Refused clients being answered with NaN now (bounded by ``refusal.MAX_REFUSALS``)."""

    def __post_init__(self) -> None:
        self.site.rejections = self.rejections

    def refuse(self, kind: str, peer: str, why: str) -> None:
        """Count a refused connection; log and record it within the rate limit."""
        site = self.site
        report = self.rejections.refused(kind, f"refused client {peer}: {why}")
        if report is None:
            return
        log.warning("site %s: %s", site.name, report.message())
        site.record_refusal(report.message(), refusal=kind, suppressed=report.suppressed,
                            refused_total=self.rejections.total)


class _Handler(Protocol):
    introduced: bool
    """The client's size ID (or site setup) fitted: its session is open."""
    on_open: Callable[[], None] | None
    """Called once the session opened (the site is then this client's)."""

    def dispatch(self, ev: Any) -> Coroutine[Any, Any, None] | None:
        """Handle ``ev`` at once (None) or return the coroutine that finishes it."""
        ...


class SessionPump:
    """Owns one protocol session and its handler for the lifetime of one client session."""

    def __init__(
        self,
        listener: SiteListener,
        peer: str,
        send: Callable[[bytes], None],
        close: Callable[[], None],
        pause: Callable[[bool], None],
        *,
        transport: Literal["tcp", "udp"],
    ) -> None:
        self.listener = listener
        self.site = site = listener.site
        self.peer = peer
        # refused now if the site cannot take a session (busy, aborted: SiteError, and the
        # transport refuses the connection); held only from the size ID on (``open_session``)
        site.claim(peer)
        self._close = close
        self._pause = pause
        self._pending: asyncio.Task[None] | None = None
        self._held = 0  # bytes received while a request waits
        self._held_paused = False  # reading paused: too much arrived during one wait
        self._write_blocked = False  # reading paused: the client does not read its replies
        self._timing: tuple[object, float] | None = None  # (event, start) of a pending request
        self.closed = False
        self.on_refused: Callable[[ElementServerSession], None] | None = None
        """Given, a client whose size ID the site cannot serve is handed to it with its
        session (answered with NaN: ``refusal.py``) instead of being closed."""
        self._idle_timeout = idle_timeout = listener.idle_timeout
        self._loop = asyncio.get_running_loop()
        self._activity = self._loop.time()
        self._idle_handle: asyncio.TimerHandle | None = self._loop.call_later(
            idle_timeout, self._idle_check)
        self._deadline = deadline = listener.message_deadline
        self._begun = (-1, 0.0)  # (stream offset, time) of a partial message first seen
        self._deadline_handle: asyncio.TimerHandle | None = self._loop.call_later(
            deadline / 2, self._deadline_check)
        self.session: ElementServerSession | ActorSession
        self.handler: _Handler
        if site.cfg.protocol == "element":
            element = ElementServerSession(max_data_size=listener.max_data_size)
            self.session, self.handler = element, ElementHandler(site, element, send, peer)
        else:
            actor = ActorSession(transport=transport)
            self.session, self.handler = actor, ActorHandler(site, actor, send, peer)
        self.handler.on_open = self._opened
        # bound once: the per-message path calls each of them (``feed``, ``_run``)
        self._time = self._loop.time
        self._receive: Callable[[bytes], None] = self.session.receive_data
        self._next_event: Callable[[], Any] = self.session.next_event
        self._dispatch: Callable[[Any], Coroutine[Any, Any, None] | None] = self.handler.dispatch
        self._element = self.session if isinstance(self.session, ElementServerSession) else None
        """Its ``drained`` spares the call to ``next_event`` that finds nothing buffered, once a
        message (a socket delivers a genericClient's requests one by one)."""

    def feed(self, data: bytes) -> None:
        if self.closed:
            return
        self._activity = self._time()
        self._receive(data)
        if self._pending is None:
            if not self._write_blocked:
                self._run()
        elif not self._held_paused:
            self._held += len(data)
            if self._held > HELD_BYTES_CAP:
                self._held_paused = True
                self._pause(True)

    # -- deadlines and backpressure ------------------------------------------------------------
    def _idle_check(self) -> None:
        """The session-idle deadline: the clock runs only while the bridge owes the client
        nothing (a request waiting on the controller or an operator is not silence), or while
        the client leaves its replies unread."""
        self._idle_handle = None
        if self.closed:
            return
        now = self._loop.time()
        if self._pending is not None and not self._write_blocked:
            self._activity = now
        idle = now - self._activity
        if idle >= self._idle_timeout:
            if self._write_blocked:
                why = (f"client has not read its replies for {idle:.1f} s "
                       f"(bridge.session_idle_timeout = {self._idle_timeout:g} s)")
            else:
                why = (f"no message from the client for {idle:.1f} s "
                       f"(bridge.session_idle_timeout = {self._idle_timeout:g} s)")
            self.abort(why)
            return
        self._idle_handle = self._loop.call_later(self._idle_timeout - idle, self._idle_check)

    def _deadline_check(self) -> None:
        """The message deadline: a message begun (unread bytes, no request in progress) and
        not finished within ``message_deadline`` ends the session; checked every half
        deadline, so it ends within one and a half."""
        self._deadline_handle = None
        if self.closed:
            return
        now = self._loop.time()
        offset, unread = self.session.partial_message
        if unread == 0 or self._pending is not None or self._write_blocked:
            self._begun = (-1, now)  # nothing begun, or its bytes wait for us, not the client
        elif self._begun[0] != offset:
            self._begun = (offset, now)
        elif now - self._begun[1] >= self._deadline:
            what = "its size ID" if not self.handler.introduced else "a message"
            self.abort(f"client did not complete {what} within {self._deadline:g} s "
                       f"({unread} byte(s) of it received; bridge.message_deadline)")
            return
        self._deadline_handle = self._loop.call_later(self._deadline / 2, self._deadline_check)

    def _opened(self) -> None:
        """The client introduced itself and its session opened: the site ends it through us."""
        self.site.attach_session_end(self.end_by_bridge)

    def writing_paused(self, paused: bool) -> None:
        """The transport's write buffer crossed its high (True) or low (False) water mark."""
        if self.closed or paused == self._write_blocked:
            return
        self._write_blocked = paused
        if paused:
            self.listener.ratelog.warning(
                "unread", "site %s: client %s does not read its replies (over %d KiB queued): "
                "not reading nor answering it until it does", self.site.name, self.peer,
                WRITE_HIGH_WATER // 1024)
            if not self._held_paused:
                self._pause(True)
            return
        self._activity = self._loop.time()
        if not self._held_paused:
            self._pause(False)
        if self._pending is None:
            self._run()

    def end_by_bridge(self, reason: str) -> None:
        """The bridge ends this session (operator abort, deadline)."""
        self.abort(reason)

    def _run(self) -> None:
        next_event, dispatch, element = self._next_event, self._dispatch, self._element
        metrics = self.site.metrics
        t0 = 0.0
        while not self.closed and not self._write_blocked:
            if metrics is not None:
                t0 = perf_counter()
            try:
                ev = next_event()
            except ProtocolError as exc:
                self._end(f"protocol error from {self.peer}: {exc}", error=True)
                return
            if type(ev) is Sentinel:  # NEED_DATA or PAUSED
                return
            try:
                handling = dispatch(ev)
                r = None if handling is None else start_eager(handling)
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
            if r is not None and isinstance(r, Suspended):
                self._held = 0
                self._pending = r.task(name=f"{self.site.name}.request")
                self._pending.add_done_callback(self._resumed)
                if metrics is not None:
                    self._timing = (ev, t0)
                return
            if metrics is not None:
                metrics.message(ev, perf_counter() - t0)
            if element is not None and element.drained:
                return  # the next ``next_event`` would be NEED_DATA

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
        self._activity = self._loop.time()
        if self._held_paused:
            self._held_paused = False
            if not self._write_blocked:
                self._pause(False)
        if not self._write_blocked:
            self._run()

    def _end(self, reason: str, *, error: bool = False) -> None:
        if self.closed:
            return
        self.closed = True
        for handle in (self._idle_handle, self._deadline_handle):
            if handle is not None:
                handle.cancel()
        self._idle_handle = self._deadline_handle = None
        if self.handler.introduced:
            self.site.close_session(reason, error=error)
        else:
            # never introduced itself (no size ID that fits): a refused connection, counted
            # and reported within the rate limit, so hostile churn grows neither log nor record
            self.listener.refuse("handshake", self.peer, f"ended before a valid size ID: "
                                 f"{reason}")
            element = self._element
            if (error and element is not None and element.size_id is not None
                    and self.on_refused is not None):  # its requests follow: told to stop
                self.on_refused(element)
                return
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
