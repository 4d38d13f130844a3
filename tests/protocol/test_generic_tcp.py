"""OpenFresco's GenericTCP protocol (``ECGenericTCP``), both roles, against a capture.

The capture (``tests/fixtures/generic_tcp``) is an emulation of ``ECGenericTCP`` written from
OpenFresco's source with ``struct`` and a socket — nothing of ``protocol/`` — talking to a
real ``sim-actuator serve --protocol generic-tcp`` process. Replayed both ways: our client
session sends its client bytes exactly, our server session reads them into the same events and
answers the captured replies exactly; and any segmentation of the stream decodes the same.
"""

from __future__ import annotations

import itertools
import json
import struct
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol import (
    NEED_DATA,
    PAUSED,
    Action,
    ConnectionClosed,
    DaqReplyReceived,
    DieReceived,
    GenericTcpClientSession,
    GenericTcpServerSession,
    LocalProtocolError,
    ReplyRequested,
    SetupLineReceived,
    Signals,
    SignalSizes,
    SizeID,
    SizeReceived,
    TrialReceived,
)
from protocol.generic_tcp import SETUP_LINE_BYTES, parameter_file_lines
from tests.support.paths import REPO

CAPTURE = REPO / "tests" / "fixtures" / "generic_tcp" / "ecgenerictcp_3act_tcp.json"
N = 3


def capture() -> dict[str, Any]:
    data: dict[str, Any] = json.loads(CAPTURE.read_text(encoding="utf-8"))
    return data


def messages(direction: str) -> list[bytes]:
    return [bytes.fromhex(m["hex"]) for m in capture()["messages"] if m["dir"] == direction]


def size_id() -> SizeID:
    return SizeID(SignalSizes(disp=N), SignalSizes(disp=N, force=N), 256)


def daq_of(reply: bytes) -> Signals:
    values = struct.unpack_from(f"<{2 * N}d", reply)
    return Signals(disp=values[:N], force=values[N:])


def server_events(stream: bytes, replies: list[bytes],
                  cuts: list[int] | None = None) -> tuple[list[object], bytes]:
    """Feed ``stream`` (cut at ``cuts``) into a server session; answer every daq request with
    the next captured reply's values; return the events and the bytes the session sent."""
    session = GenericTcpServerSession()
    events: list[object] = []
    sent = b""
    pending = iter(replies)
    bounds = [0, *sorted(set(cuts or [])), len(stream)]
    for start, end in itertools.pairwise(bounds):
        if end > start:
            session.receive_data(stream[start:end])
        while (event := session.next_event()) is not NEED_DATA:
            assert event is not PAUSED
            events.append(event)
            if isinstance(event, ReplyRequested):
                sent += session.send_daq(daq_of(next(pending)))
            if isinstance(event, DieReceived | ConnectionClosed):
                break
    return events, sent


def test_the_capture_replays_through_the_client_session_byte_for_byte() -> None:
    data = capture()
    client = GenericTcpClientSession(size_id())
    sent = [client.start()]
    sent += [client.send_setup_line(line.encode()) for line in data["parameter_lines"]]
    replies = iter(messages("server->client"))
    daqs = []
    for ctrl in [(0.0,) * N, *map(tuple, data["steps"])]:
        sent.append(client.send_ctrl(Signals(disp=ctrl)))
        sent.append(client.send_daq_request())
        client.receive_data(next(replies))
        event = client.next_event()
        assert isinstance(event, DaqReplyReceived)
        daqs.append(event.daq)
    sent.append(client.send_die())
    assert sent == messages("client->server")
    k = 68.0  # preset ideal-elastic
    for ctrl, daq in zip([(0.0,) * N, *map(tuple, data["steps"])], daqs, strict=True):
        assert daq.disp == pytest.approx(ctrl, abs=1e-12)
        assert daq.force == pytest.approx([k * d for d in ctrl], rel=1e-12)


def test_the_capture_replays_through_the_server_session_byte_for_byte() -> None:
    data = capture()
    replies = messages("server->client")
    events, sent = server_events(b"".join(messages("client->server")), replies)
    assert isinstance(events[0], SizeReceived) and events[0].size_id == size_id()
    lines = [e.line.decode() for e in events if isinstance(e, SetupLineReceived)]
    assert lines == data["parameter_lines"]
    trials = [e.trial.disp for e in events if isinstance(e, TrialReceived)]
    assert trials == [(0.0,) * N, *map(tuple, data["steps"])]
    assert [e.action for e in events if isinstance(e, ReplyRequested)] == \
        [Action.GET_DAQ_RESPONSE] * len(trials)
    assert isinstance(events[-1], DieReceived)
    assert sent == b"".join(replies)  # the replies: daq blocks from slot 0, zeros after


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(min_value=1, max_value=80000), max_size=12))
def test_any_segmentation_of_the_stream_decodes_the_same(cuts: list[int]) -> None:
    stream = b"".join(messages("client->server"))
    replies = messages("server->client")
    whole = server_events(stream, replies)
    assert server_events(stream, replies, [c % len(stream) for c in cuts]) == whole


def test_a_line_message_keeps_the_tail_of_the_longer_lines_before() -> None:
    client = GenericTcpClientSession(size_id())
    client.start()
    long = client.send_setup_line(b"abcdef")
    short = client.send_setup_line(b"xy")
    assert len(long) == len(short) == SETUP_LINE_BYTES
    assert long[:8] == b"\x02abcdef\x00" and short[:8] == b"\x02xy\x00def\x00"


def test_lines_only_between_the_id_and_the_first_vector() -> None:
    client = GenericTcpClientSession(size_id())
    with pytest.raises(LocalProtocolError, match="only legal after start"):
        client.send_setup_line(b"too early")
    client.start()
    client.send_ctrl(Signals(disp=(0.0,) * N))
    with pytest.raises(LocalProtocolError, match="before the first ctrl vector"):
        client.send_setup_line(b"too late")


def test_a_parameter_file_splits_as_getline_does_and_bad_lines_are_named() -> None:
    assert parameter_file_lines(b"a\r\nb\n\nc") == [b"a\r", b"b", b"", b"c"]
    assert parameter_file_lines(b"a\n") == [b"a"]
    with pytest.raises(LocalProtocolError, match=r"line 2 has 16384 bytes; .* at most 16383"):
        parameter_file_lines(b"ok\n" + b"x" * 16384)
    with pytest.raises(LocalProtocolError, match="line 1 holds a NUL byte at column 3"):
        parameter_file_lines(b"ab\0c")


def test_eof_inside_a_line_message_is_an_unclean_close() -> None:
    session = GenericTcpServerSession()
    client = GenericTcpClientSession(size_id())
    session.receive_data(client.start() + client.send_setup_line(b"x")[:100])
    assert isinstance(session.next_event(), SizeReceived)
    assert session.next_event() is NEED_DATA
    session.receive_data(b"")
    assert session.next_event() == ConnectionClosed(clean=False, pending_bytes=100)


LINE = st.binary(max_size=300).map(lambda b: b.replace(b"\n", b" ").replace(b"\0", b" "))
FINITE = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=80, deadline=None)
@given(n=st.integers(1, 6), lines=st.lists(LINE, max_size=4),
       steps=st.lists(st.lists(FINITE, min_size=6, max_size=6), min_size=1, max_size=5),
       cuts=st.lists(st.integers(0, 10**6), max_size=4))
def test_what_the_client_sends_the_server_reads_back(
        n: int, lines: list[bytes], steps: list[list[float]], cuts: list[int]) -> None:
    """Any sizes, lines, ctrl vectors and segmentation: the server's events are the client's
    messages, and the client decodes the server's daq replies exactly."""
    sid = SizeID(SignalSizes(disp=n), SignalSizes(disp=n, force=n, time=1), 256)
    client, server = GenericTcpClientSession(sid), GenericTcpServerSession()
    events: list[object] = []

    def deliver(data: bytes) -> bytes:
        """``data`` to the server cut at ``cuts``; the server's reply (b"" if none)."""
        bounds = [0, *sorted({c % (len(data) + 1) for c in cuts}), len(data)]
        reply = b""
        for start, end in itertools.pairwise(bounds):
            if end > start:
                server.receive_data(data[start:end])
            while (event := server.next_event()) is not NEED_DATA:
                events.append(event)
                if isinstance(event, ReplyRequested):
                    ctrl = events[-2].trial.disp  # type: ignore[attr-defined]
                    reply += server.send_daq(Signals(disp=ctrl, force=tuple(-v for v in ctrl),
                                                     time=(1.5,)))
                if isinstance(event, DieReceived):
                    return reply
        return reply

    assert deliver(client.start() + b"".join(client.send_setup_line(x) for x in lines)) == b""
    sent = []
    for values in steps:
        ctrl = tuple(values[:n])
        sent.append(ctrl)
        reply = deliver(client.send_ctrl(Signals(disp=ctrl)) + client.send_daq_request())
        client.receive_data(reply)
        event = client.next_event()
        assert isinstance(event, DaqReplyReceived)
        assert event.daq == Signals(disp=ctrl, force=tuple(-v for v in ctrl), time=(1.5,))
    deliver(client.send_die())
    assert isinstance(events[0], SizeReceived) and events[0].size_id == sid
    assert [e.line for e in events if isinstance(e, SetupLineReceived)] == lines
    assert [e.trial.disp for e in events if isinstance(e, TrialReceived)] == sent
    assert isinstance(events[-1], DieReceived)
