"""One front for the fake devices: start a simulated rig behind a real transport.

    dev = SimulatedDevice("modbus-tcp", realtime_rig(seed=1))   # or "modbus-rtu", "serial"
    link_config = dev.start()      # {"kind": "modbus-tcp", "host": "127.0.0.1", "port": 40123}
    ...                            # fdi_daemon.io.links.make_link(link_config) connects to it
    dev.set_fault("bearing_supply", 0.35)                         # while running
    dev.stop()

``start()`` returns a link config mapping that ``make_link`` accepts as is.
"""

from __future__ import annotations

from typing import Any

from hil_sim.devices.modbus_server import ModbusDevice
from hil_sim.devices.realtime import RealtimeRig
from hil_sim.devices.serial_device import SerialDevice

TRANSPORTS = ("modbus-tcp", "modbus-rtu", "serial")


class SimulatedDevice:
    """A `RealtimeRig` served over Modbus TCP, Modbus RTU on a pty, or serial frames on a pty.

    host/port: TCP bind address (port 0 picks a free port); link_path: a symlink kept
    pointing at the pty slave (a stable name across device restarts); device_id,
    word_order, fifo_depth: the Modbus register map's settings.
    """

    def __init__(
        self,
        transport: str,
        rt: RealtimeRig,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        link_path: str | None = None,
        device_id: int = 1,
        word_order: str = "big",
        fifo_depth: int = 256,
        seed: int = 0,
    ) -> None:
        if transport not in TRANSPORTS:
            raise ValueError(f"transport {transport!r} is not one of {', '.join(TRANSPORTS)}")
        self.transport = transport
        self.rt = rt
        self.host, self.port, self.link_path = host, port, link_path
        self.device_id, self.word_order = device_id, word_order
        self.modbus: ModbusDevice | None = None
        self.serial: SerialDevice | None = None
        if transport == "serial":
            self.serial = SerialDevice(rt, link_path=link_path, seed=seed)
        else:
            self.modbus = ModbusDevice(
                rt,
                device_id=device_id,
                word_order=word_order,  # type: ignore[arg-type]
                fifo_depth=fifo_depth,
            )
        self.link_config: dict[str, Any] = {}

    def start(self) -> dict[str, Any]:
        """Start serving; returns the link config that connects to this device."""
        if self.transport == "modbus-tcp":
            assert self.modbus is not None
            host, port = self.modbus.start_tcp(self.host, self.port)
            self.link_config = {
                "kind": "modbus-tcp",
                "host": host,
                "port": port,
                "device_id": self.device_id,
                "word_order": self.word_order,
            }
        elif self.transport == "modbus-rtu":
            assert self.modbus is not None
            path = self.modbus.start_rtu(self.link_path)
            self.link_config = {
                "kind": "modbus-rtu",
                "port": self.link_path or path,
                "device_id": self.device_id,
                "word_order": self.word_order,
            }
        else:
            assert self.serial is not None
            path = self.serial.start()
            self.link_config = {"kind": "serial", "port": self.link_path or path}
        return dict(self.link_config)

    @property
    def where(self) -> str:
        """Where to connect, as ``fdi sim serve`` prints it: host:port or the pty path."""
        if self.transport == "modbus-tcp":
            return f"{self.link_config['host']}:{self.link_config['port']}"
        return str(self.link_config["port"])

    def set_fault(self, name: str, value: float) -> None:
        self.rt.set_fault(name, value)

    def inject(self, kind: str, count: int = 0, seconds: float = 0.0, rate: float = 0.0) -> None:
        """Serial link faults (see `SerialDevice.inject`)."""
        if self.serial is None:
            raise ValueError("link-fault injection is only available on the serial device")
        self.serial.inject(kind, count=count, seconds=seconds, rate=rate)

    def status(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "transport": self.transport,
            "where": self.where,
            "seq": self.rt.rig.seq,
            "fs_hz": self.rt.fs_hz,
            "tick0_monotonic_s": self.rt.tick0_time,
            "faults": self.rt.faults(),
        }
        if self.serial is not None:
            out["injected"] = self.serial.injected()
        return out

    def stop(self) -> None:
        if self.serial is not None:
            self.serial.stop()
        if self.modbus is not None:
            self.modbus.stop()

    def __enter__(self) -> SimulatedDevice:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def parse_host_port(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (or ``:PORT`` for 127.0.0.1) -> (host, port); ValueError if malformed."""
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"{text!r} is not HOST:PORT (e.g. 127.0.0.1:5020)")
    return host or "127.0.0.1", int(port)


def serve_until_signalled(device: SimulatedDevice, stdin, stdout) -> None:
    """Start ``device``, print where to connect as the first stdout line, answer JSON-lines
    commands from stdin (see `hil_sim.devices.control`) and serve until SIGTERM or SIGINT."""
    import logging
    import signal
    import threading

    from hil_sim.devices.control import serve_commands

    # a client's bad request is answered with a Modbus exception; no traceback on stderr
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

    stop = threading.Event()
    previous = {
        sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGTERM, signal.SIGINT)
    }
    try:
        device.start()
        stdout.write(device.where + "\n")
        stdout.flush()
        threading.Thread(
            target=serve_commands, args=(device, stdin, stdout), daemon=True, name="device-control"
        ).start()
        while not stop.wait(0.5):
            pass
    finally:
        device.stop()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
