"""The bridge publishes every committed step over MQTT (real Mosquitto), in order."""

from __future__ import annotations

import json
import shutil
import subprocess
import time
import uuid
from pathlib import Path

import pytest

from fresco_bridge.integrator.link import GenericClientLink
from tests.support.bridge import RunningBridge
from tests.support.broker import broker_up

N = 150


@pytest.mark.skipif(shutil.which("mosquitto_sub") is None, reason="mosquitto-clients missing")
def test_committed_steps_reach_an_independent_subscriber_in_order(tmp_path: Path) -> None:
    if not broker_up():
        pytest.skip("no Mosquitto broker on 127.0.0.1:1883 and none could be started")
    prefix = f"fb-test-{uuid.uuid4().hex[:8]}"
    sub = subprocess.Popen(
        ["stdbuf", "-oL", "mosquitto_sub", "-h", "127.0.0.1", "-p", "1883",
         "-t", f"{prefix}/spring/step", "-C", str(N), "-W", "30"],
        stdout=subprocess.PIPE, text=True,
    )
    time.sleep(0.3)  # let the subscription register before the run starts
    toml = f"""
[telemetry]
mqtt_host = "127.0.0.1"
prefix = "{prefix}"
qos = 1
[[sites]]
name = "spring"
port = 0
[sites.controller]
model = "elastic"
params = {{ k = 10.0 }}
"""
    with RunningBridge(toml, tmp_path) as b:
        deadline = time.monotonic() + 5
        while not b.call(lambda: b.bridge.telemetry.stats.connected):
            assert time.monotonic() < deadline, "bridge telemetry never connected"
            time.sleep(0.02)
        with GenericClientLink("127.0.0.1", b.ports["spring"], 1, data_size=1) as link:
            for i in range(1, N + 1):
                link.set_trial((0.01 * i,), time=0.01 * i)
                link.force()
                link.commit()
            link.force()
        out, _ = sub.communicate(timeout=30)
        stats = b.call(lambda: b.bridge.telemetry.stats)
    msgs = [json.loads(line) for line in out.splitlines() if line.strip()]
    assert len(msgs) == N
    assert [m["step"] for m in msgs] == list(range(1, N + 1))
    last = msgs[-1]
    assert last["ctrl"] == pytest.approx([0.01 * N])
    assert last["daq"]["force"] == pytest.approx([10.0 * 0.01 * N])
    assert last["monitor"]["tracking_error"] == pytest.approx(0.0, abs=1e-12)
    assert last["state"] == "RUNNING"
    assert stats.dropped == 0
