"""JSON-lines control of a running fake device (``fdi sim serve`` reads them on stdin).

One JSON object per line in, one JSON object per line out (``{"ok": true, ...}`` or
``{"ok": false, "error": "..."}``):

- ``{"set": {"bearing_supply": 0.35, "accel_bias": 0.5}}``: change faults now (names as in
  the Modbus fault-control registers);
- ``{"inject": "corrupt" | "truncate", "count": N}``, ``{"inject": "garbage", "count": BYTES}``,
  ``{"inject": "stall", "seconds": S}``: link faults of the serial device;
- ``{"status": true}``: sample counter, fault settings and (serial) injection counts.
"""

from __future__ import annotations

import json
from typing import IO, Any

from hil_sim.devices.serve import SimulatedDevice


def handle_command(device: SimulatedDevice, line: str) -> dict[str, Any]:
    """Execute one command line; never raises for a bad command."""
    try:
        cmd = json.loads(line)
        if not isinstance(cmd, dict):
            raise ValueError("a command is a JSON object")
        if "set" in cmd:
            settings = cmd["set"]
            if not isinstance(settings, dict):
                raise ValueError('"set" takes an object of fault: value')
            for name, value in settings.items():
                device.set_fault(name, float(value))
            return {"ok": True, "faults": device.rt.faults()}
        if "inject" in cmd:
            device.inject(
                str(cmd["inject"]),
                count=int(cmd.get("count", 0)),
                seconds=float(cmd.get("seconds", 0.0)),
                rate=float(cmd.get("rate", 0.0)),
            )
            return {"ok": True}
        if "status" in cmd:
            return {"ok": True, "status": device.status()}
        raise ValueError('unknown command (use "set", "inject" or "status")')
    except (ValueError, TypeError) as exc:  # json.JSONDecodeError is a ValueError
        return {"ok": False, "error": str(exc)}


def serve_commands(device: SimulatedDevice, stream_in: IO[str], stream_out: IO[str]) -> None:
    """Answer command lines from ``stream_in`` until it ends (blank lines are skipped)."""
    for line in stream_in:
        if not line.strip():
            continue
        stream_out.write(json.dumps(handle_command(device, line)) + "\n")
        stream_out.flush()
