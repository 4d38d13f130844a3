"""Element protocol codec against the real OpenSeesPy / OpenFresco byte captures (spec §3)."""

from __future__ import annotations

import json
import math
import struct
from typing import Any

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from protocol import (
    NEED_DATA,
    PAUSED,
    Action,
    ClientState,
    CommitReceived,
    ConnectionClosed,
    DieReceived,
    ElementClientSession,
    ElementServerSession,
    Ignored,
    LocalProtocolError,
    RemoteProtocolError,
    ReplyReceived,
    ReplyRequested,
    ServerState,
    Signals,
    SignalSizes,
    SizeID,
    SizeReceived,
    TrialReceived,
    UdpClientFraming,
    UdpServerFraming,
)
from tests.support.paths import OPENFRESCO_CAPTURES

FIXTURES = OPENFRESCO_CAPTURES

GC_CAPTURES = sorted(
    p.name for p in FIXTURES.glob("gc_*.json") if p.name != "gc_action_sequences.json"
)


def load(name: str) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((FIXTURES / name).read_text())
    return data


def connections() -> list[tuple[str, int]]:
    return [(name, i) for name in GC_CAPTURES for i in range(len(load(name)["connections"]))]


def size_id_of(meaning: dict[str, Any]) -> SizeID:
    return SizeID(
        SignalSizes(**meaning["sizeCtrl"]), SignalSizes(**meaning["sizeDaq"]), meaning["dataSize"]
    )


def trial_of(payload: dict[str, list[float]]) -> Signals:
    return Signals(**{k: tuple(v) for k, v in payload.items()})


def vector(code: float, data_size: int, *rest: float) -> bytes:
    values = [code, *rest] + [0.0] * (data_size - 1 - len(rest))
    return struct.pack(f"<{data_size}d", *values)


def server_with(size_id: SizeID, **kwargs: Any) -> ElementServerSession:
    server = ElementServerSession(**kwargs)
    server.receive_data(size_id.encode())
    assert server.next_event() == SizeReceived(size_id)
    return server


# -- replay of every genericClient capture -----------------------------------------


@pytest.mark.parametrize(("fixture", "index"), connections())
def test_server_replays_capture_byte_exact(fixture: str, index: int) -> None:
    conn = load(fixture)["connections"][index]
    messages = conn["messages"]
    server = ElementServerSession()
    framing = UdpServerFraming()
    actions: list[int] = []
    replies = 0
    for position, message in enumerate(messages):
        if message["dir"] != "client->server":
            continue
        raw = bytes.fromhex(message["hex"])
        meaning = message["meaning"]
        if conn["transport"] == "udp":
            answer = None
            cursor = 0
            for size in meaning.get("udp_datagram_sizes", [len(raw)]):
                part, answer = framing.datagram_received(raw[cursor : cursor + size])
                cursor += size
                if part:
                    server.receive_data(part)
            if meaning["kind"] == "udp-handshake":
                assert answer == bytes.fromhex(messages[position + 1]["hex"]) == b"b"
                assert server.next_event() is NEED_DATA
                continue
            assert answer is None
        else:
            server.receive_data(raw)
        event = server.next_event()
        if meaning["kind"] == "ID":
            assert event == SizeReceived(size_id_of(meaning))
            assert list(struct.unpack("<11i", raw)) == meaning["values"]
            continue
        action = meaning["action"]
        actions.append(action)
        if action == 3:
            assert event == TrialReceived(trial_of(meaning["payload"]))
        elif action == 5:
            assert event == CommitReceived()
        elif action == 99:
            assert event == DieReceived()
            assert server.state is ServerState.CLOSED
        else:
            assert event == ReplyRequested(Action(action))
            assert server.state is ServerState.MUST_REPLY
            assert server.next_event() is PAUSED
            reply = messages[position + 1]
            assert reply["dir"] == "server->client"
            answer_meaning = reply["meaning"]
            if "force" in answer_meaning:
                sent = server.send_daq(Signals(force=tuple(answer_meaning["force"])))
            else:
                sent = server.send_matrix(answer_meaning["matrix_column_major"])
            assert sent.hex() == reply["hex"]
            replies += 1
        assert server.next_event() is NEED_DATA
    assert actions == conn["action_sequence"][: len(actions)]
    assert replies == sum(1 for m in messages if m["dir"] == "server->client" and m["nbytes"] > 1)
    server.receive_data(b"")
    assert server.next_event() == ConnectionClosed(clean=True, pending_bytes=0)


@pytest.mark.parametrize(("fixture", "index"), connections())
def test_client_reproduces_capture_byte_exact(fixture: str, index: int) -> None:
    conn = load(fixture)["connections"][index]
    messages = conn["messages"]
    client: ElementClientSession | None = None
    framing = UdpClientFraming(handshake=conn["transport"] == "udp")
    for position, message in enumerate(messages):
        meaning = message["meaning"]
        raw = bytes.fromhex(message["hex"])
        if meaning["kind"] == "udp-handshake":
            if message["dir"] == "client->server":
                assert framing.start() == raw
            else:
                assert framing.datagram_received(raw) == b""
            continue
        if message["dir"] == "server->client":
            continue
        if meaning["kind"] == "ID":
            client = ElementClientSession(size_id_of(meaning))
            sent = client.start()
        else:
            assert client is not None
            action = meaning["action"]
            if action == 3:
                sent = client.send_trial(trial_of(meaning["payload"]))
            elif action == 5:
                sent = client.send_commit()
            elif action == 99:
                sent = client.send_die()
            else:
                sent = client.send_request(Action(action))
        assert sent.hex() == message["hex"], f"message {message['i']}"
        if meaning["kind"] == "vector" and 6 <= meaning["action"] <= 15:
            assert client is not None
            reply = messages[position + 1]
            client.receive_data(bytes.fromhex(reply["hex"]))
            event = client.next_event()
            assert isinstance(event, ReplyReceived)
            assert event.action == Action(meaning["action"])
            n = client.size_id.ctrl.disp
            if "force" in reply["meaning"]:
                assert list(event.force(n)) == reply["meaning"]["force"]
            else:
                rows = [list(row) for row in event.matrix(n)]
                assert rows == reply["meaning"]["matrix_rows"]
            assert len(event.values) == client.size_id.data_size
    assert client is not None
    complete = "truncated_after_messages" not in load(fixture)
    assert (client.state is ClientState.CLOSED) == complete


def test_generic_client_data_size_rule_matches_captures() -> None:
    # max(user, 1 + 3n + 1, n*n), spec §3.3 (values observed with OpenSeesPy 3.7.1).
    assert SizeID.for_generic_client(1).data_size == 256
    assert SizeID.for_generic_client(1, 1).data_size == 5
    assert SizeID.for_generic_client(2, 1).data_size == 8
    assert SizeID.for_generic_client(10, 1).data_size == 100
    assert SizeID.for_generic_client(1, 1150).data_size == 1150
    for name, ids in [
        ("gc_1dof_static_tcp.json", SizeID.for_generic_client(1)),
        ("gc_1dof_static_tcp_datasize_min.json", SizeID.for_generic_client(1, 1)),
        ("gc_matrix_orientation_tcp.json", SizeID.for_generic_client(2, 1)),
        ("gc_udp_chunking_datasize1150.json", SizeID.for_generic_client(1, 1150)),
    ]:
        first = next(
            m for m in load(name)["connections"][0]["messages"] if m["meaning"]["kind"] == "ID"
        )
        assert ids.encode().hex() == first["hex"]
        assert SizeID.decode(bytes.fromhex(first["hex"])) == ids


def test_matrix_reply_is_column_major() -> None:
    conn = load("gc_matrix_orientation_tcp.json")["connections"][0]
    reply = next(m for m in conn["messages"] if m["meaning"].get("reply_to") == "getTangentStiff")
    server = server_with(SizeID.for_generic_client(2, 1))
    server.receive_data(vector(13, 8))
    assert server.next_event() == ReplyRequested(Action.GET_TANGENT_STIFF)
    # K = [[4, 1], [2, 3]]: slot c*n + r holds K[r][c].
    assert server.send_matrix([4.0, 2.0, 1.0, 3.0]).hex() == reply["hex"]
    event = ReplyReceived(
        Action.GET_TANGENT_STIFF, struct.unpack("<8d", bytes.fromhex(reply["hex"]))
    )
    assert event.matrix(2) == ((4.0, 1.0), (2.0, 3.0))


# -- ECSimFEAdapter-style client (daq disp + force) ----------------------------------


def test_ecsimfeadapter_capture_both_roles() -> None:
    messages = load("ecsimfeadapter_vs_opensees_adapter_tcp.json")["messages"]
    size_id = size_id_of(messages[0]["meaning"])
    assert size_id.ctrl == SignalSizes(disp=1) and size_id.daq == SignalSizes(disp=1, force=1)
    server = ElementServerSession()
    client = ElementClientSession(size_id, stale_payload=False)
    die_bytes: list[bytes] = []
    for position, message in enumerate(messages):
        if message["dir"] != "client->server":
            continue
        meaning = message["meaning"]
        server.receive_data(bytes.fromhex(message["hex"]))
        event = server.next_event()
        if meaning["kind"] == "ID":
            assert event == SizeReceived(size_id)
            assert client.start().hex() == message["hex"]
        elif meaning["action"] == 3:
            trial = Signals(disp=tuple(meaning["ctrlDisp"]))
            assert event == TrialReceived(trial)
            assert client.send_trial(trial).hex() == message["hex"]
        elif meaning["action"] == 10:
            assert event == ReplyRequested(Action.GET_FORCE)
            assert client.send_request(Action.GET_FORCE).hex() == message["hex"]
            reply = messages[position + 1]
            daq = Signals(
                disp=tuple(reply["meaning"]["daqDisp"]), force=tuple(reply["meaning"]["daqForce"])
            )
            sent = server.send_daq(daq)
            assert sent.hex() == reply["hex"]
            # disp at slot 0, force at slot 1 (its packed daq offset)
            assert struct.unpack_from("<2d", sent) == (daq.disp[0], daq.force[0])
            client.receive_data(sent)
            got = client.next_event()
            assert isinstance(got, ReplyReceived) and got.daq(size_id.daq) == daq
        else:
            assert meaning["action"] == 99
            die_bytes.append(bytes.fromhex(message["hex"]))
            if len(die_bytes) == 1:
                assert event == DieReceived()
                assert client.send_die().hex() == message["hex"]
            else:  # ECSimFEAdapter sends DIE twice: the second one is dropped
                assert event is NEED_DATA
    assert die_bytes[0] == die_bytes[1]
    assert server.bytes_after_die == size_id.vector_bytes
    server.receive_data(b"")
    assert server.next_event() == ConnectionClosed(clean=True)


def test_get_force_reply_keeps_other_slots_when_only_force_given() -> None:
    size_id = SizeID(SignalSizes(disp=1), SignalSizes(disp=1, force=1), 4)
    server = server_with(size_id)
    server.receive_data(vector(10, 4))
    assert server.next_event() == ReplyRequested(Action.GET_FORCE)
    sent = server.send_daq(Signals(force=(7.5,)))
    assert struct.unpack("<4d", sent) == (0.0, 7.5, 0.0, 0.0)


# -- action sequences (no bytes in the fixture: synthetic vectors) -----------------


def sequences() -> list[tuple[str, str, list[int]]]:
    out = []
    for variant in load("gc_action_sequences.json")["variants"]:
        for key in ("element1_actions", "element2_actions"):
            out.append((variant["label"], key, variant[key]))
    return out


@pytest.mark.parametrize(("label", "element", "codes"), sequences())
def test_action_sequences_event_kinds(label: str, element: str, codes: list[int]) -> None:
    size_id = SizeID.for_generic_client(2, 1)
    server = server_with(size_id)
    owed_count = 0
    for step, code in enumerate(codes):
        trial = (0.001 * step, -0.002 * step, 0.1, 0.2, -1.0, 1.0, 0.01 * step)
        server.receive_data(vector(code, size_id.data_size, *trial))
        event = server.next_event()
        if code == 3:
            assert event == TrialReceived(
                Signals(trial[0:2], trial[2:4], trial[4:6], (), trial[6:])
            )
        elif code == 5:
            assert event == CommitReceived()
        elif code == 99:
            assert event == DieReceived()
            assert step == len(codes) - 1
        else:
            assert 6 <= code <= 15, code
            assert event == ReplyRequested(Action(code))
            assert server.owed_action is Action(code)
            # stale payload and a further request must wait until the reply is sent
            server.receive_data(vector(3, size_id.data_size))
            assert server.next_event() is PAUSED
            if code >= 12:
                server.send_matrix([1.0, 0.0, 0.0, 1.0])
            else:
                server.send_daq(Signals(force=(1.0, 2.0)))
            assert server.next_event() == TrialReceived(
                Signals((0.0,) * 2, (0.0,) * 2, (0.0,) * 2, (), (0.0,))
            )
            owed_count += 1
    assert owed_count == sum(1 for c in codes if 6 <= c <= 15)
    assert server.state is ServerState.CLOSED


@pytest.mark.parametrize("code", [1.0, 2.0, 4.0, 98.0, 50.0, 0.0, -3.0, 3.5, 1e300])
def test_codes_without_reply_are_ignored(code: float) -> None:
    server = server_with(SizeID.for_generic_client(1, 1))
    server.receive_data(vector(code, 5, 9.0, 9.0))
    assert server.next_event() == Ignored(code)
    assert server.state is ServerState.READY
    with pytest.raises(LocalProtocolError, match="no reply is owed"):
        server.send_values([0.0])


def test_missing_time_slot_of_matlab_client_reads_as_zero() -> None:
    # MATLAB GenericClient2d: ctrl (n,n,n,0,1), dataSize max(1+3n, n*n): one slot short.
    raw = struct.pack("<11i", 1, 1, 1, 0, 1, 0, 0, 0, 1, 0, 4)
    size_id = SizeID.decode(raw)
    assert not size_id.ctrl_time_fits
    server = ElementServerSession()
    server.receive_data(raw + vector(3, 4, 0.5, 0.25, 0.125))
    assert server.next_event() == SizeReceived(size_id)
    assert server.next_event() == TrialReceived(Signals((0.5,), (0.25,), (0.125,), (), (0.0,)))
    with pytest.raises(LocalProtocolError, match="would not send its time"):
        ElementClientSession(size_id)


def test_reply_leftovers_can_be_zeroed() -> None:
    size_id = SizeID.for_generic_client(2, 1)
    for keep, expected in [(True, (5.0, 6.0, 3.0, 4.0)), (False, (5.0, 6.0, 0.0, 0.0))]:
        server = server_with(size_id, keep_reply_leftovers=keep)
        server.receive_data(vector(13, 8) + vector(10, 8))
        server.next_event()
        server.send_matrix([1.0, 2.0, 3.0, 4.0])
        server.next_event()
        assert struct.unpack_from("<4d", server.send_daq(Signals(force=(5.0, 6.0)))) == expected


@pytest.mark.parametrize("keep", [True, False])
@pytest.mark.parametrize("n", [2, 4])  # 4: the matrix fills the whole reply (n*n = dataSize)
def test_a_reused_matrix_reply_equals_a_fresh_one_with_the_same_leftovers(
        n: int, keep: bool) -> None:
    """A tuple matrix is packed once and reused (as the whole reply when it fills it); the
    reply is byte for byte what packing it again gives, leftovers included, and a list
    (mutable) is packed every time."""
    size_id = SizeID.for_generic_client(n, 8)
    assert (size_id.data_size == n * n) == (n == 4)
    damping = tuple(float(i) for i in range(1, n * n + 1))
    stiff = [9.0 - i for i in range(n * n)]
    sequence = [(14, damping), (10, None), (13, stiff), (14, damping), (14, damping),
                (10, None), (14, damping), (13, stiff), (10, None)]
    cached = server_with(size_id, keep_reply_leftovers=keep)
    fresh = server_with(size_id, keep_reply_leftovers=keep)
    ds = size_id.data_size
    force = 10.0
    for code, matrix in sequence:
        cached.receive_data(vector(code, ds))
        fresh.receive_data(vector(code, ds))
        cached.next_event()
        fresh.next_event()
        if matrix is None:
            force += 1.0
            daq = Signals(force=tuple(force * (i + 1) for i in range(n)))
            assert cached.send_daq(daq) == fresh.send_daq(daq)
        else:
            assert cached.send_matrix(matrix) == fresh.send_matrix(list(matrix))
        stiff[0] += 1.0  # a list changed in place is never answered from a stale copy


REPLY = st.sampled_from(["damp", "stiff", "daq6", "daq10", "values"])


@settings(max_examples=150, deadline=None)
@given(st.integers(1, 3), st.sampled_from([SignalSizes(0, 0, 0, 1, 0), SignalSizes(1, 1, 1, 1, 1)]),
       st.integers(0, 6), st.booleans(), st.lists(st.tuples(REPLY, st.integers(0, 2)),
                                                   max_size=30))
@example(2, SignalSizes(1, 1, 1, 1, 1), 0, True, [("damp", 0), ("daq10", 1), ("damp", 0)])
@example(1, SignalSizes(0, 0, 0, 1, 0), 3, True, [("damp", 0), ("values", 2), ("damp", 0)])
def test_a_matrix_answered_again_is_the_reply_packing_it_again_gives(
        n: int, daq_unit: SignalSizes, extra: int, keep: bool,
        replies: list[tuple[str, int]]) -> None:
    """A tuple matrix answered again is the same reply bytes while nothing past it changed
    (``_replies``): byte for byte what a session packing a list every time sends, whatever
    wrote the slots past the matrix before (daq blocks longer than it, raw values, zeroed
    left-overs)."""
    daq = SignalSizes(*(k * n for k in daq_unit.as_tuple()))
    ctrl = SignalSizes(n, n, n, 0, 1)
    size_id = SizeID(ctrl, daq, max(n * n, 1 + ctrl.total, daq.total) + extra)
    ds = size_id.data_size
    cached = server_with(size_id, keep_reply_leftovers=keep)
    fresh = server_with(size_id, keep_reply_leftovers=keep)
    matrices = [tuple(float(10 * k + i) for i in range(n * n)) for k in range(4)]
    for kind, k in replies:
        code = {"damp": 14, "stiff": 13, "daq6": 6, "daq10": 10, "values": 13}[kind]
        for server in (cached, fresh):
            server.receive_data(vector(code, ds))
            assert server.next_event() == ReplyRequested(Action(code))
        if kind in ("damp", "stiff"):
            assert cached.send_matrix(matrices[k]) == fresh.send_matrix(list(matrices[k]))
        elif kind == "values":
            values = [float(-k - i - 1) for i in range(min(ds, n * n + k))]
            assert cached.send_values(values) == fresh.send_values(values)
        else:
            signals = Signals(*(tuple(float(100 * k + i + 1) for i in range(size))
                                for size in daq.as_tuple()))
            assert cached.send_daq(signals) == fresh.send_daq(signals)


# -- bad input ----------------------------------------------------------------------


@pytest.mark.parametrize("entry", range(11))
def test_negative_size_entry_is_rejected_by_name(entry: int) -> None:
    values = [1, 1, 1, 0, 1, 0, 0, 0, 1, 0, 256]
    values[entry] = -2
    server = ElementServerSession()
    server.receive_data(struct.pack("<11i", *values))
    with pytest.raises(
        RemoteProtocolError, match=rf"size ID entry {entry} \(.+\) = -2 is negative"
    ):
        server.next_event()
    assert server.state is ServerState.ERROR
    with pytest.raises(RemoteProtocolError, match="ERROR state"):
        server.next_event()


@pytest.mark.parametrize(
    ("values", "cap", "message"),
    [
        ([1, 1, 1, 0, 1, 0, 0, 0, 1, 0, 0], 65536, r"entry 10 \(dataSize\) = 0 must be at least 1"),
        (
            [1, 1, 1, 0, 1, 0, 0, 0, 1, 0, 100000],
            4096,
            r"size ID entry 10 \(dataSize\) = 100000 exceeds the configured cap 4096",
        ),
        ([1, 1, 1, 0, 1, 0, 0, 0, 300, 0, 256], 65536, r"daq sizes \(entries 5-9\) sum to 300"),
        (
            [100, 100, 100, 0, 1, 0, 0, 0, 1, 0, 256],
            65536,
            r"ctrl sizes \(entries 0-4\) need 1 \+ 301",
        ),
        ([3, 3, 3, 0, 1, 0, 0, 0, 1, 0, 9], 65536, r"ctrl sizes .* need 1 \+ 10 slots"),
    ],
)
def test_invalid_size_id(values: list[int], cap: int, message: str) -> None:
    server = ElementServerSession(max_data_size=cap)
    server.receive_data(struct.pack("<11i", *values))
    with pytest.raises(RemoteProtocolError, match=message):
        server.next_event()
    with pytest.raises(RemoteProtocolError, match=message):
        SizeID.decode(struct.pack("<11i", *values), max_data_size=cap)


def test_size_id_constructor_validates() -> None:
    with pytest.raises(ValueError, match="daq sizes"):
        SizeID(SignalSizes(1, 1, 1, 0, 1), SignalSizes(force=10), 8)
    with pytest.raises(ValueError, match="negative"):
        SignalSizes(disp=-1)
    with pytest.raises(ValueError, match="at least 1 basic DOF"):
        SizeID.for_generic_client(0)


def test_eof_mid_id_and_mid_vector_is_unclean() -> None:
    size_id = SizeID.for_generic_client(1, 1)
    server = ElementServerSession()
    server.receive_data(size_id.encode()[:20])
    assert server.next_event() is NEED_DATA
    server.receive_data(b"")
    assert server.next_event() == ConnectionClosed(clean=False, pending_bytes=20)
    assert server.state is ServerState.CLOSED

    server = server_with(size_id)
    server.receive_data(vector(3, 5)[:13])
    server.receive_data(b"")
    assert server.next_event() == ConnectionClosed(clean=False, pending_bytes=13)
    # idempotent, and feeding data after EOF is our bug
    assert server.next_event() == ConnectionClosed(clean=False, pending_bytes=13)
    with pytest.raises(LocalProtocolError, match="after EOF"):
        server.receive_data(b"\x00" * 8)

    server = server_with(size_id)
    server.receive_data(vector(5, 5))
    server.receive_data(b"")
    assert server.next_event() == CommitReceived()
    assert server.next_event() == ConnectionClosed(clean=True, pending_bytes=0)


@pytest.mark.parametrize("code", [math.nan, math.inf, -math.inf])
def test_non_finite_action_code_is_an_error(code: float) -> None:
    server = server_with(SizeID.for_generic_client(1, 1))
    server.receive_data(vector(1, 5) + vector(code, 5))
    assert server.next_event() == Ignored(1.0)
    with pytest.raises(RemoteProtocolError, match=r"vector #2 \(stream offset 84\): slot 0"):
        server.next_event()
    assert server.state is ServerState.ERROR


def test_send_without_or_with_the_wrong_owed_reply() -> None:
    server = ElementServerSession()
    with pytest.raises(LocalProtocolError, match=r"no reply is owed \(state AWAIT_ID\)"):
        server.send_daq(Signals())
    server = server_with(SizeID.for_generic_client(2, 1))
    with pytest.raises(LocalProtocolError, match=r"send_matrix\(\) called but no reply is owed"):
        server.send_matrix([0.0] * 4)
    server.receive_data(vector(10, 8))
    server.next_event()
    with pytest.raises(LocalProtocolError, match="cannot answer GET_FORCE"):
        server.send_matrix([0.0] * 4)
    with pytest.raises(
        LocalProtocolError, match="force block has 1 values but the negotiated size is 2"
    ):
        server.send_daq(Signals(force=(1.0,)))
    with pytest.raises(LocalProtocolError, match="disp block has 1 values"):
        server.send_daq(Signals(disp=(1.0,), force=(1.0, 2.0)))
    assert server.state is ServerState.MUST_REPLY
    server.send_daq(Signals(force=(1.0, 2.0)))
    with pytest.raises(LocalProtocolError, match="no reply is owed"):
        server.send_daq(Signals(force=(1.0, 2.0)))
    server.receive_data(vector(14, 8))
    server.next_event()
    with pytest.raises(LocalProtocolError, match="cannot answer GET_DAMP"):
        server.send_daq(Signals(force=(1.0, 2.0)))
    with pytest.raises(LocalProtocolError, match=r"needs n\*n = 4 \(n = sizeCtrl disp = 2\)"):
        server.send_matrix([1.0, 2.0, 3.0])
    with pytest.raises(LocalProtocolError, match="dataSize is 8"):
        server.send_values([0.0] * 9)
    assert len(server.send_values([1.0])) == 64


def test_data_after_die_is_dropped() -> None:
    server = server_with(SizeID.for_generic_client(1, 1))
    server.receive_data(vector(99, 5) + vector(3, 5)[:7])
    assert server.next_event() == DieReceived()
    server.receive_data(vector(99, 5))
    assert server.next_event() is NEED_DATA
    assert server.bytes_after_die == 47
    server.receive_data(b"")
    assert server.next_event() == ConnectionClosed(clean=True)


def test_client_misuse_and_unsolicited_bytes() -> None:
    client = ElementClientSession(SizeID.for_generic_client(1, 1))
    with pytest.raises(LocalProtocolError, match="only legal in state READY, not AWAIT_START"):
        client.send_commit()
    client.start()
    with pytest.raises(LocalProtocolError, match="trial vel block has 0 values"):
        client.send_trial(Signals(disp=(1.0,)))
    with pytest.raises(LocalProtocolError, match=r"code 6\.\.15"):
        client.send_request(Action.COMMIT_STATE)
    client.send_request(Action.GET_FORCE)
    with pytest.raises(LocalProtocolError, match="not AWAIT_REPLY"):
        client.send_request(Action.GET_FORCE)
    client.receive_data(b"\x00" * 39)
    assert client.next_event() is NEED_DATA
    client.receive_data(b"\x00" * 9)
    assert isinstance(client.next_event(), ReplyReceived)
    with pytest.raises(RemoteProtocolError, match="while no reply was pending"):
        client.next_event()
    assert client.state is ClientState.ERROR


def test_client_unanswered_codes_round_trip() -> None:
    size_id = SizeID.for_generic_client(1, 1)
    client = ElementClientSession(size_id)
    server = ElementServerSession()
    server.receive_data(client.start())
    server.next_event()
    for code in (1.0, 2.0, 4.0, 98.0, 2.5):
        server.receive_data(client.send_unanswered(code))
        assert server.next_event() == Ignored(code)
    with pytest.raises(LocalProtocolError, match="use send_trial"):
        client.send_unanswered(10.0)
