"""Modbus TCP controller adapter (register map version 1 of ``sim_actuator`` servers).

One actuator. A move is one FC23 transaction: write COMMAND, RAMP_TIME and EXECUTE=1 and read
the status block back; then poll STATE until it leaves MOVING. A motion command whose outcome
is unknown (timeout, lost link, cancelled by the site's deadline) raises ``ControllerError`` and
is never re-sent by the adapter: the site goes to HOLD. Link loss and silence raise
``ControllerLinkError`` (the site may wait for the controller to answer again); a refusal,
fault or malformed reply raises a plain ``ControllerError``. Every call reconnects after a
loss, with jittered backoff; a *new* command is sent on a fresh link only after the status
read shows the controller healthy and idle (so the lost command is never replayed, and
setpoints are absolute).

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
import math
import struct
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import Field
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from sim_actuator.servers.modbus import (  # the one documented register map and encoding
    Reg,
    decode_float32,
    encode_float32,
)

from ._link import Backoff, HeartbeatWatch, NetworkControllerConfig, fault_name, state_name
from .base import Controller, ControllerError, ControllerLinkError, Daq

__all__ = ["MODBUS_EXCEPTIONS", "ModbusController", "ModbusControllerConfig", "Reg"]

MAP_VERSION = 1
CONTROL_RESET = 0x0001
CONTROL_HOLD = 0x0002
_MOVING, _DONE, _FAULT, _INTERLOCK = 1, 2, 3, 4


_STATUS_COUNT = Reg.SIM_TIME + 2 - Reg.STATE  # STATE .. SIM_TIME, 12 registers
_STATUS_WORDS = struct.Struct(f">{_STATUS_COUNT}H")
_STATUS_LAYOUT = struct.Struct(">HHffHHff")
"""STATE, FAULT_CODE, MEAS_DISP, MEAS_FORCE, HEARTBEAT, SEQUENCE, TARGET, SIM_TIME."""

MODBUS_EXCEPTIONS: dict[int, str] = {
    1: "ILLEGAL_FUNCTION",
    2: "ILLEGAL_DATA_ADDRESS (unmapped or read-only register)",
    3: "ILLEGAL_DATA_VALUE (value refused: not finite, bad ramp time or beyond the stroke)",
    4: "SERVER_DEVICE_FAILURE (controller in FAULT or INTERLOCK)",
    5: "ACKNOWLEDGE",
    6: "SERVER_DEVICE_BUSY (a different move is running)",
    7: "NEGATIVE_ACKNOWLEDGE",
    8: "MEMORY_PARITY_ERROR",
    10: "GATEWAY_PATH_UNAVAILABLE",
    11: "GATEWAY_TARGET_NO_RESPONSE",
}


class ModbusControllerConfig(NetworkControllerConfig):
    """A Modbus TCP actuator controller (one actuator, ``sim_actuator`` map version 1)."""

    kind: Literal["modbus"] = "modbus"
    port: int = Field(5020, ge=1, le=65535)
    device_id: int = Field(1, ge=0, le=255)
    poll_interval: float = Field(0.002, gt=0.0, allow_inf_nan=False)
    """Pause between STATE polls while a move runs, s."""
    move_timeout: float = Field(10.0, gt=0.0, le=3600.0, allow_inf_nan=False)
    """A move still MOVING after this long (wall s) is an error (like the MTS WAIT bound)."""


@dataclass(frozen=True, slots=True)
class _Status:
    state: int
    fault: int
    disp: float
    force: float
    heartbeat: int
    sequence: int
    target: float
    time: float

    @classmethod
    def parse(cls, words: list[int]) -> _Status:
        """One unpack of the 12 registers (float32 high word first is big-endian bytes)."""
        return cls(*_STATUS_LAYOUT.unpack(_STATUS_WORDS.pack(*words)))

    def describe(self) -> str:
        return f"state {state_name(self.state)}, fault {self.fault} {fault_name(self.fault)}"


class ModbusController(Controller):
    """One actuator behind a Modbus TCP controller; every call is a network round trip."""

    inline = False
    n_actuators = 1

    def __init__(self, config: ModbusControllerConfig) -> None:
        self.config = config
        self.where = f"modbus controller {config.host}:{config.port}"
        self._client: AsyncModbusTcpClient | None = None
        self._lock = asyncio.Lock()
        self._heartbeat = HeartbeatWatch(config.heartbeat_timeout, self.where)
        self._backoff = Backoff(config.reconnect_min, max(config.reconnect_min,
                                                          config.reconnect_max))
        self._interlock_ours = False
        """This adapter engaged the program interlock (``hold``) and has not released it."""

    # -- link ----------------------------------------------------------------------------------

    @property
    def connected(self) -> bool:
        return self._client is not None and self._client.connected

    async def connect(self) -> None:
        async with self._lock:
            await self._ensure_link()

    async def close(self) -> None:
        async with self._lock:
            self._drop(failed=False)

    def _drop(self, *, failed: bool = True) -> None:
        client, self._client = self._client, None
        if client is not None:
            client.close()
        self._heartbeat.reset()
        if failed:
            self._backoff.failed()

    async def _ensure_link(self) -> None:
        """Reconnect if needed (reads and hold only), after the backoff delay."""
        if self.connected:
            return
        if self._client is not None:
            self._drop()
        delay = self._backoff.wait_time()
        if delay > 0.0:
            await asyncio.sleep(delay)
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
        self._backoff.succeeded()

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
        name = MODBUS_EXCEPTIONS.get(code, "unknown exception code")
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

    def _status(self, words: list[int]) -> _Status:
        if len(words) != _STATUS_COUNT:
            self._drop()
            raise ControllerError(f"{self.where}: status reply has {len(words)} registers, "
                                  f"expected {_STATUS_COUNT}")
        status = _Status.parse(words)
        self._heartbeat.observe(status.heartbeat)
        return status

    async def _read_status(self) -> _Status:
        return self._status(await self._read(Reg.STATE, _STATUS_COUNT, "read status"))

    # -- the controller interface -------------------------------------------------------------

    async def set_ctrl(self, disp: tuple[float, ...]) -> None:
        if len(disp) != 1:
            raise ControllerError(f"{self.where}: drives 1 actuator, got {len(disp)} ctrl "
                                  f"values {list(disp)}")
        target = float(disp[0])
        if not math.isfinite(target):
            raise ControllerError(f"{self.where}: ctrl displacement {target!r} is not finite; "
                                  "not sent")
        async with self._lock:
            await self._ensure_link()  # a fresh link reads the status before any motion
            before = await self._read_status()
            if before.state == _INTERLOCK and self._interlock_ours:
                await self._write_control_locked(0, "release the interlock it engaged at HOLD")
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
                read_address=Reg.STATE, read_count=_STATUS_COUNT, write_address=Reg.COMMAND,
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

    def _check_done(self, status: _Status, target: float, sequence_before: int) -> None:
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

    async def get_daq(self) -> Daq:
        async with self._lock:
            await self._ensure_link()
            status = await self._read_status()
        if not (math.isfinite(status.disp) and math.isfinite(status.force)):
            raise ControllerError(f"{self.where}: non-finite measurement: displacement "
                                  f"{status.disp!r} mm, force {status.force!r} kN")
        return Daq((status.disp,), (status.force,))

    async def commit(self) -> None:
        """A physical rig has no trial state to commit."""

    async def tangent_stiffness(self) -> tuple[float, ...]:
        return (self.config.stiffness,)

    async def initial_stiffness(self) -> tuple[float, ...]:
        return (self.config.stiffness,)

    async def hold(self) -> None:
        """Engage the program interlock (stops a running move where it is)."""
        self._interlock_ours = True  # set first: a write whose reply is lost may have engaged it
        await self._write_control(CONTROL_HOLD, "engage the interlock")

    async def release(self, *, reset_fault: bool = False) -> None:
        """Release the program interlock (and optionally reset a latched fault)."""
        await self._write_control(CONTROL_RESET if reset_fault else 0, "release the interlock")
        self._interlock_ours = False

    async def _write_control(self, word: int, what: str) -> None:
        async with self._lock:
            await self._ensure_link()  # safe on a fresh link: it never starts motion
            await self._write_control_locked(word, what)

    async def _write_control_locked(self, word: int, what: str) -> None:
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
