"""OpenFresco's ``expControl GenericTCP`` protocol (``ECGenericTCP``), both roles, sans-IO.

OpenFresco (here: the bridge) is the *client* of a lab's controller server. The wire is the
element protocol's (spec §3, §5): the 11-int size ID, then vectors of ``dataSize`` doubles —
``[3, ctrl blocks from slot 1]`` (no reply), ``[6, stale ctrl]`` answered with the daq blocks
from slot 0, ``[99, stale]`` at the end. One addition: after the ID and before the first
vector, the lines of an optional parameter file, each a fixed 16,385-byte message whose byte 0
is 2 (``OF_RemoteTest_setup``) followed by the line and a NUL; the bytes after the NUL are what
the previous, longer lines left in the one buffer OpenFresco reuses.

A server tells a line from a vector by that first byte: every vector starts with an integral
action code, whose little-endian double has a zero low byte. Both roles reuse the element
sessions (``element.py``, ``element_client.py``); this module only adds the lines.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Literal, TypeAlias

from protocol._buffer import ReceiveBuffer
from protocol.element import ElementServerSession
from protocol.element_client import ElementClientSession
from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.events import (
    NEED_DATA,
    PAUSED,
    CommitReceived,
    ConnectionClosed,
    DieReceived,
    Ignored,
    ReplyReceived,
    ReplyRequested,
    Sentinel,
    SizeReceived,
    TrialReceived,
)
from protocol.wire import Action, ReadableBuffer, Signals, SizeID

__all__ = [
    "GENERIC_TCP_DATA_SIZE",
    "SETUP_LINE_BYTES",
    "DaqReplyReceived",
    "GenericTcpClientEvent",
    "GenericTcpClientSession",
    "GenericTcpServerEvent",
    "GenericTcpServerSession",
    "SetupLineReceived",
    "parameter_file_lines",
]

SETUP_LINE_BYTES: Final = 16385
"""One parameter-file message: byte 0 = 2, then up to 16,383 characters and a NUL."""
MAX_LINE_CHARS: Final = SETUP_LINE_BYTES - 2
GENERIC_TCP_DATA_SIZE: Final = 256
"""``OF_Network_dataSize``: ECGenericTCP's vectors are always 256 doubles."""
_SETUP_BYTE: Final = int(Action.SETUP)


@dataclass(frozen=True, slots=True)
class SetupLineReceived:
    """Server side: one line of the client's parameter file (``-initFile``), as bytes."""

    line: bytes


@dataclass(frozen=True, slots=True)
class DaqReplyReceived:
    """Client side: the daq blocks of the reply to a code-6 request."""

    daq: Signals


GenericTcpServerEvent: TypeAlias = (
    SizeReceived | SetupLineReceived | TrialReceived | CommitReceived | ReplyRequested
    | DieReceived | Ignored | ConnectionClosed
)
GenericTcpClientEvent: TypeAlias = DaqReplyReceived | ConnectionClosed


def parameter_file_lines(content: bytes) -> list[bytes]:
    """The lines ECGenericTCP sends for a parameter file: split at LF only (a CR stays, as
    ``getline`` keeps it), no empty line after a final LF. LocalProtocolError for a line too
    long for one message or holding a NUL (it would end the line early on the server)."""
    lines = content.split(b"\n")
    if lines and lines[-1] == b"":
        lines.pop()
    for number, line in enumerate(lines, 1):
        if len(line) > MAX_LINE_CHARS:
            raise LocalProtocolError(f"parameter file line {number} has {len(line)} bytes; "
                                     f"one message holds at most {MAX_LINE_CHARS}")
        nul = line.find(b"\0")
        if nul >= 0:
            raise LocalProtocolError(f"parameter file line {number} holds a NUL byte at "
                                     f"column {nul + 1}")
    return lines


class GenericTcpClientSession:
    """The client role of ``ECGenericTCP``: ID, parameter-file lines, ctrl, daq requests, DIE.

    Byte-exact with OpenFresco's: one send buffer whose payload the daq request and DIE carry
    stale, one line buffer whose tail keeps the longer lines before.
    """

    __slots__ = ("_daq_sizes", "_line", "_lines_open", "_session")

    def __init__(self, size_id: SizeID) -> None:
        self._session = ElementClientSession(size_id, stale_payload=True)
        self._daq_sizes = size_id.daq
        self._line = bytearray(SETUP_LINE_BYTES)
        self._line[0] = _SETUP_BYTE
        self._lines_open = False

    @property
    def size_id(self) -> SizeID:
        return self._session.size_id

    def start(self) -> bytes:
        """The 44-byte size ID."""
        data = self._session.start()
        self._lines_open = True
        return data

    def send_setup_line(self, line: bytes) -> bytes:
        """One parameter-file line (after ``start``, before the first ctrl vector)."""
        if not self._lines_open:
            raise LocalProtocolError("send_setup_line() is only legal after start() and "
                                     "before the first ctrl vector")
        if b"\n" in line:
            raise LocalProtocolError("send_setup_line() takes one line, without LF; "
                                     "parameter_file_lines() splits a file")
        (checked,) = parameter_file_lines(line + b"\n")
        end = 1 + len(checked)
        self._line[1:end] = checked
        self._line[end] = 0
        return bytes(self._line)

    def send_ctrl(self, ctrl: Signals) -> bytes:
        """Code 3 with the ctrl blocks from slot 1 (no reply)."""
        self._lines_open = False
        return self._session.send_trial(ctrl)

    def send_daq_request(self) -> bytes:
        """Code 6; read the reply (``next_event``) before sending anything else."""
        self._lines_open = False
        return self._session.send_request(Action.GET_DAQ_RESPONSE)

    def send_die(self) -> bytes:
        """Code 99; nothing is read afterwards."""
        self._lines_open = False
        return self._session.send_die()

    def receive_data(self, data: ReadableBuffer) -> None:
        """Bytes from the server; ``b""`` is EOF."""
        self._session.receive_data(data)

    def next_event(self) -> GenericTcpClientEvent | Literal[Sentinel.NEED_DATA]:
        event = self._session.next_event()
        if isinstance(event, ReplyReceived):
            return DaqReplyReceived(event.daq(self._daq_sizes))
        return event


class GenericTcpServerSession:
    """The lab server's role: the element server session for the ID and every vector, with
    the parameter-file lines split off the stream before the first vector."""

    __slots__ = ("_closed", "_in", "_inner", "_lines_open", "lines_received")

    def __init__(self, *, max_data_size: int = 65536) -> None:
        self._inner = ElementServerSession(max_data_size=max_data_size,
                                           keep_reply_leftovers=False)
        self._in = ReceiveBuffer()
        self._lines_open = True
        self._closed: ConnectionClosed | None = None
        self.lines_received = 0

    @property
    def size_id(self) -> SizeID | None:
        return self._inner.size_id

    @property
    def owed_action(self) -> Action | None:
        return self._inner.owed_action

    def receive_data(self, data: ReadableBuffer) -> None:
        """Bytes from the client; ``b""`` is EOF."""
        self._in.feed(data)

    def next_event(self) -> GenericTcpServerEvent | Literal[Sentinel.NEED_DATA,
                                                            Sentinel.PAUSED]:
        if self._closed is not None:
            return self._closed
        if self._inner.owed_action is not None:
            return PAUSED
        buffered = self._in
        size_id = self._inner.size_id
        if size_id is None:
            need = SizeID.SIZE_BYTES
        elif self._lines_open and buffered.available and \
                buffered.data[buffered.pos] == _SETUP_BYTE:
            if buffered.available < SETUP_LINE_BYTES:
                return self._close() if buffered.eof else NEED_DATA
            start = buffered.take(SETUP_LINE_BYTES)
            body = bytes(buffered.data[start + 1:start + SETUP_LINE_BYTES])
            self.lines_received += 1
            return SetupLineReceived(body.split(b"\0", 1)[0])
        else:
            need = size_id.vector_bytes
        if buffered.available < need:
            return self._close() if buffered.eof else NEED_DATA
        start = buffered.take(need)
        self._inner.receive_data(bytes(buffered.data[start:start + need]))
        if size_id is not None:
            self._lines_open = False
        event = self._inner.next_event()
        if event is NEED_DATA or event is PAUSED:  # pragma: no cover - a whole item was fed
            raise RemoteProtocolError(f"incomplete item of {need} bytes")
        if isinstance(event, DieReceived):
            self._closed = ConnectionClosed(clean=True, pending_bytes=buffered.discard())
        return event

    def _close(self) -> ConnectionClosed:
        pending = self._in.discard()
        self._closed = ConnectionClosed(clean=pending == 0, pending_bytes=pending)
        return self._closed

    def send_daq(self, daq: Signals) -> bytes:
        """The reply to code 6: every daq block from slot 0 (the rest zeros)."""
        return self._inner.send_daq(daq)
