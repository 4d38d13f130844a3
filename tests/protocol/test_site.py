"""Site protocol codec (ShadowExpSite <-> ActorExpSite) against the OpenFresco 2.8 captures."""

from __future__ import annotations

import json
import math
import struct
from typing import Any

import pytest

from protocol import (
    NEED_DATA,
    OPENFRESCO_VERSION,
    PAUSED,
    ActorSession,
    CommitReceived,
    ConnectionClosed,
    DaqReceived,
    DaqRequested,
    DieReceived,
    DieReplyReceived,
    Ignored,
    LocalProtocolError,
    OpenReceived,
    OpenReplyReceived,
    ProbeReceived,
    ProbeReplyReceived,
    RemoteProtocolError,
    SetupReceived,
    ShadowSession,
    Signals,
    SignalSizes,
    SiteState,
    TrialReceived,
    UdpServerFraming,
    site_data_size,
)
from tests.support.paths import OPENFRESCO_CAPTURES

FIXTURES = OPENFRESCO_CAPTURES
CAPTURES = ["site_shadow_actor_tcp.json", "site_shadow_actor_udp.json"]
SHADOW_TAG, ACTOR_TAG = 7, 9
SIZE_TRIAL = SignalSizes(2, 2, 2, 0, 1)
SIZE_OUT = SignalSizes(2, 2, 2, 2, 1)


def load(name: str) -> list[dict[str, Any]]:
    messages: list[dict[str, Any]] = json.loads((FIXTURES / name).read_text())["messages"]
    return messages


def signals_of(fields: dict[str, list[float]]) -> Signals:
    return Signals(**{k: tuple(v) for k, v in fields.items() if k in Signals.__match_args__})


def vector(values: list[float], size: int) -> bytes:
    return struct.pack(f"<{size}d", *(values + [0.0] * (size - len(values))))


def transport_of(name: str) -> str:
    return "udp" if name.endswith("_udp.json") else "tcp"


@pytest.mark.parametrize("name", CAPTURES)
def test_actor_replays_capture_byte_exact(name: str) -> None:
    messages = load(name)
    transport = transport_of(name)
    actor = ActorSession("udp" if transport == "udp" else "tcp")
    assert actor.state.name == ("AWAIT_OPEN" if transport == "udp" else "AWAIT_PROBE")
    framing = UdpServerFraming()
    kinds: list[str] = []
    last_trial_time = 0.0
    for position, message in enumerate(messages):
        if message["dir"] != "client->server":
            continue
        raw = bytes.fromhex(message["hex"])
        meaning = message["meaning"]
        if transport == "udp":
            data, answer = framing.datagram_received(raw)
            if meaning["kind"] == "udp-handshake":
                assert answer == bytes.fromhex(messages[position + 1]["hex"])
                continue
            actor.receive_data(data)
        else:
            actor.receive_data(raw)
        event = actor.next_event()
        reply = messages[position + 1] if position + 1 < len(messages) else None
        kind = meaning["kind"] if meaning["kind"] != "vector" else meaning["action_name"]
        kinds.append(kind)
        if kind == "endianness-check":
            assert event == ProbeReceived("little")
            assert actor.next_event() is PAUSED
            sent = actor.send_probe_reply()
        elif kind == "open":
            assert event == OpenReceived(SHADOW_TAG, OPENFRESCO_VERSION)
            assert actor.state.name == "MUST_REPLY"
            fields = reply["meaning"]["fields"] if reply else {}
            sent = actor.send_open_reply(
                int(fields["tag_of_actor_site"]), fields["openfresco_version"]
            )
            assert actor.state is SiteState.AWAIT_SETUP
        elif kind == "setup":
            assert event is NEED_DATA  # the two IDs are still missing
            assert actor.state is SiteState.AWAIT_SETUP
            continue
        elif kind == "ID":
            if meaning["values"] == list(SIZE_TRIAL.as_tuple()):
                assert event is NEED_DATA
            else:
                assert event == SetupReceived(256, SIZE_TRIAL, SIZE_OUT)
                assert actor.state is SiteState.READY
            continue
        elif kind == "setTrialResponse":
            trial = signals_of(meaning["fields"])
            assert event == TrialReceived(trial)
            last_trial_time = trial.time[0]
            continue
        elif kind == "commitState":
            assert event == CommitReceived()
            # the quirk: the commit carries trial time + commit time; we ignore it
            assert meaning["fields"]["time_slot"] == pytest.approx(2 * last_trial_time)
            continue
        elif kind == "getDaqResponse":
            assert event == DaqRequested()
            assert reply is not None
            sent = actor.send_daq(signals_of(reply["meaning"]["fields"]))
        else:
            assert kind == "DIE"
            assert event == DieReceived(peer_tag=SHADOW_TAG)
            sent = actor.send_die_reply(ACTOR_TAG)
            assert actor.state is SiteState.CLOSED
        assert reply is not None and reply["dir"] == "server->client"
        assert sent.hex() == reply["hex"], f"reply to message {message['i']}"
    assert kinds.count("getDaqResponse") == 3 and kinds[-1] == "DIE"
    actor.receive_data(b"")
    assert actor.next_event() == ConnectionClosed(clean=True)


@pytest.mark.parametrize("name", CAPTURES)
def test_shadow_reproduces_capture_byte_exact(name: str) -> None:
    messages = load(name)
    transport = transport_of(name)
    shadow = ShadowSession("udp" if transport == "udp" else "tcp", shadow_tag=SHADOW_TAG)
    client_bytes = [
        bytes.fromhex(m["hex"])
        for m in messages
        if m["dir"] == "client->server" and m["meaning"]["kind"] != "udp-handshake"
    ]
    server_bytes = [
        bytes.fromhex(m["hex"])
        for m in messages
        if m["dir"] == "server->client" and m["meaning"]["kind"] != "udp-handshake"
    ]
    steps = [
        signals_of(m["meaning"]["fields"])
        for m in messages
        if m["meaning"].get("action_name") == "setTrialResponse"
    ]
    outs = [
        signals_of(m["meaning"]["fields"])
        for m in messages
        if m["meaning"].get("reply_to") == "getDaqResponse"
    ]
    sent: list[bytes] = []
    replies = iter(server_bytes)

    def answer() -> Any:
        shadow.receive_data(next(replies))
        return shadow.next_event()

    if transport == "tcp":
        sent.append(shadow.send_probe())
        assert answer() == ProbeReplyReceived("little")
    sent.append(shadow.send_open())
    assert answer() == OpenReplyReceived(ACTOR_TAG, OPENFRESCO_VERSION, 0.0)
    data_size = site_data_size(SIZE_TRIAL, SIZE_OUT)
    setup = shadow.send_setup(data_size, SIZE_TRIAL, SIZE_OUT)
    sent.extend([setup[:2048], setup[2048:2068], setup[2068:]])
    for trial, out in zip(steps, outs, strict=True):
        sent.append(shadow.send_trial(trial))
        sent.append(shadow.send_daq_request())
        assert answer() == DaqReceived(out)
        sent.append(shadow.send_commit(trial.time))
    sent.append(shadow.send_die())
    assert answer() == DieReplyReceived(ACTOR_TAG, 4.0)
    assert shadow.state is SiteState.CLOSED
    assert [s.hex() for s in sent] == [c.hex() for c in client_bytes]


@pytest.mark.parametrize("transport", ["tcp", "udp"])
@pytest.mark.parametrize("data_size", [10, 256, 300])
def test_shadow_actor_in_memory(transport: str, data_size: int) -> None:
    size_trial, size_out = SignalSizes(disp=3, time=1), SignalSizes(disp=3, force=3)
    shadow = ShadowSession("tcp" if transport == "tcp" else "udp", shadow_tag=3)
    actor = ActorSession("tcp" if transport == "tcp" else "udp")

    def to_actor(data: bytes) -> object:
        actor.receive_data(data)
        return actor.next_event()

    def to_shadow(data: bytes) -> object:
        shadow.receive_data(data)
        return shadow.next_event()

    if transport == "tcp":
        assert to_actor(shadow.send_probe()) == ProbeReceived("little")
        assert to_shadow(actor.send_probe_reply()) == ProbeReplyReceived("little")
    assert to_actor(shadow.send_open()) == OpenReceived(3, OPENFRESCO_VERSION)
    # a version mismatch is reported, not judged, by the codec
    assert to_shadow(actor.send_open_reply(12, 2.7)) == OpenReplyReceived(12, 2.7)
    setup = shadow.send_setup(data_size, size_trial, size_out)
    assert len(setup) == 2048 + 40
    assert to_actor(setup) == SetupReceived(data_size, size_trial, size_out)
    for step in range(1, 4):
        trial = Signals(disp=(0.1 * step, 0.2 * step, -0.3 * step), time=(0.01 * step,))
        message = shadow.send_trial(trial)
        assert len(message) == 8 * data_size
        assert to_actor(message) == TrialReceived(trial)
        assert to_actor(shadow.send_daq_request()) == DaqRequested()
        out = Signals(disp=trial.disp, force=tuple(10.0 * d for d in trial.disp))
        reply = actor.send_daq(out)
        assert len(reply) == 8 * data_size
        assert to_shadow(reply) == DaqReceived(out)
        assert to_actor(shadow.send_commit(trial.time)) == CommitReceived()
    assert to_actor(shadow.send_die()) == DieReceived(peer_tag=3)
    reply = actor.send_die_reply(12)
    assert len(reply) == 8 * data_size
    assert to_shadow(reply) == DieReplyReceived(12)


def open_actor(transport: str = "tcp", **kwargs: Any) -> ActorSession:
    actor = ActorSession("tcp" if transport == "tcp" else "udp", **kwargs)
    if transport == "tcp":
        actor.receive_data(struct.pack("<i", 1))
        actor.next_event()
        actor.send_probe_reply()
    actor.receive_data(vector([1.0, 7.0, 2.8], 256))
    actor.next_event()
    actor.send_open_reply(9, 2.8)
    return actor


def setup_bytes(data_size: float, trial: list[int], out: list[int]) -> bytes:
    return vector([2.0, data_size, 2.8], 256) + struct.pack("<10i", *trial, *out)


def test_big_endian_probe_is_accepted_and_answered_little_endian() -> None:
    actor = ActorSession("tcp")
    actor.receive_data(struct.pack(">i", 1))
    assert actor.next_event() == ProbeReceived("big")
    assert actor.send_probe_reply() == b"\x01\x00\x00\x00"


def test_bad_probe_is_rejected() -> None:
    actor = ActorSession("tcp")
    actor.receive_data(vector([1.0, 7.0, 2.8], 256))
    with pytest.raises(
        RemoteProtocolError, match=r"endianness probe \(first 4 bytes\) is 00000000"
    ):
        actor.next_event()
    assert actor.state is SiteState.ERROR


@pytest.mark.parametrize(
    ("data_size", "trial", "out", "cap", "message"),
    [
        (256.0, [2, -2, 2, 0, 1], [2, 2, 2, 2, 1], 65536, r"sizeTrial entry 1 \(vel\) = -2"),
        (256.0, [2, 2, 2, 0, 1], [2, 2, 2, 2, -1], 65536, r"sizeOut entry 4 \(time\) = -1"),
        (6.0, [2, 2, 2, 0, 1], [1, 0, 0, 1, 0], 65536, r"sizeTrial needs 1 \+ 7 slots"),
        (8.0, [2, 2, 2, 0, 1], [2, 2, 2, 2, 1], 65536, r"sizeOut needs 9 slots"),
        (256.5, [1, 0, 0, 0, 0], [1, 0, 0, 0, 0], 65536, r"slot 1 \(dataSize\) is 256.5"),
        (math.nan, [1, 0, 0, 0, 0], [1, 0, 0, 0, 0], 65536, r"slot 1 \(dataSize\) is nan"),
        (0.0, [0, 0, 0, 0, 0], [0, 0, 0, 0, 0], 65536, r"dataSize\) = 0 is outside 1..65536"),
        (5000.0, [1, 0, 0, 0, 0], [1, 0, 0, 0, 0], 4096, r"= 5000 is outside 1..4096"),
    ],
)
def test_invalid_setup(
    data_size: float, trial: list[int], out: list[int], cap: int, message: str
) -> None:
    actor = open_actor(max_data_size=cap)
    actor.receive_data(setup_bytes(data_size, trial, out))
    with pytest.raises(RemoteProtocolError, match=message):
        actor.next_event()
    assert actor.state is SiteState.ERROR


@pytest.mark.parametrize("code", [3.0, 5.0, 6.0])
def test_step_messages_before_setup_are_rejected(code: float) -> None:
    actor = open_actor("udp")
    actor.receive_data(vector([code], 256))
    with pytest.raises(RemoteProtocolError, match=rf"code {int(code)} .* before the setup"):
        actor.next_event()


def test_unknown_codes_ignored_non_finite_rejected() -> None:
    actor = open_actor("udp")
    actor.receive_data(setup_bytes(4.0, [1, 0, 0, 0, 1], [0, 0, 0, 1, 0]))
    assert actor.next_event() == SetupReceived(4, SignalSizes(disp=1, time=1), SignalSizes(force=1))
    for code in (13.0, 10.0, 4.0, 98.0, 3.25):
        actor.receive_data(vector([code, 1.0], 4))
        assert actor.next_event() == Ignored(code)
        assert actor.state is SiteState.READY
    actor.receive_data(vector([math.nan], 4))
    with pytest.raises(RemoteProtocolError, match=r"slot 0 \(action code\) is nan"):
        actor.next_event()


def test_actor_reply_misuse() -> None:
    actor = ActorSession("tcp")
    with pytest.raises(LocalProtocolError, match=r"no reply is owed \(state AWAIT_PROBE\)"):
        actor.send_probe_reply()
    actor = open_actor("udp")
    actor.receive_data(setup_bytes(8.0, [1, 0, 0, 0, 1], [1, 0, 0, 1, 0]))
    actor.next_event()
    actor.receive_data(vector([6.0], 8) + vector([3.0, 0.5, 0.1], 8))
    assert actor.next_event() == DaqRequested()
    assert actor.next_event() is PAUSED
    with pytest.raises(LocalProtocolError, match="the owed reply is the daq reply"):
        actor.send_die_reply(9)
    with pytest.raises(LocalProtocolError, match="out force block has 0 values"):
        actor.send_daq(Signals(disp=(1.0,)))
    reply = actor.send_daq(Signals(disp=(1.0,), force=(2.0,)))
    assert struct.unpack("<8d", reply) == (1.0, 2.0, 0, 0, 0, 0, 0, 0)
    assert actor.next_event() == TrialReceived(Signals(disp=(0.5,), time=(0.1,)))


def test_eof_inside_setup_ids_is_unclean() -> None:
    actor = open_actor("udp")
    actor.receive_data(setup_bytes(8.0, [1, 0, 0, 0, 1], [1, 0, 0, 1, 0])[: 2048 + 30])
    assert actor.next_event() is NEED_DATA
    actor.receive_data(b"")
    assert actor.next_event() == ConnectionClosed(clean=False, pending_bytes=30)


def test_shadow_misuse() -> None:
    shadow = ShadowSession("tcp", shadow_tag=1)
    with pytest.raises(LocalProtocolError, match="only legal in state AWAIT_OPEN, not AWAIT_PROBE"):
        shadow.send_open()
    shadow.send_probe()
    shadow.receive_data(b"\x02\x00\x00\x00")
    with pytest.raises(RemoteProtocolError, match="probe reply is 02000000"):
        shadow.next_event()
    shadow = ShadowSession("udp", shadow_tag=1)
    shadow.send_open()
    shadow.receive_data(vector([0.0, 9.0, 2.8], 256))
    shadow.next_event()
    with pytest.raises(LocalProtocolError, match="dataSize 5 is too small, the blocks need 9"):
        shadow.send_setup(5, SIZE_TRIAL, SIZE_OUT)
    with pytest.raises(ValueError, match="transport must be"):
        ShadowSession("ssl", shadow_tag=1)  # type: ignore[arg-type]


def test_daq_reply_zeroes_the_open_reply_left_overs() -> None:
    # ActorExpSite::setSendDaqResponse zeroes sendV; with D = 256 the buffer of the open
    # reply [0, actorTag, 2.8] is reused, so slot 2 must not keep the version.
    actor = open_actor("udp")
    actor.receive_data(setup_bytes(256.0, [1, 0, 0, 0, 0], [1, 0, 0, 1, 0]))
    actor.next_event()
    actor.receive_data(vector([6.0], 256))
    assert actor.next_event() == DaqRequested()
    reply = struct.unpack("<256d", actor.send_daq(Signals(disp=(1.5,), force=(-2.0,))))
    assert reply[:3] == (1.5, -2.0, 0.0)
    assert not any(reply[2:])
    # the DIE reply overwrites slots 0 and 1 only (captured left-overs, spec §4.3)
    actor.receive_data(vector([99.0, 7.0], 256))
    assert actor.next_event() == DieReceived(peer_tag=7)
    assert struct.unpack_from("<3d", actor.send_die_reply(9)) == (4.0, 9.0, 0.0)
