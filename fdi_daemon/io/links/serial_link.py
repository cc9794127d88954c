"""Serial link: the streaming device's frames (``fdi_daemon.io.serial_frames``) over pyserial.

Opens the port by path (a real tty, or the slave side of a pty such as the one
``fdi sim serve --serial`` prints), exclusively. A device that goes away (pty master
closed, USB adapter unplugged) makes ``read`` raise `LinkError`.
"""

from __future__ import annotations

from fdi_daemon.io.links.base import Link, LinkError
from fdi_daemon.io.sample import Sample
from fdi_daemon.io.serial_frames import FrameDecoder


class SerialLink(Link):
    kind = "serial"

    def __init__(self, port: str, baudrate: int = 115200, fs_hz: float = 256.0) -> None:
        self.port = port
        self.baudrate = int(baudrate)
        self.fs_hz = float(fs_hz)
        self.decoder = FrameDecoder(fs_hz)
        self._serial = None
        self._samples = 0
        self._bytes = 0

    def describe(self) -> str:
        return f"serial {self.port} @ {self.baudrate} Bd"

    def open(self) -> None:
        import serial

        try:
            self._serial = serial.Serial(self.port, self.baudrate, timeout=0, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise LinkError(f"cannot open serial port {self.port}: {exc}") from None

    def read(self, timeout_s: float) -> list[Sample]:
        import serial

        if self._serial is None:
            raise LinkError(f"serial port {self.port} is not open")
        ser = self._serial
        try:
            if ser.timeout != max(0.0, timeout_s):  # setting it reconfigures the port
                ser.timeout = max(0.0, timeout_s)
            data = ser.read(max(1, ser.in_waiting))  # blocks until a byte or the timeout
            if data:
                data += ser.read(ser.in_waiting) if ser.in_waiting else b""
        except (serial.SerialException, OSError) as exc:
            raise LinkError(f"serial port {self.port}: {exc}") from None
        if not data:
            return []
        self._bytes += len(data)
        samples = self.decoder.feed(data)
        self._samples += len(samples)
        return samples

    def close(self) -> None:
        if self._serial is not None:
            ser, self._serial = self._serial, None
            ser.close()

    def counters(self) -> dict[str, int]:
        return {"samples": self._samples, "bytes": self._bytes, **self.decoder.counters()}
