"""UDP listener of a site (spec §2.3, §3.10).

The first datagram of a session may be OpenSees' 1-byte ``'a'`` handshake (answered ``'b'``)
or directly the size ID (OpenFresco clients without handshake). Requests are reassembled by
byte count (9126- or 512-byte chunks alike); replies go to the last peer, cut at 9126 bytes.
UDP has no EOF: a new handshake (or a datagram from another address after DIE) starts a new
session; a handshake from another address while a session is live is refused. A peer that
vanished without DIE (killed integrator, lost host) is noticed by the session-idle deadline
(``bridge.session_idle_timeout``), which ends its session so a new handshake is accepted; a
new handshake from the same peer ends its old session at once.
"""

from __future__ import annotations

import asyncio
import logging

from protocol import UdpServerFraming, chunk_datagrams
from protocol.udp import HANDSHAKE_REQUEST

from ..sites import SiteError
from .connection import SessionPump, SiteListener

log = logging.getLogger("fresco_bridge.server")


class UdpSiteEndpoint(asyncio.DatagramProtocol):
    def __init__(self, listener: SiteListener) -> None:
        self.listener = listener
        self.site = listener.site
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
        listener = self.listener
        if not listener.allowlist.admits(host):
            listener.refuse("address", peer, f"datagram dropped: address not in allowed_clients "
                            f"({listener.allowlist})")
            return
        live = self.pump is not None and not self.pump.closed
        if live and addr != self.peer_addr:
            what = "UDP handshake" if data == HANDSHAKE_REQUEST else f"{len(data)}-byte datagram"
            listener.refuse("busy", peer, f"{what} while the site serves {self.peer_addr} "
                            "(one client per site; a silent one is ended after "
                            "bridge.session_idle_timeout)")
            return
        if (live and data == HANDSHAKE_REQUEST and self.framing is not None
                and self.framing.datagrams_received > 0):
            # A 1-byte datagram is never stream data (items are 4- or 8-byte words, cut at
            # 9126 or 512 bytes): the same peer starts over (its integrator was restarted).
            assert self.pump is not None
            self.pump.abort("client started a new UDP session (handshake) without DIE")
            live = False
        if not live:
            try:
                self.pump = SessionPump(listener, peer, self._send, self._session_over,
                                        lambda on: None, transport="udp")
            except SiteError as exc:
                listener.refuse("busy" if self.site.busy else "state", peer, str(exc))
                return
            self.peer_addr = addr
            self.framing = UdpServerFraming()
        assert self.framing is not None and self.pump is not None
        stream, reply = self.framing.datagram_received(data)
        if reply is not None and self.transport is not None:
            self.transport.sendto(reply, addr)
        if stream:
            self.pump.feed(stream)

    def error_received(self, exc: Exception) -> None:
        log.warning("site %s: UDP error: %s", self.site.name, exc)
