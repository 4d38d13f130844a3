"""A real bridge run whose MQTT broker is killed mid-run: the run completes, every step is
recorded, drops are counted, and publishing resumes when the broker is back.

The broker is a private Mosquitto on a free port (the shared one is never touched). No speed is
asserted (that is the benchmark's job); the one bound below is a stall detector: had a step
waited on the dead broker it would have taken seconds (connect/publish deadlines), not ~1 ms.
"""

from __future__ import annotations

import json
import subprocess
import time
import uuid
from pathlib import Path

import pytest

from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record.export import committed_steps
from tests.support.bridge import RunningBridge
from tests.support.broker import HOST, OwnBroker, needs_mosquitto

pytestmark = needs_mosquitto

K = 10.0
QUEUE = 500  # above what the drain holds back at full speed
OUTAGE_END = 1500
STALL_S = 1.0


def _steps(link: GenericClientLink, first: int, last: int) -> float:
    """Drive steps first..last; returns the longest single step (s)."""
    longest = 0.0
    for i in range(first, last + 1):
        t0 = time.perf_counter()
        link.set_trial((0.001 * i,), time=0.01 * i)
        assert link.force()[0] == pytest.approx(K * 0.001 * i)
        link.commit()
        longest = max(longest, time.perf_counter() - t0)
    return longest


def _wait(predicate: object, what: str, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():  # type: ignore[operator]
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)


def test_broker_killed_mid_run_the_run_completes_and_publishing_resumes(
    tmp_path: Path, own_broker: OwnBroker
) -> None:
    prefix = f"fbloss-{uuid.uuid4().hex[:8]}"
    toml = f"""
[telemetry]
mqtt_host = "{HOST}"
mqtt_port = {own_broker.port}
prefix = "{prefix}"
queue_size = {QUEUE}
[[sites]]
name = "spring"
port = 0
[sites.controller]
model = "elastic"
params = {{ k = {K} }}
"""
    with RunningBridge(toml, tmp_path / "runs") as b:
        tel = b.bridge.telemetry
        assert tel is not None
        _wait(lambda: b.call(lambda: tel.stats.connected), "telemetry to connect")
        with GenericClientLink(HOST, b.ports["spring"], 1, data_size=1) as link:
            _steps(link, 1, 100)
            _wait(lambda: b.call(lambda: tel.stats.queued) == 0, "the first steps to go out")
            before = b.call(lambda: tel.stats)
            assert before.published >= 100 and before.dropped == 0

            own_broker.kill()
            longest_while_down = _steps(link, 101, OUTAGE_END)
            _wait(lambda: not b.call(lambda: tel.stats.connected), "the loss to be noticed")
            down = b.call(lambda: tel.stats)
            assert down.dropped >= OUTAGE_END - 100 - QUEUE - 5  # bounded queue: rest counted

            own_broker.start()  # same port, fresh broker
            _wait(lambda: b.call(lambda: tel.stats.reconnects) >= 1
                  and b.call(lambda: tel.stats.connected), "telemetry to reconnect", 40.0)
            # what the bounded queue kept during the outage (the oldest) goes out first
            _wait(lambda: b.call(lambda: tel.stats.queued) == 0, "the kept backlog to go out")
            backlog = b.call(lambda: tel.stats)
            assert backlog.published >= down.published + QUEUE - 5
            sub = subprocess.Popen(
                ["stdbuf", "-oL", "mosquitto_sub", "-h", HOST, "-p", str(own_broker.port),
                 "-t", f"{prefix}/spring/step", "-C", "200", "-W", "30"],
                stdout=subprocess.PIPE, text=True)
            try:
                time.sleep(0.3)  # let the subscription register
                step = OUTAGE_END + 1
                while sub.poll() is None and step < 3000:
                    _steps(link, step, step)
                    step += 1
                    time.sleep(0.005)
                out, _ = sub.communicate(timeout=20)
            finally:
                if sub.poll() is None:
                    sub.kill()
            last_step = step - 1
        after = b.call(lambda: tel.stats)
        run_dir = b.run_dir

    assert longest_while_down < STALL_S, f"a step stalled {longest_while_down:.2f} s"
    received = [json.loads(line)["step"] for line in out.strip().splitlines()]
    assert len(received) == 200
    assert received == sorted(set(received))  # in order, no duplicates
    assert received[-1] > OUTAGE_END  # live steps flow again (after any tail of the backlog)
    assert after.published > before.published
    # the run record is complete whatever happened to the broker
    steps = [s.step for s in committed_steps(run_dir) if s.site == "spring"]
    assert steps == list(range(1, last_step + 1))
