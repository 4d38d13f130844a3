"""UDP framing: handshake handling and 9126-byte chunking, against the UDP captures."""

from __future__ import annotations

import json
from typing import Any

import pytest

from protocol import (
    MAX_UDP_DATAGRAM,
    NEED_DATA,
    Action,
    ElementServerSession,
    RemoteProtocolError,
    ReplyRequested,
    Signals,
    SizeID,
    SizeReceived,
    TrialReceived,
    UdpClientFraming,
    UdpServerFraming,
    chunk_datagrams,
)
from tests.support.paths import OPENFRESCO_CAPTURES

FIXTURES = OPENFRESCO_CAPTURES
UDP_CAPTURES = [
    "gc_1dof_static_udp.json",
    "gc_2story_transient_udp.json",
    "gc_udp_chunking_datasize1150.json",
]


def messages_of(name: str) -> list[dict[str, Any]]:
    data = json.loads((FIXTURES / name).read_text())
    return [m for conn in data["connections"] for m in conn["messages"]]


def test_chunk_sizes_match_the_spec() -> None:
    assert MAX_UDP_DATAGRAM == 9126
    assert [len(c) for c in chunk_datagrams(bytes(9200))] == [9126, 74]
    assert [len(c) for c in chunk_datagrams(bytes(24000))] == [9126, 9126, 5748]
    assert [len(c) for c in chunk_datagrams(bytes(9126))] == [9126]
    assert [len(c) for c in chunk_datagrams(bytes(44))] == [44]
    assert [len(c) for c in chunk_datagrams(bytes(2048), 512)] == [512] * 4
    payload = bytes(range(256)) * 40
    assert b"".join(chunk_datagrams(payload)) == payload
    with pytest.raises(ValueError, match="at least 1"):
        chunk_datagrams(payload, 0)


@pytest.mark.parametrize("name", UDP_CAPTURES)
def test_chunking_reproduces_captured_datagram_sizes(name: str) -> None:
    checked = 0
    for message in messages_of(name):
        sizes = message["meaning"].get("udp_datagram_sizes")
        if sizes is None:
            continue
        chunks = chunk_datagrams(bytes.fromhex(message["hex"]))
        assert [len(c) for c in chunks] == sizes
        checked += 1
    assert checked > 0
    if name == "gc_udp_chunking_datasize1150.json":
        assert any(m["meaning"].get("udp_datagram_sizes") == [9126, 74] for m in messages_of(name))


@pytest.mark.parametrize("chunk", [MAX_UDP_DATAGRAM, 512, 1])
def test_server_reassembles_by_byte_count(chunk: int) -> None:
    messages = messages_of("gc_udp_chunking_datasize1150.json")
    framing = UdpServerFraming()
    server = ElementServerSession()
    events: list[object] = []
    for position, message in enumerate(messages):
        if message["dir"] != "client->server":
            continue
        raw = bytes.fromhex(message["hex"])
        for datagram in chunk_datagrams(raw, chunk):
            data, reply = framing.datagram_received(datagram)
            if reply is not None:
                assert reply == bytes.fromhex(messages[position + 1]["hex"])
            if data:
                server.receive_data(data)
        event = server.next_event()
        events.append(event)
        if isinstance(event, ReplyRequested):
            expected = messages[position + 1]
            meaning = expected["meaning"]
            if "force" in meaning:
                sent = server.send_daq(Signals(force=tuple(meaning["force"])))
            else:
                sent = server.send_matrix(meaning["matrix_column_major"])
            assert sent.hex() == expected["hex"]
            assert [len(c) for c in chunk_datagrams(sent)] == [9126, 74]
    assert framing.handshake_seen
    assert events[0] is NEED_DATA  # the 'a' handshake feeds nothing
    assert events[1] == SizeReceived(SizeID.for_generic_client(1, 1150))
    assert isinstance(events[2], TrialReceived)
    assert events[3] == ReplyRequested(Action.GET_FORCE)


def test_handshake_only_as_first_datagram() -> None:
    framing = UdpServerFraming()
    assert framing.datagram_received(b"a") == (b"", b"b")
    assert framing.datagram_received(b"a") == (b"a", None)
    # OpenFresco's own UDP clients send no handshake: the first datagram is the ID
    framing = UdpServerFraming()
    first = SizeID.for_generic_client(1).encode()
    assert framing.datagram_received(first) == (first, None)
    assert not framing.handshake_seen
    assert framing.datagram_received(b"a") == (b"a", None)


def test_client_framing() -> None:
    framing = UdpClientFraming()
    assert framing.start() == b"a"
    assert not framing.handshake_done
    assert framing.datagram_received(b"b") == b""
    assert framing.handshake_done
    assert framing.datagram_received(b"xyz") == b"xyz"
    framing = UdpClientFraming()
    with pytest.raises(RemoteProtocolError, match="expected the 1-byte reply b'b', got 2 bytes"):
        framing.datagram_received(b"zz")
    assert UdpClientFraming(handshake=False).start() is None
