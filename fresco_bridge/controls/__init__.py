"""Controller adapters (OpenFresco: experimental controls): sim, modbus, mts."""
