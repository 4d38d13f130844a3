"""fresco-bridge: the lab daemon between an FE integrator and the actuator controller."""

__version__ = "0.1.0"
