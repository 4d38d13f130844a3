"""QoS-0 telemetry goes out in batches: valid MQTT packets, in order, far fewer writes."""

from __future__ import annotations

import asyncio
import json
import shutil
import subprocess
import time
import uuid

import paho.mqtt.client as paho
import pytest

from fresco_bridge.telemetry import MqttTelemetry, StepSample
from fresco_bridge.telemetry.mqtt_batch import Qos0Batch
from tests.support.broker import broker_up


def _decode(stream: bytes) -> list[tuple[int, str, bytes]]:
    """An independent MQTT 3.1.1 PUBLISH decoder (spec §2.2.3 and §3.3)."""
    out, i = [], 0
    while i < len(stream):
        header = stream[i]
        i += 1
        remaining, shift = 0, 0
        while True:
            byte = stream[i]
            i += 1
            remaining |= (byte & 0x7F) << shift
            shift += 7
            if not byte & 0x80:
                break
        body = stream[i : i + remaining]
        assert len(body) == remaining, "truncated packet"
        i += remaining
        tlen = int.from_bytes(body[:2], "big")
        out.append((header, body[2 : 2 + tlen].decode(), body[2 + tlen :]))
    return out


def test_batch_encodes_back_to_back_publish_packets() -> None:
    batch = Qos0Batch()
    cases = [("a/b/step", b""), ("fresco/s1/step", b"x" * 100), ("t", b"y" * 127),
             ("t2", b"z" * 20_000), ("fresco/é/event", bytes(range(256)) * 9000)]
    for topic, payload in cases:
        batch.add(topic, payload)
    data, n = batch.take()
    assert n == len(cases) and batch.count == 0 and not batch.buf
    assert _decode(bytes(data)) == [(0x30, t, p) for t, p in cases]


@pytest.mark.skipif(shutil.which("mosquitto_sub") is None, reason="mosquitto-clients missing")
def test_a_burst_of_steps_arrives_in_order_in_few_writes(monkeypatch: pytest.MonkeyPatch) -> None:
    if not broker_up():
        pytest.skip("no Mosquitto broker on 127.0.0.1:1883 and none could be started")
    n = 600
    prefix = f"fb-batch-{uuid.uuid4().hex[:8]}"
    queued_publishes = 0
    original = paho.Client._packet_queue

    def counting(self: paho.Client, command: int, *args: object, **kw: object) -> object:
        nonlocal queued_publishes
        queued_publishes += (command & 0xF0) == paho.PUBLISH
        return original(self, command, *args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(paho.Client, "_packet_queue", counting)
    sub = subprocess.Popen(
        ["mosquitto_sub", "-h", "127.0.0.1", "-t", f"{prefix}/s1/step", "-C", str(n), "-W", "30"],
        stdout=subprocess.PIPE, text=True,
    )
    time.sleep(0.3)

    async def scenario() -> None:
        tel = MqttTelemetry(host="127.0.0.1", port=1883, prefix=prefix)
        task = asyncio.create_task(tel.run())
        async with asyncio.timeout(10):
            while not tel.stats.connected:
                await asyncio.sleep(0.01)
        for k in range(n):
            tel.publish_step(StepSample("s1", 1, k, 0.01 * k, (0.1,), (0.1,), (0.1,), (1.0,),
                                        "RUNNING"))
            if k % 50 == 0:
                await asyncio.sleep(0)
        tel.stop()
        async with asyncio.timeout(20):
            await task
        s = tel.stats
        assert (s.published, s.dropped, s.queued) == (n + 0, 0, 0)

    asyncio.run(scenario())
    out, _ = sub.communicate(timeout=30)
    steps = [json.loads(line)["step"] for line in out.splitlines() if line.strip()]
    assert steps == list(range(n))
    # bridge online/offline are two publishes of their own; the steps went out in batches
    assert queued_publishes <= 2 + n // 16
