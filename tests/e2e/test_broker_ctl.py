"""Operator commands over MQTT reach the same handler as the control socket (real Mosquitto)."""

from __future__ import annotations

import json
import shutil
import subprocess
import textwrap
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import pytest

from fresco_bridge import ctl
from fresco_bridge.record import read_record
from fresco_bridge.sites import SiteState
from fresco_bridge.telemetry import OperatorCommand
from tests.support.bridge import RunningBridge
from tests.support.broker import broker_up

TOKEN = "operator-token-0123456789"


def _wait_for(predicate: Callable[[], bool], what: str, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)


def _publish(prefix: str, site: str, body: str) -> None:
    subprocess.run(["mosquitto_pub", "-h", "127.0.0.1", "-p", "1883", "-u", "operator",
                    "-P", "secret", "-q", "1", "-t", f"{prefix}/{site}/cmd", "-m", body],
                   check=True, timeout=10)


@pytest.mark.skipif(shutil.which("mosquitto_pub") is None, reason="mosquitto-clients missing")
def test_mqtt_commands_drive_the_same_handler_as_the_control_socket(tmp_path: Path) -> None:
    if not broker_up():
        pytest.skip("no MQTT broker on 127.0.0.1:1883 and no mosquitto binary to start one")
    prefix = f"test-ctl-{uuid.uuid4().hex[:8]}"
    toml = textwrap.dedent(f"""
        [bridge]
        run_name = "mqtt-ctl"
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
        """)
    with RunningBridge(toml, tmp_path) as bridge:
        tel = bridge.bridge.telemetry
        assert tel is not None and tel.accept_commands
        _wait_for(lambda: tel.stats.connected, "the bridge to connect to the broker")
        events = subprocess.Popen(  # an independent subscriber sees every transition event
            ["stdbuf", "-oL", "mosquitto_sub", "-h", "127.0.0.1", "-p", "1883",
             "-t", f"{prefix}/spec/event", "-W", "30"], stdout=subprocess.PIPE, text=True)
        time.sleep(0.5)  # both subscriptions are in place

        def state() -> SiteState:
            return bridge.call(lambda: bridge.bridge.sites["spec"].state)

        _publish(prefix, "spec", f'{{"command": "pause", "token": "{TOKEN[:-1]}"}}')
        _publish(prefix, "spec", f'{{"command": "pause", "token": "{TOKEN}", "id": "op-7"}}')
        _wait_for(lambda: state() is SiteState.PAUSED, "PAUSED via MQTT")
        assert tel.stats.commands_rejected >= 1  # the wrong token was ignored
        # the same handler answers on the control socket: it sees the MQTT pause
        sock = ctl.find_socket(None, bridge.run_dir, tmp_path)
        (status,) = ctl.request(sock, "status", "spec")["sites"]
        assert status["state"] == "PAUSED" and status["reason"] == "operator pause (mqtt id op-7)"

        _publish(prefix, "spec", f'{{"command": "abort", "token": "{TOKEN}"}}')
        _wait_for(lambda: state() is SiteState.FAULT, "FAULT via MQTT")
        rejected = tel.stats.commands_rejected
        _publish(prefix, "spec", f'{{"command": "pause", "token": "{TOKEN}"}}')  # refused: FAULT
        _wait_for(lambda: tel.stats.commands_rejected == rejected + 1, "the refusal to count")
        assert ctl.request(sock, "resume", "spec")["ok"]  # the operator resumes locally
        assert state() is SiteState.IDLE
        seen: list[dict[str, object]] = []
        assert events.stdout is not None
        while not any(e["kind"] == "resume" for e in seen):
            line = events.stdout.readline()
            assert line, f"the subscriber ended before the resume event: {seen}"
            seen.append(json.loads(line))
        events.terminate()
        events.wait(10)
        status = subprocess.run(["mosquitto_sub", "-h", "127.0.0.1", "-p", "1883", "-C", "1",
                                 "-W", "5", "-t", f"{prefix}/spec/status"],
                                capture_output=True, text=True, timeout=10)
        assert json.loads(status.stdout)["state"] == "IDLE"  # retained, latest
    transitions = [(e["kind"], e["extra"]["from"], e["extra"]["to"]) for e in seen  # type: ignore[index]
                   if e["kind"] in ("pause", "abort", "resume")]
    assert transitions == [("pause", "IDLE", "PAUSED"), ("abort", "PAUSED", "FAULT"),
                           ("resume", "FAULT", "IDLE")]
    reasons = [(r["event"], r["reason"]) for r in read_record(bridge.run_dir)
               if r.get("event") in ("pause", "abort", "resume")]
    assert reasons == [("pause", "operator pause (mqtt id op-7)"),
                       ("abort", "operator abort (mqtt)"),
                       ("resume", "operator resume (control socket)")]


def test_mqtt_refusal_propagates_from_the_desk() -> None:
    """``handle_mqtt`` raises on a refused transition, so MqttTelemetry logs and counts it."""
    desk = ctl.OperatorDesk({})
    with pytest.raises(ctl.ControlError, match="no site 'x'"):
        desk.handle_mqtt(OperatorCommand(site="x", command="pause"))
