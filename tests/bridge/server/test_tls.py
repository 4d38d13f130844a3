"""Mutual TLS as OpenFresco's SSL channel: certificates made at test time with the
``openssl`` CLI; a Python ``ssl`` client and ``openssl s_client`` speak the element protocol.

Refused and logged: a client certificate from another CA, an expired one, one issued through an
intermediate CA (OpenFresco verifies at depth 1), no client certificate, and plain TCP; peers
reset before or during the handshake leave no traceback.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import shutil
import socket
import ssl
import struct
import subprocess
import textwrap
from pathlib import Path

import pytest

from fresco_bridge.config import parse_config
from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.loops import LoopKind
from fresco_bridge.record import read_record
from fresco_bridge.server.tls import MAX_HANDSHAKES
from protocol import Action, ElementClientSession, Signals, SizeID
from tests.support.bridge import RunningBridge
from tests.support.net import BATCH, connect_and_reset, loop_held
from tests.support.sessions import refusals
from tests.support.spied_bridge import wait_for

K = 10.0
pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl CLI")
LOOPS = ["asyncio", pytest.param("uvloop", marks=pytest.mark.skipif(
    importlib.util.find_spec("uvloop") is None, reason="uvloop is not installed"))]
EC = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]


def _ssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=30)


def _ca(d: Path, name: str) -> None:
    _ssl("req", "-x509", *EC, "-keyout", f"{name}.key", "-out", f"{name}.crt", "-days", "2",
         "-subj", f"/CN={name}", "-addext", "basicConstraints=critical,CA:TRUE",
         "-addext", "keyUsage=critical,keyCertSign,cRLSign", cwd=d)


def _issue(d: Path, name: str, ca: str, *, days: str = "2", ext: str = "") -> None:
    _ssl("req", *EC, "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj", f"/CN={name}",
         cwd=d)
    (d / f"{name}.ext").write_text(ext or "basicConstraints=CA:FALSE\n"
                                   "subjectAltName=IP:127.0.0.1\n")
    _ssl("x509", "-req", "-in", f"{name}.csr", "-CA", f"{ca}.crt", "-CAkey", f"{ca}.key",
         "-CAcreateserial", "-out", f"{name}.crt", "-days", days, "-extfile", f"{name}.ext",
         cwd=d)


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """OpenFresco's file names: server.crt/.key, server_ca.crt (= the CA of the clients),
    client.crt/.key, client_ca.crt (= the CA of the server)."""
    d = tmp_path_factory.mktemp("pki")
    _ca(d, "ca")
    _ca(d, "other_ca")
    _issue(d, "server", "ca")
    _issue(d, "client", "ca")
    _issue(d, "stranger", "other_ca")
    _issue(d, "expired", "ca", days="-1")
    _issue(d, "intermediate", "ca", ext="basicConstraints=critical,CA:TRUE\n"
           "keyUsage=critical,keyCertSign,cRLSign\n")
    _issue(d, "grandchild", "intermediate")
    (d / "grandchild-chain.crt").write_text((d / "grandchild.crt").read_text()
                                            + (d / "intermediate.crt").read_text())
    shutil.copy(d / "ca.crt", d / "server_ca.crt")
    shutil.copy(d / "ca.crt", d / "client_ca.crt")
    return d


def _config(pki: Path) -> str:
    return textwrap.dedent(f"""
        [bridge]
        run_name = "tls"
        [[sites]]
        name = "secure"
        port = 0
        tls = true
        cert_file = "{pki / 'server.crt'}"
        key_file = "{pki / 'server.key'}"
        client_ca_file = "{pki / 'server_ca.crt'}"
        [sites.controller]
        model = "elastic"
        params = {{ k = {K} }}
        """)


def _client_context(pki: Path, cert: str | None) -> ssl.SSLContext:
    ctx = ssl.create_default_context(cafile=str(pki / "client_ca.crt"))
    if cert is not None:
        chain = "grandchild-chain" if cert == "grandchild" else cert
        ctx.load_cert_chain(str(pki / f"{chain}.crt"), str(pki / f"{cert}.key"))
    return ctx


def _tls_link(port: int, pki: Path, cert: str | None = "client") -> GenericClientLink:
    link = GenericClientLink("127.0.0.1", port, 1, data_size=1, timeout=5.0)
    raw = socket.create_connection(("127.0.0.1", port), timeout=5.0)
    link.sock = _client_context(pki, cert).wrap_socket(raw, server_hostname="127.0.0.1")
    link._send(link.session.start())
    return link


def _steps(link: GenericClientLink) -> None:
    for i in range(1, 4):
        link.set_trial((0.1 * i,), time=0.1 * i)
        assert link.force()[0] == pytest.approx(K * 0.1 * i)
        link.commit()


def _refused(bridge: BridgeThread) -> int:
    counts = bridge.call(lambda: bridge.bridge.sites["secure"].status()["refused"])
    return int(counts.get("tls", 0))


def test_a_client_with_a_certificate_of_the_ca_is_served(pki: Path, tmp_path: Path) -> None:
    with RunningBridge(_config(pki), tmp_path) as bridge:
        link = _tls_link(bridge.ports["secure"], pki)
        assert link.sock is not None
        assert link.sock.getpeercert()["subject"] == ((("commonName", "server"),),)
        _steps(link)
        link.close()
        assert _refused(bridge) == 0


@pytest.mark.parametrize("loop", LOOPS)
@pytest.mark.parametrize(("cert", "why"), [
    ("stranger", "unable to get local issuer certificate"),
    ("expired", "expired"),
    (None, "no certificate"),
])
def test_refused_client_certificates(pki: Path, tmp_path: Path, cert: str | None, why: str,
                                     loop: LoopKind, caplog: pytest.LogCaptureFixture) -> None:
    with RunningBridge(_config(pki), tmp_path, event_loop=loop) as bridge:
        port = bridge.ports["secure"]
        with pytest.raises((ssl.SSLError, ConnectionError, OSError)):
            link = _tls_link(port, pki, cert)
            _steps(link)  # TLS 1.3: the server's refusal may arrive at the first read
        wait_for(lambda: _refused(bridge) == 1, "the refusal to be counted")
        assert bridge.call(lambda: bridge.bridge.sites["secure"].session) == 0
        link = _tls_link(port, pki)  # the site still serves a good client
        _steps(link)
        link.close()
    logged = " ".join(r.getMessage() for r in caplog.records if "refused client" in
                      r.getMessage())
    assert why in logged.lower(), logged
    events = [r for r in read_record(bridge.run_dir) if r.get("event") == "refused"]
    assert events and events[0]["refusal"] == "tls"


def test_a_certificate_issued_through_an_intermediate_is_refused(
    pki: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with RunningBridge(_config(pki), tmp_path) as bridge:
        with pytest.raises((ssl.SSLError, ConnectionError, OSError)):
            link = _tls_link(bridge.ports["secure"], pki, "grandchild")
            _steps(link)
        wait_for(lambda: _refused(bridge) == 1, "the refusal to be counted")
    assert any("verify depth 1" in r.getMessage() for r in caplog.records)


def test_plain_tcp_to_a_tls_site_is_refused(pki: Path, tmp_path: Path,
                                            caplog: pytest.LogCaptureFixture) -> None:
    with RunningBridge(_config(pki), tmp_path) as bridge:
        with socket.create_connection(("127.0.0.1", bridge.ports["secure"]), timeout=5) as s:
            s.sendall(ElementClientSession(SizeID.for_generic_client(1, 1)).start())
            s.sendall(bytes(64))
            with contextlib.suppress(ConnectionResetError):
                data = s.recv(4096)
                assert data == b"" or data[0] == 0x15  # EOF or a TLS alert, never a reply
        wait_for(lambda: _refused(bridge) == 1, "the refusal to be counted")
        assert bridge.call(lambda: bridge.bridge.sites["secure"].session) == 0
    assert any("not a TLS client" in r.getMessage() for r in caplog.records)


def test_openssl_s_client_speaks_the_element_protocol(pki: Path, tmp_path: Path) -> None:
    def asking() -> tuple[ElementClientSession, bytes]:
        session = ElementClientSession(SizeID.for_generic_client(1, 1))
        return session, session.start() + session.send_trial(
            Signals(disp=(0.5,), vel=(0.0,), accel=(0.0,), time=(0.1,))
        ) + session.send_request(Action.GET_FORCE)

    writer, stdin = asking()
    writer.receive_data(bytes(8 * writer.size_id.data_size))  # stands for the reply
    writer.next_event()
    stdin += writer.send_commit() + writer.send_die()
    session, _ = asking()
    with RunningBridge(_config(pki), tmp_path) as bridge:
        out = subprocess.run(
            ["openssl", "s_client", "-connect", f"127.0.0.1:{bridge.ports['secure']}",
             "-cert", str(pki / "client.crt"), "-key", str(pki / "client.key"),
             "-CAfile", str(pki / "client_ca.crt"), "-verify_return_error", "-quiet",
             "-ign_eof"],
            input=stdin, capture_output=True, timeout=8)
        refused = subprocess.run(
            ["openssl", "s_client", "-connect", f"127.0.0.1:{bridge.ports['secure']}",
             "-cert", str(pki / "stranger.crt"), "-key", str(pki / "stranger.key"),
             "-CAfile", str(pki / "client_ca.crt"), "-quiet", "-ign_eof"],
            input=stdin, capture_output=True, timeout=8)
        wait_for(lambda: _refused(bridge) == 1, "the refusal to be counted")
    session.receive_data(out.stdout)
    reply = session.next_event()
    assert getattr(reply, "values", (None,))[0] == pytest.approx(K * 0.5), (out.stdout,
                                                                          out.stderr[-500:])
    assert refused.stdout == b""


@pytest.mark.parametrize("event_loop", ["asyncio", "uvloop"])
def test_peers_reset_before_or_during_the_handshake_leave_no_traceback(
    pki: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture, event_loop: LoopKind
) -> None:
    if event_loop == "uvloop" and importlib.util.find_spec("uvloop") is None:
        pytest.skip("uvloop is not installed")
    caplog.set_level(logging.INFO)
    text = _config(pki)
    with BridgeThread(parse_config(text, "<test config>"), text, run_dir=tmp_path,
                      event_loop=event_loop) as bridge:
        port = bridge.ports["secure"]
        caplog.clear()
        with loop_held(bridge):  # reset before the bridge accepts them
            for _ in range(BATCH):
                connect_and_reset(port)
        for _ in range(BATCH):  # reset during the handshake: half a ClientHello, then RST
            with socket.create_connection(("127.0.0.1", port), timeout=5.0) as s:
                s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                s.sendall(bytes.fromhex("16030100c8010000c40303"))
        wait_for(lambda: sum(refusals(bridge, "secure").values()) == 2 * BATCH,
                 "every reset connection to be counted")
        link = _tls_link(port, pki)
        _steps(link)
        link.close()
    noisy = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert not [r for r in noisy if r.exc_info or r.levelno >= logging.ERROR], \
        [r.getMessage() for r in noisy]
    assert 1 <= len(noisy) <= 4, [r.getMessage() for r in noisy]

def _refused_at_once(port: int, pki: Path, cert: str | None) -> None:
    """The server's refusal reaches the client within 1 s (a handshake it let stall does not)."""
    raw = socket.create_connection(("127.0.0.1", port), timeout=1.0)
    try:
        with _client_context(pki, cert).wrap_socket(raw, server_hostname="127.0.0.1") as s:
            data = s.recv(1)  # TLS 1.3: the client's handshake ends before the server verifies
    except TimeoutError:
        pytest.fail(f"a client with {cert or 'no'} certificate was not refused within 1 s")
    except (ssl.SSLError, ConnectionError):
        return
    finally:
        raw.close()
    assert data == b"", data


@pytest.mark.parametrize("loop", LOOPS)
def test_refusals_are_immediate_and_say_why_on_both_loops(
        pki: Path, tmp_path: Path, loop: LoopKind, caplog: pytest.LogCaptureFixture) -> None:
    """uvloop reads before the handshake task runs: a ClientHello read then was once lost and
    the handshake stalled to its timeout, for bad and good clients alike (a race: many tries)."""
    tries = 12
    with RunningBridge(_config(pki), tmp_path, event_loop=loop) as bridge:
        port = bridge.ports["secure"]
        for i in range(tries):
            _refused_at_once(port, pki, "stranger" if i % 2 else None)
        wait_for(lambda: _refused(bridge) == tries, "the refusals to be counted")
        for _ in range(3):
            link = _tls_link(port, pki)
            assert link.sock is not None
            link.sock.settimeout(1.0)
            _steps(link)
            link.close()
    logged = " ".join(r.getMessage() for r in caplog.records)
    assert "client presented no certificate" in logged  # the first refusal (then rate-limited)
    assert "not completed within" not in logged


def test_handshakes_in_flight_are_bounded_the_next_is_refused_busy_before_tls(
        pki: Path, tmp_path: Path) -> None:
    """Each handshake holds an SSL object and a read buffer: a burst of connections must not
    hold a thousand (the site serves one client; the rest were refused busy after theirs)."""
    with RunningBridge(_config(pki), tmp_path) as bridge:
        port = bridge.ports["secure"]
        silent = [socket.create_connection(("127.0.0.1", port), timeout=5.0)
                  for _ in range(MAX_HANDSHAKES)]  # no ClientHello: handshakes in flight
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=5.0) as extra:
                wait_for(lambda: bridge.call(lambda: bridge.bridge.sites["secure"].status()
                                             ["refused"].get("busy", 0)) == 1,
                         "the connection past the bound to be refused busy")
                assert _closed_by_bridge(extra)
        finally:
            for s in silent:
                s.close()
        wait_for(lambda: _refused(bridge) == MAX_HANDSHAKES, "the silent ones to end")
        link = _tls_link(port, pki)  # the bound is free again
        _steps(link)
        link.close()


def _closed_by_bridge(s: socket.socket) -> bool:
    try:
        return s.recv(1) == b""
    except ConnectionResetError:
        return True
