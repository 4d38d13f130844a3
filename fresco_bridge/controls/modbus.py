"""Modbus TCP controller adapter (register map version 1 of ``sim_actuator`` servers).

One actuator per register block (channel c at ``c * 32``; the link's rules are
``network.py``'s). A move is one FC23 transaction per channel: write COMMAND, RAMP_TIME and
EXECUTE=1 and read the status block back (every channel's move starts before any is waited for);
then poll STATE until each leaves MOVING. A multi-channel site checks at connection that the
controller serves that many channels (register 23, CHANNELS); HOLD engages the interlock of
every channel. A motion command whose outcome is unknown (timeout, lost link, cancelled by the
site's deadline) raises ``ControllerError`` and is never re-sent by the adapter: the site goes
to HOLD. Link loss and silence raise ``ControllerLinkError`` (the site may wait for the
controller to answer again); a refusal, fault or malformed reply raises a plain
``ControllerError``. Every call reconnects after a loss, with jittered backoff; a *new* command
is sent on a fresh link only after the status read shows the controller healthy and idle (so the
lost command is never replayed, and setpoints are absolute).

``hold`` engages the program interlock. The next motion command the site forwards (the site
forwards nothing while it holds, so this is a new session or an operator's resume) releases it
again, but only if this adapter engaged it: an interlock engaged by an operator or another
master, or a latched fault, is reported and left alone.

With ``external_register`` the measurement also reads each channel's external displacement
(``Daq.external``, in the same request as the status block when the controller maps every
register between them, else one more read per channel; the outer-loop correction's
``measured = "external"``). Float32 values are IEEE-754 in two registers, high word first.
The heartbeat register must keep changing (checked on every status read); a physical rig cannot
report its stiffness, so the tangent and initial stiffness are a configured estimate.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any, Literal

from pydantic import Field
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from sim_actuator.wire.modbus_map import (  # the one register map, shared with the server
    CHANNEL_STRIDE,
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
    """A Modbus TCP actuator controller (``sim_actuator`` map version 1, a register block per
    actuator)."""

    kind: Literal["modbus"] = "modbus"
    port: int = Field(5020, ge=1, le=65535)
    device_id: int = Field(1, ge=0, le=255)
    poll_interval: float = Field(0.002, gt=0.0, allow_inf_nan=False)
    """Pause between STATE polls while a move runs, s."""
    move_timeout: float = Field(10.0, gt=0.0, le=3600.0, allow_inf_nan=False)
    """A move still MOVING after this long (wall s) is an error (like the MTS WAIT bound)."""
    external_register: int | None = Field(None, ge=0, le=CHANNEL_STRIDE - 2)
    """The external channel (``Daq.external``): the address, within each channel's register
    block, of a float32 displacement (mm) from a second transducer; ``sim-actuator serve``
    serves the specimen's displacement at 24 (EXT_DISP). None: no external channel."""

    def external_channel(self) -> str | None:
        return None if self.external_register is None else f"register {self.external_register}"


class ModbusController(NetworkController):
    """Actuators behind a Modbus TCP controller, a register block each; every call is a
    network round trip."""

    config: ModbusControllerConfig

    def __init__(self, config: ModbusControllerConfig, n_actuators: int = 1) -> None:
        super().__init__(config, f"modbus controller {config.host}:{config.port}", n_actuators)
        self._client: AsyncModbusTcpClient | None = None
        self.external_channel = config.external_channel()
        self._external_in_one_read = True
        """The external register is read with the status block (until a controller refuses)."""
        self._external: tuple[float, ...] | None = None
        """The external displacements read with the last status blocks, if they were."""

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
        if self.n_actuators > 1:
            served = (await self._read(Reg.CHANNELS, 1, "read CHANNELS",
                                       missing=0))[0]
            if served < self.n_actuators:
                self._drop(failed=False)
                raise ControllerError(f"{self.where}: serves {served or 1} channel(s); this "
                                      f"site drives {self.n_actuators} actuators")
        for channel in range(self.n_actuators):
            await self._read_status(channel)

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

    async def _read(self, address: int, count: int, what: str,
                    missing: int | None = None) -> list[int]:
        """``count`` registers from ``address``; with ``missing``, an unmapped address reads
        as that value (a register an older map lacks)."""
        cfg = self.config
        response = await self._request(what, lambda c: c.read_holding_registers(
            address, count=count, device_id=cfg.device_id))
        if missing is not None and response.isError() and \
                int(getattr(response, "exception_code", -1)) == 2:
            return [missing] * count
        problem = self._exception(response, what)
        if problem is not None:
            raise ControllerError(problem)
        words = list(response.registers)
        if len(words) != count:
            self._drop()
            raise ControllerError(f"{self.where}: {what}: reply has {len(words)} registers, "
                                  f"expected {count}")
        return words

    def _status(self, words: list[int], channel: int = 0) -> Status:
        if len(words) != STATUS_COUNT:
            self._drop()
            raise ControllerError(f"{self.where}: status reply has {len(words)} registers, "
                                  f"expected {STATUS_COUNT}")
        status = Status.parse(words)
        self._heartbeats[channel].observe(status.heartbeat)
        return status

    def _channel(self, channel: int) -> str:
        return "" if self.n_actuators == 1 else f" channel {channel + 1}"

    async def _read_status(self, channel: int = 0) -> Status:
        return self._status(await self._read(channel * CHANNEL_STRIDE + Reg.STATE, STATUS_COUNT,
                                             f"read status{self._channel(channel)}"), channel)

    # -- the wire of the controller interface -------------------------------------------------

    async def _move(self, targets: tuple[float, ...]) -> None:
        channels = range(self.n_actuators)
        befores = [await self._read_status(c) for c in channels]
        if self._interlock_ours and any(b.state == _INTERLOCK for b in befores):
            for c in channels:
                if befores[c].state == _INTERLOCK:
                    await self._write_control(c, 0, "release the interlock it engaged at HOLD")
            self._interlock_ours = False
            befores = [await self._read_status(c) for c in channels]
        if all(b.state != _INTERLOCK for b in befores):
            self._interlock_ours = False  # released elsewhere, or a restarted controller
        for c, (before, target) in enumerate(zip(befores, targets, strict=True)):
            if before.state == _INTERLOCK:
                raise ControllerError(
                    f"{self.where}{self._channel(c)}: cannot move to {target!r} mm: the program "
                    "interlock is engaged and not by this bridge (operator or another master); "
                    "release it at the controller")
            if before.state in (_FAULT, _MOVING):
                raise ControllerError(f"{self.where}{self._channel(c)}: cannot move to "
                                      f"{target!r} mm: {before.describe()}")
        started = [await self._start_move(c, t) for c, t in zip(channels, targets, strict=True)]
        cfg = self.config
        deadline = asyncio.get_running_loop().time() + cfg.move_timeout
        for c, (status, target, before) in enumerate(zip(started, targets, befores,
                                                         strict=True)):
            what = f"move{self._channel(c)} to {target!r} mm"
            try:
                while status.state == _MOVING:
                    if asyncio.get_running_loop().time() > deadline:
                        raise ControllerError(f"{self.where}{self._channel(c)}: still MOVING "
                                              f"after move_timeout {cfg.move_timeout:g} s")
                    await asyncio.sleep(cfg.poll_interval)
                    status = await self._read_status(c)
            except ControllerError as exc:  # keeps its kind: a lost link stays a lost link
                raise type(exc)(f"{exc}; the {what} was accepted but its completion is "
                                "unknown; it is not retried") from None
            self._check_done(c, status, target, before.sequence)

    async def _start_move(self, channel: int, target: float) -> Status:
        """One FC23: write the channel's COMMAND, RAMP_TIME, EXECUTE=1, read its status."""
        cfg = self.config
        base = channel * CHANNEL_STRIDE
        values = [*encode_float32(target), *encode_float32(cfg.ramp_time), 1]
        what = f"move{self._channel(channel)} to {target!r} mm"
        response = await self._request(what, lambda c: c.readwrite_registers(
            read_address=base + Reg.STATE, read_count=STATUS_COUNT,
            write_address=base + Reg.COMMAND, values=values, device_id=cfg.device_id),
            motion=True)
        problem = self._exception(response, what)
        if problem is not None:
            after = await self._read_status(channel)
            raise ControllerError(f"{problem}; controller {after.describe()}")
        try:
            return self._status(list(response.registers), channel)
        except ControllerError as exc:
            raise type(exc)(f"{exc}; the {what} was accepted but its completion is unknown; "
                            "it is not retried") from None

    def _check_done(self, channel: int, status: Status, target: float,
                    sequence_before: int) -> None:
        what = f"{self.where}{self._channel(channel)}: move to {target!r} mm"
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

    async def _measure(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        address = self.config.external_register
        if address is None or address < Reg.STATE or not self._external_in_one_read:
            statuses = [await self._read_status(c) for c in range(self.n_actuators)]
            self._external = None
            return tuple(s.disp for s in statuses), tuple(s.force for s in statuses)
        # the status block and the external register in one request per channel (no extra
        # round trip); a controller with an unmapped register between them answers exception
        # 02 once, and from then on the external register is read on its own
        count = max(STATUS_COUNT, address + 2 - Reg.STATE)
        statuses, external = [], []
        for c in range(self.n_actuators):
            words = await self._read(c * CHANNEL_STRIDE + Reg.STATE, count,
                                     f"read status and external channel{self._channel(c)}",
                                     missing=-1)
            if words[0] == -1:
                self._external_in_one_read = False
                return await self._measure()
            statuses.append(self._status(words[:STATUS_COUNT], c))
            external.append(decode_float32(words[address - Reg.STATE:address - Reg.STATE + 2]))
        self._external = tuple(external)
        return tuple(s.disp for s in statuses), tuple(s.force for s in statuses)

    async def _measure_external(self) -> tuple[float, ...]:
        if self._external is not None:
            return self._external
        address = self.config.external_register
        assert address is not None  # only called with an external channel
        values = []
        for c in range(self.n_actuators):
            values.append(decode_float32(await self._read(
                c * CHANNEL_STRIDE + address, 2,
                f"read the external channel{self._channel(c)} (register {address})")))
        return tuple(values)

    async def _set_interlock(self, on: bool, reset_fault: bool = False) -> None:
        for channel in range(self.n_actuators):  # HOLD holds every actuator
            if on:
                await self._write_control(channel, CONTROL_HOLD, "engage the interlock")
            else:
                await self._write_control(channel, CONTROL_RESET if reset_fault else 0,
                                          "release the interlock")

    async def _write_control(self, channel: int, word: int, what: str) -> None:
        what = f"{what}{self._channel(channel)}"
        response = await self._request(what, lambda c: c.write_register(
            channel * CHANNEL_STRIDE + Reg.CONTROL, word, device_id=self.config.device_id))
        problem = self._exception(response, what)
        if problem is not None:
            raise ControllerError(problem)

    async def sequence(self) -> int:
        """Completed moves as the controller counts them (diagnostics, tests)."""
        async with self._lock:
            await self._ensure_link()
            return (await self._read_status(0)).sequence


KIND = ControllerKind(
    name="modbus",
    config=ModbusControllerConfig,
    factory=lambda config, n, _geometry: ModbusController(config, n),
    summary="a Modbus TCP controller speaking the register map of `sim-actuator serve`, a "
    "register block per actuator",
    max_actuators=None,
)
