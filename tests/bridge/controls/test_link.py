"""Link bookkeeping of the networked adapters: jittered reconnect backoff, heartbeat watch."""

from __future__ import annotations

import asyncio
import random
import socket
import time

import pytest

from fresco_bridge.backoff import Backoff
from fresco_bridge.controls._link import HeartbeatWatch
from fresco_bridge.controls.base import ControllerError
from fresco_bridge.controls.modbus import ModbusController, ModbusControllerConfig
from fresco_bridge.controls.mts import MtsController, MtsControllerConfig


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_backoff_doubles_with_jitter_up_to_the_cap_and_resets() -> None:
    clock = Clock()
    b = Backoff(0.1, 1.0, clock=clock, rng=random.Random(7))
    assert b.wait_time() == 0.0
    delays = []
    for _ in range(8):
        b.failed()
        delays.append(b.wait_time())
    nominal = [0.1, 0.2, 0.4, 0.8, 1.0, 1.0, 1.0, 1.0]
    for got, base in zip(delays, nominal, strict=True):
        assert 0.5 * base <= got <= base
    assert len(set(delays)) == len(delays)  # jittered: no two reconnects in lockstep
    clock.now += 2.0
    assert b.wait_time() == 0.0
    b.succeeded()
    b.failed()
    assert 0.05 <= b.wait_time() <= 0.1
    with pytest.raises(ValueError, match="0 <= min <= max"):
        Backoff(1.0, 0.5)


def test_heartbeat_watch() -> None:
    clock = Clock()
    w = HeartbeatWatch(0.5, "ctl", clock=clock)
    w.observe(7)
    clock.now += 10.0
    w.observe(8)  # a long pause between calls alone is no fault: the value changed
    clock.now += 0.4
    w.observe(8)
    clock.now += 0.2
    with pytest.raises(ControllerError, match=r"ctl: stale heartbeat: the counter stayed at 8 "
                       r"for 0\.6 s \(> heartbeat_timeout 0\.5 s\)"):
        w.observe(8)
    w.observe(65535)
    w.observe(0)  # wrap-around is a change
    w.reset()
    clock.now += 5.0
    w.observe(0)  # after reset the first value starts the clock again
    off = HeartbeatWatch(None, "ctl", clock=clock)
    off.observe(1)
    clock.now += 100.0
    off.observe(1)


@pytest.mark.parametrize("kind", ["modbus", "mts"])
def test_reconnect_attempts_are_spaced_by_the_backoff(kind: str) -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]  # nobody listens once the block ends

    async def scenario() -> list[float]:
        params = {"port": port, "reconnect_min": 0.2, "reconnect_max": 0.4}
        ctl = (ModbusController(ModbusControllerConfig.model_validate(params)) if kind == "modbus"
               else MtsController(MtsControllerConfig.model_validate(params)))
        spent = []
        for _ in range(3):
            t0 = time.monotonic()
            with pytest.raises(ControllerError, match="cannot connect"):
                await ctl.get_daq()
            spent.append(time.monotonic() - t0)
        return spent

    first, second, third = asyncio.run(scenario())
    assert first < 0.15  # the first attempt goes at once
    assert 0.1 <= second <= 0.35 and 0.2 <= third <= 0.55  # 0.2 then 0.4, jittered 0.5-1x
