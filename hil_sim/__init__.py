"""Software-in-the-loop pneumatic rig: physics, scenarios, fake devices (Modbus, serial)."""
