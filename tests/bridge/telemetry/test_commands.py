"""Queueing and command validation of MqttTelemetry, without a broker (pure logic)."""

from __future__ import annotations

import json
import logging
import ssl

import pytest

from fresco_bridge.telemetry import (
    MqttTelemetry,
    NullTelemetry,
    OperatorCommand,
    SiteEvent,
    SiteStatus,
    StepSample,
    TelemetryConfigError,
)

TOKEN = "a-long-enough-command-token"


def step(k: int) -> StepSample:
    return StepSample("s1", 1, k, 0.01 * k, (0.0,), (0.0,), (0.0,), (0.0,), "RUNNING")


def commanded(received: list[OperatorCommand], **overrides: object) -> MqttTelemetry:
    options: dict[str, object] = {
        "host": "127.0.0.1", "port": 1883, "prefix": "lab/fresco", "username": "bridge",
        "password": "pw", "accept_commands": True, "command_handler": received.append,
        "command_token": TOKEN}
    options.update(overrides)
    return MqttTelemetry(**options)  # type: ignore[arg-type]


def test_publish_step_without_a_broker_keeps_the_oldest_and_counts_drops() -> None:
    tel = MqttTelemetry(host="127.0.0.1", port=1883, queue_size=10)
    for k in range(25):
        tel.publish_step(step(k))
    for _ in range(3):
        tel.publish_status(SiteStatus(site="s1", state="RUNNING"))  # coalesced per site
    tel.publish_event(SiteEvent(site="s1", kind="hold", reason="test"))
    stats = tel.stats
    assert (stats.dropped, stats.queued, stats.published, stats.connected) == (15, 12, 0, False)


def test_null_telemetry_accepts_everything_and_does_nothing() -> None:
    tel = NullTelemetry()
    tel.publish_step(step(0))
    tel.publish_status(SiteStatus(site="s1", state="IDLE"))
    tel.publish_event(SiteEvent(site="s1", kind="hold", reason="x"))
    tel.stop()
    assert tel.stats.published == tel.stats.dropped == 0


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        ({"username": None, "password": None}, "broker credentials are required"),
        ({"password": None}, "broker credentials are required"),
        ({"command_handler": None}, "command_handler is required"),
        ({"command_token": None}, "command_token of at least 16"),
        ({"command_token": "short"}, "command_token of at least 16"),
    ],
)
def test_commands_are_refused_without_credentials_handler_and_token(
    overrides: dict[str, object], match: str
) -> None:
    with pytest.raises(TelemetryConfigError, match=match):
        commanded([], **overrides)


def test_a_tls_context_counts_as_credentials() -> None:
    tel = commanded([], username=None, password=None, tls=ssl.create_default_context())
    assert tel.accept_commands


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"port": 0}, "port 0"),
        ({"prefix": "a/#"}, "prefix"),
        ({"prefix": "a//b"}, "prefix"),
        ({"qos": 3}, "qos 3"),
        ({"queue_size": 0}, "queue_size"),
        ({"reconnect_min": 2.0, "reconnect_max": 1.0}, "reconnect"),
    ],
)
def test_bad_telemetry_configuration_is_refused(options: dict[str, object], match: str) -> None:
    with pytest.raises(TelemetryConfigError, match=match):
        MqttTelemetry(**{"host": "127.0.0.1", "port": 1883, **options})  # type: ignore[arg-type]


def payload(**body: object) -> bytes:
    return json.dumps(body).encode()


@pytest.mark.parametrize(
    ("topic", "message", "retain", "reason"),
    [
        ("lab/fresco/s1/cmd", b"\xff\xfe", False, "not UTF-8"),
        ("lab/fresco/s1/cmd", b"{oops", False, "not JSON"),
        ("lab/fresco/s1/cmd", b'"pause"', False, "expected an object"),
        ("lab/fresco/s1/cmd", payload(command="pause"), False, "wrong token"),
        ("lab/fresco/s1/cmd", payload(command="pause", token=TOKEN[:-1]), False, "wrong token"),
        ("lab/fresco/s1/cmd", payload(command="pause", token=7), False, "wrong token"),
        ("lab/fresco/s1/cmd", payload(command="go", token=TOKEN), False, "unknown command 'go'"),
        ("lab/fresco/s1/cmd", payload(command="pause", token=TOKEN, x=1), False, "unknown key"),
        ("lab/fresco/s1/cmd", payload(command="pause", token=TOKEN, id=5), False, "id must be"),
        # JSON's \ud800 is a lone surrogate: no UTF-8 bytes to compare, log or record
        ("lab/fresco/s1/cmd", b'{"command":"pause","token":"\\ud800"}', False, "wrong token"),
        ("lab/fresco/s1/cmd", payload(command="pause", token=TOKEN, id="\ud800"), False,
         "id must be"),
        ("lab/fresco/s1/cmd", payload(command="\udfff", token=TOKEN), False, "unknown command"),
        ("lab/fresco/s1/cmd", payload(command="abort", token=TOKEN), True, "retained command"),
        ("lab/fresco/s1/cmd", b" " * 1025, False, "exceeds 1024"),
        ("lab/fresco/a/b/cmd", payload(command="pause", token=TOKEN), False, "valid site name"),
        ("other/s1/cmd", payload(command="pause", token=TOKEN), False, "valid site name"),
        ("lab/fresco/s1/cmd", "text", False, "expected bytes"),
    ],
)
def test_malformed_or_unauthorised_commands_are_ignored_and_logged(
    caplog: pytest.LogCaptureFixture, topic: str, message: object, retain: bool, reason: str
) -> None:
    received: list[OperatorCommand] = []
    tel = commanded(received)
    with caplog.at_level(logging.WARNING, logger="fresco_bridge.telemetry"):
        tel.handle_command_message(topic, message, retain=retain)
    assert received == []
    assert tel.stats.commands_rejected == 1
    assert reason in caplog.text
    assert TOKEN not in caplog.text


def test_a_valid_command_reaches_the_handler() -> None:
    received: list[OperatorCommand] = []
    tel = commanded(received)
    tel.handle_command_message("lab/fresco/s1/cmd",
                               payload(command="pause", token=TOKEN, id="op-42"))
    assert received == [OperatorCommand(site="s1", command="pause", request_id="op-42")]
    assert tel.stats.commands_accepted == 1


def test_commands_are_ignored_when_not_enabled(caplog: pytest.LogCaptureFixture) -> None:
    received: list[OperatorCommand] = []
    tel = MqttTelemetry(host="127.0.0.1", port=1883, command_handler=received.append,
                        command_token=TOKEN)
    with caplog.at_level(logging.WARNING, logger="fresco_bridge.telemetry"):
        tel.handle_command_message("fresco/s1/cmd", payload(command="abort", token=TOKEN))
    assert received == []
    assert "disabled" in caplog.text


def test_a_command_flood_is_logged_at_a_bounded_rate(caplog: pytest.LogCaptureFixture) -> None:
    tel = commanded([])
    with caplog.at_level(logging.WARNING, logger="fresco_bridge.telemetry"):
        for _ in range(500):
            tel.handle_command_message("lab/fresco/s1/cmd", b"garbage")
    assert tel.stats.commands_rejected == 500
    assert len([r for r in caplog.records if "ignored" in r.getMessage()]) == 10


def test_a_payload_the_checks_did_not_foresee_is_counted_not_raised(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """An exception out of the checks would end the MQTT session (telemetry, remote abort)."""
    def unforeseen(*_: object, **__: object) -> object:
        raise RuntimeError("a check's own bug")

    monkeypatch.setattr("fresco_bridge.telemetry.mqtt.decode", unforeseen)
    tel = commanded([])
    with caplog.at_level(logging.WARNING, logger="fresco_bridge.telemetry"):
        tel.handle_command_message("lab/fresco/s1/cmd", payload(command="pause", token=TOKEN))
    assert tel.stats.commands_rejected == 1
    assert "unreadable payload (RuntimeError)" in caplog.text
