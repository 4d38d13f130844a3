"""TCP listener of a site: one client session at a time, back to accepting after DIE or EOF.

genericClient leaves Nagle on, so after every message that gets no reply (3, 5) its next
request waits for our delayed ACK (~40 ms). Setting ``TCP_QUICKACK`` after a read that we do
not answer (a message without a reply, or part of a message) sends that ACK at once and
removes the stall (spec §3.11); a reply carries its ACK itself, so reads that are answered
need no system call. ``TCP_NODELAY`` keeps our replies from waiting too.

TCP keepalive probes a silent peer (a lost host, a cut cable) even while the bridge waits on
the controller or an operator, when the session-idle deadline does not run: a dead peer is
noticed within ``KEEPALIVE_IDLE + KEEPALIVE_COUNT * KEEPALIVE_INTERVAL`` s. With ``tls = true``
the connection is upgraded to mutual TLS (``server/tls.py``) before a session is opened.

A peer gone before it was accepted (connect then reset: no peer name, socket options failing)
or during the TLS handshake is a refused connection, counted and logged within the rate limit,
never a traceback.
"""

from __future__ import annotations

import asyncio
import logging
import os
import socket
import ssl
from typing import Any, cast

from protocol import ElementServerSession

from ..sites import SiteError
from .connection import HELD_BYTES_CAP, WRITE_HIGH_WATER, WRITE_LOW_WATER, SessionPump, SiteListener
from .refusal import MAX_REFUSALS, Refusal
from .tls import HANDSHAKE_TIMEOUT, MAX_HANDSHAKES, check_issued_directly, describe_failure

log = logging.getLogger("fresco_bridge.server")
_QUICKACK = getattr(socket, "TCP_QUICKACK", None)
KEEPALIVE_IDLE = 10
"""Seconds of silence before the first keepalive probe."""
KEEPALIVE_INTERVAL = 5
KEEPALIVE_COUNT = 3


def _keepalive(sock: socket.socket) -> None:
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
    for name, value in (("TCP_KEEPIDLE", KEEPALIVE_IDLE), ("TCP_KEEPINTVL", KEEPALIVE_INTERVAL),
                        ("TCP_KEEPCNT", KEEPALIVE_COUNT)):
        opt = getattr(socket, name, None)
        if opt is not None:
            sock.setsockopt(socket.IPPROTO_TCP, opt, value)


def _hand_to_tls(raw: asyncio.Transport, data: bytes) -> None:
    """Give ``data`` read off ``raw`` before ``start_tls`` to the TLS protocol now reading it.

    Runs before that protocol's ``connection_made`` (``start_tls`` schedules it after this):
    the bytes wait in its input, and its handshake starts from them. Through the protocol
    interface only (asyncio's is a ``BufferedProtocol``; uvloop's has the same two methods).
    """
    proto = cast(asyncio.BufferedProtocol, raw.get_protocol())
    if isinstance(proto, TcpConnection):  # start_tls refused before taking the transport
        return
    view = memoryview(data)
    while view:
        buf = memoryview(proto.get_buffer(len(view)))
        n = min(len(buf), len(view))
        buf[:n] = view[:n]
        proto.buffer_updated(n)
        view = view[n:]


class TcpConnection(asyncio.Protocol):
    def __init__(self, listener: SiteListener, tls: ssl.SSLContext | None = None) -> None:
        self.listener = listener
        self.site = listener.site
        self.tls = tls
        self.pump: SessionPump | Refusal | None = None
        self.transport: asyncio.Transport | None = None
        self._quickack: Any = None
        self._ack_sock: socket.socket | None = None
        self._handshake: asyncio.Task[None] | None = None
        self._early: list[bytes] = []  # TLS: raw before start_tls, then decrypted before _open
        self._replies = 0  # writes to the client so far

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # a stream transport; uvloop's do not subclass asyncio.Transport, so no isinstance
        self.transport = transport = cast(asyncio.Transport, transport)
        peername = transport.get_extra_info("peername")
        if not peername:  # reset before we got to it: the kernel no longer knows the peer
            self._vanished(transport, "an unknown peer", "no peer address")
            return
        host, port = peername[:2]
        peer = f"{host}:{port}"
        if not self.listener.allowlist.admits(host):
            self.listener.refuse("address", peer, "address not in allowed_clients "
                                 f"({self.listener.allowlist})")
            if self.tls is None:  # a plain client: told to stop (TLS bytes: cannot be)
                self._tell_to_stop(transport)
            else:
                transport.abort()
            return
        sock = transport.get_extra_info("socket")
        if sock is not None:
            try:
                self._tune(sock)
            except OSError as exc:
                self._vanished(transport, peer, str(exc))
                return
        if self.tls is None:
            self._open(transport, peer)
        else:
            self._handshake = asyncio.get_running_loop().create_task(
                self._start_tls(transport, self.tls, peer), name=f"{self.site.name}.tls")

    def _tune(self, sock: socket.socket) -> None:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        _keepalive(sock)
        if _QUICKACK is not None:
            sock.setsockopt(socket.IPPROTO_TCP, _QUICKACK, 1)
            # uvloop's transport socket builds a socket object for every call, up to 4
            # re-arms a step on the step path: re-arm through our own handle of the same
            # connection (a duplicate descriptor, closed with the connection)
            self._ack_sock = socket.socket(sock.family, sock.type, sock.proto,
                                           fileno=os.dup(sock.fileno()))
            self._quickack = self._ack_sock.setsockopt

    def _vanished(self, transport: asyncio.Transport, peer: str, why: str) -> None:
        """The peer left before its connection was accepted (connect then reset)."""
        self.listener.refuse("vanished", peer, f"connection gone before it was accepted ({why})")
        transport.abort()

    async def _start_tls(self, raw: asyncio.Transport, ctx: ssl.SSLContext, peer: str) -> None:
        listener = self.listener
        busy = ("another client holds the site" if self.site.busy else
                f"{MAX_HANDSHAKES} TLS handshakes in flight already"
                if listener.tls_handshakes >= MAX_HANDSHAKES else None)
        if busy is not None:  # refused before the handshake: no SSL object, no read buffer
            listener.refuse("busy", peer, busy)
            raw.abort()
            return
        listener.tls_handshakes += 1
        try:
            await self._handshake_then_open(raw, ctx, peer)
        finally:
            listener.tls_handshakes -= 1

    async def _handshake_then_open(self, raw: asyncio.Transport, ctx: ssl.SSLContext,
                                   peer: str) -> None:
        loop = asyncio.get_running_loop()
        # uvloop starts reading right after ``connection_made`` (pausing there is a no-op), so
        # the ClientHello may already have come to us as plain bytes; left there, the handshake
        # waited for it until its timeout. They go to the TLS layer before it starts.
        hello, self._early = b"".join(self._early), []
        if hello:
            loop.call_soon(_hand_to_tls, raw, hello)
        try:
            transport = await loop.start_tls(raw, self, ctx, server_side=True,
                                             ssl_handshake_timeout=HANDSHAKE_TIMEOUT)
        except Exception as exc:  # whatever a peer does to the handshake is its
            # refusal (reset, garbage, a closed transport), never a task's traceback
            self.listener.refuse("tls", peer, describe_failure(exc))
            raw.abort()
            return
        if transport is None:  # the peer went away during the handshake
            raw.abort()
            return
        ssl_object = transport.get_extra_info("ssl_object")
        why = check_issued_directly(ctx, None if ssl_object is None else ssl_object.getpeercert())
        if why is not None:
            self.listener.refuse("tls", peer, why)
            transport.abort()
            return
        self.transport = transport
        self._open(transport, peer)

    def _open(self, transport: asyncio.Transport, peer: str) -> None:
        try:
            self.pump = SessionPump(self.listener, peer, self._reply, transport.close,
                                    self._pause, transport="tcp")
        except SiteError as exc:
            self.listener.refuse("busy" if self.site.busy else "state", peer, str(exc))
            self._tell_to_stop(transport)
            return
        self.pump.on_refused = lambda session: self._tell_to_stop(transport, session)
        transport.set_write_buffer_limits(high=WRITE_HIGH_WATER, low=WRITE_LOW_WATER)
        early, self._early = self._early, []
        for data in early:
            self.pump.feed(data)

    def _tell_to_stop(self, transport: asyncio.Transport,
                      session: ElementServerSession | None = None) -> None:
        """A refused client: an element-protocol one is answered with NaN until it leaves
        (``refusal.py``: OpenSees then stops instead of spinning); others, and those past
        ``MAX_REFUSALS`` at once, are closed."""
        listener = self.listener
        if self.site.cfg.protocol != "element" or listener.told_to_stop >= MAX_REFUSALS:
            transport.abort()
            return
        transport.set_write_buffer_limits(high=WRITE_HIGH_WATER, low=WRITE_LOW_WATER)
        listener.told_to_stop += 1

        def ended() -> None:
            listener.told_to_stop -= 1

        self.pump = Refusal(self._reply, transport.close, max_data_size=listener.max_data_size,
                            session=session, ended=ended)
        early, self._early = self._early, []
        for data in early:
            self.pump.feed(data)

    def _reply(self, data: bytes) -> None:
        self._replies += 1
        assert self.transport is not None
        self.transport.write(data)

    def _pause(self, on: bool) -> None:
        if self.transport is None or self.transport.is_closing():
            return
        if on:
            self.transport.pause_reading()
        else:
            self.transport.resume_reading()

    def pause_writing(self) -> None:
        if self.pump is not None:
            self.pump.writing_paused(True)

    def resume_writing(self) -> None:
        if self.pump is not None:
            self.pump.writing_paused(False)

    def data_received(self, data: bytes) -> None:
        pump = self.pump
        if pump is not None:
            replies = self._replies
            pump.feed(data)
            if self._replies == replies and self._quickack is not None and not pump.closed:
                try:  # noqa: SIM105 - contextlib.suppress costs a call on the step path
                    self._quickack(socket.IPPROTO_TCP, _QUICKACK, 1)  # nothing carries our ACK
                except OSError:  # the peer is gone: connection_lost follows
                    pass
        elif self._handshake is not None and sum(map(len, self._early)) < HELD_BYTES_CAP:
            self._early.append(data)  # the handshake task has not run or not resumed yet

    def eof_received(self) -> bool | None:
        if self.pump is not None:
            self.pump.feed(b"")
        return None

    def connection_lost(self, exc: Exception | None) -> None:
        if self._ack_sock is not None:
            self._quickack = None
            self._ack_sock.close()
            self._ack_sock = None
        pump = self.pump
        if pump is None or pump.closed:
            return
        pump.feed(b"")  # the session reports a clean EOF or a message cut short
        if not pump.closed:
            pump.peer_lost(f"connection lost: {exc or 'closed by peer'}")
