"""The controllers' wire formats, shared by both ends as pymodbus shares its framers: the
simulated rig's servers (``sim_actuator/servers``) and the bridge's adapters
(``fresco_bridge/controls``) import the same register map and line format. No I/O here."""
