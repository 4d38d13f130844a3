"""Element-level ("generic") protocol: OpenSees genericClient <-> startSimAppElemServer.

Sans-IO, h11 style: feed received bytes with ``receive_data`` (``b""`` = EOF), pull
events with ``next_event``, and get the bytes to write from the ``send_*`` methods.
The wire has no framing (spec §2.1): after the 44-byte size ID every vector is exactly
``dataSize`` little-endian doubles in both directions, so sizes come from the ID only.

Reply buffers follow OpenFresco's server loop (spec §3.8): one buffer of ``dataSize``
doubles, zero at the start, in which each reply overwrites only the slots it uses. The
captures (made against the real OpenFresco server) depend on those left-overs; clients
ignore every slot past the ones they read. ``keep_reply_leftovers=False`` zeroes the
buffer before each reply instead.
"""

from __future__ import annotations

import enum
import math
import struct
from collections.abc import Sequence
from typing import Final, Literal, NoReturn, TypeAlias

from protocol._buffer import ReceiveBuffer
from protocol.element_client import ClientState, ElementClientEvent, ElementClientSession
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
from protocol.wire import (
    ACTION_BY_CODE,
    DOUBLE_BYTES,
    Action,
    BlockLayout,
    ReadableBuffer,
    Signals,
    SignalSizes,
    SizeID,
    doubles_struct,
    pack_blocks,
    unpack_blocks,
)

__all__ = [
    "NEED_DATA",
    "PAUSED",
    "Action",
    "ClientState",
    "CommitReceived",
    "ConnectionClosed",
    "DieReceived",
    "ElementClientEvent",
    "ElementClientSession",
    "ElementServerEvent",
    "ElementServerSession",
    "Ignored",
    "ReplyReceived",
    "ReplyRequested",
    "ServerState",
    "SignalSizes",
    "Signals",
    "SizeID",
    "SizeReceived",
    "TrialReceived",
    "pack_blocks",
    "unpack_blocks",
]

ElementServerEvent: TypeAlias = (
    SizeReceived
    | TrialReceived
    | CommitReceived
    | ReplyRequested
    | DieReceived
    | Ignored
    | ConnectionClosed
)

_SLOT0: Final = struct.Struct("<d")
_REPLY_ACTIONS: Final = frozenset(a for a in Action if 6 <= a <= 15)
_DAQ_ACTIONS: Final = frozenset(a for a in Action if 6 <= a <= 11)
_MATRIX_ACTIONS: Final = frozenset(a for a in Action if 12 <= a <= 15)
_DAQ_BLOCK_OF_ACTION: Final = {
    Action.GET_DISP: 0,
    Action.GET_VEL: 1,
    Action.GET_ACCEL: 2,
    Action.GET_FORCE: 3,
    Action.GET_TIME: 4,
}
_REPLY_BY_CODE: Final = {float(a.value): ReplyRequested(a) for a in _REPLY_ACTIONS}
"""Slot 0 of a request that must be answered -> its (shared, immutable) event: 10 of the 14
messages of an OpenSees step are decoded with this one lookup."""
_TRIAL_ACTION: Final = Action.SET_TRIAL_RESPONSE
_COMMIT_ACTION: Final = Action.COMMIT_STATE
_DIE_ACTION: Final = Action.DIE
_DAQ_ACTION: Final = Action.GET_DAQ_RESPONSE
_COMMIT_EVENT: Final = CommitReceived()
_PACKED_CACHE: Final = 4
"""Matrices (tuples: damping, mass, an unchanged tangent) whose packed bytes are kept: a 64-DOF
matrix is 4096 doubles, packed once instead of at every request."""
_DIE_EVENT: Final = DieReceived()


class ServerState(enum.Enum):
    """States of :class:`ElementServerSession`."""

    AWAIT_ID = "AWAIT_ID"
    READY = "READY"
    MUST_REPLY = "MUST_REPLY"
    CLOSED = "CLOSED"
    ERROR = "ERROR"


_AWAIT_ID: Final = ServerState.AWAIT_ID
_READY: Final = ServerState.READY
_MUST_REPLY: Final = ServerState.MUST_REPLY
_CLOSED: Final = ServerState.CLOSED
_ERROR: Final = ServerState.ERROR
# Module constants, not ``ServerState.READY`` on the per-message path: reading an enum member
# off its class is an attribute lookup through the enum's metaclass, several times a message.


def _check_data_size_cap(max_data_size: int) -> None:
    if max_data_size < 1:
        raise ValueError(f"max_data_size must be at least 1, got {max_data_size}")


class ElementServerSession:
    """The server role of OpenFresco's ``startSimAppElemServer`` (spec §3.8).

    After DIE the session is CLOSED and silently drops any further bytes (ECSimFEAdapter
    sends DIE twice); EOF then yields ``ConnectionClosed(clean=True)``.
    """

    __slots__ = (
        "_closed",
        "_daq_layout",
        "_data_size",
        "_error",
        "_in",
        "_keep_leftovers",
        "_matrix_count",
        "_max_data_size",
        "_owed",
        "_packed",
        "_replies",
        "_reply",
        "_reply_full",
        "_size_id",
        "_state",
        "_tail_daq",
        "_trial_layout",
        "_vector_bytes",
        "_zeros",
        "bytes_after_die",
        "drained",
        "vectors_received",
    )

    def __init__(self, *, max_data_size: int = 65536, keep_reply_leftovers: bool = True) -> None:
        _check_data_size_cap(max_data_size)
        self._max_data_size = max_data_size
        self._keep_leftovers = keep_reply_leftovers
        self._in = ReceiveBuffer()
        self._state = _AWAIT_ID
        self._size_id: SizeID | None = None
        self._vector_bytes = 0
        self._trial_layout: BlockLayout | None = None
        self._daq_layout: BlockLayout | None = None
        self._reply = bytearray()
        self._reply_full: bytes | None = None
        """The reply buffer's content when the last reply filled all of it from bytes kept
        elsewhere (a packed matrix of n*n = dataSize values): copied in only when a later
        reply writes part of the buffer."""
        self._zeros = b""
        self._matrix_count = 0
        self._data_size = 0
        self._packed: dict[int, tuple[tuple[float, ...], bytes]] = {}
        self._replies: dict[bytes, bytes] = {}
        """Whole replies to a packed matrix that fills part of the reply, by the matrix's
        bytes: every entry's slots past the matrix are what the reply buffer holds now (a
        reply that writes there empties the dict; without left-overs they are zeros in every
        entry), so a matrix answered again with the same left-overs is the same bytes, not a
        new copy of the reply (genericClient asks for the damping matrix several times a
        step, ``dataSize`` doubles each)."""
        self._tail_daq = False
        """A daq reply can write slots past the matrix (then it empties ``_replies``)."""
        self._owed: Action | None = None
        self._closed: ConnectionClosed | None = None
        self._error = ""
        self.vectors_received = 0
        """Vectors decoded so far (the ID not counted)."""
        self.bytes_after_die = 0
        """Bytes dropped because they followed a DIE."""
        self.drained = False
        """True when the event ``next_event`` last decoded in READY left less than a message
        buffered and no EOF: handled (and its reply sent), the next ``next_event`` returns
        NEED_DATA until more bytes are received (a caller may skip that call). False after
        every other ``next_event`` result."""

    # -- introspection -------------------------------------------------------------
    @property
    def state(self) -> ServerState:
        """Current protocol state."""
        return self._state

    @property
    def partial_message(self) -> tuple[int, int]:
        """(stream offset of the next unread byte, unread bytes): a transport's message
        deadline sees whether a message has been only partly received, and for how long."""
        buffered = self._in
        return buffered.consumed, len(buffered.data) - buffered.pos

    @property
    def size_id(self) -> SizeID | None:
        """The accepted size ID, None before it arrived."""
        return self._size_id

    @property
    def owed_action(self) -> Action | None:
        """The request that must be answered next (state MUST_REPLY), else None."""
        return self._owed

    # -- receiving -----------------------------------------------------------------
    def receive_data(self, data: ReadableBuffer) -> None:
        """Feed bytes from the peer; ``b""`` means EOF.

        Raises LocalProtocolError for non-empty data after EOF was fed.
        """
        buffered = self._in
        if buffered.pos == len(buffered.data) and type(data) is bytes and data \
                and self._state is not _CLOSED and not buffered.eof:
            # ReceiveBuffer.feed's usual case, inlined (once per message): everything before
            # was read, and an immutable segment is kept as it is
            buffered.data = data
            buffered.pos = 0
            return
        if self._state is _CLOSED and data and not buffered.eof:
            self.bytes_after_die += len(data)
            return
        buffered.feed(data)

    def next_event(self) -> ElementServerEvent | Literal[Sentinel.NEED_DATA, Sentinel.PAUSED]:
        """Decode the next event, or NEED_DATA / PAUSED (a reply is owed)."""
        state = self._state
        if state is _READY:
            # ReceiveBuffer.take_if inlined: this runs twice per message (the second time to
            # find that nothing more is buffered)
            buffered = self._in
            data = buffered.data
            start = buffered.pos
            count = self._vector_bytes
            if len(data) - start >= count:
                end = buffered.pos = start + count
                buffered.consumed += count
                self.drained = len(data) - end < count and not buffered.eof
                return self._decode_vector(data, start)
            self.drained = False
            if buffered.eof:
                return self._close()
            return NEED_DATA
        self.drained = False
        if state is _MUST_REPLY:
            return PAUSED
        if state is _AWAIT_ID:
            return self._next_in_await_id()
        if state is _CLOSED:
            if self._closed is not None:
                return self._closed
            return self._close() if self._in.eof else NEED_DATA
        raise RemoteProtocolError(f"session is in ERROR state: {self._error}")

    def _next_in_await_id(self) -> SizeReceived | ConnectionClosed | Literal[Sentinel.NEED_DATA]:
        buffered = self._in
        if buffered.available >= SizeID.SIZE_BYTES:
            start = buffered.take(SizeID.SIZE_BYTES)
            try:
                size_id = SizeID.decode(
                    buffered.data, max_data_size=self._max_data_size, offset=start
                )
            except RemoteProtocolError as exc:
                self._fail(str(exc))
            self._configure(size_id)
            return SizeReceived(size_id)
        if buffered.eof:
            return self._close()
        return NEED_DATA

    def _configure(self, size_id: SizeID) -> None:
        data_size = size_id.data_size
        self._size_id = size_id
        self._vector_bytes = DOUBLE_BYTES * data_size
        self._trial_layout = BlockLayout(
            size_id.ctrl, 1, data_size, allow_missing_time=True, role="trial"
        )
        self._daq_layout = BlockLayout(size_id.daq, 0, data_size, role="daq")
        self._reply = bytearray(self._vector_bytes)
        self._zeros = bytes(self._vector_bytes)
        self._matrix_count = size_id.ctrl.disp * size_id.ctrl.disp
        self._replies = {}
        self._tail_daq = size_id.daq.total > self._matrix_count
        self._data_size = data_size
        self._state = _READY

    def _decode_vector(self, data: bytes | bytearray, start: int) -> ElementServerEvent:
        self.vectors_received += 1
        code: float = _SLOT0.unpack_from(data, start)[0]
        reply = _REPLY_BY_CODE.get(code)
        if reply is not None:
            self._owed = reply.action
            self._state = _MUST_REPLY
            return reply
        action = ACTION_BY_CODE.get(code)
        if action is _TRIAL_ACTION:
            assert self._trial_layout is not None
            return TrialReceived(self._trial_layout.unpack_from(data, start))
        if action is None:
            if not math.isfinite(code):
                offset = self._in.consumed - self._vector_bytes
                self._fail(
                    f"vector #{self.vectors_received} (stream offset {offset}): slot 0 "
                    f"(action code) is {code!r}, not a finite number"
                )
            return Ignored(code)
        if action is _COMMIT_ACTION:
            return _COMMIT_EVENT
        if action is _DIE_ACTION:
            self._state = _CLOSED
            self.bytes_after_die += self._in.discard()
            return _DIE_EVENT
        return Ignored(code)

    def _close(self) -> ConnectionClosed:
        pending = self._in.discard()
        event = ConnectionClosed(clean=pending == 0, pending_bytes=pending)
        self._closed = event
        self._state = _CLOSED
        self._owed = None
        return event

    def _fail(self, message: str) -> NoReturn:
        self._state = _ERROR
        self._error = message
        raise RemoteProtocolError(message)

    # -- sending -------------------------------------------------------------------
    def _require_owed(self, method: str, allowed: frozenset[Action], hint: str) -> Action:
        owed = self._owed
        if owed in allowed and self._state is _MUST_REPLY and self._keep_leftovers:
            return owed  # the usual case
        if self._state is not _MUST_REPLY or owed is None:
            raise LocalProtocolError(
                f"{method}() called but no reply is owed (state {self._state.name})"
            )
        if owed not in allowed:
            raise LocalProtocolError(
                f"{method}() cannot answer {owed.name} (code {owed.value}); {hint}"
            )
        if not self._keep_leftovers:
            self._reply_full = None
            self._reply[:] = self._zeros  # past the matrix: zeros, as in every entry
        return owed

    def _writable(self) -> bytearray:
        """The reply buffer, holding every left-over of the replies before."""
        full = self._reply_full
        if full is not None:
            self._reply_full = None
            self._reply[:] = full
        return self._reply

    def _finish_reply(self) -> bytes:
        self._owed = None
        self._state = _READY
        return bytes(self._reply)

    def send_daq(self, daq: Signals) -> bytes:
        """Reply to codes 6..11 with daq blocks at their packed offsets from slot 0.

        Code 6 writes every daq block (all lengths must equal the daq sizes). Codes 7..11
        write the requested block (its length must equal its daq size) plus any other
        non-empty block given, each at its packed offset: an ECSimFEAdapter client reads
        its whole daq vector from a code-10 reply (spec §5), genericClient only slot 0..n-1.
        """
        action = self._require_owed(
            "send_daq", _DAQ_ACTIONS, "use send_matrix for 12..15 or send_values"
        )
        layout = self._daq_layout
        assert layout is not None
        reply = self._writable()
        if self._tail_daq:
            self._replies.clear()
        if action is _DAQ_ACTION:
            layout.pack_into(reply, daq, "daq")
            return self._finish_reply()
        if tuple(map(len, daq)) == layout.counts:
            # every block at its size (the empty ones of size 0): writing the requested block
            # and every non-empty one is writing them all, in one call
            layout.pack_exact_into(reply, daq)
            return self._finish_reply()
        requested = _DAQ_BLOCK_OF_ACTION[action]
        blocks = daq.as_tuple()
        sizes = layout.sizes.as_tuple()
        for index, block in enumerate(blocks):
            if (index == requested or block) and len(block) != sizes[index]:
                layout.check(daq, f"{action.name} reply: daq")
        for index, block in enumerate(blocks):
            if index == requested or block:
                layout.pack_block_into(reply, index, block, "daq")
        return self._finish_reply()

    def send_matrix(self, column_major: Sequence[float]) -> bytes:
        """Reply to codes 12..15: n*n values (n = sizeCtrl disp), column-major from slot 0."""
        action = self._require_owed(
            "send_matrix", _MATRIX_ACTIONS, "use send_daq for 6..11 or send_values"
        )
        count = self._matrix_count
        packed: bytes | None = None
        if type(column_major) is tuple:  # immutable: its packed bytes are kept and reused
            cached = self._packed.get(id(column_major))
            if cached is not None and cached[0] is column_major:
                packed = cached[1]  # its size was checked when it was packed
        if packed is None:
            self._check_matrix(column_major, action)
            if type(column_major) is not tuple:
                doubles_struct(count).pack_into(self._writable(), 0, *column_major)
                return self._finish_reply()
            packed = doubles_struct(count).pack(*column_major)
            if len(self._packed) >= _PACKED_CACHE:
                self._packed.clear()
            self._packed[id(column_major)] = (column_major, packed)
        self._owed = None  # _finish_reply, inlined (7 matrices a step)
        self._state = _READY
        if count == self._data_size:  # the whole reply: no copy at all
            self._reply_full = packed
            return packed
        reply = self._reply if self._reply_full is None else self._writable()
        reply[: 8 * count] = packed
        replies = self._replies
        whole = replies.get(packed)
        if whole is None:
            if len(replies) >= _PACKED_CACHE:
                replies.clear()
            whole = replies[packed] = bytes(reply)
        return whole

    def _check_matrix(self, column_major: Sequence[float], action: Action) -> None:
        """LocalProtocolError unless ``column_major`` is an n*n matrix that fits dataSize."""
        sid = self._size_id
        assert sid is not None
        n, count = sid.ctrl.disp, self._matrix_count
        if len(column_major) != count:
            raise LocalProtocolError(
                f"send_matrix() got {len(column_major)} values but {action.name} needs "
                f"n*n = {count} (n = sizeCtrl disp = {n})"
            )
        if count > sid.data_size:
            raise LocalProtocolError(
                f"send_matrix(): the {n}x{n} matrix needs {count} slots but dataSize is "
                f"{sid.data_size}"
            )

    def send_values(self, values: Sequence[float]) -> bytes:
        """Escape hatch: answer the owed request with raw *values* from slot 0."""
        self._require_owed("send_values", _REPLY_ACTIONS, "")
        assert self._size_id is not None
        if len(values) > self._size_id.data_size:
            raise LocalProtocolError(
                f"send_values() got {len(values)} values but dataSize is {self._size_id.data_size}"
            )
        doubles_struct(len(values)).pack_into(self._writable(), 0, *values)
        if len(values) > self._matrix_count:
            self._replies.clear()
        return self._finish_reply()
