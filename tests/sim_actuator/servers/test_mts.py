"""MTS-CSI-like stub: a plain asyncio line client runs a test session and probes every error."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import TypeVar

import pytest

from sim_actuator.config import RigConfig, build_rig, preset
from sim_actuator.servers.controller import RigController
from sim_actuator.servers.mts_stub import MtsStubServer

T = TypeVar("T")


def run(factory: Callable[[], Awaitable[T]]) -> T:
    async def bounded() -> T:
        return await asyncio.wait_for(factory(), 30)

    return asyncio.run(bounded())


class LineClient:
    """Minimal client: send a line, read the one reply line."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer

    async def ask(self, line: str | bytes) -> str:
        raw = line if isinstance(line, bytes) else line.encode("ascii")
        self.writer.write(raw + b"\n")
        await self.writer.drain()
        return (await self.reader.readline()).decode("ascii").rstrip("\n")

    async def close(self) -> None:
        self.writer.close()
        with contextlib.suppress(ConnectionError):
            await self.writer.wait_closed()


def fields(reply: str) -> dict[str, str]:
    head, *pairs = reply.split()
    assert head == "OK", reply
    return dict(pair.split("=", 1) for pair in pairs)


@contextlib.asynccontextmanager
async def serving(config: RigConfig, *, time_scale: float = 0.0
                  ) -> AsyncIterator[tuple[MtsStubServer, Callable[[], Awaitable[LineClient]]]]:
    controller = RigController(build_rig(config), time_scale=time_scale)
    server = MtsStubServer(controller, host="127.0.0.1", port=0)
    host, port = await server.start()
    clients: list[LineClient] = []

    async def connect() -> LineClient:
        client = LineClient(*await asyncio.open_connection(host, port))
        clients.append(client)
        return client

    try:
        yield server, connect
    finally:
        for client in clients:
            await client.close()
        await server.stop()
        await controller.close()


def test_csi_style_session_matches_an_independent_rig_exactly() -> None:
    config = preset("lab-realistic")  # noisy, delayed, compliant: floats must still round-trip
    reference = build_rig(config)

    async def scenario() -> None:
        async with serving(config) as (_, connect):
            c = await connect()
            info = fields(await c.ask("INFO"))
            assert info["channels"] == "displacement,force,command,time"
            assert fields(await c.ask("OPEN"))["test"] == "1"
            assert fields(await c.ask("SET_RAMP_TIME 0.2")) == {"ramp_time": "0.2"}
            assert fields(await c.ask("COMMAND 1.5")) == {"command": "1.5"}
            ramp = fields(await c.ask("EXECUTE"))["ramp"]
            assert fields(await c.ask(f"WAIT {ramp} 10")) == {"ramp": ramp, "state": "DONE"}
            fb = fields(await c.ask(f"acquire {ramp}"))  # verbs are case-insensitive
            expected = reference.execute(1.5, 0.2)
            assert float(fb["displacement"]) == expected.displacement
            assert float(fb["force"]) == expected.force
            assert float(fb["time"]) == expected.time
            run_fb = fields(await c.ask("RUN -0.75 10"))
            expected = reference.execute(-0.75, 0.2)
            assert (float(run_fb["displacement"]), float(run_fb["force"])) == (
                expected.displacement, expected.force)
            assert run_fb["ramp"] == "2"
            status = fields(await c.ask("STATUS"))
            assert (status["state"], status["sequence"], status["open"]) == ("DONE", "2", "1")
            assert await c.ask("CLOSE") == "OK"
            assert await c.ask("COMMAND 1") == (
                "ERR NOT_OPEN COMMAND needs an open test; send OPEN first")

    run(scenario)


@pytest.mark.parametrize(
    ("request_line", "reply_start"),
    [
        ("FOO", "ERR SYNTAX unknown request 'FOO'"),
        ("", "ERR SYNTAX empty request"),
        ("STATUS now", "ERR SYNTAX STATUS takes 0 argument(s), got 1"),
        ("WAIT 1", "ERR SYNTAX WAIT takes 2 argument(s), got 1"),
        ("COMMAND abc", "ERR SYNTAX command displacement must be a number, got 'abc'"),
        ("COMMAND inf", "ERR BAD_VALUE command displacement must be finite"),
        ("SET_RAMP_TIME -1", "ERR BAD_VALUE ramp time must be within [0, 60.0] s"),
        ("EXECUTE", "ERR NO_COMMAND send COMMAND <mm> before EXECUTE"),
        ("WAIT 7 1", "ERR UNKNOWN_RAMP ramp 7 is not the last ramp (0)"),
        ("WAIT x 1", "ERR SYNTAX ramp id must be an integer"),
        ("ACQUIRE 3", "ERR UNKNOWN_RAMP move 3 is unknown"),
        ("INTERLOCK maybe", "ERR SYNTAX INTERLOCK takes ON or OFF"),
        ("RUN 1 -5", "ERR BAD_VALUE timeout must be within"),
    ],
)
def test_bad_requests_get_specific_errors(request_line: str, reply_start: str) -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-elastic")) as (_, connect):
            c = await connect()
            assert await c.ask("OPEN") == "OK test=1"
            reply = await c.ask(request_line)
            assert reply.startswith(reply_start), reply
            assert fields(await c.ask("RUN 0.5 5"))["displacement"] == "0.5"  # still serving

    run(scenario)


def test_garbage_and_over_long_lines_do_not_kill_the_server() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-elastic")) as (_, connect):
            c = await connect()
            assert await c.ask(b"\xff\xfe\x00") == "ERR SYNTAX request is not ASCII text"
            assert await c.ask(b"X" * 5000) == "ERR TOO_LONG request line exceeds 1024 bytes"
            assert fields(await c.ask("STATUS"))["state"] == "IDLE"

    run(scenario)


def test_limit_fault_reset_and_single_owner() -> None:
    async def scenario() -> None:
        async with serving(preset("ideal-bilinear")) as (_, connect):
            a, b = await connect(), await connect()
            assert await a.ask("OPEN") == "OK test=1"
            assert (await b.ask("OPEN")).startswith("ERR BUSY a test is already open by")
            assert fields(await b.ask("STATUS"))["open"] == "1"  # read-only requests are fine
            reply = await a.ask("RUN 120 5")
            assert reply.startswith("ERR LIMIT STROKE_LIMIT: target 120.0 mm is beyond"), reply
            status = fields(await a.ask("STATUS"))
            assert (status["state"], status["fault"], status["time"]) == (
                "FAULT", "STROKE_LIMIT", "0.0")
            assert (await a.ask("RUN 1 5")).startswith("ERR FAULT fault STROKE_LIMIT is latched")
            assert await a.ask("RESET") == "OK state=IDLE"
            assert fields(await a.ask("RUN 1 5"))["displacement"] == "1.0"
            await a.close()  # disconnecting releases the test
            for _ in range(100):
                reply = await b.ask("OPEN")
                if reply.startswith("OK"):
                    break
                await asyncio.sleep(0.01)
            assert reply == "OK test=2"

    run(scenario)


def test_wait_timeout_then_interlock_stops_the_ramp() -> None:
    async def scenario() -> None:
        # time_scale 1: the 5 s ramp takes 5 s of wall time, far longer than the 0.05 s wait
        async with serving(preset("servo-hydraulic"), time_scale=1.0) as (_, connect):
            c = await connect()
            await c.ask("OPEN")
            await c.ask("SET_RAMP_TIME 5")
            await c.ask("COMMAND 2")
            ramp = fields(await c.ask("EXECUTE"))["ramp"]
            assert await c.ask("EXECUTE") == f"OK ramp={ramp}"  # same target: no new move
            assert await c.ask("COMMAND 3") == "OK command=3.0"
            assert (await c.ask("EXECUTE")).startswith("ERR BUSY move 1")
            assert await c.ask(f"WAIT {ramp} 0.05") == (
                f"ERR TIMEOUT ramp {ramp} still running after 0.05 s")
            assert (await c.ask(f"ACQUIRE {ramp}")).startswith("ERR BUSY")
            live = fields(await c.ask("ACQUIRE"))  # current feedback is always available
            assert float(live["displacement"]) < 2.0
            assert await c.ask("INTERLOCK ON") == "OK state=INTERLOCK"
            assert await c.ask(f"WAIT {ramp} 1") == (
                f"ERR INTERLOCK ramp {ramp} stopped by the interlock")
            stopped = fields(await c.ask(f"ACQUIRE {ramp}"))
            assert 0.0 <= float(stopped["displacement"]) < 2.0
            assert await c.ask("INTERLOCK OFF") == "OK state=IDLE"

    run(scenario)


def test_force_trip_is_reported_by_wait() -> None:
    from sim_actuator.config import parse_rig_config

    config = parse_rig_config({"specimen": {"kind": "elastic", "params": {"k": 10.0}},
                               "actuator": {"force_capacity": 20.0}})

    async def scenario() -> None:
        async with serving(config) as (_, connect):
            c = await connect()
            await c.ask("OPEN")
            await c.ask("COMMAND 5")
            ramp = fields(await c.ask("EXECUTE"))["ramp"]
            assert await c.ask(f"WAIT {ramp} 5") == f"ERR FAULT ramp {ramp} tripped: FORCE_LIMIT"
            assert fields(await c.ask("STATUS"))["fault"] == "FORCE_LIMIT"

    run(scenario)
