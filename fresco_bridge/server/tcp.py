"""TCP listener of a site: one client session at a time, back to accepting after DIE or EOF.

genericClient leaves Nagle on, so after every message that gets no reply (3, 5) its next
request waits for our delayed ACK (~40 ms). Re-arming ``TCP_QUICKACK`` after every read
removes that stall (spec §3.11); ``TCP_NODELAY`` keeps our replies from waiting too.
"""

from __future__ import annotations

import asyncio
import logging
import socket
from typing import Any

from ..sites import ExperimentalSite, SiteError
from .connection import SessionPump

log = logging.getLogger("fresco_bridge.server")
_QUICKACK = getattr(socket, "TCP_QUICKACK", None)


class TcpConnection(asyncio.Protocol):
    def __init__(self, site: ExperimentalSite, allowed: frozenset[str], max_data_size: int) -> None:
        self.site = site
        self.allowed = allowed
        self.max_data_size = max_data_size
        self.pump: SessionPump | None = None
        self.transport: asyncio.Transport | None = None
        self._quickack: Any = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        host, port = transport.get_extra_info("peername")[:2]
        peer = f"{host}:{port}"
        if self.allowed and host not in self.allowed:
            log.warning("site %s: refused client %s: address not in allowed_clients %s",
                        self.site.name, peer, sorted(self.allowed))
            if self.site.record is not None:
                self.site.record.event(self.site.name, self.site.session, "refused",
                                       f"client {peer} not in allowed_clients")
            transport.abort()
            return
        try:
            self.site.open_session(peer)
        except SiteError as exc:
            log.warning("site %s: refused client %s: %s", self.site.name, peer, exc)
            transport.abort()
            return
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            if _QUICKACK is not None:
                self._quickack = sock.setsockopt
                sock.setsockopt(socket.IPPROTO_TCP, _QUICKACK, 1)
        self.pump = SessionPump(
            self.site, peer, transport.write, transport.close, self._pause,
            max_data_size=self.max_data_size, transport="tcp",
        )

    def _pause(self, on: bool) -> None:
        if self.transport is None or self.transport.is_closing():
            return
        if on:
            self.transport.pause_reading()
        else:
            self.transport.resume_reading()

    def data_received(self, data: bytes) -> None:
        if self._quickack is not None:
            self._quickack(socket.IPPROTO_TCP, _QUICKACK, 1)
        if self.pump is not None:
            self.pump.feed(data)

    def eof_received(self) -> bool | None:
        if self.pump is not None:
            self.pump.feed(b"")
        return None

    def connection_lost(self, exc: Exception | None) -> None:
        pump = self.pump
        if pump is None or pump.closed:
            return
        pump.feed(b"")  # the session reports a clean EOF or a message cut short
        if not pump.closed:
            pump.peer_lost(f"connection lost: {exc or 'closed by peer'}")
