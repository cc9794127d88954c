"""Fake DAQ devices driven by the simulated rig in real time (256 Hz on the monotonic clock).

- `realtime.realtime_rig(scenario, seed, faults)` -> `RealtimeRig` (fault schedule changeable
  while running);
- `serve.SimulatedDevice(transport, rt)`: transport ``modbus-tcp`` | ``modbus-rtu`` (pty) |
  ``serial`` (pty); ``start()`` returns the link config for ``make_link``;
- `control`: JSON-lines fault control (stdin of ``fdi sim serve``).

Protocols: ``docs/protocols.md``.
"""

from hil_sim.devices.realtime import RealtimeRig, ScheduledFault, realtime_rig
from hil_sim.devices.serve import SimulatedDevice

__all__ = ["RealtimeRig", "ScheduledFault", "SimulatedDevice", "realtime_rig"]
