"""UDP listener of a site (spec §2.3, §3.10).

The first datagram of a session may be OpenSees' 1-byte ``'a'`` handshake (answered ``'b'``)
or directly the size ID (OpenFresco clients without handshake). Requests are reassembled by
byte count (9126- or 512-byte chunks alike); replies go to the last peer, cut at 9126 bytes.
UDP has no EOF: a new handshake (or a datagram from another address after DIE) starts a new
session. A peer that vanished without DIE (killed integrator, lost host) is noticed by the
session-idle deadline (``bridge.session_idle_timeout``), which ends its session; a new
handshake from the same peer ends its old session at once.

OpenSees sends its handshake once and then waits for the answer, without retrying: a handshake
from another address while a session is open is therefore queued, not dropped (the latest one),
and answered as soon as that session ends (DIE, idle deadline, ``ctl abort``), so an integrator
started while a vanished one still holds the site starts by itself (after an operator abort,
once the site is resumed). A peer that has not
introduced itself (no size ID that fits yet) holds nothing: another peer's datagram replaces
it.
"""

from __future__ import annotations

import asyncio
import logging

from protocol import UdpServerFraming, chunk_datagrams
from protocol.udp import HANDSHAKE_REQUEST

from ..sites import SiteError
from .connection import SessionPump, SiteListener

log = logging.getLogger("fresco_bridge.server")
QUEUED_RETRY = 1.0
"""Seconds between two tries to answer a queued handshake while the site takes no session."""


class UdpSiteEndpoint(asyncio.DatagramProtocol):
    def __init__(self, listener: SiteListener) -> None:
        self.listener = listener
        self.site = listener.site
        self.transport: asyncio.DatagramTransport | None = None
        self.pump: SessionPump | None = None
        self.framing: UdpServerFraming | None = None
        self.peer_addr: tuple[str, int] | None = None
        self.queued: tuple[str, int] | None = None
        """The handshake waiting for the open session to end (its address)."""
        self._retry: asyncio.TimerHandle | None = None

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
        if self.queued is not None:  # answered once the ending session is finished with
            self._answer_queued()

    def _answer_queued(self) -> None:
        """Answer the queued handshake if the site takes a session now; if it does not (an
        operator abort until ``ctl resume``, a record that cannot be written), ask again
        every ``QUEUED_RETRY`` s: the integrator is still waiting for its answer."""
        if self._retry is not None:
            self._retry.cancel()
            self._retry = None
        addr = self.queued
        if addr is None or (self.pump is not None and not self.pump.closed):
            return  # answered, or another session started first: its end answers it
        loop = asyncio.get_running_loop()
        try:
            self.site.claim(f"{addr[0]}:{addr[1]}")
        except SiteError:
            self._retry = loop.call_later(QUEUED_RETRY, self._answer_queued)
            return
        self.queued = None
        loop.call_soon(self._replay_queued, addr)

    def _replay_queued(self, addr: tuple[str, int]) -> None:
        if self.pump is not None and not self.pump.closed:  # a peer came first: wait again
            self.queued = self.queued or addr
            return
        log.info("site %s: answering the UDP handshake of %s:%d queued while the site was busy",
                 self.site.name, *addr)
        self.datagram_received(HANDSHAKE_REQUEST, addr)

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        host = addr[0]
        peer = f"{host}:{addr[1]}"
        listener = self.listener
        if not listener.allowlist.admits(host):
            listener.refuse("address", peer, f"datagram dropped: address not in allowed_clients "
                            f"({listener.allowlist})")
            return
        pump = self.pump
        live = pump is not None and not pump.closed
        if live and addr != self.peer_addr:
            assert pump is not None
            if not pump.handler.introduced:  # holds nothing yet: the newcomer takes over
                pump.abort(f"replaced by a datagram from {peer} before its size ID")
                live = False
            elif data == HANDSHAKE_REQUEST:
                self.queued = addr
                listener.refuse("busy", peer, f"UDP handshake while the site serves "
                                f"{self.peer_addr}: queued, answered when that session ends "
                                "(DIE, bridge.session_idle_timeout of silence, or "
                                "fresco-bridge ctl abort)")
                return
            else:
                listener.refuse("busy", peer, f"{len(data)}-byte datagram while the site serves "
                                f"{self.peer_addr} (one client per site)")
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
        """An ICMP error for a datagram sent (typically a vanished peer's closed port)."""
        self.listener.ratelog.warning(f"{self.site.name}.udp-error", "site %s: UDP error: %s",
                                      self.site.name, exc)
