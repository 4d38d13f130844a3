"""Telemetry to a TLS-only Mosquitto: the bridge verifies the broker's certificate.

A throw-away CA and broker certificate (IP SAN 127.0.0.1) are made with openssl; a private
Mosquitto serves TLS only. With the CA the bridge connects and an independent mosquitto_sub (same
CA) receives every step; without it the connection is refused by certificate verification.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from fresco_bridge.config import ConfigError, parse_config
from fresco_bridge.integrator.link import GenericClientLink
from tests.support.bridge import RunningBridge
from tests.support.net import HOST, wait_port

pytestmark = pytest.mark.skipif(
    not all(shutil.which(t) for t in ("mosquitto", "mosquitto_sub", "openssl", "stdbuf")),
    reason="needs mosquitto, mosquitto_sub, openssl and stdbuf")


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=60)


@pytest.fixture
def tls_broker(tmp_path: Path) -> Iterator[tuple[int, Path]]:
    d = tmp_path / "pki"
    d.mkdir()
    _openssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "2", "-subj",
             "/CN=fresco-test-ca", "-keyout", "ca.key", "-out", "ca.pem", cwd=d)
    _openssl("req", "-newkey", "rsa:2048", "-nodes", "-subj", "/CN=127.0.0.1",
             "-keyout", "server.key", "-out", "server.csr", cwd=d)
    (d / "san.ext").write_text("subjectAltName=IP:127.0.0.1,DNS:localhost\n")
    _openssl("x509", "-req", "-in", "server.csr", "-CA", "ca.pem", "-CAkey", "ca.key",
             "-CAcreateserial", "-days", "2", "-extfile", "san.ext", "-out", "server.pem", cwd=d)
    with socket.socket() as s:
        s.bind((HOST, 0))
        port = int(s.getsockname()[1])
    conf = tmp_path / "mosquitto.conf"
    lines = [f"listener {port} {HOST}", f"cafile {d / 'ca.pem'}", f"certfile {d / 'server.pem'}",
             f"keyfile {d / 'server.key'}", "allow_anonymous true", "persistence false",
             f"log_dest file {tmp_path / 'mosquitto.log'}"]
    if os.geteuid() == 0:
        lines.append("user root")
    conf.write_text("\n".join(lines) + "\n")
    proc = subprocess.Popen(["mosquitto", "-c", str(conf)])
    try:
        wait_port(port, is_open=True)
        yield port, d / "ca.pem"
    finally:
        proc.kill()
        proc.wait(timeout=10)


def _toml(port: int, prefix: str, tls: str) -> str:
    return f"""
[telemetry]
mqtt_host = "{HOST}"
mqtt_port = {port}
prefix = "{prefix}"
{tls}
[[sites]]
name = "spring"
port = 0
[sites.controller]
model = "elastic"
params = {{ k = 10.0 }}
"""


def test_steps_reach_a_subscriber_through_a_tls_only_broker(
        tmp_path: Path, tls_broker: tuple[int, Path]) -> None:
    port, ca = tls_broker
    prefix = f"fbtls-{uuid.uuid4().hex[:8]}"
    n = 50
    sub = subprocess.Popen(
        ["stdbuf", "-oL", "mosquitto_sub", "-h", HOST, "-p", str(port), "--cafile", str(ca),
         "-t", f"{prefix}/spring/step", "-C", str(n), "-W", "30"],
        stdout=subprocess.PIPE, text=True)
    try:
        time.sleep(0.3)
        toml = _toml(port, prefix, f'tls = true\ntls_ca_file = "{ca}"')
        with RunningBridge(toml, tmp_path / "runs") as b:
            tel = b.bridge.telemetry
            assert tel is not None
            deadline = time.monotonic() + 10
            while not b.call(lambda: tel.stats.connected):
                assert time.monotonic() < deadline, "no TLS connection to the broker"
                time.sleep(0.02)
            with GenericClientLink(HOST, b.ports["spring"], 1, data_size=1) as link:
                for i in range(1, n + 1):
                    link.set_trial((0.01 * i,), time=0.01 * i)
                    link.force()
                    link.commit()
        out, _ = sub.communicate(timeout=30)
    finally:
        if sub.poll() is None:
            sub.kill()
    assert [json.loads(line)["step"] for line in out.splitlines()] == list(range(1, n + 1))


def test_an_unverifiable_broker_certificate_is_refused(
        tmp_path: Path, tls_broker: tuple[int, Path], caplog: pytest.LogCaptureFixture) -> None:
    port, _ = tls_broker  # the bridge is not given the test CA: system CAs only
    with RunningBridge(_toml(port, "fbtls-refused", "tls = true"), tmp_path / "runs") as b:
        tel = b.bridge.telemetry
        assert tel is not None
        deadline = time.monotonic() + 10
        while b.call(lambda: tel.stats.failures) < 1:
            assert time.monotonic() < deadline, "the bad certificate was not noticed"
            time.sleep(0.02)
        assert not b.call(lambda: tel.stats.connected)
    assert "CERTIFICATE_VERIFY_FAILED" in caplog.text or "certificate verify" in caplog.text


def test_tls_keys_are_checked_at_config_time(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="tls_ca_file set but tls = false"):
        parse_config(_toml(1883, "p", f'tls_ca_file = "{tmp_path}"'), "lab.toml")
    with pytest.raises(ConfigError, match="tls_ca_file: no such file"):
        parse_config(_toml(1883, "p", f'tls = true\ntls_ca_file = "{tmp_path / "no.pem"}"'),
                     "lab.toml")
    with pytest.raises(ConfigError, match="go together"):
        parse_config(_toml(1883, "p", f'tls = true\ntls_cert_file = "{tmp_path}"'), "lab.toml")
