"""Modbus TCP controller adapter (register map version 1 of ``sim_actuator`` servers).

One actuator (the link's rules are ``network.py``'s). A move is one FC23 transaction: write
COMMAND, RAMP_TIME and EXECUTE=1 and read the status block back; then poll STATE until it leaves
MOVING. A motion command whose outcome is unknown (timeout, lost link, cancelled by the site's
deadline) raises ``ControllerError`` and is never re-sent by the adapter: the site goes to HOLD.
Link loss and silence raise ``ControllerLinkError`` (the site may wait for the controller to
answer again); a refusal, fault or malformed reply raises a plain ``ControllerError``. Every
call reconnects after a loss, with jittered backoff; a *new* command is sent on a fresh link
only after the status read shows the controller healthy and idle (so the lost command is never
replayed, and setpoints are absolute).

``hold`` engages the program interlock. The next motion command the site forwards (the site
forwards nothing while it holds, so this is a new session or an operator's resume) releases it
again, but only if this adapter engaged it: an interlock engaged by an operator or another
master, or a latched fault, is reported and left alone.

Float32 values are IEEE-754 in two registers, high word first. The heartbeat register must keep
changing (checked on every status read); a physical rig cannot report its stiffness, so the
tangent and initial stiffness are a configured estimate.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any, Literal

from pydantic import Field
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from sim_actuator.wire.modbus_map import (  # the one register map, shared with the server
    CONTROL_HOLD,
    CONTROL_RESET,
    EXCEPTION_MEANINGS,
    MAP_VERSION,
    STATUS_COUNT,
    Reg,
    Status,
    decode_float32,
    encode_float32,
)
from sim_actuator.wire.states import ControllerState

from ._link import NetworkControllerConfig
from .base import ControllerError, ControllerLinkError
from .kind import ControllerKind
from .network import NetworkController

__all__ = ["MODBUS_EXCEPTIONS", "ModbusController", "ModbusControllerConfig", "Reg"]

MODBUS_EXCEPTIONS = EXCEPTION_MEANINGS
_MOVING, _DONE = ControllerState.MOVING, ControllerState.DONE
_FAULT, _INTERLOCK = ControllerState.FAULT, ControllerState.INTERLOCK


class ModbusControllerConfig(NetworkControllerConfig):
    """A Modbus TCP actuator controller (one actuator, ``sim_actuator`` map version 1)."""

    kind: Literal["modbus"] = "modbus"
    port: int = Field(5020, ge=1, le=65535)
    device_id: int = Field(1, ge=0, le=255)
    poll_interval: float = Field(0.002, gt=0.0, allow_inf_nan=False)
    """Pause between STATE polls while a move runs, s."""
    move_timeout: float = Field(10.0, gt=0.0, le=3600.0, allow_inf_nan=False)
    """A move still MOVING after this long (wall s) is an error (like the MTS WAIT bound)."""


class ModbusController(NetworkController):
    """One actuator behind a Modbus TCP controller; every call is a network round trip."""

    config: ModbusControllerConfig

    def __init__(self, config: ModbusControllerConfig) -> None:
        super().__init__(config, f"modbus controller {config.host}:{config.port}")
        self._client: AsyncModbusTcpClient | None = None

    # -- the transport -------------------------------------------------------------------------

    @property
    def connected(self) -> bool:
        return self._client is not None and self._client.connected

    @property
    def _has_transport(self) -> bool:
        return self._client is not None

    def _close_transport(self) -> None:
        client, self._client = self._client, None
        if client is not None:
            client.close()

    async def _open(self) -> None:
        cfg = self.config
        client = AsyncModbusTcpClient(cfg.host, port=cfg.port, timeout=cfg.request_timeout,
                                      retries=0, reconnect_delay=0)
        try:
            ok = await asyncio.wait_for(client.connect(), cfg.connect_timeout)
        except (TimeoutError, OSError, ModbusException) as exc:
            client.close()
            self._backoff.failed()
            raise ControllerLinkError(f"{self.where}: cannot connect: {exc}") from None
        except asyncio.CancelledError:
            client.close()
            raise
        if not ok:
            client.close()
            self._backoff.failed()
            raise ControllerLinkError(f"{self.where}: cannot connect (connection refused or "
                                      f"no answer within {cfg.connect_timeout:g} s)")
        self._client = client
        version = await self._read(Reg.MAP_VERSION, 1, "read MAP_VERSION")
        if version[0] != MAP_VERSION:
            self._drop(failed=False)
            raise ControllerError(f"{self.where}: register map version {version[0]}, "
                                  f"this adapter speaks version {MAP_VERSION}")
        await self._read_status()

    async def _request(self, what: str, make: Callable[[AsyncModbusTcpClient], Awaitable[Any]],
                       *, motion: bool = False) -> Any:
        """One transaction; a lost link or timeout drops the client and raises."""
        client = self._client
        if client is None or not client.connected:
            lost = client is not None
            self._drop()
            reason = "link lost (connection closed by the controller)" if lost else "link is down"
            raise ControllerLinkError(f"{self.where}: {reason}; {what} not sent"
                                      + (" (a motion command is never sent on a link that was "
                                         "lost; the next read reconnects)" if motion else ""))
        try:
            return await make(client)
        except asyncio.CancelledError:
            self._drop()  # an unanswered transaction leaves the link in an unknown state
            raise
        except (ModbusException, OSError) as exc:
            self._drop()
            unknown = (": the outcome of the motion command is unknown and it is not retried"
                       if motion else "")
            raise ControllerLinkError(f"{self.where}: {what} failed, link lost ({exc}){unknown}"
                                      ) from None

    def _exception(self, response: Any, what: str) -> str | None:
        if not response.isError():
            return None
        code = int(getattr(response, "exception_code", -1))
        name = EXCEPTION_MEANINGS.get(code, "unknown exception code")
        return f"{self.where}: {what} refused with Modbus exception {code:02d} {name}"

    async def _read(self, address: int, count: int, what: str) -> list[int]:
        cfg = self.config
        response = await self._request(what, lambda c: c.read_holding_registers(
            address, count=count, device_id=cfg.device_id))
        problem = self._exception(response, what)
        if problem is not None:
            raise ControllerError(problem)
        words = list(response.registers)
        if len(words) != count:
            self._drop()
            raise ControllerError(f"{self.where}: {what}: reply has {len(words)} registers, "
                                  f"expected {count}")
        return words

    def _status(self, words: list[int]) -> Status:
        if len(words) != STATUS_COUNT:
            self._drop()
            raise ControllerError(f"{self.where}: status reply has {len(words)} registers, "
                                  f"expected {STATUS_COUNT}")
        status = Status.parse(words)
        self._heartbeat.observe(status.heartbeat)
        return status

    async def _read_status(self) -> Status:
        return self._status(await self._read(Reg.STATE, STATUS_COUNT, "read status"))

    # -- the wire of the controller interface -------------------------------------------------

    async def _move(self, target: float) -> None:
        before = await self._read_status()
        if before.state == _INTERLOCK and self._interlock_ours:
            await self._write_control(0, "release the interlock it engaged at HOLD")
            self._interlock_ours = False
            before = await self._read_status()
        if before.state != _INTERLOCK:
            self._interlock_ours = False  # released elsewhere, or a restarted controller
        if before.state in (_FAULT, _INTERLOCK, _MOVING):
            if before.state == _INTERLOCK:
                raise ControllerError(
                    f"{self.where}: cannot move to {target!r} mm: the program interlock is "
                    "engaged and not by this bridge (operator or another master); release "
                    "it at the controller")
            raise ControllerError(f"{self.where}: cannot move to {target!r} mm: "
                                  f"{before.describe()}")
        cfg = self.config
        values = [*encode_float32(target), *encode_float32(cfg.ramp_time), 1]
        what = f"move to {target!r} mm"
        response = await self._request(what, lambda c: c.readwrite_registers(
            read_address=Reg.STATE, read_count=STATUS_COUNT, write_address=Reg.COMMAND,
            values=values, device_id=cfg.device_id), motion=True)
        problem = self._exception(response, what)
        if problem is not None:
            after = await self._read_status()
            raise ControllerError(f"{problem}; controller {after.describe()}")
        try:
            status = self._status(list(response.registers))
            deadline = asyncio.get_running_loop().time() + cfg.move_timeout
            while status.state == _MOVING:
                if asyncio.get_running_loop().time() > deadline:
                    raise ControllerError(f"{self.where}: still MOVING after move_timeout "
                                          f"{cfg.move_timeout:g} s")
                await asyncio.sleep(cfg.poll_interval)
                status = await self._read_status()
        except ControllerError as exc:  # keeps its kind: a lost link stays a lost link
            raise type(exc)(f"{exc}; the {what} was accepted but its completion is "
                            "unknown; it is not retried") from None
        self._check_done(status, target, before.sequence)

    def _check_done(self, status: Status, target: float, sequence_before: int) -> None:
        what = f"{self.where}: move to {target!r} mm"
        if status.state == _FAULT:
            raise ControllerError(f"{what} tripped: {status.describe()} at "
                                  f"{status.disp!r} mm, {status.force!r} kN")
        if status.state == _INTERLOCK:
            raise ControllerError(f"{what} stopped by the program interlock at "
                                  f"{status.disp!r} mm")
        if status.state != _DONE:
            raise ControllerError(f"{what} did not complete: {status.describe()}")
        expected = (sequence_before + 1) & 0xFFFF
        if status.sequence != expected or status.target != decode_float32(encode_float32(target)):
            raise ControllerError(
                f"{what}: controller reports target {status.target!r} mm, sequence "
                f"{status.sequence} (expected {expected}); another master is commanding it?")

    async def _measure(self) -> tuple[float, float]:
        status = await self._read_status()
        return status.disp, status.force

    async def _set_interlock(self, on: bool, reset_fault: bool = False) -> None:
        if on:
            await self._write_control(CONTROL_HOLD, "engage the interlock")
        else:
            await self._write_control(CONTROL_RESET if reset_fault else 0,
                                      "release the interlock")

    async def _write_control(self, word: int, what: str) -> None:
        response = await self._request(what, lambda c: c.write_register(
            Reg.CONTROL, word, device_id=self.config.device_id))
        problem = self._exception(response, what)
        if problem is not None:
            raise ControllerError(problem)

    async def sequence(self) -> int:
        """Completed moves as the controller counts them (diagnostics, tests)."""
        async with self._lock:
            await self._ensure_link()
            return (await self._read_status()).sequence


KIND = ControllerKind(
    name="modbus",
    config=ModbusControllerConfig,
    factory=lambda config, n: ModbusController(config),
    summary="a Modbus TCP controller speaking the register map of `sim-actuator serve`",
)
