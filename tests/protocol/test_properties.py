"""Property tests: round trips, segmentation independence and fuzzing of the codecs."""

from __future__ import annotations

import json
import struct
from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol import (
    NEED_DATA,
    PAUSED,
    Action,
    ActorSession,
    ConnectionClosed,
    DaqRequested,
    DieReceived,
    ElementClientSession,
    ElementServerSession,
    OpenReceived,
    ProbeReceived,
    RemoteProtocolError,
    ReplyRequested,
    ShadowSession,
    Signals,
    SignalSizes,
    SizeID,
    SizeReceived,
    TrialReceived,
    pack_blocks,
    site_data_size,
    unpack_blocks,
)
from tests.support.paths import OPENFRESCO_CAPTURES

PROPS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

sizes_st = st.builds(SignalSizes, *[st.integers(0, 6)] * 5)
finite = st.floats(allow_nan=False, width=64)


@st.composite
def size_ids(draw: st.DrawFn) -> SizeID:
    ctrl = draw(st.builds(SignalSizes, *[st.integers(0, 40)] * 5))
    daq = draw(st.builds(SignalSizes, *[st.integers(0, 40)] * 5))
    low = max(1, daq.total, 1 + ctrl.total - ctrl.time)
    return SizeID(ctrl, daq, draw(st.integers(low, low + 3000)))


@PROPS
@given(size_ids())
def test_size_id_round_trip(size_id: SizeID) -> None:
    raw = size_id.encode()
    assert len(raw) == SizeID.SIZE_BYTES
    decoded = SizeID.decode(raw, max_data_size=size_id.data_size)
    assert decoded == size_id
    assert decoded.ctrl_time_fits == (1 + size_id.ctrl.total <= size_id.data_size)
    if size_id.data_size > 1:
        with pytest.raises(RemoteProtocolError, match="exceeds the configured cap"):
            SizeID.decode(raw, max_data_size=size_id.data_size - 1)


@PROPS
@given(st.lists(st.integers(-(2**31), 2**31 - 1), min_size=11, max_size=11))
def test_any_size_id_bytes_decode_or_raise_remote_error(values: list[int]) -> None:
    raw = struct.pack("<11i", *values)
    try:
        size_id = SizeID.decode(raw)
    except RemoteProtocolError as exc:
        assert "size ID" in str(exc)
        return
    assert size_id.encode() == raw
    assert size_id.daq.total <= size_id.data_size <= 65536
    assert 1 + size_id.ctrl.total - size_id.ctrl.time <= size_id.data_size


@st.composite
def blocks(draw: st.DrawFn) -> tuple[SignalSizes, Signals, int, int]:
    sizes = draw(sizes_st)
    signals = Signals(
        *(tuple(draw(st.lists(finite, min_size=n, max_size=n))) for n in sizes.as_tuple())
    )
    start = draw(st.sampled_from([0, 1]))
    data_size = start + sizes.total + draw(st.integers(0, 5))
    return sizes, signals, start, max(data_size, 1)


@PROPS
@given(blocks())
def test_signal_blocks_round_trip(case: tuple[SignalSizes, Signals, int, int]) -> None:
    sizes, signals, start, data_size = case
    raw = pack_blocks(sizes, signals, data_size, start)
    assert len(raw) == 8 * data_size
    assert unpack_blocks(sizes, bytes(raw), start) == signals
    values = struct.unpack(f"<{data_size}d", raw)
    flat = [v for block in signals.as_tuple() for v in block]
    assert list(values[start : start + sizes.total]) == flat
    assert all(v == 0.0 for v in values[:start] + values[start + sizes.total :])


# -- segmentation -------------------------------------------------------------------

ELEMENT_CODES = [3, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 1, 2, 4, 98, 3.5]


def split(stream: bytes, sizes: list[int]) -> Iterator[bytes]:
    position, index = 0, 0
    while position < len(stream):
        size = sizes[index % len(sizes)] if sizes else len(stream)
        yield stream[position : position + size]
        position += size
        index += 1


def run_element_server(chunks: Iterator[bytes]) -> list[object]:
    """Feed chunks; answer every owed reply deterministically; return events + replies. Where
    ``drained`` says the next ``next_event`` finds nothing buffered, it must be NEED_DATA."""
    server = ElementServerSession()
    out: list[object] = []
    for chunk in [*chunks, b""]:
        server.receive_data(chunk)
        while True:
            event = server.next_event()
            if event is NEED_DATA:
                break
            assert event is not PAUSED
            out.append(event)
            if isinstance(event, ReplyRequested):
                size_id = server.size_id
                assert size_id is not None
                n = size_id.ctrl.disp
                if event.action >= Action.GET_INITIAL_STIFF:
                    out.append(server.send_matrix([float(event.action)] * (n * n)))
                else:
                    out.append(server.send_daq(Signals(force=(float(event.action),) * n)))
            if isinstance(event, ConnectionClosed):
                return out
            if server.drained:  # the call a caller may skip: it finds nothing buffered
                assert server.next_event() is NEED_DATA
                break
    return out


@st.composite
def element_streams(draw: st.DrawFn) -> bytes:
    n = draw(st.integers(1, 3))
    size_id = SizeID.for_generic_client(n, draw(st.sampled_from([1, 16])))
    client = ElementClientSession(size_id)
    parts = [client.start()]
    for code in draw(st.lists(st.sampled_from(ELEMENT_CODES), max_size=25)):
        if code == 3:
            trial = Signals(
                *(
                    tuple(draw(st.lists(finite, min_size=k, max_size=k)))
                    for k in size_id.ctrl.as_tuple()
                )
            )
            parts.append(client.send_trial(trial))
        elif code == 5:
            parts.append(client.send_commit())
        elif isinstance(code, int) and 6 <= code <= 15:
            parts.append(client.send_request(Action(code)))
            client.receive_data(bytes(size_id.vector_bytes))
            client.next_event()
        else:
            parts.append(client.send_unanswered(float(code)))
    if draw(st.booleans()):
        parts.append(client.send_die())
    return b"".join(parts)


@PROPS
@given(element_streams(), st.lists(st.integers(1, 300), min_size=1, max_size=20))
def test_element_segmentation_does_not_change_events(stream: bytes, sizes: list[int]) -> None:
    whole = run_element_server(iter([stream]))
    assert run_element_server(split(stream, sizes)) == whole
    assert isinstance(whole[0], SizeReceived)


def test_one_byte_chunks_of_a_real_capture() -> None:
    data = json.loads((OPENFRESCO_CAPTURES / "gc_2story_transient_tcp.json").read_text())
    messages = data["connections"][1]["messages"]
    stream = b"".join(bytes.fromhex(m["hex"]) for m in messages if m["dir"] == "client->server")
    whole = run_element_server(iter([stream]))
    assert run_element_server(split(stream, [1])) == whole
    assert sum(isinstance(e, TrialReceived) for e in whole) == messages_count(messages, 3)
    assert isinstance(whole[-2], DieReceived)


def messages_count(messages: list[dict[str, object]], action: int) -> int:
    return sum(
        1
        for m in messages
        if isinstance(m["meaning"], dict) and m["meaning"].get("action") == action
    )


def site_stream(transport: str, data_size: int, steps: int) -> bytes:
    """Everything a ShadowSession sends in a complete run against an ActorSession."""
    shadow = ShadowSession("tcp" if transport == "tcp" else "udp", shadow_tag=5)
    actor = ActorSession("tcp" if transport == "tcp" else "udp")
    parts: list[bytes] = []

    def exchange(message: bytes, reply: object) -> None:
        parts.append(message)
        actor.receive_data(message)
        actor.next_event()
        shadow.receive_data(reply() if callable(reply) else b"")
        shadow.next_event()

    if transport == "tcp":
        exchange(shadow.send_probe(), actor.send_probe_reply)
    exchange(shadow.send_open(), lambda: actor.send_open_reply(6, 2.8))
    size_trial, size_out = SignalSizes(disp=2, time=1), SignalSizes(disp=2, force=2)
    setup = shadow.send_setup(
        max(data_size, site_data_size(size_trial, size_out, 1)), size_trial, size_out
    )
    parts.append(setup)
    actor.receive_data(setup)
    actor.next_event()
    for step in range(steps):
        trial = Signals(disp=(0.1 * step, -0.1 * step), time=(float(step),))
        parts.append(shadow.send_trial(trial))
        actor.receive_data(parts[-1])
        actor.next_event()
        exchange(
            shadow.send_daq_request(),
            lambda t=trial: actor.send_daq(Signals(disp=t.disp, force=t.disp)),
        )
        parts.append(shadow.send_commit(trial.time))
        actor.receive_data(parts[-1])
        actor.next_event()
    exchange(shadow.send_die(), lambda: actor.send_die_reply(6))
    return b"".join(parts)


def run_actor(transport: str, chunks: Iterator[bytes]) -> list[object]:
    actor = ActorSession("tcp" if transport == "tcp" else "udp")
    out: list[object] = []
    for chunk in [*chunks, b""]:
        actor.receive_data(chunk)
        while (event := actor.next_event()) is not NEED_DATA:
            assert event is not PAUSED
            out.append(event)
            if isinstance(event, ProbeReceived):
                out.append(actor.send_probe_reply())
            elif isinstance(event, OpenReceived):
                out.append(actor.send_open_reply(6, event.version))
            elif isinstance(event, DaqRequested):
                out.append(actor.send_daq(Signals(disp=(1.0, 2.0), force=(3.0, 4.0))))
            elif isinstance(event, DieReceived):
                out.append(actor.send_die_reply(6))
            elif isinstance(event, ConnectionClosed):
                return out
    return out


@PROPS
@given(
    st.sampled_from(["tcp", "udp"]),
    st.sampled_from([5, 256, 700]),
    st.integers(0, 4),
    st.lists(st.integers(1, 600), min_size=1, max_size=20),
)
def test_site_segmentation_does_not_change_events(
    transport: str, data_size: int, steps: int, sizes: list[int]
) -> None:
    stream = site_stream(transport, data_size, steps)
    whole = run_actor(transport, iter([stream]))
    assert run_actor(transport, split(stream, sizes)) == whole
    assert sum(isinstance(e, TrialReceived) for e in whole) == steps


@PROPS
@given(st.binary(max_size=400), st.lists(st.integers(1, 64), min_size=1, max_size=8))
def test_garbage_after_a_valid_id_never_crashes(garbage: bytes, sizes: list[int]) -> None:
    server = ElementServerSession()
    stream = SizeID.for_generic_client(1, 1).encode() + garbage
    try:
        run_element_server_raw(server, split(stream, sizes))
    except RemoteProtocolError as exc:
        assert "slot 0 (action code)" in str(exc)


def run_element_server_raw(server: ElementServerSession, chunks: Iterator[bytes]) -> None:
    for chunk in [*chunks, b""]:
        server.receive_data(chunk)
        while (event := server.next_event()) is not NEED_DATA:
            if isinstance(event, ReplyRequested):
                server.send_values([0.0])
            elif isinstance(event, ConnectionClosed):
                return
