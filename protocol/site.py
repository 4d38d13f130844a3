"""Site-level protocol: OpenFresco ShadowExpSite (client) <-> ActorExpSite (server), spec §4.

Sequence: [TCP only: int32 1 endianness probe each way] -> open vector [1, shadowTag,
version] answered by [0, actorTag, version] -> setup vector [2, D, ...] followed by the
two 5 x int32 IDs sizeTrial and sizeOut -> per step [3, trial blocks from slot 1],
[6] answered by the out blocks from slot 0, [5] (commit) -> [99, shadowTag] answered by
[4, actorTag]. Open and setup vectors are 256 doubles; after setup every vector is D.

Version numbers are reported, never checked here: the daemon decides what a mismatch
means (real OpenFresco peers exit unless the versions are equal).
"""

from __future__ import annotations

import enum
import math
from typing import Final, Literal

from protocol._site_base import PROBE_LITTLE, SETUP_IDS, SLOT0, THREE, TWO, SiteBase, probe_order
from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.events import (
    NEED_DATA,
    PAUSED,
    CommitReceived,
    ConnectionClosed,
    DieReceived,
    Ignored,
    Sentinel,
    TrialReceived,
)
from protocol.site_events import (
    OPENFRESCO_VERSION,
    PROBE_BYTES,
    SITE_OPEN_DOUBLES,
    STATUS_COMPLETED,
    STATUS_RECEIVED,
    ActorEvent,
    DaqReceived,
    DaqRequested,
    DieReplyReceived,
    OpenReceived,
    OpenReplyReceived,
    ProbeReceived,
    ProbeReplyReceived,
    SetupReceived,
    ShadowEvent,
    SiteState,
    SiteTransport,
    site_data_size,
)
from protocol.site_shadow import ShadowSession
from protocol.wire import (
    ACTION_BY_CODE,
    DOUBLE_BYTES,
    SIGNAL_NAMES,
    Action,
    BlockLayout,
    ReadableBuffer,
    Signals,
    SignalSizes,
)

__all__ = [
    "OPENFRESCO_VERSION",
    "PROBE_BYTES",
    "SITE_OPEN_DOUBLES",
    "ActorEvent",
    "ActorSession",
    "DaqReceived",
    "DaqRequested",
    "DieReplyReceived",
    "OpenReceived",
    "OpenReplyReceived",
    "ProbeReceived",
    "ProbeReplyReceived",
    "SetupReceived",
    "ShadowEvent",
    "ShadowSession",
    "SiteState",
    "SiteTransport",
    "site_data_size",
]

_COMMIT_EVENT: Final = CommitReceived()
_DAQ_EVENT: Final = DaqRequested()


class _Owed(enum.Enum):
    PROBE = "probe"
    OPEN = "open"
    DAQ = "daq"
    DIE = "die"


class ActorSession(SiteBase):
    """The server role of OpenFresco's ActorExpSite (``ActorExpSite::runTill``)."""

    __slots__ = (
        "_layout_out",
        "_layout_trial",
        "_max_data_size",
        "_opened",
        "_owed",
        "_reply",
        "_setup",
        "_setup_data_size",
        "_vector_bytes",
        "bytes_after_die",
    )

    def __init__(self, transport: SiteTransport, *, max_data_size: int = 65536) -> None:
        super().__init__(transport)
        if max_data_size < 1:
            raise ValueError(f"max_data_size must be at least 1, got {max_data_size}")
        self._max_data_size = max_data_size
        self._vector_bytes = DOUBLE_BYTES * SITE_OPEN_DOUBLES
        self._reply = bytearray(self._vector_bytes)
        self._owed: _Owed | None = None
        self._opened = False
        self._setup: SetupReceived | None = None
        self._setup_data_size = 0
        self._layout_trial: BlockLayout | None = None
        self._layout_out: BlockLayout | None = None
        self.bytes_after_die = 0

    @property
    def setup(self) -> SetupReceived | None:
        """The accepted setup, None before it."""
        return self._setup

    def receive_data(self, data: ReadableBuffer) -> None:
        """Feed bytes from the shadow; ``b""`` means EOF. Bytes after DIE are dropped."""
        if self._state is SiteState.CLOSED and data and not self._in.eof:
            self.bytes_after_die += len(data)
            return
        self._in.feed(data)

    def _idle_state(self) -> SiteState:
        if self._setup is not None:
            return SiteState.READY
        return SiteState.AWAIT_SETUP if self._opened else SiteState.AWAIT_OPEN

    def next_event(self) -> ActorEvent | Literal[Sentinel.NEED_DATA, Sentinel.PAUSED]:
        """Decode the next event, or NEED_DATA / PAUSED (a reply is owed)."""
        state = self._state
        if state is SiteState.MUST_REPLY:
            return PAUSED
        if state is SiteState.ERROR:
            raise RemoteProtocolError(f"session is in ERROR state: {self._error}")
        if state is SiteState.CLOSED:
            return self._close() if self._in.eof or self._closed else NEED_DATA
        buffered = self._in
        if state is SiteState.AWAIT_PROBE:
            if buffered.available < PROBE_BYTES:
                return self._close() if buffered.eof else NEED_DATA
            start = buffered.take(PROBE_BYTES)
            raw = bytes(buffered.data[start : start + PROBE_BYTES])
            order = probe_order(raw)
            if order is None:
                self._fail(
                    f"endianness probe (first 4 bytes) is {raw.hex()}, expected int32 1 "
                    "(01000000 or 00000001)"
                )
            return self._owe(_Owed.PROBE, ProbeReceived(order))
        if self._setup_data_size:
            return self._read_setup_ids()
        if buffered.available < self._vector_bytes:
            return self._close() if buffered.eof else NEED_DATA
        start = buffered.take(self._vector_bytes)
        return self._decode_vector(buffered.data, start)

    def _read_setup_ids(self) -> SetupReceived | ConnectionClosed | Literal[Sentinel.NEED_DATA]:
        buffered = self._in
        if buffered.available < SETUP_IDS.size:
            return self._close() if buffered.eof else NEED_DATA
        start = buffered.take(SETUP_IDS.size)
        return self._accept_setup(SETUP_IDS.unpack_from(buffered.data, start))

    def _owe(self, owed: _Owed, event: ActorEvent) -> ActorEvent:
        self._owed = owed
        self._state = SiteState.MUST_REPLY
        return event

    def _decode_vector(
        self, data: bytes | bytearray, start: int
    ) -> ActorEvent | Literal[Sentinel.NEED_DATA]:
        self.vectors_received += 1
        nbytes = self._vector_bytes
        code: float = SLOT0.unpack_from(data, start)[0]
        action = ACTION_BY_CODE.get(code)
        if action is Action.SET_TRIAL_RESPONSE:
            layout = self._require_setup(action, nbytes)
            return TrialReceived(layout.unpack_from(data, start))
        if action is Action.GET_DAQ_RESPONSE:
            self._require_setup(action, nbytes)
            return self._owe(_Owed.DAQ, _DAQ_EVENT)
        if action is Action.COMMIT_STATE:
            # The time slot holds trial time + commit time (spec §4.3): ignored.
            self._require_setup(action, nbytes)
            return _COMMIT_EVENT
        if action is Action.OPEN:
            _, tag, version = THREE.unpack_from(data, start)
            shadow_tag = self._int_slot(tag, "open vector slot 1 (shadow tag)", nbytes)
            return self._owe(_Owed.OPEN, OpenReceived(shadow_tag, version))
        if action is Action.SETUP:
            _, size = TWO.unpack_from(data, start)
            data_size = self._int_slot(size, "setup vector slot 1 (dataSize)", nbytes)
            if data_size < 1 or data_size > self._max_data_size:
                self._fail(
                    f"setup vector slot 1 (dataSize) = {data_size} is outside 1.."
                    f"{self._max_data_size} (the configured cap)"
                )
            self._setup_data_size = data_size
            self._state = SiteState.AWAIT_SETUP
            return self._read_setup_ids()
        if action is Action.DIE:
            _, tag = TWO.unpack_from(data, start)
            peer_tag = self._int_slot(tag, "DIE vector slot 1 (shadow tag)", nbytes)
            return self._owe(_Owed.DIE, DieReceived(peer_tag))
        if action is None and not math.isfinite(code):
            self._fail(
                f"vector #{self.vectors_received} ({self._where(nbytes)}): slot 0 (action "
                f"code) is {code!r}, not a finite number"
            )
        return Ignored(code)

    def _require_setup(self, action: Action, nbytes: int) -> BlockLayout:
        layout = self._layout_trial
        if layout is None:
            self._fail(
                f"code {action.value} ({action.name}) arrived before the setup message "
                f"({self._where(nbytes)}): the trial/out sizes are unknown"
            )
        return layout

    def _accept_setup(self, values: tuple[int, ...]) -> SetupReceived:
        data_size = self._setup_data_size
        for index, value in enumerate(values):
            if value < 0:
                role = "sizeTrial" if index < 5 else "sizeOut"
                self._fail(
                    f"site setup {role} entry {index % 5} ({SIGNAL_NAMES[index % 5]}) = "
                    f"{value} is negative"
                )
        size_trial = SignalSizes(*values[:5])
        size_out = SignalSizes(*values[5:])
        if 1 + size_trial.total > data_size:
            self._fail(
                f"site setup sizeTrial needs 1 + {size_trial.total} slots but dataSize "
                f"(setup vector slot 1) is {data_size}"
            )
        if size_out.total > data_size:
            self._fail(
                f"site setup sizeOut needs {size_out.total} slots but dataSize "
                f"(setup vector slot 1) is {data_size}"
            )
        self._setup_data_size = 0
        self._layout_trial = BlockLayout(size_trial, 1, data_size, role="trial")
        self._layout_out = BlockLayout(size_out, 0, data_size, role="out")
        if DOUBLE_BYTES * data_size != len(self._reply):
            self._reply = bytearray(DOUBLE_BYTES * data_size)
        self._vector_bytes = DOUBLE_BYTES * data_size
        self._setup = SetupReceived(data_size, size_trial, size_out)
        self._state = SiteState.READY
        return self._setup

    # -- replies -------------------------------------------------------------------
    def _require_owed(self, method: str, owed: _Owed) -> None:
        if self._state is not SiteState.MUST_REPLY or self._owed is None:
            raise LocalProtocolError(
                f"{method}() called but no reply is owed (state {self._state.name})"
            )
        if self._owed is not owed:
            raise LocalProtocolError(
                f"{method}() called but the owed reply is the {self._owed.value} reply"
            )

    def _replied(self, state: SiteState) -> None:
        self._owed = None
        self._state = state

    def send_probe_reply(self) -> bytes:
        """Answer the TCP endianness probe with little-endian int32 1."""
        self._require_owed("send_probe_reply", _Owed.PROBE)
        self._replied(SiteState.AWAIT_OPEN)
        return PROBE_LITTLE

    def send_open_reply(self, actor_tag: int, version: float) -> bytes:
        """``[0 (completed), actorTag, version]`` in a vector of the current length."""
        self._require_owed("send_open_reply", _Owed.OPEN)
        THREE.pack_into(self._reply, 0, STATUS_COMPLETED, float(actor_tag), version)
        self._opened = True
        self._replied(self._idle_state())
        return bytes(self._reply)

    def send_daq(self, out: Signals) -> bytes:
        """All out blocks packed from slot 0, rest zero, no status code (setSendDaqResponse)."""
        self._require_owed("send_daq", _Owed.DAQ)
        layout = self._layout_out
        assert layout is not None
        layout.check(out, "out")
        self._reply[:] = bytes(len(self._reply))
        layout.pack_into(self._reply, out, "out")
        self._replied(SiteState.READY)
        return bytes(self._reply)

    def send_die_reply(self, actor_tag: int) -> bytes:
        """``[4 (received), actorTag, left-overs...]``; the session is CLOSED afterwards."""
        self._require_owed("send_die_reply", _Owed.DIE)
        TWO.pack_into(self._reply, 0, STATUS_RECEIVED, float(actor_tag))
        self._replied(SiteState.CLOSED)
        self.bytes_after_die += self._in.discard()
        return bytes(self._reply)
