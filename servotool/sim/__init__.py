"""The simulated drive: register bank, drive behaviour, plant physics, Modbus server."""
