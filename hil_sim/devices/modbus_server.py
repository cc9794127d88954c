"""Fake DAQ device: the register map of ``fdi_daemon.io.modbus_map`` served over Modbus TCP
or Modbus RTU on a pty, fed by the rig in real time.

pymodbus 3.16 server API: a `SimDevice` with separate blocks (coils, discrete inputs,
holding registers, input registers) and an ``action`` callback that fills the input
registers from the live FIFO on every read and applies fault-control writes to the rig.
The event loop runs in a background thread that also advances the rig, so register reads
and sample publishing never race. TCP binds 127.0.0.1 unless told otherwise. RTU: the
device opens a pty, serves on the master side and reports the slave path (optionally also
a stable symlink to it, replaced on restart) for the client to open.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import math
import os
import threading
import time
import tty

from fdi_daemon.io import modbus_map as mm
from hil_sim.devices.realtime import DeviceSample, RealtimeRig


class RegisterImage:
    """Device-side register contents: header + FIFO of encoded slots + fault registers."""

    def __init__(
        self,
        rt: RealtimeRig,
        word_order: mm.WordOrder = "big",
        fifo_depth: int = 256,
        scales: tuple[float, float, float] = (1.0, 1.0, 1.0),
    ) -> None:
        if not 1 <= fifo_depth <= (65536 - mm.HEADER_REGS) // mm.WORDS_PER_SAMPLE:
            raise ValueError(f"fifo_depth {fifo_depth} does not fit the register space")
        self.rt = rt
        self.word_order = word_order
        self.fifo_depth = int(fifo_depth)
        self.scales = scales
        self.counter = 0
        self._fifo: collections.deque[list[int]] = collections.deque(maxlen=self.fifo_depth)
        self._saturated = False

    @property
    def input_size(self) -> int:
        return mm.slot_address(self.fifo_depth)

    def publish(self, samples: list[DeviceSample]) -> None:
        wo = self.word_order
        sv, sa, sp = self.scales
        for s in samples:
            self._fifo.appendleft(
                mm.encode_slot(s.seq, s.v_in / sv, s.accel / sa, s.position / sp, wo)
            )
            self.counter = s.seq + 1
        if samples:
            self._saturated = samples[-1].saturated

    def header(self) -> mm.Header:
        status = mm.STATUS_RUNNING
        if self._saturated:
            status |= mm.STATUS_SATURATED
        if self.rt.fault_injected:
            status |= mm.STATUS_FAULT_INJECTED
        return mm.Header(
            self.counter,
            int(round(self.rt.fs_hz)),
            status,
            self.fifo_depth,
            len(self._fifo),
            mm.MAP_VERSION,
            mm.WORDS_PER_SAMPLE,
            *self.scales,
        )

    def fill_inputs(self, registers: list[int], offset: int, count: int) -> None:
        """Write the live values of input registers [offset, offset + count) into ``registers``."""
        end = offset + count
        if offset < mm.HEADER_REGS:
            head = mm.encode_header(self.header(), self.word_order)
            stop = min(end, mm.HEADER_REGS)
            registers[offset:stop] = head[offset:stop]
        first = max(0, (offset - mm.HEADER_REGS) // mm.WORDS_PER_SAMPLE)
        last = (end - 1 - mm.HEADER_REGS) // mm.WORDS_PER_SAMPLE
        empty = [0] * mm.WORDS_PER_SAMPLE
        for j in range(first, last + 1):
            slot = self._fifo[j] if j < len(self._fifo) else empty
            base = mm.slot_address(j)
            lo, hi = max(offset, base), min(end, base + mm.WORDS_PER_SAMPLE)
            registers[lo:hi] = slot[lo - base : hi - base]

    def fill_holding(self, registers: list[int]) -> None:
        registers[0 : mm.FAULT_REGS] = mm.encode_faults(self.rt.faults(), self.word_order)

    def write_holding(self, offset: int, values: list[int]) -> bool:
        """Apply a fault-control write; False (and nothing applied) if a value is invalid."""
        if offset < 0 or offset + len(values) > mm.FAULT_REGS:
            return False
        image = mm.encode_faults(self.rt.faults(), self.word_order)
        image[offset : offset + len(values)] = values
        new = mm.decode_faults(image, self.word_order)
        end = offset + len(values)
        changed = {
            name: new[name]
            for name, (reg, _) in mm.FAULT_REGISTERS.items()
            if reg < end and offset < reg + 2
        }  # the values this write touched
        for name, value in changed.items():
            if not math.isfinite(value) or (value < 0 and name != "accel_bias"):
                return False
        for name, value in changed.items():
            self.rt.set_fault(name, value)
        return True


class _PtyTransport(asyncio.Transport):
    """Write side of the pty master for the pymodbus request handler."""

    def __init__(self, fd: int) -> None:
        super().__init__()
        self._fd = fd
        self._closing = False

    def write(self, data: bytes) -> None:
        with contextlib.suppress(BlockingIOError):  # nobody reading: a lost reply, as on a wire
            os.write(self._fd, data)

    def close(self) -> None:
        self._closing = True

    def is_closing(self) -> bool:
        return self._closing


class ModbusDevice:
    """The fake DAQ as a Modbus server in a background thread.

    ``start_tcp(host, port)`` -> (host, port) actually bound (port 0 picks a free one);
    ``start_rtu(link_path=None)`` -> slave path of the pty to open; ``stop()``.
    """

    def __init__(
        self,
        rt: RealtimeRig,
        device_id: int = 1,
        word_order: mm.WordOrder = "big",
        fifo_depth: int = 256,
        scales: tuple[float, float, float] = (1.0, 1.0, 1.0),
    ) -> None:
        if not 1 <= device_id <= 247:
            raise ValueError(f"device id {device_id} is not in 1..247")
        self.rt = rt
        self.device_id = device_id
        self.image = RegisterImage(rt, word_order, fifo_depth, scales)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._stop: asyncio.Event | None = None
        self._where: object = None
        self._link_path: str | None = None

    # ------------------------------------------------------------------ public
    def start_tcp(self, host: str = "127.0.0.1", port: int = 0) -> tuple[str, int]:
        return self._start(self._serve_tcp(host, port))  # type: ignore[return-value]

    def start_rtu(self, link_path: str | None = None) -> str:
        self._link_path = link_path
        return self._start(self._serve_rtu())  # type: ignore[return-value]

    def stop(self, timeout_s: float = 5.0) -> None:
        if self._loop is not None and self._stop is not None and self._thread is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
            self._thread.join(timeout_s)
        self._thread = None
        if self._link_path:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self._link_path)

    # ------------------------------------------------------------------ internals
    def _start(self, coro) -> object:
        if self._thread is not None:
            raise RuntimeError("device already started")

        def body() -> None:
            try:
                asyncio.run(coro)
            except BaseException as exc:  # reported to the starting thread
                self._error = exc
                self._ready.set()

        self._thread = threading.Thread(target=body, name="fake-modbus-device", daemon=True)
        self._thread.start()
        self._ready.wait()
        if self._error is not None:
            raise self._error
        return self._where

    def _simdevice(self):
        from pymodbus.constants import ExcCodes
        from pymodbus.simulator import DataType, SimData, SimDevice

        image = self.image

        async def action(function_code, start_address, address, count, registers, values):
            offset = address - start_address
            if function_code == 4:
                image.fill_inputs(registers, offset, count)
            elif function_code == 3:
                image.fill_holding(registers)
            elif values is not None and not image.write_holding(offset, list(values)):
                return ExcCodes.ILLEGAL_VALUE
            return None

        bits = [SimData(0, values=[False] * 16, datatype=DataType.BITS)]
        holding = [SimData(0, count=mm.FAULT_REGS, values=0, datatype=DataType.REGISTERS)]
        inputs = [
            SimData(0, count=image.input_size, values=0, datatype=DataType.REGISTERS, readonly=True)
        ]
        return SimDevice(
            id=self.device_id, simdata=(bits, list(bits), holding, inputs), action=action
        )

    async def _tick(self) -> None:
        rt = self.rt
        while True:
            delay = rt.next_tick_time - time.monotonic()
            if delay > 0:
                await asyncio.sleep(delay)
            self.image.publish(rt.advance())

    async def _run_until_stopped(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        self.rt.start()  # before "ready": status() and tick0_time are valid once start returns
        ticker = asyncio.create_task(self._tick())
        self._ready.set()
        await self._stop.wait()
        ticker.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await ticker

    async def _serve_tcp(self, host: str, port: int) -> None:
        from pymodbus.server import ModbusTcpServer

        server = ModbusTcpServer([self._simdevice()], address=(host, port))
        await server.serve_forever(background=True)
        sock = server.transport.sockets[0]  # type: ignore[attr-defined]
        self._where = (host, sock.getsockname()[1])
        try:
            await self._run_until_stopped()
        finally:
            await server.shutdown()

    async def _serve_rtu(self) -> None:
        from pymodbus.framer import FramerType
        from pymodbus.server import ModbusSerialServer

        master, slave = os.openpty()
        tty.setraw(slave)  # no echo or line editing before the client configures the port
        os.set_blocking(master, False)
        path = os.ttyname(slave)
        if self._link_path:
            tmp = f"{self._link_path}.tmp{os.getpid()}"
            os.symlink(path, tmp)
            os.replace(tmp, self._link_path)
        # The server object gives the RTU framer and request handling; the pty is our transport.
        server = ModbusSerialServer([self._simdevice()], framer=FramerType.RTU, port=path)
        handler = server.handle_new_connection()
        handler.connection_made(_PtyTransport(master))
        loop = asyncio.get_running_loop()

        def on_readable() -> None:
            try:
                data = os.read(master, 4096)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # cannot happen while we hold the slave open; never spin on it
                loop.remove_reader(master)
                return
            if data:
                handler.data_received(data)

        loop.add_reader(master, on_readable)
        self._where = path
        try:
            await self._run_until_stopped()
        finally:
            loop.remove_reader(master)
            os.close(master)
            os.close(slave)
