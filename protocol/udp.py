"""UDP framing for both protocols (spec §2.3, §3.10): handshake and datagram chunking.

UDP adds no framing of its own: each item (ID or vector) is sent as datagrams of at
most 9126 bytes (``MAX_UDP_DATAGRAM`` of OpenSees/OpenFresco ``UDP_Socket``; the plain-C
clients use 512), and the receiver reads by byte count. So the server simply feeds every
datagram into the session's byte stream; only the optional ``'a'``/``'b'`` handshake
(always sent by OpenSees genericClient and by ShadowExpSite, never by OpenFresco's
element servers and clients) is handled here.

Replies MUST be split with :func:`chunk_datagrams`: the OpenSees receiver reads each
chunk with one ``recvfrom`` of exactly the chunk length, so a larger datagram is
truncated and the client hangs.

Scope: one framing object serves one session (one peer). A later ``b"a"`` from a NEW
peer address after that session ended is a new connection; recognising it (and
creating a fresh framing + session for it) is the daemon's job, since only the daemon
sees addresses. Within a session every datagram after the first is stream data, even a
1-byte ``b"a"``.
"""

from __future__ import annotations

from typing import Final

from protocol.errors import RemoteProtocolError

__all__ = [
    "HANDSHAKE_REPLY",
    "HANDSHAKE_REQUEST",
    "MAX_UDP_DATAGRAM",
    "UdpClientFraming",
    "UdpServerFraming",
    "chunk_datagrams",
]

MAX_UDP_DATAGRAM: Final = 9126
"""Largest datagram of OpenSees/OpenFresco ``UDP_Socket`` (Socket.h)."""
HANDSHAKE_REQUEST: Final = b"a"
HANDSHAKE_REPLY: Final = b"b"


def chunk_datagrams(payload: bytes, max_datagram: int = MAX_UDP_DATAGRAM) -> list[bytes]:
    """Split one item into datagrams of *max_datagram* bytes plus a remainder.

    dataSize 1150 (9200 bytes) -> [9126, 74]; 3000 -> [9126, 9126, 5748].
    """
    if max_datagram < 1:
        raise ValueError(f"max_datagram must be at least 1, got {max_datagram}")
    size = len(payload)
    if size <= max_datagram:
        return [bytes(payload)]
    return [bytes(payload[i : i + max_datagram]) for i in range(0, size, max_datagram)]


class UdpServerFraming:
    """Server side of one UDP peer: strips the optional handshake, passes the rest on."""

    __slots__ = ("datagrams_received", "handshake_seen")

    def __init__(self) -> None:
        self.datagrams_received = 0
        self.handshake_seen = False

    def datagram_received(self, data: bytes) -> tuple[bytes, bytes | None]:
        """Return (bytes for the session's ``receive_data``, handshake reply or None).

        The FIRST datagram being exactly ``b"a"`` is the OpenSees handshake: reply
        ``b"b"`` and feed nothing. Any other first datagram is already the first item.
        Empty datagrams are returned as ``b""``: do NOT feed those (b"" means EOF).
        """
        first = self.datagrams_received == 0
        self.datagrams_received += 1
        if first and data == HANDSHAKE_REQUEST:
            self.handshake_seen = True
            return b"", HANDSHAKE_REPLY
        return bytes(data), None


class UdpClientFraming:
    """Client side (our own genericClient/Shadow emulations): 'a' out, expect 'b' back."""

    __slots__ = ("_handshake", "_handshake_done")

    def __init__(self, *, handshake: bool = True) -> None:
        self._handshake = handshake
        self._handshake_done = not handshake

    @property
    def handshake_done(self) -> bool:
        """True once ``b"b"`` arrived (or when no handshake is used)."""
        return self._handshake_done

    def start(self) -> bytes | None:
        """The handshake datagram to send first, or None without handshake."""
        return HANDSHAKE_REQUEST if self._handshake else None

    def datagram_received(self, data: bytes) -> bytes:
        """Return the bytes to feed into the client session (``b""``: nothing)."""
        if not self._handshake_done:
            if data != HANDSHAKE_REPLY:
                raise RemoteProtocolError(
                    f"UDP handshake: expected the 1-byte reply b'b', got {len(data)} bytes "
                    f"starting {bytes(data[:8]).hex()}"
                )
            self._handshake_done = True
            return b""
        return bytes(data)
