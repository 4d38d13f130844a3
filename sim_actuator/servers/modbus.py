"""Modbus TCP face of the simulated rig (pymodbus 3.16 SimDevice datastore).

The register map (0-based PDU addresses; float32 is IEEE-754 in two registers, **high word
first** ("big" word order, ABCD; ``mbpoll -B``); holding and input registers are one shared
address space, so FC03 and FC04 read the same values):

====== ============ ======== ==== ===========================================================
addr   name         type     acc  meaning
====== ============ ======== ==== ===========================================================
0-1    COMMAND      float32  rw   target displacement, mm (absolute)
2-3    RAMP_TIME    float32  rw   ramp time of the next move, s (0 = step)
4      EXECUTE      uint16   rw   write 1: start a move to COMMAND over RAMP_TIME; 0: no-op
5      CONTROL      uint16   rw   bit0 (1): reset a latched fault; bit1 (2): program interlock
6-9    -            -        -    not mapped: exception 02 (illegal data address)
10     STATE        uint16   ro   0 IDLE, 1 MOVING, 2 DONE, 3 FAULT, 4 INTERLOCK
11     FAULT_CODE   uint16   ro   0 none, 1 stroke limit, 2 force limit
12-13  MEAS_DISP    float32  ro   measured displacement at the end of the last move, mm
14-15  MEAS_FORCE   float32  ro   measured force at the end of the last move, kN
16     HEARTBEAT    uint16   ro   +1 at a fixed rate (default 10 Hz), wraps at 65536
17     SEQUENCE     uint16   ro   completed moves, wraps at 65536
18-19  TARGET       float32  ro   target of the current or last accepted move, mm
20-21  SIM_TIME     float32  ro   simulated time, s
22     MAP_VERSION  uint16   ro   1
23     CHANNELS     uint16   ro   channels served
24-25  EXT_DISP     float32  ro   external displacement at the end of the last move: the
                                  specimen's, behind frame compliance and pin play, mm
====== ============ ======== ==== ===========================================================

Every write of 1 to EXECUTE is a trigger (no 0 -> 1 edge needed; the register reads back what
was written, so FC06 echoes stay valid). A write that covers COMMAND..EXECUTE in one FC16 or
FC23 request is atomic: the new command and ramp time are used. Re-executing the running
move's own target and ramp time is a harmless no-op; re-executing after DONE runs a move of
zero length. When CONTROL and EXECUTE are in one write, CONTROL acts first.

Several channels (``sim-actuator serve --channels N``): channel c's block is the same table at
``c * 32 + addr`` (``CHANNEL_STRIDE``), each driving its own rig; register 23 (CHANNELS, ro) of
every block reads N (1 for one channel), so STATE .. EXT_DISP is one contiguous read.

Exception codes: 01 coil/discrete-input functions; 02 unmapped address or write to a read-only
register (from pymodbus); 03 EXECUTE or CONTROL value not allowed, command not finite, ramp time
outside [0, max], or target beyond the stroke (the controller then also latches FAULT with
FAULT_CODE 1, nothing moves); 04 execute while FAULT or INTERLOCK; 06 execute of a different
target while MOVING. Any unit id is accepted.
"""

from __future__ import annotations

import logging

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from sim_actuator.servers.controller import (
    CommandRejected,
    ControllerBusy,
    ControllerError,
    ControllerFaulted,
    ControllerInterlocked,
    LimitExceeded,
    RigController,
)
from sim_actuator.wire.modbus_map import (  # the one register map, shared with the bridge
    CHANNEL_STRIDE,
    CONTROL_HOLD,
    CONTROL_RESET,
    MAP_VERSION,
    Reg,
    decode_float32,
    encode_float32,
)

__all__ = [
    "CONTROL_HOLD",
    "CONTROL_RESET",
    "MAP_VERSION",
    "ModbusRigServer",
    "Reg",
    "decode_float32",
    "encode_float32",
]

_log = logging.getLogger(__name__)

_WRITE_FUNCTIONS = frozenset((6, 16, 23))
_BIT_FUNCTIONS = frozenset((1, 2, 5, 15))


class ModbusRigServer:
    """A pymodbus TCP server whose register map drives one :class:`RigController` per
    channel (a register block each)."""

    def __init__(self, controller: RigController | list[RigController], *,
                 host: str = "127.0.0.1", port: int = 502) -> None:
        self.controllers = controller if isinstance(controller, list) else [controller]
        if not self.controllers:
            raise ValueError("a Modbus rig server needs at least one channel")
        self.controller = self.controllers[0]
        self.host = host
        self.port = port
        self._server: ModbusTcpServer | None = None

    def _device(self) -> SimDevice:
        blocks: list[SimData] = []
        for channel, controller in enumerate(self.controllers):
            base, rig = channel * CHANNEL_STRIDE, controller.rig
            blocks += [
                SimData(base + Reg.COMMAND, count=1, values=encode_float32(rig.command),
                        datatype=DataType.REGISTERS),
                SimData(base + Reg.RAMP_TIME, count=1,
                        values=encode_float32(rig.default_ramp_time),
                        datatype=DataType.REGISTERS),
                SimData(base + Reg.EXECUTE, count=2, values=0, datatype=DataType.REGISTERS),
                SimData(base + Reg.STATE, count=Reg.EXT_DISP + 2 - Reg.STATE, values=0,
                        datatype=DataType.REGISTERS, readonly=True),
            ]
        # id 0: answer whatever unit id a master uses, as Modbus TCP servers usually do
        return SimDevice(id=0, simdata=blocks, action=self._action)

    async def start(self) -> tuple[str, int]:
        """Listen; return the bound (host, port) (port 0 picks a free one)."""
        self._server = ModbusTcpServer(self._device(), address=(self.host, self.port))
        await self._server.serve_forever(background=True)
        transport = self._server.transport
        sockets = getattr(transport, "sockets", None)
        if sockets:
            self.host, self.port = sockets[0].getsockname()[:2]
        return self.host, self.port

    async def stop(self) -> None:
        """Close the listener and every connection."""
        if self._server is not None:
            await self._server.shutdown()  # type: ignore[no-untyped-call]
            self._server = None

    # -- the datastore hook ------------------------------------------------------------------

    async def _action(
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: list[int],
        set_values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """Called by pymodbus before every request is served; never raises."""
        del count
        try:
            if function_code in _BIT_FUNCTIONS:
                return ExcCodes.ILLEGAL_FUNCTION
            if set_values is not None and function_code in _WRITE_FUNCTIONS:
                values = [int(v) for v in set_values]
                rejected = self._on_write(start_address, address, registers, values)
                if rejected is not None:
                    return rejected
            self._refresh(start_address, registers)
        except Exception:  # a bug here must not take the server down
            _log.exception("modbus action failed (fc=%s, address=%s)", function_code, address)
            return ExcCodes.DEVICE_FAILURE
        return None

    def _on_write(self, start: int, address: int, registers: list[int],
                  values: list[int]) -> ExcCodes | None:
        channel, base = address // CHANNEL_STRIDE, address // CHANNEL_STRIDE * CHANNEL_STRIDE
        if channel >= len(self.controllers) or \
                (address + len(values) - 1) // CHANNEL_STRIDE != channel:
            return ExcCodes.ILLEGAL_ADDRESS  # one write, one channel
        controller = self.controllers[channel]
        view = list(registers)
        view[address - start : address - start + len(values)] = values
        touched = range(address - base, address - base + len(values))

        def word(addr: int) -> int:
            return view[base + addr - start]

        if Reg.CONTROL in touched:
            control = word(Reg.CONTROL)
            if control & ~(CONTROL_RESET | CONTROL_HOLD):
                return ExcCodes.ILLEGAL_VALUE
            if control & CONTROL_RESET:
                controller.reset()
            controller.set_interlock(bool(control & CONTROL_HOLD))
        if Reg.EXECUTE in touched:
            execute = word(Reg.EXECUTE)
            if execute not in (0, 1):
                return ExcCodes.ILLEGAL_VALUE
            if execute == 1:
                target = decode_float32([word(Reg.COMMAND), word(Reg.COMMAND + 1)])
                ramp = decode_float32([word(Reg.RAMP_TIME), word(Reg.RAMP_TIME + 1)])
                return self._execute(controller, target, ramp)
        return None

    def _execute(self, controller: RigController, target: float,
                 ramp_time: float) -> ExcCodes | None:
        try:
            controller.execute(target, ramp_time)
        except (CommandRejected, LimitExceeded) as exc:
            _log.info("execute refused: %s", exc)
            return ExcCodes.ILLEGAL_VALUE
        except ControllerBusy as exc:
            _log.info("execute refused: %s", exc)
            return ExcCodes.DEVICE_BUSY
        except (ControllerFaulted, ControllerInterlocked) as exc:
            _log.info("execute refused: %s", exc)
            return ExcCodes.DEVICE_FAILURE
        except ControllerError as exc:  # pragma: no cover - every subclass is mapped above
            _log.info("execute refused: %s", exc)
            return ExcCodes.DEVICE_FAILURE
        return None

    def _refresh(self, start: int, registers: list[int]) -> None:
        """Copy every channel's state into its read-only block before a request is served."""
        n = len(self.controllers)
        for channel, c in enumerate(self.controllers):
            base = channel * CHANNEL_STRIDE - start

            def put(addr: int, words: list[int], base: int = base) -> None:
                registers[base + addr : base + addr + len(words)] = words

            put(Reg.STATE, [int(c.state)])
            put(Reg.FAULT_CODE, [int(c.fault)])
            put(Reg.MEAS_DISP, encode_float32(c.measurement.displacement))
            put(Reg.MEAS_FORCE, encode_float32(c.measurement.force))
            put(Reg.HEARTBEAT, [c.heartbeat & 0xFFFF])
            put(Reg.SEQUENCE, [c.sequence & 0xFFFF])
            put(Reg.TARGET, encode_float32(c.target))
            put(Reg.SIM_TIME, encode_float32(c.rig.time))
            put(Reg.MAP_VERSION, [MAP_VERSION])
            put(Reg.EXT_DISP, encode_float32(c.measurement.specimen_displacement))
            put(Reg.CHANNELS, [n])
