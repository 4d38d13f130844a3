"""Modbus TCP server of the simulated rig, driven by pymodbus's client and by Debian's mbpoll."""

from __future__ import annotations

import asyncio
import contextlib
import math
import re
import shutil
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any, TypeVar

import pytest
from pymodbus.client import AsyncModbusTcpClient

from sim_actuator.config import RigConfig, build_rig, parse_rig_config, preset
from sim_actuator.servers.controller import ControllerState, RigController
from sim_actuator.servers.modbus import (
    CONTROL_HOLD,
    CONTROL_RESET,
    MAP_VERSION,
    ModbusRigServer,
    Reg,
    decode_float32,
    encode_float32,
)

T = TypeVar("T")
MBPOLL = "/usr/bin/mbpoll"


def run(factory: Callable[[], Awaitable[T]]) -> T:
    async def bounded() -> T:
        return await asyncio.wait_for(factory(), 30)

    return asyncio.run(bounded())


def f32(value: float) -> float:
    return decode_float32(encode_float32(value))


@contextlib.asynccontextmanager
async def serving(config: RigConfig, *, time_scale: float = 0.0,
                  heartbeat_hz: float | None = None
                  ) -> AsyncIterator[tuple[RigController, AsyncModbusTcpClient, int]]:
    controller = RigController(build_rig(config), time_scale=time_scale)
    server = ModbusRigServer(controller, host="127.0.0.1", port=0)
    host, port = await server.start()
    if heartbeat_hz is not None:
        controller.start_heartbeat(heartbeat_hz)
    client = AsyncModbusTcpClient(host, port=port, timeout=3, retries=0)
    assert await client.connect()
    try:
        yield controller, client, port
    finally:
        client.close()
        await server.stop()
        await controller.close()


async def read_status(client: AsyncModbusTcpClient) -> dict[str, Any]:
    r = await client.read_input_registers(Reg.STATE, count=Reg.MAP_VERSION - Reg.STATE + 1,
                                          device_id=1)
    assert not r.isError(), r
    w = r.registers

    def at(addr: int) -> int:
        return int(w[addr - Reg.STATE])

    def flt(addr: int) -> float:
        return decode_float32([at(addr), at(addr + 1)])

    return {
        "state": ControllerState(at(Reg.STATE)), "fault": at(Reg.FAULT_CODE),
        "disp": flt(Reg.MEAS_DISP), "force": flt(Reg.MEAS_FORCE),
        "heartbeat": at(Reg.HEARTBEAT), "sequence": at(Reg.SEQUENCE),
        "target": flt(Reg.TARGET), "time": flt(Reg.SIM_TIME), "version": at(Reg.MAP_VERSION),
    }


async def move(client: AsyncModbusTcpClient, target: float, ramp: float) -> dict[str, Any]:
    r = await client.write_registers(
        Reg.COMMAND, [*encode_float32(target), *encode_float32(ramp), 1], device_id=1
    )
    assert not r.isError(), r
    for _ in range(10000):
        status = await read_status(client)
        if status["state"] is not ControllerState.MOVING:
            return status
        await asyncio.sleep(0.001)
    raise AssertionError("move did not finish")


def exception_code(response: Any) -> int | None:
    return response.exception_code if response.isError() else None


def test_word_order_is_high_word_first() -> None:
    assert encode_float32(1.2345) == [16286, 1049]
    assert decode_float32([16286, 1049]) == pytest.approx(1.2345, abs=1e-7)


def test_moves_match_an_independent_rig_to_float32() -> None:
    config = preset("servo-hydraulic")
    reference = build_rig(config)

    async def scenario() -> None:
        async with serving(config) as (_, client, _port):
            first = await read_status(client)
            assert first["state"] is ControllerState.IDLE
            assert first["version"] == MAP_VERSION
            for i, target in enumerate([0.4, 1.5, -1.0, 0.0], start=1):
                status = await move(client, target, 0.2)
                expected = reference.execute(f32(target), f32(0.2))
                assert status["state"] is ControllerState.DONE
                assert status["fault"] == 0
                assert status["sequence"] == i
                assert status["disp"] == f32(expected.displacement)
                assert status["force"] == f32(expected.force)
                assert status["target"] == f32(target)
                assert status["time"] == f32(expected.time)

    run(scenario)


def test_fc23_writes_the_command_and_reads_the_result_in_one_transaction() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear")) as (_, client, _port):
            r = await client.readwrite_registers(
                read_address=Reg.STATE, read_count=6, write_address=Reg.COMMAND,
                values=[*encode_float32(1.25), *encode_float32(0.5), 1], device_id=1,
            )
            assert not r.isError(), r
            assert r.registers[0] == ControllerState.DONE  # an ideal rig completes at once
            assert decode_float32(r.registers[2:4]) == 1.25
            assert decode_float32(r.registers[4:6]) == pytest.approx(35.4, abs=1e-5)

    run(scenario)


def test_re_execute_is_harmless_and_heartbeat_advances() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear"), heartbeat_hz=50.0) as (_, client, _port):
            a = await move(client, 2.0, 0.1)
            r = await client.write_register(Reg.EXECUTE, 1, device_id=1)  # same target again
            assert not r.isError(), r
            b = await read_status(client)
            assert (b["disp"], b["force"]) == (a["disp"], a["force"])
            assert b["sequence"] == a["sequence"] + 1
            beat = b["heartbeat"]
            for _ in range(400):
                await asyncio.sleep(0.01)
                if (await read_status(client))["heartbeat"] != beat:
                    break
            else:
                raise AssertionError("heartbeat did not advance")

    run(scenario)


def test_busy_interlock_and_idempotent_execute_while_moving() -> None:
    async def scenario() -> None:
        # time_scale 1: a 2 s ramp takes 2 s of wall time, so the move is still running below
        async with serving(preset("ideal-bilinear"), time_scale=1.0) as (ctl, client, _port):
            r = await client.write_registers(
                Reg.COMMAND, [*encode_float32(3.0), *encode_float32(2.0), 1], device_id=1)
            assert not r.isError(), r
            assert (await read_status(client))["state"] is ControllerState.MOVING
            same = await client.write_register(Reg.EXECUTE, 1, device_id=1)
            assert not same.isError()
            assert ctl.move_id == 1
            other = await client.write_registers(
                Reg.COMMAND, [*encode_float32(-3.0), *encode_float32(2.0), 1], device_id=1)
            assert exception_code(other) == 6  # device busy
            hold = await client.write_register(Reg.CONTROL, CONTROL_HOLD, device_id=1)
            assert not hold.isError()
            status = await read_status(client)
            assert status["state"] is ControllerState.INTERLOCK
            assert status["sequence"] == 0  # the move was stopped, not completed
            assert 0.0 < status["disp"] < 3.0  # where the piston was when it stopped
            refused = await client.write_register(Reg.EXECUTE, 1, device_id=1)
            assert exception_code(refused) == 4
            release = await client.write_register(Reg.CONTROL, 0, device_id=1)
            assert not release.isError()
            assert (await read_status(client))["state"] is ControllerState.IDLE

    run(scenario)


def test_bad_requests_get_exception_codes_and_the_server_keeps_working() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear")) as (_, client, _port):
            assert exception_code(await client.read_holding_registers(6, count=1)) == 2
            ext = await client.read_input_registers(Reg.EXT_DISP, count=4)  # 26 is unmapped
            assert exception_code(ext) == 2
            assert exception_code(await client.read_holding_registers(500, count=1)) == 2
            assert exception_code(await client.write_register(Reg.STATE, 1)) == 2  # read-only
            assert exception_code(await client.write_registers(4, [0, 0, 0])) == 2  # 4..6
            assert exception_code(await client.write_register(Reg.EXECUTE, 2)) == 3
            assert exception_code(await client.write_register(Reg.CONTROL, 4)) == 3
            assert exception_code(await client.read_coils(0, count=1)) == 1
            nan = await client.write_registers(
                Reg.COMMAND, [*encode_float32(math.nan), *encode_float32(0.1), 1])
            assert exception_code(nan) == 3
            negative = await client.write_registers(
                Reg.COMMAND, [*encode_float32(1.0), *encode_float32(-1.0), 1])
            assert exception_code(negative) == 3
            assert (await read_status(client))["state"] is ControllerState.IDLE  # nothing latched
            beyond = await client.write_registers(
                Reg.COMMAND, [*encode_float32(150.0), *encode_float32(0.1), 1])
            assert exception_code(beyond) == 3
            status = await read_status(client)
            assert (status["state"], status["fault"]) == (ControllerState.FAULT, 1)
            assert status["time"] == 0.0  # no motion
            assert exception_code(await client.write_register(Reg.EXECUTE, 1)) == 4
            assert not (await client.write_register(Reg.CONTROL, CONTROL_RESET)).isError()
            assert (await read_status(client))["state"] is ControllerState.IDLE
            ok = await move(client, 1.0, 0.1)
            assert (ok["state"], ok["disp"]) == (ControllerState.DONE, 1.0)

    run(scenario)


def test_force_trip_shows_fault_code_two() -> None:
    config = parse_rig_config({"specimen": {"kind": "elastic", "params": {"k": 10.0}},
                               "actuator": {"force_capacity": 20.0}})

    async def scenario() -> None:
        async with serving(config) as (_, client, _port):
            status = await move(client, 5.0, 0.5)
            assert (status["state"], status["fault"]) == (ControllerState.FAULT, 2)
            assert 20.0 < status["force"] <= 20.2
            assert status["sequence"] == 0

    run(scenario)


async def _mbpoll(*args: str) -> tuple[int, str]:
    proc = await asyncio.create_subprocess_exec(
        MBPOLL, *args, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT)
    out, _ = await proc.communicate()
    assert proc.returncode is not None
    return proc.returncode, out.decode(errors="replace")


def _values(output: str) -> dict[int, float]:
    return {int(a): float(v) for a, v in re.findall(r"^\[(\d+)\]:\s+(\S+)", output, re.M)}


@pytest.mark.skipif(not shutil.which(MBPOLL), reason="Debian's mbpoll is not installed")
def test_mbpoll_drives_a_move_and_reads_the_measurement() -> None:
    """An independent master (libmodbus-based mbpoll) writes float32s with -B and reads back."""
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear")) as (_, _client, port):
            common = ["-m", "tcp", "-p", str(port), "-a", "1", "-0", "-1", "-o", "5"]
            rc, out = await _mbpoll(*common, "-r", str(Reg.COMMAND), "-t", "4:float", "-B",
                                    "127.0.0.1", "--", "1.25", "0.5")
            assert rc == 0, out
            rc, out = await _mbpoll(*common, "-r", str(Reg.EXECUTE), "-t", "4", "127.0.0.1", "1")
            assert rc == 0, out
            rc, out = await _mbpoll(*common, "-r", str(Reg.STATE), "-c", "2", "-t", "3",
                                    "127.0.0.1")
            assert rc == 0, out
            assert _values(out) == {Reg.STATE: ControllerState.DONE, Reg.FAULT_CODE: 0}
            rc, out = await _mbpoll(*common, "-r", str(Reg.MEAS_DISP), "-c", "2", "-t", "3:float",
                                    "-B", "127.0.0.1")
            assert rc == 0, out
            bare_force = 0.008 * 68.0 * 1.25 + 35.0 * (1 - 0.008)  # on the hardening branch
            measured = _values(out)
            assert measured[Reg.MEAS_DISP] == pytest.approx(1.25, rel=1e-5)
            assert measured[Reg.MEAS_FORCE] == pytest.approx(bare_force, rel=1e-5)
            rc, out = await _mbpoll(*common, "-r", "6", "-t", "3", "127.0.0.1")
            assert rc != 0
            assert "Illegal data address" in out

    run(scenario)


def test_several_channels_a_register_block_each() -> None:
    from sim_actuator.wire.modbus_map import CHANNEL_STRIDE

    async def scenario() -> None:
        rigs = [RigController(build_rig(preset("ideal-elastic"))) for _ in range(3)]
        server = ModbusRigServer(rigs, host="127.0.0.1", port=0)
        host, port = await server.start()
        client = AsyncModbusTcpClient(host, port=port, timeout=3, retries=0)
        assert await client.connect()
        try:
            base = 2 * CHANNEL_STRIDE  # channel 3 moves alone
            r = await client.write_registers(
                base + Reg.COMMAND, [*encode_float32(0.5), *encode_float32(0.0), 1], device_id=1)
            assert not r.isError(), r
            assert [c.target for c in rigs] == [0.0, 0.0, 0.5]
            r = await client.read_holding_registers(base + Reg.STATE,
                                                    count=Reg.CHANNELS - Reg.STATE + 1,
                                                    device_id=1)
            w = r.registers
            assert decode_float32(w[Reg.MEAS_FORCE - Reg.STATE:][:2]) == f32(34.0)
            assert w[Reg.CHANNELS - Reg.STATE] == 3 and w[Reg.SEQUENCE - Reg.STATE] == 1
            # one write, one channel: a write spanning two blocks is refused, nothing moves
            r = await client.write_registers(CHANNEL_STRIDE - 1, [0] * 8, device_id=1)
            assert exception_code(r) == 2
            assert [c.sequence for c in rigs] == [0, 0, 1]
        finally:
            client.close()
            await server.stop()

    run(scenario)
