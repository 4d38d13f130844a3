"""A burst of QoS-0 steps reaches a subscriber whole and in order, and is counted exactly."""

from __future__ import annotations

import asyncio
import json
import shutil
import subprocess
import time
import uuid

import pytest

from fresco_bridge.telemetry import MqttTelemetry, StepSample
from tests.support.broker import broker_up


@pytest.mark.skipif(shutil.which("mosquitto_sub") is None, reason="mosquitto-clients missing")
def test_a_burst_of_steps_arrives_in_order() -> None:
    if not broker_up():
        pytest.skip("no Mosquitto broker on 127.0.0.1:1883 and none could be started")
    n = 600
    prefix = f"fb-burst-{uuid.uuid4().hex[:8]}"
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
        assert (s.published, s.dropped, s.queued) == (n, 0, 0)

    asyncio.run(scenario())
    out, _ = sub.communicate(timeout=30)
    steps = [json.loads(line)["step"] for line in out.splitlines() if line.strip()]
    assert steps == list(range(n))
