"""``fresco-bridge demo --mqtt``: the demo's committed steps reach an independent subscriber.

Telemetry stays off by default (the embedded demo needs no broker); with ``--mqtt`` every
committed step of the damper site is published, in order, to the real Mosquitto.
"""

from __future__ import annotations

import json
import subprocess
import time
import uuid
from pathlib import Path

import pytest

from fresco_bridge.cli import main as cli_main
from fresco_bridge.demo import demo_config_text
from tests.support.broker import broker_up, needs_mosquitto

pytestmark = needs_mosquitto


def test_demo_telemetry_is_off_unless_asked() -> None:
    assert "[telemetry]" not in demo_config_text()
    text = demo_config_text(mqtt="10.0.0.5:1884", mqtt_prefix="lab", metrics_port=0)
    assert 'mqtt_host = "10.0.0.5"' in text and "mqtt_port = 1884" in text
    assert 'prefix = "lab"' in text and "metrics_port = 0" in text
    with pytest.raises(ValueError, match="port after ':' must be a number"):
        demo_config_text(mqtt="host:abc")


def test_demo_with_mqtt_publishes_every_committed_step_in_order(tmp_path: Path) -> None:
    if not broker_up():
        pytest.skip("no Mosquitto broker on 127.0.0.1:1883 and none could be started")
    prefix = f"fb-demo-{uuid.uuid4().hex[:8]}"
    n_commits = 101  # 1 s at dt 0.01: step 0 (the initial state) + 100 steps
    sub = subprocess.Popen(
        ["stdbuf", "-oL", "mosquitto_sub", "-h", "127.0.0.1", "-p", "1883",
         "-t", f"{prefix}/damper/step", "-C", str(n_commits), "-W", "60"],
        stdout=subprocess.PIPE, text=True)
    try:
        time.sleep(0.3)  # let the subscription register before the run starts
        rc = cli_main(["demo", "--simple", "--duration", "1.0", "--runs", str(tmp_path / "runs"),
                       "--mqtt", "127.0.0.1:1883", "--mqtt-prefix", prefix])
        out, _ = sub.communicate(timeout=60)
    finally:
        if sub.poll() is None:
            sub.kill()
    assert rc == 0
    msgs = [json.loads(line) for line in out.splitlines() if line.strip()]
    assert [m["step"] for m in msgs] == list(range(1, n_commits + 1))
    summary = json.loads(next((tmp_path / "runs").glob("*-demo/summary.json")).read_text())
    assert summary["committed_steps_in_record"] == n_commits
    # what was published is what was recorded: the last damper force matches the CSV
    last_csv = (next((tmp_path / "runs").glob("*-demo/steps.csv")).read_text()
                .strip().splitlines()[-1].split(","))
    header = (next((tmp_path / "runs").glob("*-demo/steps.csv")).read_text()
              .splitlines()[0].split(","))
    assert msgs[-1]["daq"]["force"][0] == pytest.approx(
        float(last_csv[header.index("meas_force")]), rel=1e-12)
