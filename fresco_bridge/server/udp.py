"""UDP listener of a site (spec §2.3, §3.10).

The first datagram of a session may be OpenSees' 1-byte ``'a'`` handshake (answered ``'b'``)
or directly the size ID (OpenFresco clients without handshake). Requests are reassembled by
byte count (9126- or 512-byte chunks alike); replies go to the last peer, cut at 9126 bytes.
UDP has no EOF: a new handshake (or a datagram from another address after DIE) starts a new
session; a handshake from another address while a session is live is refused.
"""

from __future__ import annotations

import asyncio
import logging

from protocol import UdpServerFraming, chunk_datagrams

from ..sites import ExperimentalSite, SiteError
from .connection import SessionPump

log = logging.getLogger("fresco_bridge.server")


class UdpSiteEndpoint(asyncio.DatagramProtocol):
    def __init__(self, site: ExperimentalSite, allowed: frozenset[str], max_data_size: int) -> None:
        self.site = site
        self.allowed = allowed
        self.max_data_size = max_data_size
        self.transport: asyncio.DatagramTransport | None = None
        self.pump: SessionPump | None = None
        self.framing: UdpServerFraming | None = None
        self.peer_addr: tuple[str, int] | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def _send(self, data: bytes) -> None:
        if self.transport is None or self.peer_addr is None:
            return
        for chunk in chunk_datagrams(data):
            self.transport.sendto(chunk, self.peer_addr)

    def _session_over(self) -> None:
        self.pump = None
        self.framing = None

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        host = addr[0]
        peer = f"{host}:{addr[1]}"
        if self.allowed and host not in self.allowed:
            log.warning("site %s: dropped datagram from %s: address not in allowed_clients",
                        self.site.name, peer)
            return
        live = self.pump is not None and not self.pump.closed
        if live and addr != self.peer_addr:
            if data == b"a":
                log.warning("site %s: refused UDP handshake from %s: busy with %s",
                            self.site.name, peer, self.peer_addr)
            else:
                log.warning("site %s: dropped %d-byte datagram from %s (not the session peer)",
                            self.site.name, len(data), peer)
            return
        if live and data == b"a" and self.framing is not None and self.framing.started:
            assert self.pump is not None
            self.pump.abort("client started a new UDP session (handshake) without DIE")
            live = False
        if not live:
            try:
                self.site.open_session(peer)
            except SiteError as exc:
                log.warning("site %s: refused UDP client %s: %s", self.site.name, peer, exc)
                return
            self.peer_addr = addr
            self.framing = UdpServerFraming()
            self.pump = SessionPump(
                self.site, peer, self._send, self._session_over, lambda on: None,
                max_data_size=self.max_data_size, transport="udp",
            )
        assert self.framing is not None and self.pump is not None
        stream, reply = self.framing.datagram_received(data)
        if reply is not None and self.transport is not None:
            self.transport.sendto(reply, addr)
        if stream:
            self.pump.feed(stream)

    def error_received(self, exc: Exception) -> None:
        log.warning("site %s: UDP error: %s", self.site.name, exc)
