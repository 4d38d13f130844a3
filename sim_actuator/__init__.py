"""A simulated structural test rig: specimen hysteresis, actuator dynamics, unmodelled effects."""
