"""fresco-bridge: the lab daemon between an FE integrator and the actuator controller."""

import os as _os

if _os.environ.get("FRESCO_BRIDGE_PURE", "") not in ("", "0"):  # run the pure sources
    from ._compiled import use_pure_sources

    use_pure_sources()

__version__ = "0.1.0"
