"""MQTT telemetry against a real Mosquitto, checked by an independent ``mosquitto_sub``.

The in-order and command tests use the broker on 127.0.0.1:1883 (started if absent); the
broker-kill test runs its own Mosquitto on a free port so the shared one is never touched.
Assertions are on counts and contents only; deadlines just keep a failure from hanging.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import subprocess
import time
import uuid

import pytest

from fresco_bridge.indicators import MonitorSample
from fresco_bridge.telemetry import (
    MqttTelemetry,
    OperatorCommand,
    SiteEvent,
    SiteStatus,
    StepSample,
)
from tests.support.broker import (
    HOST,
    OwnBroker,
    Subscriber,
    clear_retained,
    needs_mosquitto,
)

TOKEN = "0123456789abcdef-test-token"

pytestmark = needs_mosquitto


def sample(step: int, site: str = "s1") -> StepSample:
    x = 0.01 * step
    monitor = MonitorSample(tracking_error=-0.001 * x, ti=-0.5 * x, nrms=0.02 if step else None,
                            fei_amplitude=None, fei_delay=None)
    return StepSample(site=site, session=1, step=step, time=0.01 * step, trial=(x,), ctrl=(x,),
                      daq_disp=(0.999 * x,), daq_force=(12.5 * x,), state="RUNNING",
                      predicted_force=12.4 * x, monitor=monitor)


async def wait_until(predicate: object, deadline_s: float = 15.0) -> None:
    async with asyncio.timeout(deadline_s):
        while not predicate():  # type: ignore[operator]
            await asyncio.sleep(0.01)


@pytest.mark.parametrize(("compact", "qos"), [(False, 0), (True, 1)])
def test_steps_of_a_short_run_arrive_complete_and_in_order(
    system_broker: int, compact: bool, qos: int
) -> None:
    n = 400
    prefix = f"fbtest-{uuid.uuid4().hex[:10]}"

    async def scenario() -> list[tuple[str, bytes]]:
        sub = await Subscriber.start(system_broker, f"{prefix}/s1/step", count=n)
        try:
            tel = MqttTelemetry(host=HOST, port=system_broker, prefix=prefix, qos=qos,
                                compact=compact)
            runner = asyncio.create_task(tel.run())
            for step in range(n):  # queued before and while connecting: nothing may be lost
                tel.publish_step(sample(step))
                await asyncio.sleep(0)
            tel.stop()
            async with asyncio.timeout(20):
                await runner
            assert tel.stats.published == n
            assert tel.stats.dropped == 0
            return await sub.finish()
        finally:
            sub.kill()

    messages = asyncio.run(scenario())
    assert [topic for topic, _ in messages] == [f"{prefix}/s1/step"] * n
    assert [payload for _, payload in messages] == [sample(k).to_json(compact) for k in range(n)]
    clear_retained(system_broker, f"{prefix}/_bridge/status")


def test_status_is_retained_and_events_and_bridge_state_are_published(system_broker: int) -> None:
    prefix = f"fbtest-{uuid.uuid4().hex[:10]}"

    async def scenario() -> tuple[list[tuple[str, bytes]], list[tuple[str, bytes]]]:
        tel = MqttTelemetry(host=HOST, port=system_broker, prefix=prefix)
        runner = asyncio.create_task(tel.run())
        sub = await Subscriber.start(system_broker, f"{prefix}/#", count=3)
        try:
            tel.publish_status(SiteStatus(site="s1", state="RUNNING", session=1, step=0))
            tel.publish_status(SiteStatus(site="s1", state="HOLD", session=1, step=7,
                                          reason="trial 1.2 mm beyond upper limit 1.0 mm"))
            tel.publish_event(SiteEvent(site="s1", kind="limit", reason="upper limit", step=7,
                                        extra={"signal": "ctrl_disp", "value": 1.2, "limit": 1.0}))
            live = await sub.finish()  # bridge online, one status (coalesced or both), event
        finally:
            sub.kill()
        tel.stop()
        async with asyncio.timeout(20):
            await runner
        late = await Subscriber.start(system_broker, f"{prefix}/+/status", count=2)
        late_retained = await late.finish()
        return live, late_retained

    live, late_retained = asyncio.run(scenario())
    by_topic = {topic: json.loads(payload) for topic, payload in live}
    assert by_topic[f"{prefix}/_bridge/status"]["online"] is True
    assert by_topic[f"{prefix}/s1/event"]["extra"] == {"signal": "ctrl_disp", "value": 1.2,
                                                        "limit": 1.0}
    assert by_topic[f"{prefix}/s1/status"]["state"] == "HOLD"  # RUNNING superseded, unsent
    # a late subscriber gets the retained latest site state, and the bridge marked offline
    retained = {topic: json.loads(payload) for topic, payload in late_retained}
    assert retained[f"{prefix}/s1/status"]["state"] == "HOLD"
    assert retained[f"{prefix}/s1/status"]["reason"] == "trial 1.2 mm beyond upper limit 1.0 mm"
    assert retained[f"{prefix}/_bridge/status"]["online"] is False
    clear_retained(system_broker, f"{prefix}/s1/status", f"{prefix}/_bridge/status")


def test_broker_killed_mid_run_never_slows_steps_and_publishing_resumes(
    own_broker: OwnBroker,
) -> None:
    prefix = "fbkill"
    queue_size = 100

    async def scenario() -> None:
        tel = MqttTelemetry(host=HOST, port=own_broker.port, prefix=prefix,
                            queue_size=queue_size, timeout=2.0, keepalive=2,
                            reconnect_min=0.05, reconnect_max=0.3)
        runner = asyncio.create_task(tel.run())
        submitted = 0

        def step_loop(first: int, count: int) -> int:
            nonlocal submitted
            for k in range(first, first + count):
                tel.publish_step(sample(k))  # a plain call: it cannot wait on the broker
                submitted += 1
            return count

        await wait_until(lambda: tel.stats.connected)
        tel.publish_status(SiteStatus(site="s1", state="RUNNING", session=1, step=0))
        for k in range(50):
            step_loop(k, 1)
            await asyncio.sleep(0)
        await wait_until(lambda: tel.stats.queued == 0)
        published_before = tel.stats.published

        own_broker.kill()
        done = 0
        for k in range(50, 2050):  # the run goes on while the broker is gone
            done += step_loop(k, 1)
            await asyncio.sleep(0)
        assert done == 2000
        failures = tel.stats.failures
        await wait_until(lambda: tel.stats.failures >= failures + 2)  # refused, retried
        assert not tel.stats.connected
        s = tel.stats
        assert s.dropped >= 2000 - queue_size - 10  # queue full: the rest is counted, not kept
        assert s.published + s.dropped + s.queued == submitted + 1  # every message accounted

        await asyncio.to_thread(own_broker.start)  # same port
        await wait_until(lambda: tel.stats.reconnects >= 1 and tel.stats.connected)
        # the retained status was republished to the fresh (non-persistent) broker
        status_sub = await Subscriber.start(own_broker.port, f"{prefix}/s1/status", count=1)
        retained = await status_sub.finish()
        assert json.loads(retained[0][1])["state"] == "RUNNING"
        # and new steps flow again, seen by an independent subscriber
        step_sub = await Subscriber.start(own_broker.port, f"{prefix}/s1/step", count=1)
        try:
            k = 2050
            async with asyncio.timeout(15):
                while step_sub.proc.returncode is None and not step_sub.messages:
                    step_loop(k, 1)
                    k += 1
                    await asyncio.sleep(0.005)
            received = await step_sub.finish()
        finally:
            step_sub.kill()
        assert json.loads(received[0][1])["step"] >= 50  # sent after the broker came back
        assert tel.stats.published > published_before
        tel.stop()
        async with asyncio.timeout(20):
            await runner
        s = tel.stats
        assert s.queued == 0
        # the status is republished once per reconnect (the broker had lost it)
        assert s.published + s.dropped == submitted + 1 + s.reconnects

    asyncio.run(scenario())


def test_commands_over_mqtt_need_the_token_and_bad_ones_are_ignored_and_logged(
    system_broker: int, caplog: pytest.LogCaptureFixture
) -> None:
    prefix = f"fbtest-{uuid.uuid4().hex[:10]}"
    topic = f"{prefix}/s1/cmd"

    def send(payload: str, *, retain: bool = False, target: str = topic) -> None:
        args = ["mosquitto_pub", "-h", HOST, "-p", str(system_broker), "-t", target, "-q", "1",
                "-m", payload]
        subprocess.run([*args, "-r"] if retain else args, check=True, timeout=10)

    def cmd(command: str, token: str = TOKEN, **extra: str) -> str:
        return json.dumps({"command": command, "token": token, **extra})

    # a stale retained abort sitting on the broker before the bridge subscribes
    send(cmd("abort", id="stale"), retain=True)
    malformed = [
        "not json at all",
        "[1, 2, 3]",
        cmd("pause", token="wrong-token-wrong-token"),
        json.dumps({"command": "pause"}),
        cmd("explode"),
        cmd("pause", extra="x"),
        "x" * 2000,
    ]
    received: list[OperatorCommand] = []

    def handler(command: OperatorCommand) -> None:
        if command.site != "s1":
            raise KeyError(f"no site {command.site!r}")
        received.append(command)

    async def scenario() -> None:
        tel = MqttTelemetry(host=HOST, port=system_broker, prefix=prefix, username="fresco",
                            password="lab-password", accept_commands=True,
                            command_handler=handler, command_token=TOKEN)
        runner = asyncio.create_task(tel.run())
        # probe until the subscription is live (the retained abort arrives first)
        async with asyncio.timeout(15):
            while not received:
                await asyncio.to_thread(send, cmd("resume", id="probe"))
                await asyncio.sleep(0.05)
        for payload in malformed:
            await asyncio.to_thread(send, payload)
        await asyncio.to_thread(send, cmd("pause", id="final"), target=f"{prefix}/ghost/cmd")
        await asyncio.to_thread(send, cmd("abort", id="final"))
        await wait_until(lambda: any(c.request_id == "final" for c in received))
        tel.stop()
        async with asyncio.timeout(20):
            await runner
        assert tel.stats.commands_rejected == len(malformed) + 1 + 1  # + retained, + unknown site

    with caplog.at_level(logging.WARNING, logger="fresco_bridge.telemetry"):
        try:
            asyncio.run(scenario())
        finally:
            clear_retained(system_broker, topic, f"{prefix}/_bridge/status")

    assert all(c.site == "s1" for c in received)
    assert {c.request_id for c in received} == {"probe", "final"}  # never "stale"
    assert [c.command for c in received if c.request_id == "final"] == ["abort"]
    text = caplog.text
    for reason in ("retained command", "not JSON", "expected an object", "wrong token",
                   "unknown command 'explode'", "unknown key(s) ['extra']",
                   "exceeds 1024", "refused by the daemon: \"no site 'ghost'\""):
        assert reason in text, reason
    assert TOKEN not in text


def test_cancelling_run_marks_the_bridge_offline(system_broker: int) -> None:
    prefix = f"fbtest-{uuid.uuid4().hex[:10]}"

    async def scenario() -> list[tuple[str, bytes]]:
        tel = MqttTelemetry(host=HOST, port=system_broker, prefix=prefix)
        runner = asyncio.create_task(tel.run())
        await wait_until(lambda: tel.stats.connected)
        runner.cancel()
        with pytest.raises(asyncio.CancelledError):  # outside: a timeout must fail the test
            async with asyncio.timeout(10):
                await runner
        sub = await Subscriber.start(system_broker, f"{prefix}/_bridge/status", count=1)
        return await sub.finish()

    try:
        messages = asyncio.run(scenario())
    finally:
        clear_retained(system_broker, f"{prefix}/_bridge/status")
    assert json.loads(messages[0][1]) == {"v": 1, "online": False}


def test_a_broker_that_never_acknowledges_cannot_hang_the_task() -> None:
    """CONNACK, then silence: no PUBACK, no close. Cancel and stop both end within deadlines.

    aiomqtt's own ``__aexit__`` waits for the disconnect with no timeout; this is the hang that
    once held a CI run for 300 s.
    """

    async def silent_broker(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await reader.readexactly(2)  # CONNECT fixed header (short packet: 1-byte length)
        writer.write(b"\x20\x02\x00\x00")  # CONNACK, session present 0, accepted
        await writer.drain()
        with contextlib.suppress(Exception):
            while await reader.read(4096):
                pass  # swallow PUBLISH/DISCONNECT; never answer, never close

    async def scenario() -> float:
        server = await asyncio.start_server(silent_broker, HOST, 0)
        port = server.sockets[0].getsockname()[1]
        tel = MqttTelemetry(host=HOST, port=port, prefix="fbtest-silent", timeout=0.5,
                            qos=1)
        runner = asyncio.create_task(tel.run())
        await wait_until(lambda: tel.stats.connected or tel.stats.failures > 0)
        start = time.monotonic()
        runner.cancel()
        with pytest.raises(asyncio.CancelledError):
            async with asyncio.timeout(10):
                await runner
        elapsed = time.monotonic() - start
        server.close()
        return elapsed

    assert asyncio.run(scenario()) < 5.0


def test_a_cancel_lost_inside_aiomqtt_still_stops_the_task(
        system_broker: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Python 3.11's wait_for drops a cancel that races the reply; run() must still stop."""
    prefix = f"fbtest-{uuid.uuid4().hex[:10]}"
    original = MqttTelemetry._publish_bridge_online
    entered = asyncio.Event()

    async def publish_that_swallows_cancel(self: MqttTelemetry, client: object, *,
                                           online: bool, timeout: float | None = None) -> None:
        if online:
            entered.set()
            # exactly what 3.11's wait_for does when the PUBACK races the cancel:
            with contextlib.suppress(asyncio.CancelledError):
                await asyncio.sleep(5)
        await original(self, client, online=online, timeout=timeout)  # type: ignore[arg-type]

    monkeypatch.setattr(MqttTelemetry, "_publish_bridge_online", publish_that_swallows_cancel)

    async def scenario() -> None:
        tel = MqttTelemetry(host=HOST, port=system_broker, prefix=prefix)
        runner = asyncio.create_task(tel.run())
        async with asyncio.timeout(10):
            await entered.wait()
        runner.cancel()
        with pytest.raises(asyncio.CancelledError):
            async with asyncio.timeout(10):
                await runner

    try:
        asyncio.run(scenario())
    finally:
        clear_retained(system_broker, f"{prefix}/_bridge/status")
