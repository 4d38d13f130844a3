"""Element-level protocol, client role: what OpenSees ``genericClient`` sends (spec §3.3-3.6).

Used by our own Python integrator, the benchmarks and the tests; byte-exact with the
OpenSeesPy captures, stale payloads included.
"""

from __future__ import annotations

import enum
import struct
from typing import Final, Literal, TypeAlias

from protocol._buffer import ReceiveBuffer
from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.events import NEED_DATA, ConnectionClosed, ReplyReceived, Sentinel
from protocol.wire import (
    ACTION_BY_CODE,
    Action,
    BlockLayout,
    ReadableBuffer,
    Signals,
    SizeID,
    doubles_struct,
)

__all__ = ["ClientState", "ElementClientEvent", "ElementClientSession"]

ElementClientEvent: TypeAlias = ReplyReceived | ConnectionClosed

_SLOT0: Final = struct.Struct("<d")
_REPLY_ACTIONS: Final = frozenset(a for a in Action if 6 <= a <= 15)


class ClientState(enum.Enum):
    """States of :class:`ElementClientSession`."""

    AWAIT_START = "AWAIT_START"
    READY = "READY"
    AWAIT_REPLY = "AWAIT_REPLY"
    CLOSED = "CLOSED"
    ERROR = "ERROR"


class ElementClientSession:
    """The client role of OpenSees ``genericClient`` (spec §3.3-3.6).

    Like genericClient it keeps ONE send buffer: requests other than code 3 only
    rewrite slot 0 and so carry a stale copy of the last trial (byte-exact with the
    captures). ``stale_payload=False`` zeroes slots 1.. of non-trial requests instead
    (as the ECSimFEAdapter emulation in the fixtures does).
    """

    __slots__ = (
        "_closed",
        "_error",
        "_in",
        "_pending",
        "_reply_struct",
        "_send",
        "_size_id",
        "_stale",
        "_state",
        "_trial_layout",
        "_vector_bytes",
        "_zeros",
    )

    def __init__(self, size_id: SizeID, *, stale_payload: bool = True) -> None:
        if not size_id.ctrl_time_fits:
            raise LocalProtocolError(
                f"size ID ctrl sizes need 1 + {size_id.ctrl.total} slots but dataSize is "
                f"{size_id.data_size}: this client would not send its time value"
            )
        self._size_id = size_id
        self._stale = stale_payload
        self._vector_bytes = size_id.vector_bytes
        self._trial_layout = BlockLayout(size_id.ctrl, 1, size_id.data_size, role="trial")
        self._send = bytearray(self._vector_bytes)
        self._zeros = bytes(self._vector_bytes)
        self._reply_struct = doubles_struct(size_id.data_size)
        self._in = ReceiveBuffer()
        self._state = ClientState.AWAIT_START
        self._pending: Action | None = None
        self._closed: ConnectionClosed | None = None
        self._error = ""

    @property
    def state(self) -> ClientState:
        """Current protocol state."""
        return self._state

    @property
    def size_id(self) -> SizeID:
        """The size ID this client announces."""
        return self._size_id

    def _require(self, method: str, state: ClientState) -> None:
        if self._state is not state:
            raise LocalProtocolError(
                f"{method}() is only legal in state {state.name}, not {self._state.name}"
            )

    def start(self) -> bytes:
        """The 44-byte size ID, the first item of the connection."""
        self._require("start", ClientState.AWAIT_START)
        self._state = ClientState.READY
        return self._size_id.encode()

    def _vector(self, code: float, *, keep_payload: bool) -> bytes:
        if not keep_payload:
            self._send[:] = self._zeros
        _SLOT0.pack_into(self._send, 0, code)
        return bytes(self._send)

    def send_trial(self, trial: Signals) -> bytes:
        """Code 3 with the trial blocks packed from slot 1 (no reply)."""
        self._require("send_trial", ClientState.READY)
        self._trial_layout.pack_into(self._send, trial, "trial")
        return self._vector(Action.SET_TRIAL_RESPONSE, keep_payload=True)

    def send_commit(self) -> bytes:
        """Code 5 (no reply)."""
        self._require("send_commit", ClientState.READY)
        return self._vector(Action.COMMIT_STATE, keep_payload=self._stale)

    def send_request(self, action: Action) -> bytes:
        """Codes 6..15; the reply must be read (``next_event``) before the next send."""
        self._require("send_request", ClientState.READY)
        if action not in _REPLY_ACTIONS:
            raise LocalProtocolError(
                f"send_request() takes a code 6..15 that gets a reply, not {action!r}"
            )
        self._pending = action
        self._state = ClientState.AWAIT_REPLY
        return self._vector(action, keep_payload=self._stale)

    def send_unanswered(self, code: float) -> bytes:
        """A vector with an arbitrary code the server must not answer (1, 2, 4, 98, ...)."""
        self._require("send_unanswered", ClientState.READY)
        if ACTION_BY_CODE.get(code) in _REPLY_ACTIONS or code in (3.0, 99.0):
            raise LocalProtocolError(
                f"send_unanswered() got code {code}: use send_trial/send_request/send_die"
            )
        return self._vector(code, keep_payload=self._stale)

    def send_die(self) -> bytes:
        """Code 99; the connection is finished afterwards (no reply is read)."""
        self._require("send_die", ClientState.READY)
        self._state = ClientState.CLOSED
        return self._vector(Action.DIE, keep_payload=self._stale)

    def receive_data(self, data: ReadableBuffer) -> None:
        """Feed bytes from the server; ``b""`` means EOF."""
        self._in.feed(data)

    def next_event(self) -> ElementClientEvent | Literal[Sentinel.NEED_DATA]:
        """The reply to the pending request, ConnectionClosed, or NEED_DATA."""
        state = self._state
        buffered = self._in
        if state is ClientState.AWAIT_REPLY:
            if buffered.available >= self._vector_bytes:
                start = buffered.take(self._vector_bytes)
                values: tuple[float, ...] = self._reply_struct.unpack_from(buffered.data, start)
                action = self._pending
                assert action is not None
                self._pending = None
                self._state = ClientState.READY
                return ReplyReceived(action, values)
        elif state is ClientState.ERROR:
            raise RemoteProtocolError(f"session is in ERROR state: {self._error}")
        elif self._closed is not None:
            return self._closed
        elif buffered.available and state is not ClientState.CLOSED:
            message = (
                f"server sent {buffered.available} bytes at stream offset "
                f"{buffered.consumed} while no reply was pending"
            )
            self._state = ClientState.ERROR
            self._error = message
            raise RemoteProtocolError(message)
        if buffered.eof:
            pending = buffered.discard()
            self._closed = ConnectionClosed(clean=pending == 0, pending_bytes=pending)
            self._state = ClientState.CLOSED
            self._pending = None
            return self._closed
        return NEED_DATA
