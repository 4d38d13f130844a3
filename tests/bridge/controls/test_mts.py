"""MTS-like controller adapter against the real simulated-rig line server on loopback."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import math
import socket
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any, TypeVar

import pytest

from fresco_bridge.controls.base import ControllerError
from fresco_bridge.controls.mts import MtsController, MtsControllerConfig
from sim_actuator.config import RigConfig, build_rig, parse_rig_config, preset
from sim_actuator.servers.controller import RigController
from sim_actuator.servers.mts_stub import MtsStubServer

T = TypeVar("T")


def run(factory: Callable[[], Awaitable[T]]) -> T:
    async def bounded() -> T:
        return await asyncio.wait_for(factory(), 30)

    return asyncio.run(bounded())


class Served:
    """A rig controller behind the line server that can be stopped and started again."""

    def __init__(self, controller: RigController) -> None:
        self.controller = controller
        self.server: MtsStubServer | None = None
        self.port = 0

    async def start(self) -> None:
        self.server = MtsStubServer(self.controller, host="127.0.0.1", port=self.port)
        _, self.port = await self.server.start()

    async def stop(self) -> None:
        if self.server is not None:
            await self.server.stop()
            self.server = None


@contextlib.asynccontextmanager
async def serving(config: RigConfig, *, time_scale: float = 0.0, heartbeat_hz: float | None = 50.0,
                  **adapter: Any) -> AsyncIterator[tuple[Served, MtsController]]:
    served = Served(RigController(build_rig(config), time_scale=time_scale))
    await served.start()
    if heartbeat_hz is not None:
        served.controller.start_heartbeat(heartbeat_hz)
    options: dict[str, Any] = {"reconnect_min": 0.01, "reconnect_max": 0.05,
                               "request_timeout": 0.5, **adapter}
    ctl = MtsController(MtsControllerConfig(kind="mts", port=served.port, **options))
    await ctl.connect()
    try:
        yield served, ctl
    finally:
        await ctl.close()
        await served.stop()
        await served.controller.close()


@pytest.mark.parametrize("rig", ["ideal-bilinear", "lab-realistic"])
def test_a_command_sequence_matches_the_rig_exactly(rig: str) -> None:
    config = preset(rig)
    reference = build_rig(config)

    async def scenario() -> None:
        async with serving(config, ramp_time=0.2) as (served, ctl):
            for i, target in enumerate([0.4, 1.5, -1.0, 0.0, 2.5, 2.5], start=1):
                await ctl.set_ctrl((target,))
                daq = await ctl.get_daq()
                expected = reference.execute(target, 0.2)
                assert daq.disp == (expected.displacement,)  # shortest repr round-trips
                assert daq.force == (expected.force,)
                await ctl.commit()
                assert served.controller.sequence == i
            assert await ctl.tangent_stiffness() == (68.0,)
            assert await ctl.initial_stiffness() == (68.0,)

    run(scenario)


def test_server_stopped_mid_move_raises_and_the_move_is_not_retried() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear"), time_scale=1.0, ramp_time=0.3) as (s, ctl):
            move = asyncio.create_task(ctl.set_ctrl((1.0,)))
            while s.controller.move_id == 0:
                await asyncio.sleep(0.005)
            stopping = asyncio.create_task(s.stop())
            with pytest.raises(ControllerError, match=r"link lost.*outcome of the motion "
                               r"command is unknown and it is not retried"):
                await move
            await stopping
            with pytest.raises(ControllerError, match="cannot connect"):
                await ctl.set_ctrl((1.0,))  # the controller is gone: nothing is sent
            await s.start()  # same controller, same port
            await s.controller.wait(5.0)
            daq = await ctl.get_daq()  # a read reconnects
            assert daq.disp == (pytest.approx(1.0, abs=1e-9),)
            assert s.controller.move_id == 1  # the move was never re-sent
            assert s.controller.sequence == 1
            await ctl.set_ctrl((1.5,))  # a new absolute command, on a link re-validated first
            assert s.controller.move_id == 2 and s.controller.target == 1.5

    run(scenario)


def test_get_daq_reconnects_after_the_server_restarts() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear")) as (s, ctl):
            await ctl.set_ctrl((0.3,))
            first = await ctl.get_daq()
            await s.stop()
            with pytest.raises(ControllerError, match="link lost"):
                await ctl.get_daq()
            with pytest.raises(ControllerError, match="cannot connect"):
                await ctl.get_daq()  # still down: refused, with a clear message
            await s.start()
            assert await ctl.get_daq() == first  # ACQUIRE of the same ramp
            await ctl.set_ctrl((0.6,))
            assert s.controller.sequence == 2

    run(scenario)


def test_beyond_stroke_is_a_limit_fault_until_reset() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear")) as (s, ctl):
            with pytest.raises(ControllerError, match="ERR LIMIT STROKE_LIMIT"):
                await ctl.set_ctrl((200.0,))
            with pytest.raises(ControllerError, match="state FAULT, fault STROKE_LIMIT"):
                await ctl.set_ctrl((1.0,))
            assert s.controller.move_id == 0
            await ctl.release(reset_fault=True)
            await ctl.set_ctrl((1.0,))
            assert s.controller.sequence == 1

    run(scenario)


def test_force_trip_names_the_fault() -> None:
    config = parse_rig_config({"specimen": {"kind": "elastic", "params": {"k": 10.0}},
                               "actuator": {"force_capacity": 20.0}})

    async def scenario() -> None:
        async with serving(config, ramp_time=0.5) as (s, ctl):
            with pytest.raises(ControllerError, match=r"ERR FAULT .*FORCE_LIMIT"):
                await ctl.set_ctrl((5.0,))
            assert s.controller.sequence == 0

    run(scenario)


def test_hold_engages_the_interlock_and_release_frees_it() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear")) as (s, ctl):
            await ctl.hold()
            assert s.controller.interlock
            await ctl.release()
            assert not s.controller.interlock
            await ctl.hold()
            # the site forwards a command again (new session): the bridge's own interlock goes
            await ctl.set_ctrl((1.0,))
            assert not s.controller.interlock and s.controller.sequence == 1
            # an interlock the bridge did not engage (operator, another master) stays
            s.controller.set_interlock(True)
            with pytest.raises(ControllerError, match="interlock is engaged and not by this "
                               "bridge"):
                await ctl.set_ctrl((2.0,))
            assert s.controller.interlock and s.controller.sequence == 1

    run(scenario)


def test_wait_timeout_is_an_error_and_the_ramp_is_not_resent() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear"), time_scale=1.0, ramp_time=1.0,
                           wait_timeout=0.05) as (s, ctl):
            with pytest.raises(ControllerError, match="still running after wait_timeout"):
                await ctl.set_ctrl((1.0,))
            with pytest.raises(ControllerError, match="state MOVING"):
                await ctl.set_ctrl((1.0,))
            assert s.controller.move_id == 1
            await ctl.hold()  # stops the ramp where it is
            assert s.controller.sequence == 0

    run(scenario)


def test_stale_heartbeat_is_an_error_and_a_live_one_is_not() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear"), heartbeat_hz=None,
                           heartbeat_timeout=0.05) as (s, ctl):
            await ctl.get_daq()
            await asyncio.sleep(0.1)
            with pytest.raises(ControllerError, match="stale heartbeat"):
                await ctl.get_daq()
            with pytest.raises(ControllerError, match="stale heartbeat"):
                await ctl.set_ctrl((1.0,))
            assert s.controller.move_id == 0  # checked before the motion command
        async with serving(preset("ideal-bilinear"), heartbeat_hz=100.0,
                           heartbeat_timeout=0.05) as (_, ctl):
            await ctl.get_daq()
            await asyncio.sleep(0.1)
            await ctl.get_daq()

    run(scenario)


def test_nan_measurement_is_an_error() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear")) as (s, ctl):
            await ctl.set_ctrl((1.0,))
            s.controller.measurement = dataclasses.replace(s.controller.measurement,
                                                           displacement=math.nan)
            with pytest.raises(ControllerError, match="non-finite measurement"):
                await ctl.get_daq()

    run(scenario)


def test_busy_test_refused_connection_and_bad_input_are_clear_errors() -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]  # closed once the block ends: nobody listens there

    async def scenario() -> None:
        with pytest.raises(ControllerError, match="cannot connect"):
            await MtsController(MtsControllerConfig(kind="mts", port=port)).connect()
        async with serving(preset("ideal-bilinear")) as (s, ctl):
            other = MtsController(MtsControllerConfig(kind="mts", port=s.port))
            with pytest.raises(ControllerError, match="cannot open the test: ERR BUSY"):
                await other.connect()
            with pytest.raises(ControllerError, match="drives 1 actuator, got 2"):
                await ctl.set_ctrl((1.0, 2.0))
            with pytest.raises(ControllerError, match="not finite"):
                await ctl.set_ctrl((math.nan,))

    run(scenario)


def test_config_is_strict() -> None:
    with pytest.raises(ValueError, match="extra"):
        MtsControllerConfig.model_validate({"kind": "mts", "wait": 1.0})
    with pytest.raises(ValueError, match="wait_timeout"):
        MtsControllerConfig.model_validate({"kind": "mts", "wait_timeout": 0.0})


def test_three_channels_one_ramp_each_its_own_rig() -> None:
    from sim_actuator.config import channel_config

    names = ["ideal-bilinear", "servo-hydraulic", "ideal-elastic"]
    references = [build_rig(channel_config(preset(n), c)) for c, n in enumerate(names)]

    async def scenario() -> None:
        rigs = [RigController(build_rig(channel_config(preset(n), c)), time_scale=0.2)
                for c, n in enumerate(names)]
        server = MtsStubServer(rigs, host="127.0.0.1", port=0)
        _, port = await server.start()
        for rig in rigs:
            rig.start_heartbeat(50.0)
        ctl = MtsController(MtsControllerConfig(kind="mts", port=port, ramp_time=0.05,
                                                request_timeout=0.5), 3)
        try:
            for targets in [(0.4, -0.2, 1.0), (1.5, 0.3, -0.5)]:
                await ctl.set_ctrl(targets)
                daq = await ctl.get_daq()
                expected = [r.execute(t, 0.05) for r, t in zip(references, targets, strict=True)]
                assert daq.disp == tuple(m.displacement for m in expected)
                assert daq.force == tuple(m.force for m in expected)
            await ctl.hold()  # HOLD holds every actuator
            assert all(r.interlock for r in rigs)
            await ctl.set_ctrl((0.1, 0.1, 0.1))  # releases the interlock it engaged
            assert [r.target for r in rigs] == [0.1] * 3
            # a target one channel refuses (beyond its stroke): no channel moves
            with pytest.raises(ControllerError, match=r"channel 2.*beyond the actuator stroke"):
                await ctl.set_ctrl((0.2, 500.0, 0.2))
            assert [r.target for r in rigs] == [0.1] * 3 and [r.sequence for r in rigs] == [3] * 3
        finally:
            await ctl.close()
            await server.stop()
            for rig in rigs:
                await rig.close()

    run(scenario)


def test_a_server_with_other_channels_than_the_site_is_refused() -> None:
    async def scenario() -> None:
        rigs = [RigController(build_rig(preset("ideal-elastic"))) for _ in range(2)]
        server = MtsStubServer(rigs, host="127.0.0.1", port=0)
        _, port = await server.start()
        ctl = MtsController(MtsControllerConfig(kind="mts", port=port, heartbeat_timeout=None), 3)
        try:
            with pytest.raises(ControllerError, match="has 2 dofs, expected 3"):
                await ctl.connect()
        finally:
            await ctl.close()
            await server.stop()

    run(scenario)
