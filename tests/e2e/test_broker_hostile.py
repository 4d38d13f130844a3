"""Hostile command payloads against a real Mosquitto: the MQTT session survives them all.

A lone surrogate in a token (``{"token":"\\ud800"}``) once raised out of the listener and ended
the session: each such message cost a reconnect, and telemetry and the remote abort with it.
The lab's own broker configuration (``docker/mosquitto-local.conf``) drops oversize publishes
before any subscriber reads them.
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import uuid
from collections.abc import Awaitable, Callable
from pathlib import Path

from fresco_bridge.telemetry import MqttTelemetry, OperatorCommand
from tests.support.broker import clear_retained, needs_mosquitto
from tests.support.net import HOST, free_ports, wait_port

pytestmark = needs_mosquitto
TOKEN = "0123456789abcdef-test-token"
DOCKER = Path(__file__).resolve().parents[2] / "docker"
SURROGATE = json.dumps({"command": "pause", "token": "\ud800"})  # ASCII: a \ud800 escape
HOSTILE_LINES = [SURROGATE] * 30 + [json.dumps(body) for body in (
    {"command": "pause", "token": TOKEN, "id": "\udfff"},
    {"command": "\ud800", "token": TOKEN},
    {"\ud800": 1},
)]
HOSTILE_FILES = [b"\xff\xfe{", b'{"command":"pause","token":"\xed\xa0\x80"}', b"{" * (2 << 20)]


def _publish(port: int, topic: str, *, lines: list[str] | None = None,
             data: bytes | None = None) -> None:
    """``mosquitto_pub``: each line a message (``-l``), or ``data`` as one message."""
    args = ["mosquitto_pub", "-h", HOST, "-p", str(port), "-t", topic, "-q", "1"]
    args += ["-l"] if lines is not None else ["-s"]
    stdin = "\n".join(lines).encode() + b"\n" if lines is not None else data
    subprocess.run(args, input=stdin, check=True, timeout=20)


def _command(command: str, request_id: str) -> str:
    return json.dumps({"command": command, "token": TOKEN, "id": request_id})


async def _listening(port: int, prefix: str,
                     hostile: Callable[[str], Awaitable[None]]) -> MqttTelemetry:
    """A commanded telemetry that got ``hostile`` then a valid abort; stopped again."""
    topic = f"{prefix}/s1/cmd"
    received: list[OperatorCommand] = []
    tel = MqttTelemetry(host=HOST, port=port, prefix=prefix, username="fresco",
                        password="lab-password", accept_commands=True,
                        command_handler=received.append, command_token=TOKEN)
    runner = asyncio.create_task(tel.run())
    try:
        async with asyncio.timeout(15):  # until the subscription is live
            while not received:
                await asyncio.to_thread(_publish, port, topic, lines=[_command("resume", "probe")])
                await asyncio.sleep(0.05)
        await hostile(topic)
        await asyncio.to_thread(_publish, port, topic, lines=[_command("abort", "final")])
        async with asyncio.timeout(15):
            while not any(c.request_id == "final" for c in received):
                await asyncio.sleep(0.01)
        assert tel.stats.connected
    finally:
        tel.stop()
        async with asyncio.timeout(20):
            await runner
    return tel


def test_surrogates_bad_utf8_and_oversize_payloads_never_end_the_session(
        system_broker: int) -> None:
    prefix = f"fbtest-{uuid.uuid4().hex[:10]}"

    async def hostile(topic: str) -> None:
        await asyncio.to_thread(_publish, system_broker, topic, lines=HOSTILE_LINES)
        for data in HOSTILE_FILES:
            await asyncio.to_thread(_publish, system_broker, topic, data=data)

    try:
        tel = asyncio.run(_listening(system_broker, prefix, hostile))
    finally:
        clear_retained(system_broker, f"{prefix}/_bridge/status")
    stats = tel.stats
    assert (stats.reconnects, stats.failures) == (0, 0)  # one session throughout
    assert stats.commands_rejected == len(HOSTILE_LINES) + len(HOSTILE_FILES)
    assert stats.commands_accepted >= 2  # a probe, then the abort after all of it


def test_the_lab_broker_drops_oversize_publishes(tmp_path: Path) -> None:
    port = free_ports(1)[0]
    broker = subprocess.Popen(["mosquitto", "-c", str(DOCKER / "mosquitto-local.conf"),
                               "-p", str(port)], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    try:
        wait_port(port, is_open=True)

        async def oversize(topic: str) -> None:
            await asyncio.to_thread(_publish, port, topic, data=b"{" * (2 << 20))

        tel = asyncio.run(_listening(port, "fbtest", oversize))
    finally:
        broker.kill()
        broker.wait(timeout=10)
    assert tel.stats.commands_rejected == 0  # the 2 MiB message never reached the bridge
