"""Links (serial framing, Modbus register maps), recordings and sinks."""
