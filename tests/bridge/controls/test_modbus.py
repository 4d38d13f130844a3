"""Modbus controller adapter against the real simulated-rig Modbus server on loopback."""

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
from fresco_bridge.controls.modbus import ModbusController, ModbusControllerConfig
from sim_actuator.config import RigConfig, build_rig, parse_rig_config, preset
from sim_actuator.servers.controller import RigController
from sim_actuator.servers.modbus import ModbusRigServer, decode_float32, encode_float32

T = TypeVar("T")


def run(factory: Callable[[], Awaitable[T]]) -> T:
    async def bounded() -> T:
        return await asyncio.wait_for(factory(), 30)

    return asyncio.run(bounded())


def f32(value: float) -> float:
    return decode_float32(encode_float32(value))


class Served:
    """A rig controller behind a Modbus server that can be stopped and started again."""

    def __init__(self, controller: RigController) -> None:
        self.controller = controller
        self.server: ModbusRigServer | None = None
        self.port = 0

    async def start(self) -> None:
        self.server = ModbusRigServer(self.controller, host="127.0.0.1", port=self.port)
        _, self.port = await self.server.start()

    async def stop(self) -> None:
        if self.server is not None:
            await self.server.stop()
            self.server = None


@contextlib.asynccontextmanager
async def serving(config: RigConfig, *, time_scale: float = 0.0, heartbeat_hz: float | None = 50.0,
                  **adapter: Any) -> AsyncIterator[tuple[Served, ModbusController]]:
    served = Served(RigController(build_rig(config), time_scale=time_scale))
    await served.start()
    if heartbeat_hz is not None:
        served.controller.start_heartbeat(heartbeat_hz)
    options: dict[str, Any] = {"reconnect_min": 0.01, "reconnect_max": 0.05,
                               "request_timeout": 0.5, **adapter}
    ctl = ModbusController(ModbusControllerConfig(kind="modbus", port=served.port, **options))
    await ctl.connect()
    try:
        yield served, ctl
    finally:
        await ctl.close()
        await served.stop()
        await served.controller.close()


def test_a_command_sequence_matches_the_rig_to_float32() -> None:
    config = preset("ideal-bilinear")
    reference = build_rig(config)

    async def scenario() -> None:
        async with serving(config, ramp_time=0.2) as (served, ctl):
            for i, target in enumerate([0.4, 1.5, -1.0, 0.0, 2.5, 2.5], start=1):
                await ctl.set_ctrl((target,))
                daq = await ctl.get_daq()
                expected = reference.execute(f32(target), f32(0.2))
                assert daq.disp == (f32(expected.displacement),)
                assert daq.force == (f32(expected.force),)
                await ctl.commit()
                assert served.controller.sequence == i
            assert await ctl.tangent_stiffness() == (68.0,)
            assert await ctl.initial_stiffness() == (68.0,)

    run(scenario)


def test_slow_moves_are_polled_until_done() -> None:
    async def scenario() -> None:
        # time_scale 1: a 0.1 s ramp + 0.05 s settle takes 0.15 s of wall time
        async with serving(preset("ideal-elastic"), time_scale=1.0, ramp_time=0.1) as (s, ctl):
            await ctl.set_ctrl((0.5,))
            daq = await ctl.get_daq()
            assert daq.disp == (pytest.approx(0.5, abs=1e-6),)
            assert daq.force == (pytest.approx(34.0, abs=1e-4),)
            assert s.controller.sequence == 1

    run(scenario)


def test_server_stopped_mid_move_raises_and_the_move_is_not_retried() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear"), time_scale=1.0, ramp_time=0.3) as (s, ctl):
            move = asyncio.create_task(ctl.set_ctrl((1.0,)))
            while s.controller.move_id == 0:
                await asyncio.sleep(0.005)
            await s.stop()
            with pytest.raises(ControllerError, match=r"link lost.*it is not retried"):
                await move
            with pytest.raises(ControllerError, match="cannot connect"):
                await ctl.set_ctrl((1.0,))  # the controller is gone: nothing is sent
            await s.start()  # same controller, same port
            await s.controller.wait(5.0)
            daq = await ctl.get_daq()  # a read reconnects
            assert daq.disp == (pytest.approx(1.0, abs=1e-6),)
            assert s.controller.move_id == 1  # the move was never re-sent
            assert await ctl.sequence() == 1
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
            assert await ctl.get_daq() == first
            await ctl.set_ctrl((0.6,))  # motion works again once a read re-validated the link
            assert s.controller.sequence == 2

    run(scenario)


def test_beyond_stroke_names_the_exception_and_the_fault() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear")) as (s, ctl):
            with pytest.raises(ControllerError, match=r"exception 03 ILLEGAL_DATA_VALUE.*"
                               r"FAULT, fault 1 STROKE_LIMIT"):
                await ctl.set_ctrl((200.0,))
            assert s.controller.sequence == 0
            with pytest.raises(ControllerError, match="state FAULT, fault 1 STROKE_LIMIT"):
                await ctl.set_ctrl((1.0,))
            await ctl.release(reset_fault=True)
            await ctl.set_ctrl((1.0,))
            assert s.controller.sequence == 1

    run(scenario)


def test_force_trip_is_a_fault_with_its_code() -> None:
    config = parse_rig_config({"specimen": {"kind": "elastic", "params": {"k": 10.0}},
                               "actuator": {"force_capacity": 20.0}})

    async def scenario() -> None:
        async with serving(config, ramp_time=0.5) as (s, ctl):
            with pytest.raises(ControllerError, match="tripped: state FAULT, fault 2 FORCE_LIMIT"):
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
            s.controller.measurement = dataclasses.replace(s.controller.measurement,
                                                           force=math.nan)
            with pytest.raises(ControllerError, match="non-finite measurement"):
                await ctl.get_daq()

    run(scenario)


def test_bad_input_and_refused_connection_are_clear_errors() -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]  # closed once the block ends: nobody listens there

    async def scenario() -> None:
        ctl = ModbusController(ModbusControllerConfig(kind="modbus", port=port))
        with pytest.raises(ControllerError, match="cannot connect"):
            await ctl.connect()
        async with serving(preset("ideal-bilinear")) as (_, ctl):
            with pytest.raises(ControllerError, match="drives 1 actuator, got 2"):
                await ctl.set_ctrl((1.0, 2.0))
            with pytest.raises(ControllerError, match="not finite"):
                await ctl.set_ctrl((math.inf,))
            with pytest.raises(ControllerError, match="reply has 5 registers, expected 12"):
                ctl._status([0] * 5)

    run(scenario)


def test_config_is_strict() -> None:
    with pytest.raises(ValueError, match="extra"):
        ModbusControllerConfig.model_validate({"kind": "modbus", "prot": 5020})
    with pytest.raises(ValueError, match="port"):
        ModbusControllerConfig.model_validate({"kind": "modbus", "port": 0})


def test_status_parse_follows_the_register_map() -> None:
    from sim_actuator.wire.modbus_map import Reg, Status, encode_float32

    words = [0] * (Reg.SIM_TIME + 2 - Reg.STATE)

    def put(addr: int, regs: list[int]) -> None:
        words[addr - Reg.STATE: addr - Reg.STATE + len(regs)] = regs

    put(Reg.STATE, [2])
    put(Reg.FAULT_CODE, [1])
    put(Reg.MEAS_DISP, encode_float32(-1.25))
    put(Reg.MEAS_FORCE, encode_float32(3.5e-3))
    put(Reg.HEARTBEAT, [65535])
    put(Reg.SEQUENCE, [7])
    put(Reg.TARGET, encode_float32(12.75))
    put(Reg.SIM_TIME, encode_float32(0.5))
    assert Status.parse(words) == Status(2, 1, -1.25, f32(3.5e-3), 65535, 7, 12.75, 0.5)
    assert Status.parse(words).describe() == "state DONE, fault 1 STROKE_LIMIT"


def test_a_move_still_running_after_move_timeout_is_an_error_and_not_resent() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear"), time_scale=1.0, ramp_time=0.5,
                           move_timeout=0.1) as (s, ctl):
            with pytest.raises(ControllerError, match=r"still MOVING after move_timeout 0\.1 s"
                               r".*it is not retried"):
                await ctl.set_ctrl((1.0,))
            assert s.controller.move_id == 1
            await s.controller.wait(5.0)
            assert s.controller.move_id == 1 and s.controller.sequence == 1

    run(scenario)


# -- several channels: a register block per actuator ------------------------------------------


@contextlib.asynccontextmanager
async def serving_channels(names: list[str], n_site: int, *, time_scale: float = 0.0,
                           ) -> AsyncIterator[tuple[list[RigController], ModbusController]]:
    from sim_actuator.config import channel_config

    rigs = [RigController(build_rig(channel_config(preset(name), c)), time_scale=time_scale)
            for c, name in enumerate(names)]
    server = ModbusRigServer(rigs, host="127.0.0.1", port=0)
    _, port = await server.start()
    for rig in rigs:
        rig.start_heartbeat(50.0)
    ctl = ModbusController(ModbusControllerConfig(
        kind="modbus", port=port, ramp_time=0.05, reconnect_min=0.01, reconnect_max=0.05,
        request_timeout=0.5), n_site)
    try:
        yield rigs, ctl
    finally:
        await ctl.close()
        await server.stop()
        for rig in rigs:
            await rig.close()


def test_three_channels_each_its_own_rig_to_float32() -> None:
    from sim_actuator.config import channel_config

    names = ["ideal-bilinear", "servo-hydraulic", "lab-realistic"]
    references = [build_rig(channel_config(preset(n), c)) for c, n in enumerate(names)]

    async def scenario() -> None:
        async with serving_channels(names, 3, time_scale=0.5) as (rigs, ctl):
            for i, targets in enumerate([(0.4, -0.2, 1.0), (1.5, 0.3, -0.5), (0.0, 0.0, 2.0)], 1):
                await ctl.set_ctrl(targets)
                daq = await ctl.get_daq()
                expected = [r.execute(f32(t), f32(0.05)) for r, t in zip(references, targets,
                                                                         strict=True)]
                assert daq.disp == tuple(f32(m.displacement) for m in expected)
                assert daq.force == tuple(f32(m.force) for m in expected)
                assert [r.sequence for r in rigs] == [i, i, i]
            assert await ctl.tangent_stiffness() == (68.0, 0, 0, 0, 68.0, 0, 0, 0, 68.0)
            await ctl.hold()  # HOLD holds every actuator
            assert all(r.interlock for r in rigs)
            await ctl.set_ctrl((0.1, 0.1, 0.1))  # the bridge's own interlocks are released
            assert not any(r.interlock for r in rigs) and [r.target for r in rigs] == \
                [f32(0.1)] * 3
            rigs[1].set_interlock(True)  # an operator's interlock on one channel: no move at all
            with pytest.raises(ControllerError, match=r"channel 2: cannot move .* not by this"):
                await ctl.set_ctrl((0.2, 0.2, 0.2))
            assert [r.target for r in rigs] == [f32(0.1)] * 3

    run(scenario)


def test_a_server_with_fewer_channels_than_the_site_is_refused_before_any_move() -> None:
    async def scenario() -> None:
        async with serving_channels(["ideal-elastic"] * 2, 3) as (rigs, ctl):
            with pytest.raises(ControllerError, match=r"serves 2 channel.*drives 3 actuators"):
                await ctl.set_ctrl((1.0, 1.0, 1.0))
            assert [r.sequence for r in rigs] == [0, 0]
        async with serving_channels(["ideal-elastic"], 2) as (rigs, ctl):
            with pytest.raises(ControllerError, match=r"serves 1 channel.*drives 2 actuators"):
                await ctl.connect()

    run(scenario)
