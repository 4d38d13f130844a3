"""Network faces of the simulated rig: Modbus TCP and an MTS-CSI-like line protocol.

Both wrap one :class:`~sim_actuator.servers.controller.RigController`, which owns the rig and
its state machine; ``sim-actuator serve`` runs one of them as its own process.
"""

from sim_actuator.servers.controller import ControllerState, RigController
from sim_actuator.servers.modbus import ModbusRigServer
from sim_actuator.servers.mts_stub import MtsStubServer

__all__ = ["ControllerState", "ModbusRigServer", "MtsStubServer", "RigController"]
