"""Bad input: each case gets a clear log line, other sites keep working, the record stays intact."""

from __future__ import annotations

import logging
import math
import socket
import struct
import time
from pathlib import Path

import pytest

from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import read_record
from fresco_bridge.record.export import committed_steps
from fresco_bridge.sites import SiteState
from protocol import Action, SizeID
from tests.support.bridge import RunningBridge
from tests.support.spied_bridge import told_to_stop, wait_for

CONFIG = """
[bridge]
run_name = "bad-input"
max_data_size = 1000
allowed_clients = ["127.0.0.1", "127.0.0.2"]

[[sites]]
name = "spring"
port = 0
dofs = 1
[sites.controller]
model = "bilinear"
params = { k0 = 100.0, fy = 20.0, alpha = 0.02 }

[[sites]]
name = "other"
port = 0
dofs = 1
[sites.controller]
model = "elastic"
params = { k = 50.0 }

[[sites]]
name = "guarded"
port = 0
dofs = 1
allowed_clients = ["127.0.0.2"]
[sites.controller]
model = "elastic"
params = { k = 10.0 }
"""


def _vector(code: float, *values: float, size: int = 5) -> bytes:
    slots = [code, *values] + [0.0] * (size - 1 - len(values))
    return struct.pack(f"<{size}d", *slots)


def _raw(port: int, source: str = "127.0.0.1") -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.settimeout(5.0)
    s.bind((source, 0))
    s.connect(("127.0.0.1", port))
    return s


def _closed_by_bridge(s: socket.socket) -> bool:
    try:
        return s.recv(1) == b""
    except ConnectionResetError:
        return True


def _good_session(port: int, k: float, steps: int = 5) -> None:
    """A complete well-behaved client session: trial, force, commit; forces checked."""
    with GenericClientLink("127.0.0.1", port, 1, data_size=1) as link:
        for i in range(1, steps + 1):
            d = 0.01 * i
            link.set_trial((d,), time=float(i))
            assert link.force()[0] == pytest.approx(k * d, rel=1e-12)
            link.commit()


@pytest.fixture
def bridge(tmp_path: Path):  # type: ignore[no-untyped-def]
    with RunningBridge(CONFIG, tmp_path) as b:
        yield b


def _after_bad_client(bridge, caplog, fragment: str) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + 5.0  # the bridge logs from its own thread
    while time.monotonic() < deadline and not any(
        fragment in r.getMessage() for r in caplog.records
    ):
        time.sleep(0.01)
    assert any(fragment in r.getMessage() for r in caplog.records), (
        f"no log line containing {fragment!r}: {[r.getMessage() for r in caplog.records]}"
    )
    # the same site serves the next client, the other site is unaffected
    _good_session(bridge.ports["spring"], 100.0)
    _good_session(bridge.ports["other"], 50.0)


@pytest.mark.parametrize(
    ("ints", "fragment"),
    [
        ([1, 1, 1, 0, 1, 0, 0, 0, 1, 0, -5], "entry 10"),
        ([1, 1, 1, 0, 1, 0, 0, 0, -1, 0, 256], "entry 8"),
        ([1, 1, 1, 0, 1, 0, 0, 0, 1, 0, 5000], "cap 1000"),
    ],
    ids=["negative-datasize", "negative-size", "above-cap"],
)
def test_malformed_size_id(bridge, caplog, ints: list[int], fragment: str) -> None:  # type: ignore[no-untyped-def]
    caplog.set_level(logging.INFO, logger="fresco_bridge")
    s = _raw(bridge.ports["spring"])
    s.sendall(struct.pack("<11i", *ints))
    assert _closed_by_bridge(s)
    s.close()
    _after_bad_client(bridge, caplog, fragment)


@pytest.mark.parametrize(
    ("ints", "fragment"),
    [
        ([2, 2, 2, 0, 1, 0, 0, 0, 2, 0, 256], "do not fit site spring"),
        ([1, 1, 1, 2, 1, 0, 0, 0, 1, 0, 256], "force control"),
    ],
    ids=["wrong-dofs", "force-ctrl"],
)
def test_unfitting_size_id_is_told_to_stop(bridge, caplog, ints: list[int], fragment: str) -> None:  # type: ignore[no-untyped-def]
    """A valid size ID the site cannot serve: refused, and its requests answered with NaN
    until DIE (an OpenSees client then stops; a closed socket made it spin)."""
    caplog.set_level(logging.INFO, logger="fresco_bridge")
    s = _raw(bridge.ports["spring"])
    s.sendall(struct.pack("<11i", *ints))
    s.sendall(_vector(3.0, 0.01, size=256) + _vector(10.0, size=256))  # trial, then force
    reply = b""
    while len(reply) < 8 * 256:
        chunk = s.recv(8 * 256 - len(reply))
        assert chunk, "closed instead of answered"
        reply += chunk
    assert all(math.isnan(v) for v in struct.unpack("<256d", reply))
    s.sendall(_vector(99.0, size=256))
    assert _closed_by_bridge(s)
    s.close()
    _after_bad_client(bridge, caplog, fragment)


def test_eof_mid_vector(bridge, caplog) -> None:  # type: ignore[no-untyped-def]
    caplog.set_level(logging.INFO, logger="fresco_bridge")
    s = _raw(bridge.ports["spring"])
    s.sendall(SizeID.for_generic_client(1, 1).encode() + _vector(3.0, 0.01)[:17])
    s.close()
    _after_bad_client(bridge, caplog, "middle of a message")
    events = [r for r in read_record(bridge.run_dir) if r["kind"] == "event"]
    assert any("17 byte(s)" in e["reason"] for e in events)


def test_unknown_action_codes_are_ignored_and_stream_stays_in_sync(bridge, caplog) -> None:  # type: ignore[no-untyped-def]
    caplog.set_level(logging.INFO, logger="fresco_bridge")
    s = _raw(bridge.ports["spring"])
    s.sendall(SizeID.for_generic_client(1, 1).encode())
    s.sendall(_vector(3.0, 0.05, 0.0, 0.0, 1.0))
    for code in (42.0, 4.0, 1.0, 98.0, 2.5):
        s.sendall(_vector(code))
    s.sendall(_vector(float(Action.GET_FORCE)))
    reply = s.recv(40)
    assert struct.unpack("<5d", reply)[0] == pytest.approx(5.0)
    s.sendall(_vector(99.0))
    s.close()
    # said once (the first), the others counted: a peer's repeats cannot flood the log
    assert sum("ignoring action code" in r.getMessage() for r in caplog.records) == 1
    _after_bad_client(bridge, caplog, "ignoring action code 42.0")


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_trial_holds_and_is_never_forwarded(bridge, caplog, bad: float) -> None:  # type: ignore[no-untyped-def]
    caplog.set_level(logging.INFO, logger="fresco_bridge")
    site = bridge.bridge.sites["spring"]
    link = GenericClientLink("127.0.0.1", bridge.ports["spring"], 1, data_size=1).connect()
    link.set_trial((0.1,), time=1.0)
    assert link.force()[0] == pytest.approx(10.0)
    assert link.matrix(Action.GET_DAMP) == link.matrix(Action.GET_MASS) == ((0.0,),)
    link.commit()
    link.set_trial((bad,), time=2.0)
    # the client still gets answers (it would hang forever otherwise): NaN, so it stops
    assert math.isnan(link.force()[0])
    for action in (Action.GET_DAMP, Action.GET_MASS):  # the configured ones answer NaN too
        assert all(math.isnan(v) for row in link.matrix(action) for v in row), action
    link.set_trial((0.15,), time=3.0)  # not forwarded while in HOLD either
    assert math.isnan(link.force()[0])
    assert bridge.call(lambda: site.state) is SiteState.HOLD
    assert bridge.call(lambda: site.controller._models[0].committed) == pytest.approx((0.1, 10.0))
    link.close()
    assert any("HOLD" in r.getMessage() and "non-finite" in r.getMessage()
               for r in caplog.records)
    holds = [r for r in read_record(bridge.run_dir) if r.get("event") == "hold"]
    assert len(holds) == 1 and "not forwarded" in holds[0]["reason"]
    # every trial that reached the controller is finite
    trials = [r for r in read_record(bridge.run_dir) if r["kind"] == "trial"]
    assert all(isinstance(v, float) for r in trials for v in r["ctrl"])
    _after_bad_client(bridge, caplog, "non-finite")
    assert bridge.call(lambda: site.state) is SiteState.IDLE


def test_client_from_disallowed_address(bridge, caplog) -> None:  # type: ignore[no-untyped-def]
    caplog.set_level(logging.INFO, logger="fresco_bridge")
    s = _raw(bridge.ports["guarded"], source="127.0.0.1")
    assert told_to_stop(s)
    s.close()
    assert any("not in allowed_clients" in r.getMessage() for r in caplog.records)
    ok = _raw(bridge.ports["guarded"], source="127.0.0.2")  # the allowed address is served
    ok.sendall(SizeID.for_generic_client(1, 1).encode() + _vector(3.0, 0.2) + _vector(10.0))
    assert struct.unpack("<5d", ok.recv(40))[0] == pytest.approx(2.0)
    ok.sendall(_vector(99.0))
    ok.close()
    _after_bad_client(bridge, caplog, "refused client")


def test_second_concurrent_client_is_refused(bridge, caplog) -> None:  # type: ignore[no-untyped-def]
    caplog.set_level(logging.INFO, logger="fresco_bridge")
    with GenericClientLink("127.0.0.1", bridge.ports["spring"], 1, data_size=1) as first:
        wait_for(lambda: bridge.call(lambda: bridge.bridge.sites["spring"].busy), "the session")
        intruder = _raw(bridge.ports["spring"])
        assert told_to_stop(intruder)
        intruder.close()
        first.set_trial((0.02,), time=1.0)
        assert first.force()[0] == pytest.approx(2.0)
        first.commit()
    assert any("busy" in r.getMessage() for r in caplog.records)
    deadline = time.monotonic() + 5.0  # DIE is processed asynchronously: wait for its event
    while not any(r.get("event") == "session-close" for r in read_record(bridge.run_dir)):
        assert time.monotonic() < deadline, "session never closed"
        time.sleep(0.01)
    steps = committed_steps(bridge.run_dir)
    assert [s.cmd_disp for s in steps if s.site == "spring"] == [(0.02,)]


def test_other_sites_are_served_while_a_bad_client_is_still_connected(bridge, caplog) -> None:  # type: ignore[no-untyped-def]
    """A client stuck mid-message (half a vector sent, socket open) blocks nothing else: the
    other site runs a whole session meanwhile, and the record holds it intact."""
    caplog.set_level(logging.INFO, logger="fresco_bridge")
    stuck = _raw(bridge.ports["spring"])
    stuck.sendall(SizeID.for_generic_client(1, 1).encode() + _vector(3.0, 0.01)[:17])
    try:
        _good_session(bridge.ports["other"], 50.0, steps=20)  # while `stuck` is open
        intruder = _raw(bridge.ports["spring"])  # its own site stays one-client-at-a-time
        assert told_to_stop(intruder)
        intruder.close()
    finally:
        stuck.close()
    _after_bad_client(bridge, caplog, "middle of a message")
    other = [s for s in committed_steps(bridge.run_dir) if s.site == "other"]
    assert [s.cmd_disp for s in other[:20]] == [(0.01 * i,) for i in range(1, 21)]
    assert all(s.meas_force == pytest.approx((50.0 * s.cmd_disp[0],)) for s in other)
