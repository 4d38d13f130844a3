"""Shared machinery of the two site-protocol roles (internal)."""

from __future__ import annotations

import math
import struct
from typing import Final, Literal, NoReturn

from protocol._buffer import ReceiveBuffer
from protocol.errors import RemoteProtocolError
from protocol.events import ConnectionClosed
from protocol.site_events import SiteState, SiteTransport

__all__ = [
    "PROBE_LITTLE",
    "SETUP_IDS",
    "SLOT0",
    "THREE",
    "TWO",
    "SiteBase",
    "probe_order",
]

PROBE_LITTLE: Final = struct.pack("<i", 1)
_PROBE_BIG: Final = struct.pack(">i", 1)
SLOT0: Final = struct.Struct("<d")
THREE: Final = struct.Struct("<3d")
TWO: Final = struct.Struct("<2d")
SETUP_IDS: Final = struct.Struct("<10i")


def check_transport(transport: str) -> None:
    """ValueError unless *transport* is ``"tcp"`` or ``"udp"``."""
    if transport not in ("tcp", "udp"):
        raise ValueError(f"transport must be 'tcp' or 'udp', got {transport!r}")


def probe_order(raw: bytes) -> Literal["little", "big"] | None:
    """Byte order of a peer from its 4-byte int32 1 probe, None if it is not 1."""
    if raw == PROBE_LITTLE:
        return "little"
    if raw == _PROBE_BIG:
        return "big"
    return None


class SiteBase:
    """Receive buffer, state and error bookkeeping shared by both roles."""

    __slots__ = ("_closed", "_error", "_in", "_state", "_transport", "vectors_received")

    def __init__(self, transport: SiteTransport) -> None:
        check_transport(transport)
        self._transport: SiteTransport = transport
        self._in = ReceiveBuffer()
        self._state = SiteState.AWAIT_PROBE if transport == "tcp" else SiteState.AWAIT_OPEN
        self._closed: ConnectionClosed | None = None
        self._error = ""
        self.vectors_received = 0

    @property
    def state(self) -> SiteState:
        """Current protocol state."""
        return self._state

    @property
    def partial_message(self) -> tuple[int, int]:
        """(stream offset of the next unread byte, unread bytes): a transport's message
        deadline sees whether a message has been only partly received, and for how long."""
        buffered = self._in
        return buffered.consumed, len(buffered.data) - buffered.pos

    @property
    def transport(self) -> SiteTransport:
        """``"tcp"`` (with endianness probe) or ``"udp"`` (handshake done by udp.py)."""
        return self._transport

    def _fail(self, message: str) -> NoReturn:
        self._state = SiteState.ERROR
        self._error = message
        raise RemoteProtocolError(message)

    def _close(self) -> ConnectionClosed:
        if self._closed is None:
            pending = self._in.discard()
            self._closed = ConnectionClosed(clean=pending == 0, pending_bytes=pending)
            self._state = SiteState.CLOSED
        return self._closed

    def _where(self, nbytes: int) -> str:
        return f"stream offset {self._in.consumed - nbytes}"

    def _int_slot(self, value: float, what: str, nbytes: int) -> int:
        if not math.isfinite(value) or not value.is_integer():
            self._fail(f"{what} is {value!r}, not an integer ({self._where(nbytes)})")
        return int(value)
