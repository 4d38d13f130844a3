"""The Modbus register map of the simulated rig's controller (version 1), for both ends.

0-based PDU addresses; float32 is IEEE-754 in two registers, **high word first** ("big" word
order, ABCD; ``mbpoll -B``); holding and input registers are one shared address space. The
table, the write semantics and the exception codes are documented in
``sim_actuator/servers/modbus.py`` (the server) and ``sim_actuator/README.md``.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from .states import fault_name, state_name

__all__ = [
    "CHANNEL_STRIDE",
    "CONTROL_HOLD",
    "CONTROL_RESET",
    "EXCEPTION_MEANINGS",
    "MAP_VERSION",
    "STATUS_COUNT",
    "Reg",
    "Status",
    "decode_float32",
    "encode_float32",
]

MAP_VERSION = 1
CONTROL_RESET = 0x0001
"""CONTROL bit 0: reset a latched fault."""
CONTROL_HOLD = 0x0002
"""CONTROL bit 1: the program interlock (a running move stops where it is)."""


class Reg:
    """Register addresses (first register of each float32)."""

    COMMAND = 0
    RAMP_TIME = 2
    EXECUTE = 4
    CONTROL = 5
    STATE = 10
    FAULT_CODE = 11
    MEAS_DISP = 12
    MEAS_FORCE = 14
    HEARTBEAT = 16
    SEQUENCE = 17
    TARGET = 18
    SIM_TIME = 20
    MAP_VERSION = 22
    CHANNELS = 23
    """Channels served (1 for one channel; an older one-channel server left it unmapped)."""
    EXT_DISP = 24
    """External displacement, float32 mm: the simulated rig's specimen displacement behind
    frame compliance, pin play and servo undershoot (a transducer on the specimen)."""


CHANNEL_STRIDE = 32
"""Channel c's block is the table above at addresses ``c * CHANNEL_STRIDE + Reg.*``: channel 0
is the one-actuator map itself."""


EXCEPTION_MEANINGS: dict[int, str] = {
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
"""What each Modbus exception code means for this controller."""


def encode_float32(value: float) -> list[int]:
    """Two registers, high word first; values beyond float32 range become +-inf."""
    try:
        raw = struct.pack(">f", value)
    except OverflowError:
        raw = struct.pack(">f", math.copysign(math.inf, value))
    high, low = struct.unpack(">HH", raw)
    return [high, low]


def decode_float32(words: list[int]) -> float:
    """Inverse of :func:`encode_float32`."""
    value: float = struct.unpack(">f", struct.pack(">HH", words[0], words[1]))[0]
    return value


STATUS_COUNT = Reg.SIM_TIME + 2 - Reg.STATE
"""The status block STATE .. SIM_TIME: 12 registers, read in one request."""
_STATUS_WORDS = struct.Struct(f">{STATUS_COUNT}H")
_STATUS_LAYOUT = struct.Struct(">HHffHHff")


@dataclass(frozen=True, slots=True)
class Status:
    """The status block: STATE, FAULT_CODE, MEAS_DISP, MEAS_FORCE, HEARTBEAT, SEQUENCE, TARGET,
    SIM_TIME."""

    state: int
    fault: int
    disp: float
    force: float
    heartbeat: int
    sequence: int
    target: float
    time: float

    @classmethod
    def parse(cls, words: list[int]) -> Status:
        """One unpack of the 12 registers (float32 high word first is big-endian bytes)."""
        return cls(*_STATUS_LAYOUT.unpack(_STATUS_WORDS.pack(*words)))

    def describe(self) -> str:
        return f"state {state_name(self.state)}, fault {self.fault} {fault_name(self.fault)}"
