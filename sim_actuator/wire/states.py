"""The controller state and fault codes, as both wire formats carry them (Modbus registers
STATE/FAULT_CODE by number, MTS-like lines by name)."""

from __future__ import annotations

from enum import IntEnum

__all__ = ["ControllerState", "FaultCode", "fault_name", "state_name"]


class ControllerState(IntEnum):
    """What the controller is doing (the Modbus STATE register value)."""

    IDLE = 0
    MOVING = 1
    DONE = 2
    FAULT = 3
    INTERLOCK = 4


class FaultCode(IntEnum):
    """Why the rig latched a fault (the Modbus FAULT_CODE register value)."""

    NONE = 0
    STROKE_LIMIT = 1
    FORCE_LIMIT = 2


def state_name(code: int) -> str:
    """The state word as a name; an unknown code says so."""
    try:
        return ControllerState(code).name
    except ValueError:
        return f"UNKNOWN({code})"


def fault_name(code: int) -> str:
    """The fault code as a name; an unknown code says so."""
    try:
        return FaultCode(code).name
    except ValueError:
        return f"UNKNOWN({code})"
