"""Site-level protocol, client role: OpenFresco ShadowExpSite (spec §4).

Used by tests and tools to drive an ActorSession (ours or a real ActorExpSite) exactly as
the real shadow would, byte for byte.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from typing import Literal

from protocol._site_base import PROBE_LITTLE, SLOT0, THREE, TWO, SiteBase, probe_order
from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.events import NEED_DATA, Sentinel
from protocol.site_events import (
    OPENFRESCO_VERSION,
    PROBE_BYTES,
    SITE_OPEN_DOUBLES,
    DaqReceived,
    DieReplyReceived,
    OpenReplyReceived,
    ProbeReplyReceived,
    ShadowEvent,
    SiteState,
    SiteTransport,
    site_data_size,
)
from protocol.wire import DOUBLE_BYTES, Action, BlockLayout, ReadableBuffer, Signals, SignalSizes

__all__ = ["ShadowSession"]


class _Awaiting(enum.Enum):
    PROBE = "probe reply"
    OPEN = "open reply"
    DAQ = "daq reply"
    DIE = "DIE reply"


class ShadowSession(SiteBase):
    """The client role of OpenFresco's ShadowExpSite, byte-exact with its send buffer.

    One send buffer like the real shadow: the setup vector reuses the open vector (so
    slot 2 still holds the version), code 6/5/99 only rewrite slot 0 (and the tag for
    99), and ``send_commit(time)`` ADDS the commit time into the time slot, which still
    holds the trial time (the commit-time quirk of spec §4.3).
    """

    __slots__ = (
        "_awaiting",
        "_layout_out",
        "_layout_trial",
        "_reply_bytes",
        "_send",
        "_shadow_tag",
        "_time_offset",
        "_version",
    )

    def __init__(
        self,
        transport: SiteTransport,
        *,
        shadow_tag: int,
        version: float = OPENFRESCO_VERSION,
    ) -> None:
        super().__init__(transport)
        self._shadow_tag = shadow_tag
        self._version = version
        self._send = bytearray(DOUBLE_BYTES * SITE_OPEN_DOUBLES)
        self._reply_bytes = DOUBLE_BYTES * SITE_OPEN_DOUBLES
        self._awaiting: _Awaiting | None = None
        self._layout_trial: BlockLayout | None = None
        self._layout_out: BlockLayout | None = None
        self._time_offset = 0

    def _require(self, method: str, state: SiteState) -> None:
        if self._state is not state:
            raise LocalProtocolError(
                f"{method}() is only legal in state {state.name}, not {self._state.name}"
            )

    def _await(self, awaiting: _Awaiting) -> None:
        self._awaiting = awaiting
        self._state = SiteState.AWAIT_REPLY

    def send_probe(self) -> bytes:
        """TCP only: the little-endian int32 1 endianness probe."""
        self._require("send_probe", SiteState.AWAIT_PROBE)
        self._await(_Awaiting.PROBE)
        return PROBE_LITTLE

    def send_open(self) -> bytes:
        """``[1, shadowTag, version]`` in a 256-double vector."""
        self._require("send_open", SiteState.AWAIT_OPEN)
        THREE.pack_into(self._send, 0, float(Action.OPEN), float(self._shadow_tag), self._version)
        self._await(_Awaiting.OPEN)
        return bytes(self._send)

    def send_setup(self, data_size: int, size_trial: SignalSizes, size_out: SignalSizes) -> bytes:
        """Setup vector ``[2, D, left-overs]`` followed by the sizeTrial and sizeOut IDs."""
        self._require("send_setup", SiteState.AWAIT_SETUP)
        needed = site_data_size(size_trial, size_out, 1)
        if data_size < needed:
            raise LocalProtocolError(
                f"send_setup(): dataSize {data_size} is too small, the blocks need {needed} "
                "(use site_data_size())"
            )
        TWO.pack_into(self._send, 0, float(Action.SETUP), float(data_size))
        message = bytes(self._send) + size_trial.encode() + size_out.encode()
        if data_size != SITE_OPEN_DOUBLES:
            self._send = bytearray(DOUBLE_BYTES * data_size)
        self._reply_bytes = DOUBLE_BYTES * data_size
        self._layout_trial = BlockLayout(size_trial, 1, data_size, role="trial")
        self._layout_out = BlockLayout(size_out, 0, data_size, role="out")
        self._time_offset = self._layout_trial.offsets[4]
        self._state = SiteState.READY
        return message

    def send_trial(self, trial: Signals) -> bytes:
        """Code 3: zeroed buffer, trial blocks from slot 1 (no reply)."""
        self._require("send_trial", SiteState.READY)
        layout = self._layout_trial
        assert layout is not None
        layout.check(trial, "trial")
        self._send[:] = bytes(len(self._send))
        layout.pack_into(self._send, trial, "trial")
        SLOT0.pack_into(self._send, 0, float(Action.SET_TRIAL_RESPONSE))
        return bytes(self._send)

    def send_daq_request(self) -> bytes:
        """Code 6 (stale payload); the reply arrives as :class:`DaqReceived`."""
        self._require("send_daq_request", SiteState.READY)
        SLOT0.pack_into(self._send, 0, float(Action.GET_DAQ_RESPONSE))
        self._await(_Awaiting.DAQ)
        return bytes(self._send)

    def send_commit(self, time: Sequence[float] | None = None) -> bytes:
        """Code 5; with *time* the values are ADDED to the time slots (spec §4.3)."""
        self._require("send_commit", SiteState.READY)
        layout = self._layout_trial
        assert layout is not None
        if time is not None and layout.sizes.time:
            if len(time) != layout.sizes.time:
                raise LocalProtocolError(
                    f"send_commit() got {len(time)} time values, sizeTrial time is "
                    f"{layout.sizes.time}"
                )
            for index, value in enumerate(time):
                offset = self._time_offset + DOUBLE_BYTES * index
                (current,) = SLOT0.unpack_from(self._send, offset)
                SLOT0.pack_into(self._send, offset, current + value)
        SLOT0.pack_into(self._send, 0, float(Action.COMMIT_STATE))
        return bytes(self._send)

    def send_die(self) -> bytes:
        """``[99, shadowTag, stale...]``; the actor answers with :class:`DieReplyReceived`."""
        if self._state in (SiteState.AWAIT_PROBE, SiteState.AWAIT_REPLY, SiteState.CLOSED):
            raise LocalProtocolError(f"send_die() is not legal in state {self._state.name}")
        TWO.pack_into(self._send, 0, float(Action.DIE), float(self._shadow_tag))
        self._await(_Awaiting.DIE)
        return bytes(self._send)

    def receive_data(self, data: ReadableBuffer) -> None:
        """Feed bytes from the actor; ``b""`` means EOF."""
        self._in.feed(data)

    def next_event(self) -> ShadowEvent | Literal[Sentinel.NEED_DATA]:
        """The reply to the pending request, ConnectionClosed, or NEED_DATA."""
        state = self._state
        if state is SiteState.ERROR:
            raise RemoteProtocolError(f"session is in ERROR state: {self._error}")
        buffered = self._in
        awaiting = self._awaiting
        if awaiting is None:
            if self._closed is not None:
                return self._closed
            if buffered.available and state is not SiteState.CLOSED:
                self._fail(
                    f"actor sent {buffered.available} bytes at {self._where(0)} while no "
                    "reply was pending"
                )
            return self._close() if buffered.eof else NEED_DATA
        nbytes = PROBE_BYTES if awaiting is _Awaiting.PROBE else self._reply_bytes
        if buffered.available < nbytes:
            return self._close() if buffered.eof else NEED_DATA
        start = buffered.take(nbytes)
        data = buffered.data
        self._awaiting = None
        self._state = SiteState.READY
        if awaiting is _Awaiting.PROBE:
            raw = bytes(data[start : start + PROBE_BYTES])
            order = probe_order(raw)
            if order is None:
                self._fail(f"endianness probe reply is {raw.hex()}, expected int32 1")
            self._state = SiteState.AWAIT_OPEN
            return ProbeReplyReceived(order)
        self.vectors_received += 1
        if awaiting is _Awaiting.OPEN:
            status, tag, version = THREE.unpack_from(data, start)
            actor_tag = self._int_slot(tag, "open reply slot 1 (actor tag)", nbytes)
            self._state = SiteState.AWAIT_SETUP
            return OpenReplyReceived(actor_tag, version, status)
        if awaiting is _Awaiting.DIE:
            status, tag = TWO.unpack_from(data, start)
            actor_tag = self._int_slot(tag, "DIE reply slot 1 (actor tag)", nbytes)
            self._state = SiteState.CLOSED
            return DieReplyReceived(actor_tag, status)
        layout = self._layout_out
        assert layout is not None
        return DaqReceived(layout.unpack_from(data, start))
