"""A site with displacement correction publishes each step's corrections and residual over MQTT
(real Mosquitto on 127.0.0.1:1883), the same as its record's correction lines."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import time
import uuid
from pathlib import Path

import pytest

from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import read_record
from fresco_bridge.record.export import correction_lines
from tests.bridge.sites.test_site_correction import lab
from tests.support.bridge import RunningBridge
from tests.support.broker import broker_up

TARGETS = [6.0 * math.sin(2 * math.pi * i / 20) for i in range(1, 41)]
CORRECTION = """tolerance = 0.01
max_correction = 3.0
max_iterations = 2
gain = 0.5
policy = "accept-with-event"
measured = "external"
"""


@pytest.mark.skipif(shutil.which("mosquitto_sub") is None, reason="mosquitto-clients missing")
def test_each_step_message_carries_its_correction(tmp_path: Path) -> None:
    if not broker_up():
        pytest.skip("no Mosquitto broker on 127.0.0.1:1883 and none could be started")
    prefix = f"fb-test-{uuid.uuid4().hex[:8]}"
    sub = subprocess.Popen(
        ["stdbuf", "-oL", "mosquitto_sub", "-h", "127.0.0.1", "-p", "1883",
         "-t", f"{prefix}/frame/step", "-C", str(len(TARGETS)), "-W", "30"],
        stdout=subprocess.PIPE, text=True,
    )
    try:
        time.sleep(0.3)  # let the subscription register before the run starts
        config = (f'[telemetry]\nmqtt_host = "127.0.0.1"\nprefix = "{prefix}"\nqos = 1\n'
                  + lab(tmp_path, CORRECTION))
        with RunningBridge(config, tmp_path / "runs") as b:
            deadline = time.monotonic() + 5
            while not b.call(lambda: b.bridge.telemetry.stats.connected):
                assert time.monotonic() < deadline, "bridge telemetry never connected"
                time.sleep(0.02)
            with GenericClientLink("127.0.0.1", b.ports["frame"], 1, timeout=30.0) as link:
                for i, t in enumerate(TARGETS, 1):
                    link.set_trial((t,), time=0.01 * i)
                    link.force()
                    link.commit()
            out, _ = sub.communicate(timeout=30)
            run_dir = b.run_dir
    finally:
        if sub.poll() is None:
            sub.kill()
            sub.wait(timeout=5)
    msgs = [json.loads(line) for line in out.splitlines() if line.strip()]
    assert [m["step"] for m in msgs] == list(range(1, len(TARGETS) + 1))
    lines = {c.step: c for c in correction_lines(read_record(run_dir))}
    for m in msgs:
        c = lines[m["step"]]
        assert m["correction"] == {"corrections": c.corrections, "residual": c.residual,
                                   "outcome": c.outcome}
    outcomes = {m["correction"]["outcome"] for m in msgs}
    assert outcomes == {"converged", "not-converged"}  # both kinds went out
