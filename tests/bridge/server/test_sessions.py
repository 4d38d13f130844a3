"""Sessions cannot lock, exhaust or flood a site.

A real bridge in a thread, real TCP/UDP sockets on loopback: a UDP client that vanishes
without DIE, a re-handshake from the same peer, an idle or half-open TCP connection, an idle
client the operator aborts, a client that never reads its replies, and connection churn from a
refused address. Each time another (good) client is then served correctly.
"""

from __future__ import annotations

import contextlib
import gc
import socket
import struct
import textwrap
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from fresco_bridge.cli import main as cli_main
from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink, LinkError
from fresco_bridge.record import read_record
from fresco_bridge.server.connection import WRITE_HIGH_WATER
from fresco_bridge.server.tcp import KEEPALIVE_COUNT, KEEPALIVE_IDLE, KEEPALIVE_INTERVAL
from fresco_bridge.sites import SiteState
from fresco_bridge.sites.access import Allowlist, RejectionLog
from protocol import Action, ElementClientSession, SizeID
from tests.support.bridge import RunningBridge
from tests.support.sessions import K, closes, config, peer, refusals, served, steps, vanish
from tests.support.spied_bridge import refused, wait_for


def udp_handshake_answered(port: int, timeout: float) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.settimeout(timeout)
        s.connect(("127.0.0.1", port))
        s.send(b"a")
        try:
            return s.recv(16) == b"b"
        except TimeoutError:
            return False


# -- UDP -----------------------------------------------------------------------------------------
def test_a_vanished_udp_client_frees_its_site_after_the_idle_deadline(tmp_path: Path) -> None:
    with RunningBridge(config(idle=1.0), tmp_path) as bridge:
        port = bridge.ports["udp"]
        link = GenericClientLink("127.0.0.1", port, 1, data_size=1, transport="udp",
                                 timeout=5.0).connect()
        steps(link)
        vanish(link)  # no DIE, no EOF: UDP cannot tell
        assert not udp_handshake_answered(port, 0.2)  # still its session: refused
        wait_for(lambda: peer(bridge, "udp") == "", "the silent session to end", timeout=10)
        served(port, "udp")  # a new integrator from a new address is served
        assert "no message from the client" in closes(bridge, "udp")[0]
        assert "session_idle_timeout" in closes(bridge, "udp")[0]


def test_a_new_handshake_from_the_same_udp_peer_starts_a_new_session(tmp_path: Path) -> None:
    with RunningBridge(config(), tmp_path) as bridge:
        port = bridge.ports["udp"]
        link = GenericClientLink("127.0.0.1", port, 1, data_size=1, transport="udp",
                                 timeout=5.0).connect()
        steps(link)
        assert link.sock is not None
        link.sock.send(b"a")  # the integrator restarts on the same address, no DIE
        assert link.sock.recv(16) == b"b"
        link.session = ElementClientSession(SizeID.for_generic_client(1, 1))
        link._send(link.session.start())
        steps(link, start=4)
        link.close()
        assert bridge.call(lambda: bridge.bridge.sites["udp"].session) == 2
        assert "new UDP session (handshake) without DIE" in closes(bridge, "udp")[0]


# -- TCP -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("sends", ["nothing", "size ID"])
def test_an_idle_or_half_open_tcp_connection_is_ended_by_the_idle_deadline(
    tmp_path: Path, sends: str
) -> None:
    with RunningBridge(config(idle=1.0), tmp_path) as bridge:
        port = bridge.ports["tcp"]
        with socket.create_connection(("127.0.0.1", port), timeout=10.0) as idle:
            if sends == "size ID":  # then silence
                idle.sendall(ElementClientSession(SizeID.for_generic_client(1, 1)).start())
                wait_for(lambda: peer(bridge, "tcp") != "", "the idle session to open")
                assert refused(port)  # it holds the site meanwhile
            else:  # a connection that has not introduced itself holds no site
                served(port)
            assert idle.recv(1) == b""  # ended by the bridge (within the deadline's timeout)
        wait_for(lambda: peer(bridge, "tcp") == "", "the site to be free")
        served(port)
        if sends == "nothing":  # never introduced itself: a refused connection, not a session
            wait_for(lambda: refusals(bridge, "tcp") == {"handshake": 1}, "the refusal")
            assert len(closes(bridge, "tcp")) == 2  # the good clients' sessions only
        else:
            assert "no message from the client" in closes(bridge, "tcp")[0]


def test_an_operator_pause_does_not_end_a_waiting_session(tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]
                                                           ) -> None:
    with RunningBridge(config(idle=0.5), tmp_path) as bridge:
        with GenericClientLink("127.0.0.1", bridge.ports["tcp"], 1, data_size=1,
                               timeout=10.0) as link:
            steps(link, 1)
            assert cli_main(["ctl", "pause", "--site", "tcp", "--run-dir",
                             str(bridge.run_dir)]) == 0
            link.set_trial((0.2,), time=0.2)
            answer: list[float] = []
            waiter = threading.Thread(target=lambda: answer.append(link.force()[0]))
            waiter.start()
            time.sleep(1.5)  # three idle deadlines: the request waits for the operator
            assert peer(bridge, "tcp") != "" and answer == []
            assert cli_main(["ctl", "resume", "--site", "tcp", "--run-dir",
                             str(bridge.run_dir)]) == 0
            waiter.join(10)
            assert answer == [pytest.approx(K * 0.2)]
            link.commit()
        capsys.readouterr()


def test_tcp_keepalive_is_on_for_every_session(tmp_path: Path) -> None:
    from fresco_bridge.server.tcp import TcpConnection

    with RunningBridge(config(), tmp_path) as bridge, \
            GenericClientLink("127.0.0.1", bridge.ports["tcp"], 1, data_size=1) as link:
        steps(link, 1)

        def options() -> list[tuple[int, ...]]:
            out = []
            for conn in gc.get_objects():
                if isinstance(conn, TcpConnection) and conn.pump is not None \
                        and not conn.pump.closed:
                    sock = conn.transport.get_extra_info("socket")  # type: ignore[union-attr]
                    out.append((sock.getsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE),
                                sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPIDLE),
                                sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPINTVL),
                                sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPCNT)))
            return out

        assert bridge.call(options) == [(1, KEEPALIVE_IDLE, KEEPALIVE_INTERVAL, KEEPALIVE_COUNT)]


@pytest.mark.parametrize("transport", ["tcp", "udp"])
def test_ctl_abort_ends_an_idle_session(tmp_path: Path, transport: str,
                                        capsys: pytest.CaptureFixture[str],
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("fresco_bridge.sites.core.ABORT_GRACE", 1.0)
    with RunningBridge(config(), tmp_path) as bridge:
        port = bridge.ports[transport]
        link = GenericClientLink("127.0.0.1", port, 1, data_size=1, transport=transport,
                                 timeout=5.0).connect()
        steps(link, 1)  # then it sits there, silent (a hung integrator)
        assert cli_main(["ctl", "abort", "--site", transport, "--run-dir",
                         str(bridge.run_dir)]) == 0
        wait_for(lambda: peer(bridge, transport) == "", "the aborted idle session to end",
                 timeout=15)
        assert cli_main(["ctl", "resume", "--site", transport, "--run-dir",
                         str(bridge.run_dir)]) == 0
        capsys.readouterr()
        vanish(link)
        served(port, transport)
        assert "aborted by the operator" in closes(bridge, transport)[0]


# -- backpressure --------------------------------------------------------------------------------
def _write_buffers(bridge: BridgeThread, site: str) -> list[int]:
    from fresco_bridge.server.tcp import TcpConnection

    def sizes() -> list[int]:
        return [c.transport.get_write_buffer_size() for c in gc.get_objects()
                if isinstance(c, TcpConnection) and c.site.name == site
                and c.transport is not None and not c.transport.is_closing()]

    return bridge.call(sizes)


def test_a_client_that_never_reads_is_paused_then_ended_and_others_are_served(
    tmp_path: Path
) -> None:
    data_size = 4096  # each getForce request and reply: 32 KiB
    with RunningBridge(config(idle=2.0), tmp_path) as bridge:
        port = bridge.ports["tcp"]
        hog = socket.create_connection(("127.0.0.1", port), timeout=10.0)
        hog.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        session = ElementClientSession(SizeID.for_generic_client(1, data_size))
        hog.sendall(session.start())
        request = session.send_request(Action.GET_FORCE)
        sent = 0
        peak = 0
        hog.settimeout(0.5)
        deadline = time.monotonic() + 20.0
        try:
            while sent < (256 << 20) and time.monotonic() < deadline:
                hog.sendall(request)  # never reads a reply
                sent += len(request)
                if sent % (1 << 20) < len(request):
                    peak = max([peak, *_write_buffers(bridge, "tcp")])
        except (TimeoutError, ConnectionError):
            pass  # its own socket is full: the bridge stopped reading it
        peak = max([peak, *_write_buffers(bridge, "tcp")])
        assert peak <= WRITE_HIGH_WATER + 8 * data_size + 8, f"{peak} bytes queued"
        served(bridge.ports["other"])  # another site is served meanwhile
        wait_for(lambda: peer(bridge, "tcp") == "", "the non-reading session to end",
                 timeout=15)
        hog.close()
        assert "has not read its replies" in closes(bridge, "tcp")[0]
        served(port)


# -- refused connections -------------------------------------------------------------------------
def test_refused_connections_are_counted_and_logged_within_a_rate_limit(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    guarded = textwrap.dedent("""
        [[sites]]
        name = "guarded"
        port = 0
        allowed_clients = ["127.0.0.9"]
        [sites.controller]
        model = "elastic"
        params = { k = 10.0 }
        """)
    with RunningBridge(config(extra_site=guarded), tmp_path) as bridge:
        size_before = (bridge.run_dir / "record.jsonl").stat().st_size
        for _ in range(300):
            with socket.create_connection(("127.0.0.1", bridge.ports["guarded"]), timeout=5):
                pass
        wait_for(lambda: bridge.call(
            lambda: bridge.bridge.sites["guarded"].status()["refused"]) == {"address": 300},
            "every refusal to be counted")
        refusals = [r for r in read_record(bridge.run_dir) if r.get("event") == "refused"]
        grown = (bridge.run_dir / "record.jsonl").stat().st_size - size_before
        served(bridge.ports["tcp"])
    logged = [r for r in caplog.records if "refused client" in r.getMessage()]
    assert 1 <= len(refusals) <= 3 and 1 <= len(logged) <= 3
    assert grown < 2000, f"the record grew {grown} bytes for 300 refused connections"


@pytest.mark.parametrize("transport", ["tcp", "udp"])
def test_churn_of_malformed_sessions_from_an_allowed_address_is_counted_not_logged_each(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, transport: str
) -> None:
    """An allowed client that connects and sends a size ID that does not parse, 300 times:
    each is a refused connection (counted), not a session (no record lines, no log lines
    each; before: ~425 record bytes and two log lines per connection)."""
    bad_size_id = struct.pack("<11i", *([-5] * 11))
    with RunningBridge(config(), tmp_path) as bridge:
        port = bridge.ports[transport]
        size_before = (bridge.run_dir / "record.jsonl").stat().st_size
        caplog.clear()
        for _ in range(300):
            if transport == "tcp":
                with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
                    s.sendall(bad_size_id)
                    with contextlib.suppress(OSError):
                        s.recv(16)  # the bridge closes it
            else:  # every datagram from a new address (port), as a restarted integrator's
                with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                    s.sendto(bad_size_id, ("127.0.0.1", port))
                wait_for(lambda: peer(bridge, transport) == "", "the bad session to end")
        wait_for(lambda: sum(refusals(bridge, transport).values()) == 300,
                 "every bad connection to be counted")
        assert refusals(bridge, transport) == {"handshake": 300}
        grown = (bridge.run_dir / "record.jsonl").stat().st_size - size_before
        served(port, transport)
    logged = [r for r in caplog.records if r.name.startswith("fresco_bridge")
              and "size ID" in r.getMessage()]
    assert 1 <= len(logged) <= 3, [r.getMessage() for r in logged]
    assert "ended before a valid size ID" in logged[0].getMessage()
    assert grown < 2000, f"the record grew {grown} bytes for 300 malformed connections"


def test_rejection_log_reports_the_first_then_one_summary_per_interval() -> None:
    now = [0.0]
    log = RejectionLog(interval=10.0, clock=lambda: now[0])
    reports: list[Any] = []
    for i in range(100):
        now[0] = i * 0.5  # 50 s of churn, two connections a second
        reports.append(log.refused("address", f"refused {i}"))
    shown = [r for r in reports if r is not None]
    assert len(shown) == 5 and log.total == 100 and log.counts == {"address": 100}
    assert shown[0].suppressed == 0 and sum(r.suppressed for r in shown) == 76  # 19 still pending
    assert "not logged" in shown[1].message()


def test_an_open_allowlist_is_announced_loudly_at_start(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    text = config().replace('allowed_clients = ["127.0.0.1"]',
                            "allowed_clients = []\nallow_any_client = true")
    with RunningBridge(text, tmp_path) as bridge:
        served(bridge.ports["tcp"])
    loud = [r for r in caplog.records if "ADMITS CLIENTS FROM ANY ADDRESS" in r.getMessage()]
    assert sorted(r.getMessage().split()[1] for r in loud) == ["other", "tcp", "udp"]
    assert all(r.levelname == "WARNING" for r in loud)


def test_allowlist_matches_addresses_and_networks() -> None:
    allow = Allowlist(["127.0.0.1", "192.168.10.0/24"])
    assert allow.admits("127.0.0.1") and allow.admits("192.168.10.77")
    assert not allow.admits("192.168.11.1") and not allow.admits("127.0.0.2")
    assert Allowlist([]).admits("8.8.8.8") and str(Allowlist([])) == "any address"


def test_link_error_type_is_what_the_tests_expect() -> None:
    assert issubclass(LinkError, ConnectionError) and SiteState.IDLE
