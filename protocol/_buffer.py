"""Byte accumulator with exact-length reads (items have no length prefix, spec §2.2)."""

from __future__ import annotations

from protocol.errors import LocalProtocolError
from protocol.wire import ReadableBuffer

__all__ = ["ReceiveBuffer"]

_COMPACT_AT = 1 << 16


class ReceiveBuffer:
    """Bytes fed so far; items are taken by count, segment boundaries mean nothing."""

    __slots__ = ("consumed", "data", "eof", "pos")

    def __init__(self) -> None:
        self.data: bytes | bytearray = bytearray()
        """The underlying buffer; valid for offsets from :meth:`take` until the next feed (an
        attribute, not a property: it is read once per vector)."""
        self.pos = 0
        """Offset in :attr:`data` of the next unread byte."""
        self.consumed = 0
        """Stream offset of the next unread byte (for error messages)."""
        self.eof = False

    def feed(self, data: ReadableBuffer) -> None:
        """Append *data*; ``b""`` records EOF."""
        if not data:
            self.eof = True
            return
        if self.eof:
            raise LocalProtocolError(
                f"receive_data() got {len(data)} bytes after EOF (b'') was already fed"
            )
        buf, pos = self.data, self.pos
        if pos == len(buf):  # everything read: the usual case, one request per segment
            self.pos = 0
            # immutable bytes are kept as they are (no copy); anything else is copied
            self.data = data if type(data) is bytes else bytearray(data)
            return
        if isinstance(buf, bytes):  # a kept segment with an unread tail: continue in a bytearray
            buf = self.data = bytearray(memoryview(buf)[pos:])
            self.pos = pos = 0
        elif pos >= _COMPACT_AT:
            del buf[:pos]
            self.pos = 0
        buf += data

    @property
    def available(self) -> int:
        """Unread bytes."""
        return len(self.data) - self.pos

    def take(self, count: int) -> int:
        """Consume *count* bytes; return their start offset in :attr:`data` (read at once)."""
        start = self.pos
        self.pos = start + count
        self.consumed += count
        return start

    def take_if(self, count: int) -> int:
        """Consume *count* bytes if that many are unread: their start offset in :attr:`data`
        (read at once), else -1 and nothing consumed (one call on the per-vector path)."""
        start = self.pos
        if len(self.data) - start < count:
            return -1
        self.pos = start + count
        self.consumed += count
        return start

    def discard(self) -> int:
        """Drop every unread byte; return how many were dropped."""
        dropped = self.available
        self.data = bytearray()
        self.pos = 0
        self.consumed += dropped
        return dropped
