"""fresco-bridge: the lab daemon between an FE integrator and the actuator controller."""

from ._compiled import pure_requested as _pure_requested
from ._compiled import use_pure_sources as _use_pure_sources

if _pure_requested():  # FRESCO_BRIDGE_PURE=1: run the pure sources of the compiled modules
    _use_pure_sources()

__version__ = "0.1.0"
