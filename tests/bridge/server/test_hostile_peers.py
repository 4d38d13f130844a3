"""Peers that trickle, reset or vanish cannot lock a site nor flood the log.

A real bridge in a thread, real sockets on loopback: a client trickling one byte a second (its
size ID, or a message once introduced) is ended by ``bridge.message_deadline`` although every
byte resets the idle clock, and a second client is served; a connect-then-reset flood leaves a
few log lines and no traceback; a UDP integrator that arrives while a vanished one still holds
the site is answered once the site is free (its one handshake is queued, not dropped).
"""

from __future__ import annotations

import importlib.util
import logging
import socket
import struct
import threading
from pathlib import Path

import pytest

from fresco_bridge.cli import main as cli_main
from fresco_bridge.config import parse_config
from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.logs import RateLimitedLog
from fresco_bridge.loops import LoopKind
from protocol import ElementClientSession, SizeID
from tests.support.bridge import RunningBridge
from tests.support.net import BATCH, connect_and_reset, loop_held
from tests.support.sessions import K, closes, config, peer, refusals, served, vanish
from tests.support.spied_bridge import refused, wait_for

IDLE = 1.5  # longer than the trickle's byte interval: the idle clock alone never ends it
DEADLINE = 2.0
TRICKLE_INTERVAL = 1.0


def hostile_config() -> str:
    return config(idle=IDLE, deadline=DEADLINE)


class Trickle:
    """Sends ``data`` one byte every ``TRICKLE_INTERVAL`` s until the bridge cuts it."""

    def __init__(self, sock: socket.socket, data: bytes) -> None:
        self.sock, self.data = sock, data
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        for i in range(len(self.data)):
            if self.stop.wait(0 if i == 0 else TRICKLE_INTERVAL):
                return
            try:
                self.sock.send(self.data[i:i + 1])
            except OSError:
                return

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=10)
        self.sock.close()


@pytest.mark.parametrize("trickles", ["size ID", "message"])
def test_a_trickling_client_is_ended_by_the_message_deadline_and_another_is_served(
    tmp_path: Path, trickles: str
) -> None:
    size_id = ElementClientSession(SizeID.for_generic_client(1, 1)).start()
    with RunningBridge(hostile_config(), tmp_path) as bridge:
        port = bridge.ports["tcp"]
        sock = socket.create_connection(("127.0.0.1", port), timeout=10.0)
        if trickles == "message":  # introduced: it holds the site, then trickles a trial
            sock.sendall(size_id)
            wait_for(lambda: peer(bridge, "tcp") != "", "its session to open")
            trickle = Trickle(sock, struct.pack("<5d", 3.0, 0.1, 0.0, 0.0, 0.1))
            assert refused(port)  # the site is its, until the deadline
        else:  # no size ID yet: it holds nothing, a good client is served meanwhile
            trickle = Trickle(sock, size_id)
            served(port)
        try:
            assert sock.recv(1) == b""  # ended by the bridge (the socket's timeout: 10 s)
        finally:
            trickle.close()
        wait_for(lambda: peer(bridge, "tcp") == "", "the site to be free")
        served(port)
        refused_kinds = refusals(bridge, "tcp")
    if trickles == "message":
        assert "bridge.message_deadline" in closes(bridge, "tcp")[0]
        assert "did not complete a message" in closes(bridge, "tcp")[0]
    else:
        assert refused_kinds == {"handshake": 1}  # a refused connection, not a session
        assert len(closes(bridge, "tcp")) == 2  # the good clients' sessions only


@pytest.mark.parametrize("event_loop", ["asyncio", "uvloop"])
def test_a_connect_reset_flood_leaves_a_few_log_lines_and_the_bridge_serves(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, event_loop: LoopKind
) -> None:
    if event_loop == "uvloop" and importlib.util.find_spec("uvloop") is None:
        pytest.skip("uvloop is not installed")
    caplog.set_level(logging.INFO)
    n = 300
    text = hostile_config()
    with BridgeThread(parse_config(text, "<test config>"), text, run_dir=tmp_path,
                      event_loop=event_loop) as bridge:
        port = bridge.ports["tcp"]
        caplog.clear()
        for _ in range(n // 2):  # reset after the bridge accepted them
            connect_and_reset(port)
        # Each held batch starts from an empty accept queue: the kernel's backlog is then never
        # the limit (a queue still holding the batch before made a connect time out).

        def counted(k: int) -> None:
            wait_for(lambda: sum(refusals(bridge, "tcp").values()) == k,
                     f"{k} connections to be counted as refused")

        counted(n // 2)
        for batch in range(n // 2 // BATCH):  # reset before: the peer's address is already gone
            with loop_held(bridge):
                for _ in range(BATCH):
                    connect_and_reset(port)
            counted(n // 2 + BATCH * (batch + 1))
        served(port)
    noisy = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert not [r for r in noisy if r.exc_info or r.levelno >= logging.ERROR], \
        [r.getMessage() for r in noisy]
    assert 1 <= len(noisy) <= 4, [r.getMessage() for r in noisy]


def test_a_udp_handshake_while_a_vanished_peer_holds_the_site_is_answered_when_it_is_free(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="fresco_bridge")
    with RunningBridge(hostile_config(), tmp_path) as bridge:
        port = bridge.ports["udp"]
        vanished = GenericClientLink("127.0.0.1", port, 1, data_size=1, transport="udp",
                                     timeout=5.0).connect()
        vanished.set_trial((0.1,), time=0.1)
        assert vanished.force()[0] == pytest.approx(K * 0.1)
        vanished.commit()
        assert vanished.sock is not None
        vanished.sock.close()  # killed: no DIE; UDP cannot tell
        vanished.sock = None
        # the next integrator sends its one handshake at once and waits (the link's 10 s)
        served(port, "udp")
        wait_for(lambda: len(closes(bridge, "udp")) == 2, "both sessions to be closed")
        udp_closes = closes(bridge, "udp")
    assert "no message from the client" in udp_closes[0]
    assert "client sent DIE" in udp_closes[1]
    said = " ".join(r.getMessage() for r in caplog.records)
    assert "queued, answered when that session ends" in said


def test_a_queued_udp_handshake_is_answered_when_the_operator_resumes_an_aborted_site(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """docs/safety.md's advice: ``ctl abort`` ends the vanished client's session at once, the
    site stays in FAULT (the queued handshake waits), ``ctl resume`` lets the new one in."""
    monkeypatch.setattr("fresco_bridge.sites.core.ABORT_GRACE", 0.5)
    with RunningBridge(config(), tmp_path) as bridge:  # the idle deadline: 60 s
        port = bridge.ports["udp"]
        run_dir = str(bridge.run_dir)
        vanished = GenericClientLink("127.0.0.1", port, 1, data_size=1, transport="udp",
                                     timeout=5.0).connect()
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.settimeout(10.0)
            s.sendto(b"a", ("127.0.0.1", port))  # queued
            wait_for(lambda: refusals(bridge, "udp") == {"busy": 1}, "the handshake queued")
            assert cli_main(["ctl", "abort", "--site", "udp", "--run-dir", run_dir]) == 0
            wait_for(lambda: peer(bridge, "udp") == "", "the aborted session to end")
            assert cli_main(["ctl", "resume", "--site", "udp", "--run-dir", run_dir]) == 0
            capsys.readouterr()
            assert s.recv(1) == b"b"  # answered (within the socket's timeout)
        vanish(vanished)


def test_a_udp_peer_without_a_size_id_is_replaced_by_the_next(tmp_path: Path) -> None:
    with RunningBridge(hostile_config(), tmp_path) as bridge:
        port = bridge.ports["udp"]
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.settimeout(5.0)
            s.sendto(b"a", ("127.0.0.1", port))
            assert s.recv(1) == b"b"  # handshake answered, then nothing
            served(port, "udp")  # holds nothing: the next integrator is served at once
        wait_for(lambda: len(closes(bridge, "udp")) == 1, "the served session to be closed")
        assert bridge.call(lambda: bridge.bridge.sites["udp"].session) == 1


def test_rate_limited_log_says_the_first_then_one_line_per_interval_with_the_count(
    caplog: pytest.LogCaptureFixture
) -> None:
    now = [0.0]
    rl = RateLimitedLog(logging.getLogger("fresco_bridge.test"), interval=10.0,
                        clock=lambda: now[0])
    caplog.set_level(logging.WARNING, logger="fresco_bridge.test")
    assert rl.warning("reset", "peer %s reset", "a")
    assert not any(rl.warning("reset", "peer %s reset", "b") for _ in range(5))
    assert rl.warning("other", "another cause")  # each cause has its own interval
    now[0] = 10.0
    assert rl.warning("reset", "peer %s reset", "c")
    assert [r.getMessage() for r in caplog.records] == [
        "peer a reset", "another cause",
        "peer c reset (5 more not logged in the last 10 s)"]
