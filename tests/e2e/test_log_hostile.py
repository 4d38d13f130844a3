"""Hostile operator input against a real ``fresco-bridge serve`` (its stderr is the log) and the
machine's Mosquitto: arbitrary bytes and JSON (deep nesting, huge numbers, control characters)
on the control socket and on the MQTT command topic. The bridge stays up, answers every control
line it can read, and every line its log gains is one line of its own format, without control
characters and never a traceback; a forged line inside an MQTT request id stays inside its line.
"""

from __future__ import annotations

import contextlib
import json
import re
import socket
import subprocess
import sys
import tempfile
import textwrap
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from tests.support.broker import SYSTEM_PORT, broker_up

paho = pytest.importorskip("paho.mqtt.client")

FRESCO_BRIDGE = str(Path(sys.executable).parent / "fresco-bridge")
TOKEN = "hostile-token-0123456789"
FORGED = "x\n2026-12-07 09:00:00,000 INFO fresco_bridge: stopped\u001b[2J"
LINE = re.compile(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} (DEBUG|INFO|WARNING|ERROR|CRITICAL) +"
                  r"[\w.]+: ")
CONTROL = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069]")


@dataclass
class Served:
    proc: subprocess.Popen[str]
    log: Path
    sock: Path
    prefix: str
    mqtt: Any


@pytest.fixture(scope="module")
def served() -> Iterator[Served]:
    if not broker_up():
        pytest.skip("no MQTT broker on 127.0.0.1:1883 and no mosquitto binary to start one")
    with tempfile.TemporaryDirectory(prefix="fblog") as d:
        root = Path(d)
        prefix = f"test-log-{uuid.uuid4().hex[:8]}"
        cfg = root / "lab.toml"
        cfg.write_text(textwrap.dedent(f"""
            [bridge]
            run_dir = "{root / 'runs'}"
            run_name = "hostile"
            control_socket = "{root / 'c.sock'}"
            [telemetry]
            mqtt_host = "127.0.0.1"
            prefix = "{prefix}"
            username = "bridge"
            password = "secret"
            accept_commands = true
            command_token = "{TOKEN}"
            [[sites]]
            name = "spec"
            port = 0
            """), encoding="utf-8")
        log = root / "serve.log"
        with log.open("w") as err:
            proc = subprocess.Popen([FRESCO_BRIDGE, "serve", "--config", str(cfg)],
                                    stdout=subprocess.PIPE, stderr=err, text=True)
        client = paho.Client(paho.CallbackAPIVersion.VERSION2, client_id=f"{prefix}-pub")
        client.username_pw_set("operator", "secret")
        try:
            assert proc.stdout is not None
            ready = proc.stdout.readline()
            assert ready.startswith("fresco-bridge ready:"), log.read_text()
            client.connect("127.0.0.1", SYSTEM_PORT)
            client.loop_start()
            served = Served(proc, log, root / "c.sock", prefix, client)
            _wait_connected(served)
            yield served
        finally:
            client.loop_stop()
            client.disconnect()
            proc.terminate()
            proc.wait(30)


def _ask(path: Path, data: bytes) -> bytes:
    """One request line, the bridge's answer (b"" if it closed without one)."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(10.0)
        s.connect(str(path))
        s.sendall(data)
        answer = b""
        while not answer.endswith(b"\n"):
            chunk = s.recv(65536)
            if not chunk:
                break
            answer += chunk
    return answer


def _status(served: Served) -> dict[str, Any]:
    (site,) = json.loads(_ask(served.sock, b'{"command": "status"}\n'))["sites"]
    return dict(site)


def _wait_connected(served: Served) -> None:
    """The bridge's command subscription is in place: a paused-then-resumed site says so."""
    _sync(served, "connect")


def _sync(served: Served, tag: str) -> None:
    """Every MQTT message published before has been handled: the bridge pauses on one that
    follows them on the same connection (messages of one client arrive in order)."""
    _ask(served.sock, b'{"command": "resume"}\n')  # out of PAUSED or FAULT, if it is there
    rid = f"sync-{tag}-{uuid.uuid4().hex[:6]}"
    body = json.dumps({"command": "pause", "token": TOKEN, "id": rid})
    deadline = time.monotonic() + 30.0
    while True:
        served.mqtt.publish(f"{served.prefix}/spec/cmd", body, qos=1).wait_for_publish(10)
        until = time.monotonic() + 2.0
        while time.monotonic() < until:
            if rid in (_status(served)["reason"] or ""):
                _ask(served.sock, b'{"command": "resume"}\n')
                return
            time.sleep(0.02)
        assert time.monotonic() < deadline, "the bridge did not handle the MQTT commands"


JSON_LEAF = (st.none() | st.booleans() | st.integers(min_value=-(10 ** 4000),
                                                     max_value=10 ** 4000)
             | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=80))
JSON = st.recursive(JSON_LEAF, lambda inner: st.lists(inner, max_size=4)
                    | st.dictionaries(st.text(max_size=12), inner, max_size=4), max_leaves=20)
HOSTILE_TEXT = st.text(st.characters(codec="utf-8") | st.sampled_from(
    "\n\r\x1b\x00\x7f\x85\u2028\u2029\u202e\t"), max_size=64)
COMMAND = st.sampled_from(["status", "pause", "resume", "abort", "reboot"]) | HOSTILE_TEXT
DEEP = st.builds(lambda n, open_: (open_ * n).encode(), st.integers(1, 4000),
                 st.sampled_from(["[", "{", '{"a":', "[{\"command\":"]))


def _control_line(draw_kind: int, raw: bytes, doc: Any, command: str, text: str) -> bytes:
    if draw_kind == 0:
        return raw.replace(b"\n", b" ") + b"\n"
    if draw_kind == 1:
        return json.dumps(doc).encode()[:5000] + b"\n"
    return json.dumps({"command": command, "site": text, "id": text}).encode() + b"\n"


def _mqtt_payload(draw_kind: int, raw: bytes, doc: Any, command: str, text: str) -> bytes:
    if draw_kind == 0:
        return raw
    if draw_kind == 1:
        return json.dumps(doc).encode()[:1024]
    return json.dumps({"command": command, "token": TOKEN, "id": text}).encode()


def test_a_forged_line_in_an_mqtt_request_id_stays_inside_its_line(served: Served) -> None:
    """Runs first (module order): the bridge's first abort line is not rate-limited."""
    body = json.dumps({"command": "abort", "token": TOKEN, "id": FORGED})
    served.mqtt.publish(f"{served.prefix}/spec/cmd", body, qos=1).wait_for_publish(10)
    deadline = time.monotonic() + 20.0
    while _status(served)["state"] != "FAULT":
        assert time.monotonic() < deadline, "the abort was not handled"
        time.sleep(0.02)
    _ask(served.sock, b'{"command": "resume"}\n')
    text = served.log.read_text(encoding="utf-8")  # the first abort: not rate-limited
    assert ("telemetry: operator command abort accepted for site spec (id x\\n2026-12-07 "
            "09:00:00,000 INFO fresco_bridge: stopped\\x1b[2J)\n") in text
    assert not re.search(r"^2026-12-07 09:00:00,000 INFO", text, re.MULTILINE)


@settings(max_examples=300, deadline=None, suppress_health_check=[
    HealthCheck.function_scoped_fixture, HealthCheck.too_slow, HealthCheck.data_too_large])
@given(kind=st.integers(0, 2), raw=st.binary(max_size=4200) | DEEP, doc=JSON, command=COMMAND,
       text=HOSTILE_TEXT, site=st.sampled_from(["spec", "nope", "spéc", "a b", "x" * 80]))
@example(kind=2, raw=b"", doc=None, command="pause", text=FORGED, site="spec")
@example(kind=0, raw=b"[" * 4000, doc=None, command="status", text="", site="spec")
@example(kind=0, raw=b"9" * 4090, doc=None, command="status", text="", site="spec")
def test_hostile_operator_input_leaves_one_clean_line_per_log_line(
        served: Served, kind: int, raw: bytes, doc: Any, command: str, text: str,
        site: str) -> None:
    line = _control_line(kind, raw, doc, command, text)
    if len(line) <= 4096:
        answer = _ask(served.sock, line)
        assert answer.endswith(b"\n") and answer.count(b"\n") == 1, (line[:80], answer)
        assert isinstance(json.loads(answer), dict)
    else:  # answered "longer than 4096 bytes" and closed, or reset while still sending
        with contextlib.suppress(ConnectionError):
            _ask(served.sock, line)
    served.mqtt.publish(f"{served.prefix}/{site}/cmd",
                        _mqtt_payload(kind, raw, doc, command, text), qos=1)
    assert served.proc.poll() is None, served.log.read_text()[-2000:]


def test_zz_the_log_after_the_hostile_input(served: Served) -> None:
    """Runs after the property test (module order): every line the log gained is clean."""
    _sync(served, "end")
    assert served.proc.poll() is None
    text = served.log.read_bytes().decode("utf-8")  # strict: no lone surrogate written
    lines = text.split("\n")
    assert lines[-1] == ""
    bad = [ln for ln in lines[:-1] if not LINE.match(ln) or CONTROL.search(ln)]
    assert bad == [], bad[:5]
    assert "Traceback" not in text and "RecursionError" not in text
    assert not any(ln.startswith("2026-12-07 09:00:00,000") for ln in lines)
